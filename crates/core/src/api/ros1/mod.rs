//! The ROS1 interface of `ros1-navigation-interface.txt`: what its topics and services ask of
//! the core, and the status codes it publishes. Sans-IO like the MQTT dialects; the node that
//! moves the messages is `runtime::links::ros1` (the `ros1` feature).
//!
//! Requests are typed ([`adapter::Ros1Request`]) and recorded under the source [`SOURCE`]
//! with their ROS names and fields, so a recorded session replays with them and without
//! ROS; [`adapter::Ros1Adapter`] hands them to the core and answers them by id:
//! - `/cmd_vel` (geometry_msgs/Twist) goes through the arbiter and the command watchdog like
//!   every velocity source;
//! - `/navi_stop` 5 ends every move, goal, task or mission and the vehicle comes to rest
//!   without latching (the spec excepts continuous velocity control);
//! - `/autocharge` 1 is a mission of one CHARGING step: to the configured dock, then until the
//!   BMS reports charging;
//! - `/set_navi_cmd` is a move (or cmd 5, the stop) with the request's fields;
//! - `/set_shape` and `/set_region` add a wall, a keep-out circle or a keep-out polygon to the
//!   zones (map frame), or remove one by its `shapeId`; each answer also goes out on
//!   `/androidmsg_virtualmapstatus` (62 made, 63 refused);
//! - `/get_position` and `/navi_info` are queries answered from the core and the build, and
//!   `/robot_ssh` and `/set_wifi` are always refused ([`queries`]), recorded as the others
//!   (a Wi-Fi password never is).
//!
//! The interface definitions the node is built from are in `interfaces/`, one folder per
//! package: the standard ones field for field as ROS defines them, and the spec's own
//! `map_msgs` from its field tables (its `long` is int64, `int` int32).

pub mod adapter;
pub mod messages;
pub mod odometry;
pub mod publisher;
pub mod queries;
pub mod status;
pub mod topics;

use serde_json::json;

/// Source name of the node's commands in recordings and the engine.
pub const SOURCE: &str = crate::sources::ROS1;

/// The owner of the motions and missions the node asks for.
pub const OWNER: &str = "ros1";

/// Frame of the fused pose (REP-105).
pub const MAP_FRAME: &str = "map";
/// Frame of wheel odometry (REP-105): continuous, drifting.
pub const ODOM_FRAME: &str = "odom";
/// The vehicle's own frame (REP-103: x forward, y left, z up).
pub const BASE_FRAME: &str = "base_link";

/// `/navi_info`'s `nav_info` JSON: what the build is.
pub fn navi_info(vehicle: &str) -> String {
    json!({
        "coco_num": "",
        "navi_channel": "chassisd",
        "numero": vehicle,
        "version_code": env!("CARGO_PKG_VERSION"),
        "version_name": concat!("chassisd ", env!("CARGO_PKG_VERSION")),
    })
    .to_string()
}

/// Seconds and nanoseconds of a ROS time from a timestamp (nanoseconds since the epoch).
pub fn ros_time(t: crate::time::Timestamp) -> (u32, u32) {
    let nanos = t.as_nanos();
    (
        u32::try_from(nanos / 1_000_000_000).unwrap_or(u32::MAX),
        (nanos % 1_000_000_000) as u32,
    )
}

/// The quaternion (x, y, z, w) of a rotation by `yaw` about z.
pub fn yaw_quaternion(yaw: f64) -> [f64; 4] {
    let (s, c) = (yaw / 2.0).sin_cos();
    [0.0, 0.0, s, c]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_and_rotations_follow_ros() {
        let t = crate::time::Timestamp::from_nanos(1_700_000_000_123_456_789);
        assert_eq!(ros_time(t), (1_700_000_000, 123_456_789));
        let [x, y, z, w] = yaw_quaternion(std::f64::consts::FRAC_PI_2);
        assert_eq!((x, y), (0.0, 0.0));
        assert!((z - 0.5f64.sqrt()).abs() < 1e-12 && (w - 0.5f64.sqrt()).abs() < 1e-12);
    }
}
