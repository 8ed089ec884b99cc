//! What chassisd and the ROS 2 node's process say to each other: one JSON line each way per
//! message, on the child's standard input and output. chassisd builds every message the
//! node publishes and decides every goal; the node's process moves them over DDS and hands
//! up what it takes, as the JSON of its type.

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::interface::Joining;
use crate::config::ros2::Ros2Config;

/// The longest line either side takes: a `/zones` of some thousand points fits.
pub const MAX_LINE: usize = 4 << 20;

/// The node process's settings: the first line it reads.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NodeSettings {
    /// `[ros2]`.
    pub config: Ros2Config,
    /// Where and how it joins DDS (the configuration's, or ROS 2's environment's).
    pub joining: Joining,
}

/// chassisd → the node's process.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ToNode {
    /// Messages to publish, each on its topic (a name of the table, before the namespace).
    Publish { messages: Vec<(String, Value)> },
    /// The vehicle's answer to goal `goal`: taken, or why not.
    Goal {
        goal: u64,
        verdict: Result<(), String>,
    },
    /// Goal `goal`'s feedback (nav2_msgs/NavigateToPose_Feedback as JSON).
    Feedback { goal: u64, msg: Value },
    /// Goal `goal` ended: its action_msgs/GoalStatus and its result.
    Ended {
        goal: u64,
        status: i8,
        result: Value,
    },
}

/// The node's process → chassisd.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FromNode {
    /// The node is on the domain: the messages published once are due.
    Ready,
    /// A message taken on `topic`, as the JSON of its type.
    Message { topic: String, msg: Value },
    /// A `navigate_to_pose` goal, numbered `goal` by the process.
    Goal { goal: u64, msg: Value },
    /// Its client asks to cancel goal `goal`.
    Cancel { goal: u64 },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_cross_as_one_line_each_and_back() {
        let down = [
            ToNode::Publish {
                messages: vec![("/odom".into(), serde_json::json!({"a": [1, 2]}))],
            },
            ToNode::Goal {
                goal: 3,
                verdict: Err("a goal in frame \"odom\" cannot be reached".into()),
            },
            ToNode::Ended {
                goal: 3,
                status: 4,
                result: serde_json::json!({"error_code": 0, "error_msg": ""}),
            },
        ];
        for message in down {
            let line = serde_json::to_string(&message).unwrap();
            assert!(!line.contains('\n'));
            assert_eq!(serde_json::from_str::<ToNode>(&line).unwrap(), message);
        }
        let up = FromNode::Message {
            topic: "/cmd_vel".into(),
            msg: serde_json::json!({"linear": {"x": 0.5}}),
        };
        let line = serde_json::to_string(&up).unwrap();
        assert_eq!(serde_json::from_str::<FromNode>(&line).unwrap(), up);
    }
}
