//! SET_LNG_LAT (100 on `setting/navigation`): moves the datum of the local frame.

use serde_json::Value;

use super::{Context, Done};
use crate::api::root::error::RootError;
use crate::geodesy::Geodetic;
use crate::vehicle::Command;

/// `[longitude, latitude, height]`, degrees and metres. The core judges the place (latitude,
/// longitude and height ranges) for every channel.
fn parse(data: &Value) -> Result<Geodetic, RootError> {
    let values: Option<Vec<f64>> = data
        .as_array()
        .filter(|a| a.len() == 3)
        .and_then(|a| a.iter().map(Value::as_f64).collect());
    match values.and_then(|v| <[f64; 3]>::try_from(v).ok()) {
        Some([lon_deg, lat_deg, h_m]) => Ok(Geodetic {
            lat_deg,
            lon_deg,
            h_m,
        }),
        None => Err(RootError::invalid(
            "data must be [longitude, latitude, height]",
        )),
    }
}

pub(super) fn handle(data: &Value, cx: &mut Context<'_>) -> Result<Done, RootError> {
    cx.core.command(Command::SetDatum(parse(data)?))?;
    Ok(Done::Acked)
}
