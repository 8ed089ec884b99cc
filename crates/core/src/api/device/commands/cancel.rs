//! `cancel` (an extension in the spec's shape, `data: {}`): ends the goal under way (or any
//! motion) and brings the vehicle to rest, without the latch of an e-stop; the goal's own ack
//! follows with 3001. Done also when nothing was under way.

use serde_json::Value;

use super::{Answered, Context};
use crate::api::device::error::DeviceError;
use crate::vehicle::Command;

pub(super) fn handle(_data: &Value, cx: &mut Context<'_>) -> Result<Answered, DeviceError> {
    cx.core.command(Command::CancelMotion)?;
    Ok(Answered::Now)
}
