//! SET_MAP (0 on `setting/map`): maps belong to the navigation stack above this driver; the
//! request is still checked.

use serde_json::Value;

use super::{Context, Done};
use crate::api::root::error::RootError;

pub(super) fn handle(data: &Value, _cx: &mut Context<'_>) -> Result<Done, RootError> {
    if data.as_str().is_none() {
        return Err(RootError::invalid("data must be the map's name"));
    }
    Err(RootError::NotAvailable(
        "maps belong to the navigation stack above this driver",
    ))
}
