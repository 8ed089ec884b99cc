//! Why a device request failed, and the code each reason gets.

use crate::api::request_body::BodyError;
use crate::vehicle::chassis::CommandRejected;

/// Goal cancelled (or: already mapping).
pub const CANCELLED: u32 = 3001;
/// Goal failed.
pub const FAILED: u32 = 3002;
/// Not available in this driver.
pub const NOT_AVAILABLE: u32 = 3003;
/// Malformed or invalid request.
pub const BAD_REQUEST: u32 = 4000;
/// Unknown command.
pub const UNKNOWN: u32 = 4004;
/// Payload too large.
pub const TOO_LARGE: u32 = 4013;

/// A request answered with `success: false`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DeviceError {
    /// A goal ended before it was reached: replaced, stopped, or overridden.
    #[error("{0}")]
    Cancelled(String),
    /// The vehicle refused the command, or the goal failed.
    #[error("{0}")]
    Failed(String),
    /// Belongs to the navigation stack, and none is configured.
    #[error("not available: {0}")]
    NotAvailable(&'static str),
    /// Malformed or invalid.
    #[error("{0}")]
    BadRequest(String),
    /// No such command.
    #[error("unknown command {0:?}")]
    Unknown(String),
    /// Larger than the link takes.
    #[error("{0}")]
    TooLarge(String),
}

impl DeviceError {
    /// The ack's `code`.
    pub fn code(&self) -> u32 {
        match self {
            Self::Cancelled(_) => CANCELLED,
            Self::Failed(_) => FAILED,
            Self::NotAvailable(_) => NOT_AVAILABLE,
            Self::BadRequest(_) => BAD_REQUEST,
            Self::Unknown(_) => UNKNOWN,
            Self::TooLarge(_) => TOO_LARGE,
        }
    }

    /// A bad request, for the reason given.
    pub fn bad(reason: impl Into<String>) -> Self {
        Self::BadRequest(reason.into())
    }
}

/// The device dialect answers every refusal of the vehicle with 3002 and its reason.
impl From<CommandRejected> for DeviceError {
    fn from(e: CommandRejected) -> Self {
        Self::Failed(e.to_string())
    }
}

impl From<BodyError> for DeviceError {
    fn from(e: BodyError) -> Self {
        match e {
            BodyError::TooLarge { .. } => Self::TooLarge(e.to_string()),
            BodyError::Malformed(_) | BodyError::NotAnObject => Self::BadRequest(e.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_reason_has_its_code() {
        let too_large = DeviceError::from(BodyError::TooLarge { len: 9, max: 1 });
        assert_eq!(too_large.code(), TOO_LARGE);
        assert_eq!(too_large.to_string(), "payload of 9 bytes exceeds 1");
        assert_eq!(
            DeviceError::from(BodyError::NotAnObject).code(),
            BAD_REQUEST
        );
        assert_eq!(DeviceError::from(CommandRejected::NoDrives).code(), FAILED);
        assert_eq!(
            DeviceError::Unknown("fly".into()).to_string(),
            "unknown command \"fly\""
        );
        assert_eq!(DeviceError::Cancelled(String::new()).code(), CANCELLED);
        assert_eq!(DeviceError::NotAvailable("x").code(), NOT_AVAILABLE);
    }
}
