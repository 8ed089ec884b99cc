//! `start_mapping`, `stop_mapping` and `use_map`: mapping belongs to the navigation stack.
//! With `mapping_forward` the request is passed on as it came (and its ack relayed back by
//! the dialect); without, it is refused with 3003.

use serde_json::Value;

use super::{Answered, Context};
use crate::api::device::error::DeviceError;
use crate::api::mqtt::Publish;

pub(super) fn handle(_data: &Value, cx: &mut Context<'_>) -> Result<Answered, DeviceError> {
    let Some(forward) = cx.forward else {
        return Err(DeviceError::NotAvailable(
            "mapping belongs to the navigation stack, and no mqtt.device.mapping_forward is \
             configured",
        ));
    };
    cx.out.push(Publish::reply(
        format!("{forward}/{}", cx.command),
        cx.payload.to_vec(),
    ));
    Ok(Answered::Elsewhere)
}
