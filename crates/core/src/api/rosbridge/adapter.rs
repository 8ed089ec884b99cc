//! What rosbridge clients publish, typed: the check a message passes before it is recorded,
//! the form it is recorded in (its topic's name, `{"id": ID, "msg": MESSAGE}` with the
//! client's message as sent), and the adapter that hands it to the core and answers it.

use serde_json::Value;

use super::SOURCE;
use super::messages::goal_from_pose_stamped;
use super::topics::{CMD_VEL, GOAL_POSE};
use crate::api::adapter::{self, RequestAdapter};
use crate::api::legacy;
use crate::api::requests::{self, Twist};
use crate::vehicle::Command;

/// Whether a client's `msg` for the topic `name` (one clients publish) can go to the core:
/// the reason to refuse it at once otherwise, naming `topic` as the client gave it.
pub fn check(name: &str, topic: &str, msg: &Value) -> Result<(), String> {
    match name {
        CMD_VEL => {
            // A Twist names both speeds; one missing is a broken message, not a zero.
            let number = |v: &str, axis: &str| {
                msg.get(v)
                    .and_then(|o| o.get(axis))
                    .is_some_and(Value::is_number)
            };
            if number("linear", "x") && number("angular", "z") {
                Ok(())
            } else {
                Err(format!(
                    "{topic}: msg needs linear.x and angular.z as numbers (a geometry_msgs/Twist)"
                ))
            }
        }
        GOAL_POSE => goal_from_pose_stamped(msg)
            .map(|_| ())
            .map_err(|reason| format!("{topic}: {reason}")),
        _ => Err(format!("{topic}: clients do not publish it")),
    }
}

/// The record payload of a client's `msg`, with the id its answer comes back with.
pub fn encode(id: u64, msg: &Value) -> bytes::Bytes {
    adapter::encode_request(Some(id), msg)
}

/// A recorded message's id and core command.
pub fn decode(topic: &str, payload: &[u8]) -> (Option<u64>, Result<Command, String>) {
    if legacy::is_legacy(topic) {
        return (None, legacy::decode(topic, payload));
    }
    match topic {
        CMD_VEL => {
            let (id, twist) = adapter::decode_request::<Twist>(topic, payload);
            (id, twist.and_then(|t| requests::velocity(&t)))
        }
        GOAL_POSE => {
            let (id, msg) = adapter::decode_request::<Value>(topic, payload);
            let goal = msg.and_then(|m| {
                let (x, y, yaw) =
                    goal_from_pose_stamped(&m).map_err(|reason| format!("{topic}: {reason}"))?;
                requests::goal(topic, x, y, yaw)
            });
            (id, goal)
        }
        _ => (None, Err(format!("unknown topic {topic:?}"))),
    }
}

/// The rosbridge server's adapter.
pub const ADAPTER: RequestAdapter = RequestAdapter::new(SOURCE, decode);

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn published_messages_decode_to_commands_with_their_ids() {
        let twist = json!({"linear": {"x": 0.3}, "angular": {"z": 0.1}});
        assert_eq!(check(CMD_VEL, "/cmd_vel", &twist), Ok(()));
        assert_eq!(
            decode(CMD_VEL, &encode(3, &twist)),
            (Some(3), Ok(Command::Velocity { vx: 0.3, wz: 0.1 }))
        );
        let pose = json!({"header": {"frame_id": "map"},
                          "pose": {"position": {"x": 2.0, "y": 1.0}}});
        assert_eq!(check(GOAL_POSE, "/goal_pose", &pose), Ok(()));
        assert!(matches!(
            decode(GOAL_POSE, &encode(4, &pose)),
            (Some(4), Ok(Command::Goal { tag: None, .. }))
        ));
    }

    #[test]
    fn broken_messages_are_refused_with_the_reason() {
        let half = json!({"linear": {"x": 0.3}});
        assert!(
            check(CMD_VEL, "cmd_vel", &half)
                .unwrap_err()
                .contains("angular.z")
        );
        let odom = json!({"header": {"frame_id": "odom"}, "pose": {"position": {"x": 1, "y": 1}}});
        assert!(
            check(GOAL_POSE, "/goal_pose", &odom)
                .unwrap_err()
                .contains("\"map\"")
        );
        // Recorded messages are claims: a sideways twist is refused when it is replayed.
        let sideways = json!({"linear": {"x": 0.3, "y": 0.2}, "angular": {"z": 0.0}});
        let (id, refused) = decode(CMD_VEL, &encode(5, &sideways));
        assert_eq!(id, Some(5));
        assert!(refused.unwrap_err().contains("differential drive"));
        assert!(check("/plan", "/plan", &json!({})).is_err());
    }

    #[test]
    fn old_recordings_decode_as_the_local_channel_read_them() {
        assert_eq!(
            decode("goal", br#"{"x":1.0,"y":2.0,"yaw":0.5}"#).1,
            requests::goal("goal", 1.0, 2.0, 0.5)
        );
        assert!(decode("goal", br#"{"x":1.0,"y":2.0}"#).1.is_err());
    }
}
