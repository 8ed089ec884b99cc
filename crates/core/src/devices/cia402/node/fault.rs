//! Faults of a node, and the CiA 402 fault-reset handshake: bit 7 of the controlword low for
//! a cycle, then the rising edge, on every attempt; the fault stays latched until the
//! statusword leaves Fault, and the attempts are bounded.

use std::fmt;

use super::{DriveNode, Phase};
use crate::devices::canopen::ObjectAddress;
use crate::devices::canopen::emcy::Emcy;
use crate::devices::canopen::sdo::AbortCode;
use crate::devices::cia402::state::{DriveState, Goal, controlword, next_controlword};
use crate::time::Timestamp;

/// Why a drive stopped. Latched until the owner resets it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DriveFault {
    /// The CAN interface went down.
    LinkDown,
    /// No heartbeat within the timeout.
    HeartbeatLost,
    /// The node rebooted (unexpected boot-up) and lost its set-up.
    Rebooted,
    /// The drive reports a fault in its statusword.
    Drive {
        /// Axis, 0-based.
        axis: usize,
        /// The statusword.
        statusword: u16,
    },
    /// An emergency message.
    Emcy(Emcy),
    /// An SDO transfer was aborted.
    SdoAbort {
        /// The object.
        object: ObjectAddress,
        /// The abort code.
        code: AbortCode,
    },
    /// An SDO transfer got no answer.
    SdoTimeout {
        /// The object.
        object: ObjectAddress,
    },
    /// The enable sequence did not reach operation enabled in time.
    EnableTimeout {
        /// Where it stopped.
        state: DriveState,
    },
    /// No feedback from an axis within the feedback timeout, though the node may still send
    /// heartbeats.
    FeedbackStale {
        /// Axis, 0-based.
        axis: usize,
    },
}

impl DriveFault {
    /// Whether communication with the node is in doubt (as opposed to the drive refusing).
    pub fn is_communication(&self) -> bool {
        matches!(
            self,
            Self::LinkDown | Self::HeartbeatLost | Self::Rebooted | Self::SdoTimeout { .. }
        )
    }
}

impl fmt::Display for DriveFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::LinkDown => write!(f, "CAN interface down"),
            Self::HeartbeatLost => write!(f, "heartbeat lost"),
            Self::Rebooted => write!(f, "node rebooted unexpectedly"),
            Self::Drive { axis, statusword } => {
                write!(
                    f,
                    "drive fault on axis {} (statusword 0x{statusword:04X})",
                    axis + 1
                )
            }
            Self::Emcy(e) => write!(f, "{e}"),
            Self::SdoAbort { object, code } => write!(f, "SDO {object} aborted: {code}"),
            Self::SdoTimeout { object } => write!(f, "SDO {object} timed out"),
            Self::EnableTimeout { state } => write!(f, "enable timed out in state {state}"),
            Self::FeedbackStale { axis } => write!(f, "no feedback from axis {}", axis + 1),
        }
    }
}

/// A fault reset under way: bit 7 low for at least a cycle, then the rising edge, then the
/// statusword must leave Fault within the wait; else the next attempt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct FaultReset {
    /// 1-based.
    attempt: u8,
    step: ResetStep,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum ResetStep {
    /// Bit 7 low, since this tick.
    Low(Timestamp),
    /// Bit 7 high (the edge) since this tick.
    Edge(Timestamp),
}

impl DriveNode {
    /// Resets a latched fault (the owner's deliberate act). A drive in Fault gets the reset
    /// handshake and its fault stays latched until the statusword leaves Fault; other faults
    /// clear at once if their condition is gone. Only a running node can be reset; returns
    /// whether the fault is cleared or being reset.
    pub fn reset_fault(&mut self, t: Timestamp) -> bool {
        if self.phase != Phase::Running {
            return self.fault.is_none();
        }
        if self.drive_state().is_some_and(DriveState::is_fault) {
            if self.reset.is_none() {
                self.reset = Some(FaultReset {
                    attempt: 1,
                    step: ResetStep::Low(t),
                });
            }
            return true;
        }
        if let Some(DriveFault::FeedbackStale { axis }) = self.fault
            && self.feedback_age(t, axis) > self.settings.feedback_timeout
        {
            return false;
        }
        self.fault = None;
        true
    }

    pub(super) fn raise(&mut self, fault: DriveFault) {
        if self.fault.is_none() {
            self.fault = Some(fault);
        }
        if self.goal == Goal::Enabled {
            self.goal = Goal::QuickStop;
        }
        self.enable_asked_at = None;
        self.targets.iter_mut().for_each(|t| *t = 0);
    }

    /// One step of the fault reset handshake in `state`.
    pub(super) fn step_reset(&mut self, t: Timestamp, state: DriveState, reset: FaultReset) {
        let low = controlword::DISABLE_VOLTAGE;
        if !state.is_fault() {
            // Out of Fault: the reset worked.
            tracing::info!(
                node = self.settings.node.get(),
                attempt = reset.attempt,
                "fault reset"
            );
            self.reset = None;
            self.fault = None;
            self.controlword = next_controlword(state, self.goal).unwrap_or(low);
            return;
        }
        self.reset = match reset.step {
            // Bit 7 must be seen low for a cycle before the edge.
            ResetStep::Low(since) if self.sent_controlword == Some(low) && t > since => {
                self.controlword = controlword::FAULT_RESET;
                self.stats.fault_resets += 1;
                Some(FaultReset {
                    step: ResetStep::Edge(t),
                    ..reset
                })
            }
            ResetStep::Low(_) => {
                self.controlword = low;
                Some(reset)
            }
            ResetStep::Edge(since) if t.saturating_since(since) <= self.settings.reset_wait => {
                Some(reset)
            }
            ResetStep::Edge(_) if reset.attempt < self.settings.reset_attempts => {
                self.controlword = low;
                Some(FaultReset {
                    attempt: reset.attempt + 1,
                    step: ResetStep::Low(t),
                })
            }
            ResetStep::Edge(_) => {
                tracing::warn!(
                    node = self.settings.node.get(),
                    attempts = reset.attempt,
                    "fault reset failed: the drive stays in fault"
                );
                self.controlword = low;
                None
            }
        };
    }
}
