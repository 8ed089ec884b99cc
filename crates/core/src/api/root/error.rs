//! Why a root request failed, and the answer code each reason gets.

use crate::api::request_body::BodyError;
use crate::vehicle::chassis::CommandRejected;

/// Done.
pub const OK: u32 = 0;
/// Invalid request.
pub const INVALID: u32 = 1;
/// Unknown messageType.
pub const UNKNOWN_TYPE: u32 = 2;
/// Not available in this driver.
pub const NOT_AVAILABLE: u32 = 3;
/// Refused by the vehicle.
pub const REFUSED: u32 = 4;

/// A request answered with a non-zero code.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RootError {
    /// Malformed, mistyped or out of range: the request's fault.
    #[error("{0}")]
    Invalid(String),
    /// No command of this `messageType` is taken on the topic.
    #[error("messageType {kind} is not taken on {base}/set")]
    UnknownType {
        /// The topic's base (`cmd/navigation`).
        base: String,
        /// The `messageType`.
        kind: u64,
    },
    /// Belongs to another part of the robot's software: the reason says which.
    #[error("not available: {0}")]
    NotAvailable(&'static str),
    /// The vehicle's state refuses it.
    #[error("{0}")]
    Refused(String),
}

impl RootError {
    /// The answer's `code`.
    pub fn code(&self) -> u32 {
        match self {
            Self::Invalid(_) => INVALID,
            Self::UnknownType { .. } => UNKNOWN_TYPE,
            Self::NotAvailable(_) => NOT_AVAILABLE,
            Self::Refused(_) => REFUSED,
        }
    }

    /// An invalid request, for the reason given.
    pub fn invalid(reason: impl Into<String>) -> Self {
        Self::Invalid(reason.into())
    }
}

/// A wrong value is the request's fault (INVALID), anything else the vehicle's state
/// (REFUSED).
impl From<CommandRejected> for RootError {
    fn from(e: CommandRejected) -> Self {
        if e.is_bad_value() {
            Self::Invalid(e.to_string())
        } else {
            Self::Refused(e.to_string())
        }
    }
}

impl From<BodyError> for RootError {
    fn from(e: BodyError) -> Self {
        Self::Invalid(e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_reason_has_its_code() {
        assert_eq!(RootError::invalid("x").code(), INVALID);
        let unknown = RootError::UnknownType {
            base: "cmd/map".into(),
            kind: 9,
        };
        assert_eq!(unknown.code(), UNKNOWN_TYPE);
        assert_eq!(
            unknown.to_string(),
            "messageType 9 is not taken on cmd/map/set"
        );
        assert_eq!(RootError::NotAvailable("maps").code(), NOT_AVAILABLE);
        assert_eq!(RootError::from(CommandRejected::NoDrives).code(), REFUSED);
        assert_eq!(RootError::from(CommandRejected::NotFinite).code(), INVALID);
        assert_eq!(RootError::from(BodyError::NotAnObject).code(), INVALID);
    }
}
