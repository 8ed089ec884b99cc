//! DRIVE (100 on `cmd/chassis`): a velocity command through the drive train's limits, ramps
//! and watchdog.

use serde_json::Value;

use super::{Context, Done};
use crate::api::root::error::RootError;
use crate::vehicle::Command;

/// `{"linear": m/s, "angular": rad/s}`.
struct Drive {
    linear: f64,
    angular: f64,
}

impl Drive {
    fn parse(data: &Value) -> Result<Self, RootError> {
        match (
            data.get("linear").and_then(Value::as_f64),
            data.get("angular").and_then(Value::as_f64),
        ) {
            (Some(linear), Some(angular)) => Ok(Self { linear, angular }),
            _ => Err(RootError::invalid(
                "data needs numbers linear (m/s) and angular (rad/s)",
            )),
        }
    }
}

pub(super) fn handle(data: &Value, cx: &mut Context<'_>) -> Result<Done, RootError> {
    let drive = Drive::parse(data)?;
    cx.core.command(Command::Velocity {
        vx: drive.linear,
        wz: drive.angular,
    })?;
    Ok(Done::Acked)
}
