//! The ROS1 interface of `ros1-navigation-interface.txt`: what its topics and services ask of
//! the core, and the status codes it publishes. Sans-IO like the MQTT dialects; the node that
//! moves the messages is `runtime::links::ros1` (the `ros1` feature).
//!
//! Requests become the local channel's commands (`api::local`), recorded under the source
//! [`SOURCE`], so a recorded session replays with them and without ROS:
//! - `/cmd_vel` (geometry_msgs/Twist) is `cmd_vel`, through the arbiter and the command
//!   watchdog like every velocity source;
//! - `/navi_stop` 5 is `set_navi_cmd` 5: every move, goal, task or mission ends and the
//!   vehicle comes to rest without latching (the spec excepts continuous velocity control);
//! - `/autocharge` 1 is a mission of one CHARGING step: to the configured dock, then until the
//!   BMS reports charging;
//! - `/set_navi_cmd` is `set_navi_cmd` with the request's fields.
//!
//! The interface definitions the node is built from are in `interfaces/`, one folder per
//! package: the standard ones field for field as ROS defines them, and the spec's own
//! `map_msgs` from its field tables (its `long` is int64, `int` int32).

pub mod odometry;
pub mod status;

use serde_json::json;

use crate::control::MotionTag;
use crate::vehicle::Command;

/// Source name of the node's commands in recordings and the engine.
pub const SOURCE: &str = "ros1";

/// The owner of the motions and missions the node asks for.
pub const OWNER: &str = "ros1";

/// Frame of the fused pose (REP-105).
pub const MAP_FRAME: &str = "map";
/// Frame of wheel odometry (REP-105): continuous, drifting.
pub const ODOM_FRAME: &str = "odom";
/// The vehicle's own frame (REP-103: x forward, y left, z up).
pub const BASE_FRAME: &str = "base_link";

/// A command for the engine: a topic of the local channel and its JSON.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    /// The local channel's topic.
    pub topic: &'static str,
    /// Its JSON payload.
    pub payload: String,
    /// Whether, accepted, it starts a motion (whose start the node announces).
    pub starts_motion: bool,
}

/// `/cmd_vel`: the twist as it came; the local channel refuses components a ground vehicle
/// cannot follow (any but linear x and angular z) and values that are not finite.
pub fn cmd_vel(linear: [f64; 3], angular: [f64; 3]) -> Request {
    // serde_json writes a non-finite number as null, which the decoder refuses by name.
    Request {
        topic: crate::api::local::CMD_VEL,
        payload: json!({
            "linear": {"x": linear[0], "y": linear[1], "z": linear[2]},
            "angular": {"x": angular[0], "y": angular[1], "z": angular[2]},
        })
        .to_string(),
        starts_motion: false,
    }
}

/// `/navi_stop`: 5 stops every motion; any other value is refused.
pub fn navi_stop(data: i16) -> Result<Request, String> {
    if data != 5 {
        return Err(format!("/navi_stop takes 5 (stop), not {data}"));
    }
    Ok(Request {
        topic: crate::api::local::SET_NAVI_CMD,
        payload: json!({"cmd": "5"}).to_string(),
        starts_motion: false,
    })
}

/// `/autocharge`: 1 starts the charging action; any other value is refused.
pub fn autocharge(data: i16) -> Result<Request, String> {
    if data != 1 {
        return Err(format!("/autocharge takes 1 (charge), not {data}"));
    }
    Ok(Request {
        topic: crate::api::local::MISSION,
        payload: json!([{"action": "CHARGING", "parameters": {"time": 0}}]).to_string(),
        starts_motion: true,
    })
}

/// `/set_navi_cmd`: the request's fields as the local channel takes them.
pub fn set_navi_cmd(cmd: &str, distance: i64) -> Request {
    Request {
        topic: crate::api::local::SET_NAVI_CMD,
        payload: json!({"cmd": cmd, "distance": distance}).to_string(),
        // Command 5 is the stop; every other one the local channel takes is a move.
        starts_motion: cmd != "5",
    }
}

/// The node's tag on a mission or goal it asked for, so it can tell that mission's end.
pub fn tagged(command: Command) -> Command {
    let tag = Some(MotionTag {
        owner: OWNER,
        id: 0,
    });
    match command {
        Command::Mission { steps, tag: None } => Command::Mission { steps, tag },
        Command::Goal { goal, tag: None } => Command::Goal { goal, tag },
        other => other,
    }
}

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
    use crate::api::local;

    #[test]
    fn requests_decode_as_the_local_channel_takes_them() {
        let r = cmd_vel([0.3, 0.0, 0.0], [0.0, 0.0, 0.2]);
        assert_eq!(
            local::decode(r.topic, r.payload.as_bytes()),
            Ok(Some(Command::Velocity { vx: 0.3, wz: 0.2 }))
        );
        let r = set_navi_cmd("1", 50);
        assert!(matches!(
            local::decode(r.topic, r.payload.as_bytes()),
            Ok(Some(Command::Move(_)))
        ));
        assert!(r.starts_motion);
        let r = navi_stop(5).unwrap();
        assert_eq!(
            local::decode(r.topic, r.payload.as_bytes()),
            Ok(Some(Command::CancelMotion))
        );
        assert!(!r.starts_motion);
        let r = autocharge(1).unwrap();
        assert!(matches!(
            local::decode(r.topic, r.payload.as_bytes()).map(|c| c.map(tagged)),
            Ok(Some(Command::Mission {
                tag: Some(MotionTag { owner: OWNER, .. }),
                ..
            }))
        ));
    }

    #[test]
    fn what_a_vehicle_cannot_do_is_refused_with_the_reason() {
        assert!(navi_stop(4).unwrap_err().contains("takes 5"));
        assert!(autocharge(0).unwrap_err().contains("takes 1"));
        let r = cmd_vel([0.3, 0.5, 0.0], [0.0, 0.0, 0.0]);
        assert!(local::decode(r.topic, r.payload.as_bytes()).is_err());
        let r = cmd_vel([f64::NAN, 0.0, 0.0], [0.0, 0.0, 0.0]);
        assert!(local::decode(r.topic, r.payload.as_bytes()).is_err());
        let r = set_navi_cmd("9", 10);
        assert!(local::decode(r.topic, r.payload.as_bytes()).is_err());
    }

    #[test]
    fn times_and_rotations_follow_ros() {
        let t = crate::time::Timestamp::from_nanos(1_700_000_000_123_456_789);
        assert_eq!(ros_time(t), (1_700_000_000, 123_456_789));
        let [x, y, z, w] = yaw_quaternion(std::f64::consts::FRAC_PI_2);
        assert_eq!((x, y), (0.0, 0.0));
        assert!((z - 0.5f64.sqrt()).abs() < 1e-12 && (w - 0.5f64.sqrt()).abs() < 1e-12);
    }
}
