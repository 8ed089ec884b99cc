//! NMT boot of a node: reset communication, wait for the boot-up, set it up over SDO, start
//! it; again from the start when the interface comes back or the node reboots.

use super::fault::DriveFault;
use super::{AxisFeedback, DriveNode, Phase, Tag};
use crate::devices::can::Frame;
use crate::devices::canopen::nmt::{NmtCommand, NmtState};
use crate::time::Timestamp;

impl DriveNode {
    /// Starts (or restarts) the node: NMT reset communication, then set-up on boot-up.
    pub fn start(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        self.sdo.clear();
        self.reset = None;
        self.running_since = None;
        self.controlword = 0;
        self.nmt = None;
        self.axes
            .iter_mut()
            .for_each(|a| *a = AxisFeedback::default());
        self.sent_controlword = None;
        self.queued_controlword = None;
        self.sent_targets = None;
        self.phase = Phase::Booting {
            since: t,
            attempts: 1,
        };
        self.stats.resets += 1;
        out.push(NmtCommand::ResetCommunication.frame(Some(self.settings.node)));
    }

    /// The interface went down.
    pub fn link_down(&mut self) {
        if self.phase == Phase::Running && self.fault.is_none() {
            self.fault = Some(DriveFault::LinkDown);
        }
        self.phase = Phase::Offline;
        self.sdo.clear();
        self.last_heartbeat = None;
    }

    /// The interface is (back) up: contact the node again. A latched fault stays latched.
    pub fn link_up(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if self.phase == Phase::Offline {
            self.start(t, out);
        }
    }

    pub(super) fn on_heartbeat(&mut self, t: Timestamp, frame: &Frame, out: &mut Vec<Frame>) {
        let Some(state) = frame
            .data()
            .first()
            .and_then(|b| NmtState::from_heartbeat(*b))
        else {
            return;
        };
        self.stats.heartbeats += 1;
        self.nmt = Some(state);
        self.last_heartbeat = Some(t);
        match (self.phase, state) {
            (Phase::Booting { .. }, _) => self.configure(t, out),
            // A second boot-up while setting up (a repeated reset): start the set-up over.
            (Phase::Configuring, NmtState::BootUp) => self.configure(t, out),
            (Phase::Running, NmtState::BootUp) => {
                // It lost its set-up while running: stop, and set it up again.
                self.raise(DriveFault::Rebooted);
                self.configure(t, out);
            }
            _ => {}
        }
    }

    pub(super) fn configure(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        self.sdo.clear();
        self.queued_controlword = None;
        self.sent_controlword = None;
        self.phase = Phase::Configuring;
        for (i, request) in self.setup.iter().enumerate() {
            self.sdo.push(*request, Tag::Setup(i));
        }
        self.poll_sdo(t, out);
    }

    pub(super) fn finish_setup(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        out.push(NmtCommand::Start.frame(Some(self.settings.node)));
        self.phase = Phase::Running;
        self.running_since = Some(t);
        self.next_poll = t;
        self.next_command = t;
        // Feedback first, so the controlword follows the drive's real state.
        self.request_feedback();
    }
}
