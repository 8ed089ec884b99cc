//! SWITCH_MODE (6 on `cmd/navigation`): `data` 0 navigation (autonomous moves only), 1 manual
//! (velocity commands).

use serde_json::Value;

use super::{Context, Done};
use crate::api::root::error::RootError;
use crate::vehicle::{Command, DriveMode};

pub(super) fn handle(data: &Value, cx: &mut Context<'_>) -> Result<Done, RootError> {
    let mode = match data.as_u64() {
        Some(0) => DriveMode::Navigation,
        Some(1) => DriveMode::Manual,
        _ => {
            return Err(RootError::invalid(
                "data must be 0 (navigation) or 1 (manual)",
            ));
        }
    };
    cx.core.command(Command::SetMode(mode))?;
    Ok(Done::Acked)
}
