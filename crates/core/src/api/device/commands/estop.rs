//! `estop` (an extension in the spec's shape): `data: {"engaged": bool}` engages or releases
//! the software emergency stop.

use serde_json::Value;

use super::{Answered, Context};
use crate::api::device::error::DeviceError;
use crate::vehicle::Command;

pub(super) fn handle(data: &Value, cx: &mut Context<'_>) -> Result<Answered, DeviceError> {
    let engaged = data
        .get("engaged")
        .and_then(Value::as_bool)
        .ok_or_else(|| DeviceError::bad("data needs a boolean engaged"))?;
    cx.core.command(Command::EmergencyStop { engaged })?;
    Ok(Answered::Now)
}
