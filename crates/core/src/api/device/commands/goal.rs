//! `goal`: drive to a pose in the map frame. It is answered once, when it ends: success, 3001
//! when cancelled, 3002 when it failed; a goal refused at once gets 3002 with the reason.

use std::collections::VecDeque;

use serde_json::Value;

use super::{Answered, Context};
use crate::api::device::error::DeviceError;
use crate::control::goal::GoalPose;
use crate::control::{MotionResult, MotionTag, Outcome};
use crate::fusion::planar::wrap;
use crate::vehicle::Command;

/// Goals answered at their end at most: the oldest request is forgotten beyond this (a goal
/// replaced by another ends at once, so only a flood could pile them up).
const MAX_PENDING: usize = 16;

/// The goals under way or ended but not yet answered.
#[derive(Default)]
pub(in crate::api::device) struct Goals {
    /// The number of the last goal started.
    last: u64,
    /// Each goal's number and `msg_id`.
    pending: VecDeque<(u64, Value)>,
}

impl Goals {
    fn next_tag(&mut self) -> MotionTag {
        self.last += 1;
        MotionTag {
            owner: "device",
            id: self.last,
        }
    }

    fn started(&mut self, tag: MotionTag, msg_id: Value) {
        if self.pending.len() == MAX_PENDING {
            self.pending.pop_front();
        }
        self.pending.push_back((tag.id, msg_id));
    }

    /// The `msg_id` of the goal that ended with `result` and how it ended; `None` when it
    /// was not one of this dialect's goals (or long forgotten).
    pub(in crate::api::device) fn ended(
        &mut self,
        result: &MotionResult,
    ) -> Option<(Value, Result<(), DeviceError>)> {
        let tag = result.tag?;
        let at = self.pending.iter().position(|(id, _)| *id == tag.id)?;
        let (_, msg_id) = self.pending.remove(at)?;
        let outcome = match &result.outcome {
            Outcome::Succeeded => Ok(()),
            Outcome::Cancelled(_) => Err(DeviceError::Cancelled(result.to_string())),
            Outcome::TimedOut | Outcome::Aborted(_) => Err(DeviceError::Failed(result.to_string())),
        };
        Some((msg_id, outcome))
    }
}

pub(super) fn handle(data: &Value, cx: &mut Context<'_>) -> Result<Answered, DeviceError> {
    let goal = parse_goal(data).map_err(DeviceError::BadRequest)?;
    let tag = cx.goals.next_tag();
    cx.core.command(Command::Goal {
        goal,
        tag: Some(tag),
    })?;
    cx.goals.started(tag, cx.msg_id.clone());
    Ok(Answered::AtItsEnd)
}

/// A goal's `data`: `x`, `y` in the map frame (m, east and north of the datum) and `z`, the
/// z of the heading's quaternion (sin(yaw / 2), so 0.7071 is 90°), with `w` (cos(yaw / 2))
/// optional. A `z` outside −1..1 is refused, not read as radians.
fn parse_goal(data: &Value) -> Result<GoalPose, String> {
    let number = |k: &str| {
        data.get(k)
            .and_then(Value::as_f64)
            .filter(|v| v.is_finite())
    };
    let (Some(x), Some(y), Some(z)) = (number("x"), number("y"), number("z")) else {
        return Err(
            "data needs finite numbers x, y (m, map frame) and z (the heading's \
                    quaternion z)"
                .to_owned(),
        );
    };
    let yaw = match data.get("w") {
        None => {
            if !(-1.0..=1.0).contains(&z) {
                return Err(format!(
                    "z {z} is outside -1..1: z is the quaternion z of the heading \
                     (sin(yaw/2); 0.7071 is 90°), not an angle"
                ));
            }
            2.0 * z.asin()
        }
        Some(w) => {
            let Some(w) = w.as_f64().filter(|w| w.is_finite()) else {
                return Err("w must be a finite number".to_owned());
            };
            if (z.hypot(w) - 1.0).abs() > 0.01 {
                return Err(format!(
                    "z {z} and w {w} are not a unit quaternion of a heading"
                ));
            }
            2.0 * z.atan2(w)
        }
    };
    Ok(GoalPose {
        x,
        y,
        yaw: wrap(yaw),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn goal_headings_are_quaternion_z_and_nothing_else() {
        let yaw = |data: &str| parse_goal(&serde_json::from_str(data).unwrap()).map(|g| g.yaw);
        let close = |r: Result<f64, String>, deg: f64| {
            let got = r.unwrap();
            assert!(
                wrap(got - deg.to_radians()).abs() < 1e-4,
                "{}° for {deg}°",
                got.to_degrees()
            );
        };
        close(yaw(r#"{"x":1.23,"y":4.56,"z":0.7071}"#), 90.0);
        close(yaw(r#"{"x":0,"y":0,"z":0}"#), 0.0);
        close(yaw(r#"{"x":0,"y":0,"z":-1}"#), -180.0);
        close(
            yaw(r#"{"x":0,"y":0,"z":0.7071,"w":-0.7071}"#),
            270.0 - 360.0,
        );
        for bad in [
            r#"{"x":0,"y":0,"z":1.57}"#,
            r#"{"x":0,"y":0,"z":0.5,"w":0.5}"#,
            r#"{"x":0,"y":0}"#,
            r#"{"x":"1","y":0,"z":0}"#,
            r#"{"x":0,"y":0,"z":0,"w":"1"}"#,
        ] {
            assert!(yaw(bad).is_err(), "{bad}");
        }
        let e = yaw(r#"{"x":0,"y":0,"z":1.57}"#).unwrap_err();
        assert!(e.contains("not an angle"), "{e}");
    }
}
