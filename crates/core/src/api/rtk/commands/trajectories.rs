//! The trajectory commands (`trajectory_control`): list, save, delete one, delete all.

use serde_json::Value;

use super::{Answered, Context};
use crate::api::mqtt::Publish;
use crate::api::request_body::Fields;
use crate::api::rtk::TRAJECTORY_DATA;
use crate::api::rtk::error::RtkError;
use crate::api::trajectory::{self, Trajectory};
use crate::config::mqtt::packet_limit;

/// `get_all_trajectory`: every stored trajectory on `trajectory_data` (an array, possibly
/// empty), refused when it would not fit in one packet of the link.
pub(super) fn get_all(_message: &Fields, cx: &mut Context<'_>) -> Result<Answered, RtkError> {
    let all = cx.store.all()?;
    let json = serde_json::to_string(&all).unwrap_or_default();
    let answer = Publish::reply(TRAJECTORY_DATA, json);
    let limit = packet_limit(cx.max_payload);
    if answer.packet_len() > limit {
        let points: usize = all.iter().map(|t| t.data.len()).sum();
        return Err(RtkError::invalid(format!(
            "the {} trajectories stored ({points} points) make a trajectory_data of {} bytes, more than an MQTT packet may carry here ({limit} bytes: 4 × mqtt.max_payload); raise mqtt.max_payload, or delete trajectories",
            all.len(),
            answer.payload.len()
        )));
    }
    cx.out.push(answer);
    Ok(Answered::Published)
}

/// `save_trajectory`: `data` is the trajectory, checked, under its canonical name.
pub(super) fn save(message: &Fields, cx: &mut Context<'_>) -> Result<Answered, RtkError> {
    let data = message
        .get("data")
        .ok_or_else(|| RtkError::invalid("no \"data\" object"))?;
    let mut t: Trajectory = serde::Deserialize::deserialize(data)
        .map_err(|e: serde_json::Error| RtkError::invalid(format!("data: {e}")))?;
    t.name = trajectory::canonical_name(&t.name)?;
    t.check()?;
    cx.store.save(&t)?;
    Ok(Answered::Feedback)
}

/// `delete_trajectory`: the trajectory `name`.
pub(super) fn delete(message: &Fields, cx: &mut Context<'_>) -> Result<Answered, RtkError> {
    let name = message
        .get("name")
        .and_then(Value::as_str)
        .ok_or_else(|| RtkError::invalid("no \"name\" string"))?;
    cx.store.delete(&trajectory::canonical_name(name)?)?;
    Ok(Answered::Feedback)
}

/// `delete_all_trajectory`.
pub(super) fn delete_all(_message: &Fields, cx: &mut Context<'_>) -> Result<Answered, RtkError> {
    cx.store.delete_all()?;
    Ok(Answered::Feedback)
}
