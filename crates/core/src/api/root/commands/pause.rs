//! PAUSE (1 on `cmd/navigation`): the operator's stop, holding a trajectory task where it is.
//! `data` is not read.

use serde_json::Value;

use super::{Context, Done};
use crate::api::root::error::RootError;
use crate::vehicle::Command;

pub(super) fn handle(_data: &Value, cx: &mut Context<'_>) -> Result<Done, RootError> {
    cx.core.command(Command::Pause)?;
    Ok(Done::Acked)
}
