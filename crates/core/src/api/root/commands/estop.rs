//! ESTOP (101 on `cmd/chassis`, an extension): `data` 1 engages the software e-stop, 0
//! releases it.

use serde_json::Value;

use super::{Context, Done};
use crate::api::root::error::RootError;
use crate::vehicle::Command;

pub(super) fn handle(data: &Value, cx: &mut Context<'_>) -> Result<Done, RootError> {
    let engaged = match data.as_u64() {
        Some(1) => true,
        Some(0) => false,
        _ => return Err(RootError::invalid("data must be 1 (engage) or 0 (release)")),
    };
    cx.core.command(Command::EmergencyStop { engaged })?;
    Ok(Done::Acked)
}
