//! The native ROS 2 node's interface, sans-IO: device-mqtt-api.md's "WebSocket/ROS2 Topic"
//! topics and what a ROS 2 stack expects of a base (odometry, frames, the receiver's fix,
//! the IMU), the messages it takes, and the `navigate_to_pose` action. The node that moves
//! the messages over DDS is `runtime::links::ros2` (the `ros2` feature).
//!
//! - [`topics`]: every topic, its type and QoS, in two tables (published, taken);
//! - [`publisher`]: the messages due from the engine's feed, by the first table (the
//!   rosbridge server's messages, which are ROS 2's already, and `/fix`, `/imu/data`,
//!   `/tf_static` of [`messages`]);
//! - [`adapter`]: what the node takes, recorded under the source [`SOURCE`] as it came and
//!   handed to the core: `/cmd_vel` (Twist or TwistStamped) through the arbiter, limits,
//!   watchdog and zones as every velocity source, `/goal_pose` as the device dialect's goal,
//!   `/initialpose` as root's INIT_POSITION, `navigate_to_pose` goals tagged as the node's;
//! - [`navigate`]: the action's goals, their feedback and results.
//!
//! The interface definitions the node's types are generated from are in `interfaces/`, one
//! folder per package, as ROS 2 Jazzy defines them.

pub mod adapter;
pub mod messages;
pub mod navigate;
pub mod publisher;
pub mod topics;

/// Source name of the node's requests in recordings and the engine.
pub const SOURCE: &str = crate::sources::ROS2;

/// The owner of the goals the node asks for.
pub const OWNER: &str = "ros2";

/// The action's name, and the record topic of its goals.
pub const NAVIGATE_TO_POSE: &str = "/navigate_to_pose";
/// The record topic of a cancel of the goal under way.
pub const NAVIGATE_TO_POSE_CANCEL: &str = "/navigate_to_pose/cancel";
