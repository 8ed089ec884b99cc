//! `reset` (an extension in the spec's shape, `data: {}`): re-arms a latched stop once its
//! cause has cleared.

use serde_json::Value;

use super::{Answered, Context};
use crate::api::device::error::DeviceError;
use crate::vehicle::Command;

pub(super) fn handle(_data: &Value, cx: &mut Context<'_>) -> Result<Answered, DeviceError> {
    cx.core.command(Command::Reset)?;
    Ok(Answered::Now)
}
