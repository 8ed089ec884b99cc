//! device-mqtt-api.md's "WebSocket/ROS2 Topic" interfaces, served over the rosbridge v2
//! protocol (what roslibjs, roslibpy and Foxglove speak): the operations, a client's
//! session, the topic table, what is published when, and the ROS messages as JSON. Moving
//! the bytes is `runtime::links::websocket`'s job.

pub mod adapter;
pub mod envelope;
pub mod latches;
pub mod messages;
pub mod ops;
pub mod parts;
pub mod publisher;
pub mod session;
pub mod topics;

/// The command source of what WebSocket clients publish (`/cmd_vel`, `/goal_pose`), so a
/// recording keeps it and replays without a client ([`adapter`]).
pub const SOURCE: &str = crate::sources::WEBSOCKET;
