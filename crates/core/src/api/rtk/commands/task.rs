//! The task commands (`task_control`): start a task on a stored trajectory, cancel it, and
//! make the vehicle's place the local frame's origin.

use std::sync::Arc;

use serde_json::Value;

use super::{Answered, Context};
use crate::api::request_body::Fields;
use crate::api::rtk::error::RtkError;
use crate::api::trajectory::{self, TrajectoryStore};
use crate::control::MotionTag;
use crate::vehicle::chassis::CommandRejected;
use crate::vehicle::{Command, PathPoints, PathRequest};

/// `start_task`: follows the trajectory `name` from its point `id` at up to `speed` m/s.
pub(super) fn start(message: &Fields, cx: &mut Context<'_>) -> Result<Answered, RtkError> {
    let path = start_task(message, cx.store)?;
    cx.core.command(Command::FollowPath {
        path: Arc::new(path),
        tag: Some(MotionTag {
            owner: "rtk",
            id: 0,
        }),
    })?;
    Ok(Answered::Feedback)
}

/// `cancel_task`: ends the motion under way and, when that is done, re-arms a latched stop.
pub(super) fn cancel(_message: &Fields, cx: &mut Context<'_>) -> Result<Answered, RtkError> {
    match cx.core.command(Command::CancelMotion) {
        // Without drives no task can run: there is nothing to cancel.
        Ok(()) | Err(CommandRejected::NoDrives) => {}
        Err(e) => return Err(e.into()),
    }
    // rtk has no velocity command and no reset: its deliberate stop is the act that re-arms a
    // latched stop whose causes have cleared. While one holds, the task is still cancelled;
    // the next start_task's refusal names the cause.
    let _ = cx.core.command(Command::Reset);
    Ok(Answered::Feedback)
}

/// `init_rtk_data`: the vehicle's place becomes the local frame's origin.
pub(super) fn init_rtk_data(_message: &Fields, cx: &mut Context<'_>) -> Result<Answered, RtkError> {
    cx.core.command(Command::ZeroLocalFrame)?;
    Ok(Answered::Feedback)
}

/// The path of a `start_task` message: the named trajectory from point `id` on.
fn start_task(message: &Fields, store: &mut dyn TrajectoryStore) -> Result<PathRequest, RtkError> {
    let name = message
        .get("name")
        .and_then(Value::as_str)
        .ok_or_else(|| RtkError::invalid("no \"name\" string"))?;
    let id = match message.get("id") {
        None => 0,
        Some(v) => v
            .as_u64()
            .and_then(|id| usize::try_from(id).ok())
            .ok_or_else(|| {
                RtkError::invalid("\"id\" must be a point index (a whole number from 0)")
            })?,
    };
    let speed = message
        .get("speed")
        .and_then(Value::as_f64)
        .ok_or_else(|| RtkError::invalid("no \"speed\" number (m/s)"))?;
    let speed = crate::api::task_speed(speed).map_err(RtkError::Invalid)?;
    let name = &trajectory::canonical_name(name)?;
    let trajectory = store.get(name)?;
    if id >= trajectory.data.len() {
        return Err(RtkError::invalid(format!(
            "trajectory {name:?} has {} points; id {id} is past its end (ids count from 0)",
            trajectory.data.len()
        )));
    }
    Ok(PathRequest {
        points: PathPoints::Geodetic(
            trajectory.data[id..]
                .iter()
                .map(|p| (p.latitude, p.longitude))
                .collect(),
        ),
        speed,
    })
}
