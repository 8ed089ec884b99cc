//! Why an rtk command failed: said in the feedback's `message`, as a client of rtk can act on
//! it.

use crate::api::request_body::BodyError;
use crate::api::trajectory::TrajectoryError;
use crate::vehicle::chassis::CommandRejected;
use crate::vehicle::safety::Refusal;

/// A command answered `<cmd>_failse`.
#[derive(Debug, thiserror::Error)]
pub enum RtkError {
    /// Too large, or not JSON.
    #[error("{0}")]
    Body(BodyError),
    /// No command named.
    #[error("no \"cmd\" string in the message")]
    NoCommand,
    /// No such command.
    #[error("unknown command {0:?}")]
    Unknown(String),
    /// The command with another `cmd_type` than its own.
    #[error("cmd_type must be {expected:?} for {cmd}, not {given}")]
    WrongType {
        /// The command.
        cmd: &'static str,
        /// Its type.
        expected: &'static str,
        /// The type given, quoted, or `absent`.
        given: String,
    },
    /// A field missing, mistyped or out of range.
    #[error("{0}")]
    Invalid(String),
    /// The trajectory store's refusal or failure.
    #[error("{0}")]
    Trajectory(#[from] TrajectoryError),
    /// A change answered as done whose write to the trajectory folder failed.
    #[error(
        "{what}: kept in memory only, the trajectory folder's write failed ({reason}); it is \
         lost at the next start"
    )]
    NotWritten {
        /// The trajectory, or every trajectory.
        what: String,
        /// Why the write failed.
        reason: String,
    },
    /// The vehicle's refusal.
    #[error("{}", in_rtk_words(.0))]
    Refused(#[from] CommandRejected),
}

impl RtkError {
    /// A field missing, mistyped or out of range, for the reason given.
    pub fn invalid(reason: impl Into<String>) -> Self {
        Self::Invalid(reason.into())
    }
}

/// A message that is JSON but not an object names no command.
impl From<BodyError> for RtkError {
    fn from(e: BodyError) -> Self {
        match e {
            BodyError::NotAnObject => Self::NoCommand,
            other => Self::Body(other),
        }
    }
}

/// A refusal as an rtk client can act on it: a latched stop is re-armed by `cancel_task`, as
/// rtk has neither a velocity command nor a reset.
fn in_rtk_words(refusal: &CommandRejected) -> String {
    match refusal {
        CommandRejected::Safety(Refusal::Latched { reason, first }) => format!(
            "stopped ({reason}): {}send cancel_task to re-arm, then start_task again",
            first
                .as_ref()
                .map(|f| format!("{f}, then "))
                .unwrap_or_default()
        ),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_latched_stop_names_rtks_way_to_re_arm() {
        let latched = RtkError::from(CommandRejected::Safety(Refusal::Latched {
            reason: "operator stop".into(),
            first: None,
        }));
        assert_eq!(
            latched.to_string(),
            "stopped (operator stop): send cancel_task to re-arm, then start_task again"
        );
        assert_eq!(
            RtkError::from(BodyError::NotAnObject).to_string(),
            "no \"cmd\" string in the message"
        );
        assert_eq!(
            RtkError::from(CommandRejected::NoDrives).to_string(),
            "no drives are configured"
        );
    }
}
