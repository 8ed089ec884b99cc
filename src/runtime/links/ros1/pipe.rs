//! What chassisd and the ROS1 node's process say to each other: one JSON line each way per
//! message, on the child's standard input and output. chassisd builds every message the
//! node publishes (the node's process only puts them on the wire), and the node's process
//! hands up every request it takes, with a call number when a service caller waits for the
//! answer.

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::api::ros1::adapter::Ros1Request;
use crate::config::ros1::Ros1Config;

/// The longest line either side takes: a `/set_region` of some thousand points fits; a
/// larger request is refused by the node's process before it is sent.
pub const MAX_LINE: usize = 4 << 20;

/// The node process's settings: the first line it reads.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NodeSettings {
    /// `[ros1]`.
    pub config: Ros1Config,
}

/// chassisd → the node's process.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ToNode {
    /// Messages to publish, each on its topic.
    Publish { messages: Vec<(String, Value)> },
    /// The vehicle's answer to the request the node's process numbered `call`.
    Answer { call: u64, result: Verdict },
}

/// The vehicle's answer to a request: taken (with what a query asked for), or why not.
pub type Verdict = Result<Option<Value>, String>;

/// The node's process → chassisd.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FromNode {
    /// Registered with the master (again): the latched topics are due.
    Registered,
    /// A request taken from a topic or a service; `call` when its caller waits for the
    /// answer.
    Request {
        call: Option<u64>,
        request: Ros1Request,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_cross_as_one_line_each_and_back() {
        let to = ToNode::Publish {
            messages: vec![("/odom".into(), serde_json::json!({"a": [1, 2]}))],
        };
        let line = serde_json::to_string(&to).unwrap();
        assert!(!line.contains('\n'));
        assert_eq!(serde_json::from_str::<ToNode>(&line).unwrap(), to);
        let from = FromNode::Request {
            call: Some(3),
            request: Ros1Request::SetNaviCmd {
                cmd: "1".into(),
                distance: 50,
            },
        };
        let line = serde_json::to_string(&from).unwrap();
        assert_eq!(serde_json::from_str::<FromNode>(&line).unwrap(), from);
        for result in [
            Err("refused".into()),
            Ok(None),
            Ok(Some(serde_json::json!({"x": 1.5, "y": -2.0}))),
        ] {
            let answer = ToNode::Answer { call: 3, result };
            let line = serde_json::to_string(&answer).unwrap();
            assert_eq!(serde_json::from_str::<ToNode>(&line).unwrap(), answer);
        }
    }
}
