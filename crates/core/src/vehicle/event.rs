//! What the core tells the operator's log, by kind. Each kind's text is its `Display`; a link
//! that shows events (the log, the live page) writes that, and a part that must act on one
//! matches its kind instead of reading the text.

use std::fmt;

use super::gate::GateReason;
use crate::control::MotionResult;
use crate::control::mission::MissionEvent;

/// One event.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The localiser's or the map filter's news, in their words.
    Localisation(String),
    /// The RTK corrections' watch: they stopped, or flow again.
    Corrections(String),
    /// A motion's progress, in its words.
    Motion(String),
    /// The zones' guard: a stop at a boundary, a zone left.
    Zone(String),
    /// A motion ended, and how.
    MotionEnded(MotionResult),
    /// The GNSS gate closed.
    GateClosed(GateReason),
    /// The GNSS gate opened.
    GateOpened,
    /// A mission's step started or ended, or the mission ended.
    Mission(MissionEvent),
    /// A zone was added (its kind and name said) or removed.
    ZoneEdited {
        /// What changed.
        what: String,
        /// The zone's id.
        id: u32,
    },
    /// A latched stop's reason, when it changes; `None` once re-armed.
    SafetyStop(Option<String>),
    /// A drive's fault appeared, or cleared (`None`).
    DriveFault {
        /// The drive's name.
        drive: String,
        /// The fault.
        fault: Option<String>,
    },
    /// A drive runs (after start-up or a reset).
    DriveRunning(String),
    /// The cutter was switched; without a `[cutter]` there was nothing to switch.
    Cutter {
        /// On or off.
        on: bool,
        /// Whether a cutter is configured.
        configured: bool,
    },
    /// A receiver's news: what it turned out to be, a change in what it sends.
    Receiver(String),
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Localisation(text)
            | Self::Corrections(text)
            | Self::Motion(text)
            | Self::Zone(text)
            | Self::Receiver(text) => f.write_str(text),
            Self::MotionEnded(result) => result.fmt(f),
            Self::GateClosed(reason) => write!(
                f,
                "GNSS gate closed: {reason}; the blade stops, a path task or a mission pauses \
                 until it opens, a goal or a move under way ends"
            ),
            Self::GateOpened => f.write_str(
                "GNSS gate open: the fix has been good for zones.resume_after_s; autonomous \
                 work is taken",
            ),
            Self::Mission(event) => event.fmt(f),
            Self::ZoneEdited { what, id } => write!(f, "zones: {what} (id {id})"),
            Self::SafetyStop(Some(reason)) => write!(f, "safety stop: {reason}"),
            Self::SafetyStop(None) => f.write_str("safety stop cleared: re-armed"),
            Self::DriveFault {
                drive,
                fault: Some(fault),
            } => write!(f, "drive {drive}: fault: {fault}"),
            Self::DriveFault { drive, fault: None } => write!(f, "drive {drive}: fault cleared"),
            Self::DriveRunning(drive) => write!(f, "drive {drive}: running"),
            Self::Cutter {
                on,
                configured: true,
            } => write!(f, "cutter {}", if *on { "on" } else { "off" }),
            Self::Cutter {
                configured: false, ..
            } => f.write_str("cutter switch asked for, but no [cutter] is configured"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_kind_says_what_the_log_said_before_it_had_kinds() {
        assert_eq!(
            Event::SafetyStop(Some("e-stop".into())).to_string(),
            "safety stop: e-stop"
        );
        assert_eq!(
            Event::SafetyStop(None).to_string(),
            "safety stop cleared: re-armed"
        );
        let fault = Event::DriveFault {
            drive: "left".into(),
            fault: Some("overcurrent".into()),
        };
        assert_eq!(fault.to_string(), "drive left: fault: overcurrent");
        let cleared = Event::DriveFault {
            drive: "left".into(),
            fault: None,
        };
        assert_eq!(cleared.to_string(), "drive left: fault cleared");
        let off = Event::Cutter {
            on: false,
            configured: true,
        };
        assert_eq!(off.to_string(), "cutter off");
        let missing = Event::Cutter {
            on: true,
            configured: false,
        };
        assert!(missing.to_string().contains("no [cutter]"));
        let added = Event::ZoneEdited {
            what: "keep-out zone \"pond\" added".into(),
            id: 3,
        };
        assert_eq!(
            added.to_string(),
            "zones: keep-out zone \"pond\" added (id 3)"
        );
        assert!(Event::GateOpened.to_string().starts_with("GNSS gate open:"));
    }
}
