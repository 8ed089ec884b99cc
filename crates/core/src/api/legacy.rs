//! Requests as recordings held them before the protocol adapters: the ROS1 node's and the
//! rosbridge clients' requests re-encoded as the local channel's commands (its topic names,
//! which lack a ROS name's leading slash, and its JSON). They decode as they did then, so
//! such a recording replays to the same bytes and answers (`fixtures/ros-legacy`). Nothing
//! records requests this way any more.

use crate::vehicle::Command;

/// Whether a request of a ROS adapter's source is in the old form.
pub fn is_legacy(topic: &str) -> bool {
    !topic.starts_with('/')
}

/// An old-form request's command, or why it was refused then.
pub fn decode(topic: &str, payload: &[u8]) -> Result<Command, String> {
    super::local::command(topic, payload)
}
