//! The node's watchdogs: its heartbeat, the staleness of each axis's feedback, and the time
//! the enable sequence may take.

use std::time::Duration;

use super::fault::DriveFault;
use super::{DriveNode, Phase};
use crate::devices::can::Frame;
use crate::devices::cia402::state::DriveState;
use crate::time::Timestamp;

impl DriveNode {
    /// A heartbeat silent beyond its timeout: fault, command standstill (in case only the
    /// heartbeat is missing), and boot the node again. Returns whether it was lost.
    pub(super) fn check_heartbeat(&mut self, t: Timestamp, out: &mut Vec<Frame>) -> bool {
        let Some(last) = self.last_heartbeat else {
            return false;
        };
        if t.saturating_since(last) <= self.settings.heartbeat_timeout {
            return false;
        }
        self.raise(DriveFault::HeartbeatLost);
        self.phase = Phase::Booting {
            since: t,
            attempts: 0,
        };
        self.send_stop(out);
        self.sdo.clear();
        true
    }

    /// An axis silent beyond the feedback timeout faults, heartbeats or not.
    pub(super) fn check_feedback(&mut self, t: Timestamp) {
        if let Some(axis) =
            (0..self.axes.len()).find(|&a| self.feedback_age(t, a) > self.settings.feedback_timeout)
        {
            self.raise(DriveFault::FeedbackStale { axis });
        }
    }

    /// An enable asked for longer than the enable timeout without reaching it faults.
    pub(super) fn check_enable(&mut self, t: Timestamp, state: Option<DriveState>) {
        if let (Some(state), Some(asked)) = (state, self.enable_asked_at)
            && state != DriveState::OperationEnabled
            && t.saturating_since(asked) > self.settings.enable_timeout
        {
            self.raise(DriveFault::EnableTimeout { state });
        }
    }

    /// How long since `axis` last reported (since running, if it never did).
    pub(super) fn feedback_age(&self, t: Timestamp, axis: usize) -> Duration {
        let last = self
            .axes
            .get(axis)
            .and_then(|a| a.rx)
            .into_iter()
            .chain(self.running_since)
            .max();
        last.map_or(Duration::ZERO, |last| t.saturating_since(last))
    }
}
