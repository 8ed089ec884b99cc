//! The `navigate_to_pose` action's goals, sans-IO: which the vehicle took, their feedback at
//! each status tick and their results when their motions end. The node's process speaks the
//! action protocol; this decides what it says. nav2_msgs/action/NavigateToPose of Jazzy and
//! Kilted: the result is `error_code` and `error_msg`.

use std::collections::BTreeMap;

use serde_json::{Value, json};

use super::OWNER;
use crate::api::rosbridge::messages::MAP_FRAME;
use crate::api::rosbridge::parts::header;
use crate::control::{MotionResult, Outcome};
use crate::time::Timestamp;
use crate::vehicle::VehicleStatus;

/// action_msgs/GoalStatus: how a goal ended.
pub const STATUS_SUCCEEDED: i8 = 4;
/// Cancelled as its client asked.
pub const STATUS_CANCELED: i8 = 5;
/// Ended otherwise: a fault, a timeout, another command.
pub const STATUS_ABORTED: i8 = 6;

/// NavigateToPose's result codes: none (Jazzy's only constant), unknown and a timeout
/// (Kilted's constants; the same message on the wire).
const ERROR_NONE: u16 = 0;
const ERROR_UNKNOWN: u16 = 9000;
const ERROR_TIMEOUT: u16 = 9003;

/// Below this speed no time remaining is estimated, m/s.
const MOVING_MPS: f64 = 0.05;
/// Goals the vehicle keeps at once: one runs, the others ended (a new goal preempts).
const MAX_GOALS: usize = 16;

/// A goal the vehicle took.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Goal {
    /// Where to, in `map`.
    target: (f64, f64),
    /// When the vehicle took it.
    accepted: Timestamp,
    /// Its client asked to cancel it.
    cancel_requested: bool,
}

/// How a goal ended: its action_msgs/GoalStatus and its result message.
#[derive(Debug, Clone, PartialEq)]
pub struct Ended {
    /// The goal (the id its request was recorded with).
    pub goal: u64,
    /// Its status.
    pub status: i8,
    /// Its NavigateToPose result.
    pub result: Value,
}

/// The goals under way.
#[derive(Debug, Default)]
pub struct Navigation {
    goals: BTreeMap<u64, Goal>,
}

impl Navigation {
    /// Goal `goal`, toward `target` in `map`, taken by the vehicle at `t`.
    pub fn accepted(&mut self, goal: u64, target: (f64, f64), t: Timestamp) {
        if self.goals.len() >= MAX_GOALS
            && let Some(&oldest) = self.goals.keys().next()
        {
            self.goals.remove(&oldest);
        }
        self.goals.insert(
            goal,
            Goal {
                target,
                accepted: t,
                cancel_requested: false,
            },
        );
    }

    /// Whether goal `goal` is under way.
    pub fn is_active(&self, goal: u64) -> bool {
        self.goals.contains_key(&goal)
    }

    /// Its client asks to cancel goal `goal`: whether it is under way (and so is being
    /// cancelled).
    pub fn cancel(&mut self, goal: u64) -> bool {
        match self.goals.get_mut(&goal) {
            Some(g) => {
                g.cancel_requested = true;
                true
            }
            None => false,
        }
    }

    /// Each goal's feedback at a status tick: where the vehicle is, how far it has to go,
    /// how long it has been going and, while it moves, how long it may take yet.
    pub fn feedback(&self, status: &VehicleStatus) -> Vec<(u64, Value)> {
        let t = status.time;
        let p = status.pose;
        self.goals
            .iter()
            .map(|(&id, goal)| {
                let distance = (goal.target.0 - p.x).hypot(goal.target.1 - p.y);
                let speed = status.chassis.as_ref().map_or(0.0, |c| c.vx.abs());
                let remaining = if speed > MOVING_MPS {
                    distance / speed
                } else {
                    0.0
                };
                let [qx, qy, qz, qw] = crate::api::ros1::yaw_quaternion(p.yaw);
                let feedback = json!({
                    "current_pose": {
                        "header": header(t, MAP_FRAME),
                        "pose": {
                            "position": {"x": p.x, "y": p.y, "z": 0.0},
                            "orientation": {"x": qx, "y": qy, "z": qz, "w": qw},
                        },
                    },
                    "navigation_time": duration(t.saturating_since(goal.accepted).as_secs_f64()),
                    "estimated_time_remaining": duration(remaining),
                    "number_of_recoveries": 0,
                    "distance_remaining": distance,
                });
                (id, feedback)
            })
            .collect()
    }

    /// The end of one of the node's goals, when `result` is one.
    pub fn ended(&mut self, result: &MotionResult) -> Option<Ended> {
        let tag = result.tag.filter(|tag| tag.owner == OWNER)?;
        let goal = self.goals.remove(&tag.id)?;
        let (status, code) = match result.outcome {
            Outcome::Succeeded => (STATUS_SUCCEEDED, ERROR_NONE),
            Outcome::Cancelled(_) if goal.cancel_requested => (STATUS_CANCELED, ERROR_NONE),
            Outcome::TimedOut => (STATUS_ABORTED, ERROR_TIMEOUT),
            Outcome::Cancelled(_) | Outcome::Aborted(_) => (STATUS_ABORTED, ERROR_UNKNOWN),
        };
        let message = match result.outcome {
            Outcome::Succeeded => String::new(),
            ref other => other.to_string(),
        };
        Some(Ended {
            goal: tag.id,
            status,
            result: json!({"error_code": code, "error_msg": message}),
        })
    }
}

/// builtin_interfaces/Duration of `seconds` (≥ 0).
fn duration(seconds: f64) -> Value {
    let seconds = seconds.clamp(0.0, f64::from(i32::MAX));
    let sec = seconds.floor();
    json!({"sec": sec as i32, "nanosec": ((seconds - sec) * 1e9) as u32})
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::goal::GoalPose;
    use crate::control::moves::HeadingSource;
    use crate::control::{CancelReason, MotionKind, MotionTag};
    use crate::vehicle::Pose2D;

    fn end_of(id: u64, owner: &'static str, outcome: Outcome) -> MotionResult {
        MotionResult {
            id: 1,
            kind: MotionKind::Goal(GoalPose {
                x: 1.0,
                y: 1.0,
                yaw: 0.0,
            }),
            tag: Some(MotionTag { owner, id }),
            outcome,
            duration_s: 1.0,
            planned_s: 1.0,
            error: 0.0,
            heading_error: None,
            heading: HeadingSource::Map,
            wheel_scale: 1.0,
            cross_track: None,
        }
    }

    #[test]
    fn feedback_tells_where_the_vehicle_is_and_how_far_it_has_to_go() {
        let mut n = Navigation::default();
        n.accepted(3, (10.0, 0.0), Timestamp::from_nanos(1_000_000_000));
        let status = VehicleStatus {
            time: Timestamp::from_nanos(3_500_000_000),
            pose: Pose2D {
                x: 4.0,
                y: 0.0,
                yaw: 0.0,
            },
            ..Default::default()
        };
        let feedback = n.feedback(&status);
        assert_eq!(feedback.len(), 1);
        let (id, f) = &feedback[0];
        assert_eq!(*id, 3);
        assert_eq!(f["distance_remaining"], 6.0);
        assert_eq!(
            f["navigation_time"],
            json!({"sec": 2, "nanosec": 500_000_000})
        );
        assert_eq!(f["current_pose"]["header"]["frame_id"], "map");
    }

    #[test]
    fn results_say_how_each_goal_ended() {
        let mut n = Navigation::default();
        let t = Timestamp::from_nanos(0);
        for id in [1, 2, 3, 4] {
            n.accepted(id, (1.0, 1.0), t);
        }
        assert!(n.cancel(2) && !n.cancel(99));
        let done = n.ended(&end_of(1, OWNER, Outcome::Succeeded)).unwrap();
        assert_eq!(
            (done.status, done.result["error_code"].clone()),
            (STATUS_SUCCEEDED, json!(0))
        );
        let cancelled = n
            .ended(&end_of(
                2,
                OWNER,
                Outcome::Cancelled(CancelReason::StopRequested),
            ))
            .unwrap();
        assert_eq!(cancelled.status, STATUS_CANCELED);
        let preempted = n
            .ended(&end_of(
                3,
                OWNER,
                Outcome::Cancelled(CancelReason::StopRequested),
            ))
            .unwrap();
        assert_eq!(
            preempted.status, STATUS_ABORTED,
            "not asked for by its client"
        );
        assert!(!preempted.result["error_msg"].as_str().unwrap().is_empty());
        let late = n.ended(&end_of(4, OWNER, Outcome::TimedOut)).unwrap();
        assert_eq!(late.result["error_code"], ERROR_TIMEOUT);
        assert!(
            n.ended(&end_of(4, OWNER, Outcome::Succeeded)).is_none(),
            "once"
        );
        n.accepted(5, (0.0, 0.0), t);
        assert!(n.ended(&end_of(5, "device", Outcome::Succeeded)).is_none());
        assert!(n.is_active(5));
    }
}
