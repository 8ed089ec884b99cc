//! What the ROS 2 node takes, as the core sees it: each message as it came (the node's
//! process decodes its CDR into the JSON of its type), recorded under its ROS name as
//! `{"id": ID, "msg": MESSAGE}`, and the adapter that hands it to the core. A recording
//! replays without DDS.

use serde_json::Value;

use super::topics::{CMD_VEL, GOAL_POSE, INITIAL_POSE};
use super::{NAVIGATE_TO_POSE, NAVIGATE_TO_POSE_CANCEL, OWNER, SOURCE};
use crate::api::adapter::{self, RequestAdapter};
use crate::api::requests::{self, Twist};
use crate::api::rosbridge::messages::{MAP_FRAME, goal_from_pose_stamped};
use crate::control::MotionTag;
use crate::vehicle::Command;

/// The record payload of a message the node took, with the id its answer comes back
/// with (`None`: nobody waits for it).
pub fn encode(id: Option<u64>, msg: &Value) -> bytes::Bytes {
    adapter::encode_request(id, msg)
}

/// `/cmd_vel`'s velocity: a geometry_msgs/Twist, or a TwistStamped's twist.
fn velocity(msg: Value) -> Result<Command, String> {
    let twist = match msg {
        Value::Object(mut fields) if fields.contains_key("twist") => {
            fields.remove("twist").unwrap_or_default()
        }
        other => other,
    };
    let twist: Twist = serde_json::from_value(twist)
        .map_err(|e| format!("{CMD_VEL}: not a geometry_msgs/Twist: {e}"))?;
    requests::velocity(&twist)
}

/// `/initialpose` (geometry_msgs/PoseWithCovarianceStamped in `map`): the vehicle placed
/// there, as root's INIT_POSITION places it, with its limits.
fn initial_pose(msg: &Value) -> Result<Command, String> {
    let frame = msg
        .pointer("/header/frame_id")
        .and_then(Value::as_str)
        .unwrap_or("");
    if !(frame.is_empty() || frame == MAP_FRAME) {
        return Err(format!(
            "{INITIAL_POSE}: a pose in frame {frame:?} cannot place the vehicle: give it in \"map\""
        ));
    }
    let number = |pointer: &str| msg.pointer(pointer).and_then(Value::as_f64);
    let values = [
        "/pose/pose/position/x",
        "/pose/pose/position/y",
        "/pose/pose/orientation/x",
        "/pose/pose/orientation/y",
        "/pose/pose/orientation/z",
        "/pose/pose/orientation/w",
    ]
    .map(number);
    let [Some(x), Some(y), Some(qx), Some(qy), Some(qz), Some(qw)] = values else {
        return Err(format!(
            "{INITIAL_POSE}: pose.pose needs its position and orientation as numbers"
        ));
    };
    match requests::quaternion_yaw([qx, qy, qz, qw]) {
        Some(yaw) if x.is_finite() && y.is_finite() => Ok(Command::SetPose { x, y, yaw }),
        _ => Err(format!(
            "{INITIAL_POSE}: values must be finite, the quaternion of unit length"
        )),
    }
}

/// A goal to drive to from `/goal_pose` or `navigate_to_pose` (its `pose`).
fn goal(topic: &str, pose_stamped: &Value) -> Result<Command, String> {
    let (x, y, yaw) =
        goal_from_pose_stamped(pose_stamped).map_err(|reason| format!("{topic}: {reason}"))?;
    requests::goal(topic, x, y, yaw)
}

/// A recorded message's id and core command. A `navigate_to_pose` goal is tagged with its
/// id, so the node can tell its end.
pub fn decode(topic: &str, payload: &[u8]) -> (Option<u64>, Result<Command, String>) {
    let (id, msg) = adapter::decode_request::<Value>(topic, payload);
    let command = msg.and_then(|msg| match topic {
        CMD_VEL => velocity(msg),
        GOAL_POSE => goal(topic, &msg),
        INITIAL_POSE => initial_pose(&msg),
        NAVIGATE_TO_POSE => {
            let pose = msg.get("pose").unwrap_or(&Value::Null);
            let tag = MotionTag {
                owner: OWNER,
                id: id.unwrap_or(0),
            };
            goal(topic, pose).map(|goal| requests::tagged(goal, tag))
        }
        NAVIGATE_TO_POSE_CANCEL => Ok(Command::CancelMotion),
        _ => Err(format!("unknown topic {topic:?}")),
    });
    (id, command)
}

/// The ROS 2 node's adapter.
pub const ADAPTER: RequestAdapter = RequestAdapter::new(SOURCE, decode);

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn twist(x: f64, z: f64) -> Value {
        json!({"linear": {"x": x, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": z}})
    }

    #[test]
    fn both_cmd_vel_types_are_velocities() {
        assert_eq!(
            decode(CMD_VEL, &encode(None, &twist(0.3, 0.1))),
            (None, Ok(Command::Velocity { vx: 0.3, wz: 0.1 }))
        );
        let stamped = json!({
            "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "base_link"},
            "twist": twist(-0.2, 0.0),
        });
        assert_eq!(
            decode(CMD_VEL, &encode(None, &stamped)).1,
            Ok(Command::Velocity { vx: -0.2, wz: 0.0 })
        );
        let sideways = json!({"linear": {"x": 0.0, "y": 0.4, "z": 0.0}, "angular": {}});
        assert!(
            decode(CMD_VEL, &encode(None, &sideways))
                .1
                .unwrap_err()
                .contains("differential drive")
        );
    }

    #[test]
    fn a_pose_estimate_places_the_vehicle_within_init_positions_limits() {
        let half = 0.5f64.sqrt();
        let pose = |frame: &str, w: f64| {
            json!({
                "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": frame},
                "pose": {
                    "pose": {
                        "position": {"x": 4.0, "y": -1.0, "z": 0.0},
                        "orientation": {"x": 0.0, "y": 0.0, "z": half, "w": w},
                    },
                    "covariance": vec![0.0; 36],
                },
            })
        };
        let Ok(Command::SetPose { x, y, yaw }) =
            decode(INITIAL_POSE, &encode(None, &pose("map", half))).1
        else {
            panic!("a pose in map places the vehicle");
        };
        assert_eq!((x, y), (4.0, -1.0));
        assert!((yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert!(
            decode(INITIAL_POSE, &encode(None, &pose("odom", half)))
                .1
                .unwrap_err()
                .contains("\"map\"")
        );
        assert!(
            decode(INITIAL_POSE, &encode(None, &pose("map", 5.0)))
                .1
                .unwrap_err()
                .contains("unit length")
        );
    }

    #[test]
    fn a_navigation_goal_is_tagged_with_its_id_and_a_cancel_stops_it() {
        let goal = json!({
            "pose": {
                "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "map"},
                "pose": {"position": {"x": 2.0, "y": 1.0, "z": 0.0},
                         "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
            },
            "behavior_tree": "",
        });
        let (id, command) = decode(NAVIGATE_TO_POSE, &encode(Some(9), &goal));
        assert_eq!(id, Some(9));
        assert!(matches!(
            command,
            Ok(Command::Goal {
                tag: Some(MotionTag {
                    owner: OWNER,
                    id: 9
                }),
                ..
            })
        ));
        let (_, refused) = decode(NAVIGATE_TO_POSE, &encode(Some(10), &json!({"pose": {}})));
        assert!(refused.unwrap_err().contains("/navigate_to_pose"));
        assert_eq!(
            decode(NAVIGATE_TO_POSE_CANCEL, &encode(Some(11), &json!({}))),
            (Some(11), Ok(Command::CancelMotion))
        );
    }
}
