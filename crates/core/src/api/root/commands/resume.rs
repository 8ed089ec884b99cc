//! CONTINUE (2 on `cmd/navigation`): re-arms a PAUSE and goes on with the paused task. `data`
//! is not read.

use serde_json::Value;

use super::{Context, Done};
use crate::api::root::error::RootError;
use crate::vehicle::Command;

pub(super) fn handle(_data: &Value, cx: &mut Context<'_>) -> Result<Done, RootError> {
    cx.core.command(Command::Continue)?;
    Ok(Done::Acked)
}
