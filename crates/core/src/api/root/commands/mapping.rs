//! MAPPING_START and MAPPING_STOP (3 and 4 on `cmd/map`): mapping belongs to the navigation
//! stack above this driver; the request is still checked, so a malformed one hears so.

use serde_json::Value;

use super::{Context, Done};
use crate::api::root::error::RootError;

pub(super) fn handle(data: &Value, _cx: &mut Context<'_>) -> Result<Done, RootError> {
    if data.get("name").and_then(Value::as_str).is_none() {
        return Err(RootError::invalid("data.name must be a string"));
    }
    Err(RootError::NotAvailable(
        "mapping belongs to the navigation stack above this driver",
    ))
}
