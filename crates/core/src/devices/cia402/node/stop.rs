//! The last act: quick stop and zero targets, on exit, on a panic (frames computed ahead)
//! and when the node's heartbeat is lost.

use super::command::target_writes;
use super::{DriveNode, Phase};
use crate::devices::can::Frame;
use crate::devices::canopen::sdo::{SdoData, SdoRequest};
use crate::devices::cia402::profile::Transport;
use crate::devices::cia402::state::{Goal, controlword};

impl DriveNode {
    /// The frames that quick-stop this drive with zero targets, whatever its state: the
    /// RPDOs, or SDO writes of the controlword and targets (sent without waiting for
    /// answers). For the last act on exit or panic; empty in listen-only mode.
    pub fn stop_frames(&self) -> Vec<Frame> {
        if self.monitor {
            return Vec::new();
        }
        let node = self.settings.node;
        let zero = vec![0; self.targets.len()];
        match self.profile.command.mode {
            Transport::Pdo => self
                .rpdos
                .iter()
                .filter_map(|(cob, mapping)| {
                    let values: Vec<i64> = mapping
                        .entries()
                        .iter()
                        .map(|e| {
                            if e.object == self.profile.objects.controlword {
                                i64::from(controlword::QUICK_STOP)
                            } else {
                                0
                            }
                        })
                        .collect();
                    Frame::standard(*cob, &mapping.pack(&values))
                })
                .collect(),
            Transport::Sdo => std::iter::once(SdoRequest::Write(
                self.profile.objects.controlword,
                SdoData::u16(controlword::QUICK_STOP),
            ))
            .chain(target_writes(&self.profile, &zero))
            .map(|r| r.frame(node))
            .collect(),
        }
    }

    /// Quick stop now, zero targets, and stay stopped: the daemon is exiting. The frames
    /// go to `out`.
    pub fn shut_down(&mut self, out: &mut Vec<Frame>) {
        self.goal = Goal::QuickStop;
        self.enable_asked_at = None;
        self.targets.iter_mut().for_each(|x| *x = 0);
        if self.phase == Phase::Running && !self.monitor {
            self.send_stop(out);
        }
    }

    /// Zero targets and a quick stop, sent straight away.
    pub(super) fn send_stop(&mut self, out: &mut Vec<Frame>) {
        self.targets.iter_mut().for_each(|x| *x = 0);
        self.controlword = controlword::QUICK_STOP;
        out.extend(self.stop_frames());
        self.sent_controlword = Some(self.controlword);
        self.sent_targets = Some(self.targets.clone());
    }
}
