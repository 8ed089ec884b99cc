//! RESET (102 on `cmd/chassis`, an extension): re-arms a latched stop once its cause has
//! cleared. `data` is not read.

use serde_json::Value;

use super::{Context, Done};
use crate::api::root::error::RootError;
use crate::vehicle::Command;

pub(super) fn handle(_data: &Value, cx: &mut Context<'_>) -> Result<Done, RootError> {
    cx.core.command(Command::Reset)?;
    Ok(Done::Acked)
}
