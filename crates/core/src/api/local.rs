//! The local command channel: `chassisd run --commands-stdin` reads one command per line,
//! `TOPIC JSON`, for operators and tests before a network dialect is connected.
//!
//! `cmd_vel {"linear":{"x":0.3},"angular":{"z":0.1}}` is a velocity command in the shape
//! of ROS `geometry_msgs/Twist` (the `/cmd_vel` of ros1-navigation-interface.txt): `linear.x`
//! m/s forward, `angular.z` rad/s counter-clockwise; other components must be zero or absent.
//!
//! The local frame can be set as the network protocols set it:
//! - `init_rtk_data {}` re-zeroes the local frame at the vehicle (rtk-mqtt-protocol.md);
//! - `init_position {"x":1.0,"y":2.0,"yaw":0.5}` makes the vehicle read this pose, metres and
//!   radians (INIT_POSITION of root-mqtt-api.rst);
//! - `set_lng_lat [113.0196, 23.1496, 12.3]` moves the datum to this longitude, latitude
//!   (degrees) and height (m), in SET_LNG_LAT's order.
//!
//! Moves (`/set_navi_cmd` of ros1-navigation-interface.txt, its request as JSON):
//! - `set_navi_cmd {"cmd": "1", "distance": 100}`: `cmd` 1 forward, 2 back (distance in cm),
//!   3 turn left, 4 turn right (degrees), 5 stop. `cmd` is a string in the service; a number
//!   is taken too. `distance` is a whole or decimal number ≥ 0, up to 10000 cm or 3600°; cmd 5
//!   needs none. The move closes its loop on the vehicle's own pose; its end (succeeded,
//!   cancelled, timed out, aborted, with the reason) is logged. A new move replaces the one
//!   under way; a `cmd_vel` (in manual mode), `stop` or cmd 5 ends it. Cmd 5 brings the
//!   vehicle to rest without latching: the next move needs no re-arm.
//! - `goal {"x": 10.0, "y": 2.0, "yaw": 1.57}` goes to this pose in the map frame (metres east
//!   and north of the datum, radians counter-clockwise from east), as `device/{serial}/goal`
//!   does; it needs the vehicle located. Its end is logged the same way.
//!
//! - `follow_path {"path": [x0, y0, x1, y1, ...], "speed": 0.5}` follows the path through
//!   these points of the map frame (metres, the flat list of root MISSION's COVERAGE) at up to
//!   `speed` m/s, as `start_task` follows a saved trajectory; it needs the vehicle located and
//!   the GNSS quality of `motion.task_min_gnss`. Its end, with the cross-track error, is
//!   logged.
//! - `pause {}` holds a path task where it is and latches the operator's stop (other motion
//!   ends), as root PAUSE; `continue {}` re-arms and goes on from there, as CONTINUE.
//!
//! - `mission [{"action": "WAIT", "parameters": {"seconds": 5}}, ...]` runs root MISSION's
//!   steps (its `data` array, the same checks); progress and the end are logged.
//!
//! Safety:
//! - `stop {}` stops and latches, as an operator's stop;
//! - `estop {"engaged":true}` engages the software emergency stop (latches), `{"engaged":false}`
//!   releases it (which does not re-arm);
//! - `reset {}` re-arms a latched stop once its cause has cleared, resetting drive faults (a
//!   zero `cmd_vel` does the same).

use serde::Deserialize;

use super::adapter::RequestAdapter;

use super::requests;
use crate::geodesy::Geodetic;
use crate::vehicle::{Command, PathPoints, PathRequest};

/// Topic of velocity commands.
pub const CMD_VEL: &str = "cmd_vel";
/// Topic that re-zeroes the local frame.
pub const INIT_RTK_DATA: &str = "init_rtk_data";
/// Topic that sets the pose.
pub const INIT_POSITION: &str = "init_position";
/// Topic that sets the datum.
pub const SET_LNG_LAT: &str = "set_lng_lat";
/// Topic of the operator's stop.
pub const STOP: &str = "stop";
/// Topic of the software emergency stop.
pub const ESTOP: &str = "estop";
/// Topic that re-arms a latched stop.
pub const RESET: &str = "reset";
/// Topic of distance and angle moves.
pub const SET_NAVI_CMD: &str = "set_navi_cmd";
/// Topic of goals.
pub const GOAL: &str = "goal";
/// Topic of path tasks.
pub const FOLLOW_PATH: &str = "follow_path";
/// Topic that pauses a task.
pub const PAUSE: &str = "pause";
/// Topic that goes on with it.
pub const CONTINUE: &str = "continue";
/// Topic of missions.
pub const MISSION: &str = "mission";
/// Largest payload accepted, bytes ...
pub const MAX_PAYLOAD: usize = 4096;
/// ... except for a path, bytes (some 10,000 points).
pub const MAX_PATH_PAYLOAD: usize = 256 * 1024;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct EStop {
    engaged: bool,
}

/// An empty JSON object (or nothing at all).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Empty {}

/// `/set_navi_cmd`'s request.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NaviCmd {
    cmd: serde_json::Value,
    #[serde(default)]
    distance: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FollowPath {
    path: Vec<f64>,
    speed: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Pose {
    x: f64,
    y: f64,
    yaw: f64,
}

/// Source name of the local command channel (`chassisd run --commands-stdin`) in
/// recordings and the engine.
pub const SOURCE: &str = crate::sources::LOCAL_COMMANDS;

/// The local channel's adapter: each line's command to the core, and its answer.
pub const ADAPTER: RequestAdapter =
    RequestAdapter::new(SOURCE, |topic, payload| (None, command(topic, payload)));

/// A line's command, or why it is refused (a topic this channel does not know included).
pub fn command(topic: &str, payload: &[u8]) -> Result<Command, String> {
    match decode(topic, payload) {
        Ok(Some(command)) => Ok(command),
        Ok(None) => Err(format!("unknown topic {topic:?}")),
        Err(e) => Err(e),
    }
}

/// Decodes a command; `Ok(None)` for topics this channel does not know.
pub fn decode(topic: &str, payload: &[u8]) -> Result<Option<Command>, String> {
    if ![
        CMD_VEL,
        INIT_RTK_DATA,
        INIT_POSITION,
        SET_LNG_LAT,
        STOP,
        ESTOP,
        RESET,
        SET_NAVI_CMD,
        GOAL,
        FOLLOW_PATH,
        PAUSE,
        CONTINUE,
        MISSION,
    ]
    .contains(&topic)
    {
        return Ok(None);
    }
    let limit = if topic == FOLLOW_PATH || topic == MISSION {
        MAX_PATH_PAYLOAD
    } else {
        MAX_PAYLOAD
    };
    if payload.len() > limit {
        return Err(format!(
            "payload of {} bytes exceeds {limit}",
            payload.len()
        ));
    }
    let parse_error = |e: serde_json::Error| format!("{topic}: {e}");
    match topic {
        CMD_VEL => {
            requests::velocity(&serde_json::from_slice(payload).map_err(parse_error)?).map(Some)
        }
        INIT_RTK_DATA => Ok(Some(Command::ZeroLocalFrame)),
        STOP | RESET | PAUSE | CONTINUE => {
            if !payload.iter().all(u8::is_ascii_whitespace) {
                serde_json::from_slice::<Empty>(payload).map_err(parse_error)?;
            }
            Ok(Some(match topic {
                STOP => Command::Stop,
                RESET => Command::Reset,
                PAUSE => Command::Pause,
                _ => Command::Continue,
            }))
        }
        MISSION => {
            let data: serde_json::Value = serde_json::from_slice(payload).map_err(parse_error)?;
            let steps =
                super::requests::mission_steps(&data).map_err(|e| format!("{topic}: {e}"))?;
            Ok(Some(Command::Mission {
                steps: std::sync::Arc::new(steps),
                tag: None,
            }))
        }
        FOLLOW_PATH => {
            let f: FollowPath = serde_json::from_slice(payload).map_err(parse_error)?;
            let points = super::path_points(&f.path).map_err(|e| format!("{topic}: {e}"))?;
            let speed = super::task_speed(f.speed).map_err(|e| format!("{topic}: {e}"))?;
            Ok(Some(Command::FollowPath {
                path: std::sync::Arc::new(PathRequest {
                    points: PathPoints::Map(points),
                    speed,
                }),
                tag: None,
            }))
        }
        SET_NAVI_CMD => {
            let n: NaviCmd = serde_json::from_slice(payload).map_err(parse_error)?;
            requests::navi_cmd(&n.cmd, n.distance).map(Some)
        }
        ESTOP => {
            let e: EStop = serde_json::from_slice(payload).map_err(parse_error)?;
            Ok(Some(Command::EmergencyStop { engaged: e.engaged }))
        }
        GOAL => {
            let p: Pose = serde_json::from_slice(payload).map_err(parse_error)?;
            requests::goal(topic, p.x, p.y, p.yaw).map(Some)
        }
        INIT_POSITION => {
            let p: Pose = serde_json::from_slice(payload).map_err(parse_error)?;
            if ![p.x, p.y, p.yaw].iter().all(|v| v.is_finite()) {
                return Err(format!("{topic}: x, y and yaw must be finite"));
            }
            Ok(Some(Command::SetPose {
                x: p.x,
                y: p.y,
                yaw: p.yaw,
            }))
        }
        _ => {
            let [lon_deg, lat_deg, h_m]: [f64; 3] =
                serde_json::from_slice(payload).map_err(parse_error)?;
            if !(-90.0..=90.0).contains(&lat_deg)
                || !(-180.0..=180.0).contains(&lon_deg)
                || !h_m.is_finite()
            {
                return Err(format!(
                    "{topic}: [longitude, latitude, height] must be within ±180°, ±90° and finite"
                ));
            }
            Ok(Some(Command::SetDatum(Geodetic {
                lat_deg,
                lon_deg,
                h_m,
            })))
        }
    }
}

/// Splits a console line `TOPIC JSON` into topic and payload.
pub fn split_line(line: &str) -> Option<(&str, &str)> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') {
        return None;
    }
    Some(
        line.split_once(char::is_whitespace)
            .map_or((line, ""), |(t, p)| (t, p.trim())),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::MoveKind;

    #[test]
    fn decodes_twists() {
        assert_eq!(
            decode(
                "cmd_vel",
                br#"{"linear":{"x":0.3,"y":0,"z":0},"angular":{"x":0,"y":0,"z":-0.2}}"#
            ),
            Ok(Some(Command::Velocity { vx: 0.3, wz: -0.2 }))
        );
        assert_eq!(
            decode("cmd_vel", br#"{"angular":{"z":1}}"#),
            Ok(Some(Command::Velocity { vx: 0.0, wz: 1.0 }))
        );
        assert_eq!(decode("other", b"x"), Ok(None));
        assert!(decode("cmd_vel", b"{").is_err());
        assert!(decode("cmd_vel", br#"{"linear":{"y":1}}"#).is_err());
        assert!(decode("cmd_vel", br#"{"linear":{"x":"fast"}}"#).is_err());
        assert!(decode("cmd_vel", br#"{"linear":{"x":1},"extra":1}"#).is_err());
        assert!(decode("cmd_vel", &vec![b' '; 5000]).is_err());
    }

    #[test]
    fn decodes_frame_commands() {
        assert_eq!(
            decode("init_rtk_data", b"{}"),
            Ok(Some(Command::ZeroLocalFrame))
        );
        assert_eq!(
            decode("init_position", br#"{"x":1,"y":-2.5,"yaw":0.5}"#),
            Ok(Some(Command::SetPose {
                x: 1.0,
                y: -2.5,
                yaw: 0.5
            }))
        );
        assert!(decode("init_position", br#"{"x":1,"y":2}"#).is_err());
        assert_eq!(
            decode("set_lng_lat", b"[123.0145612, 23.41576123, 34]"),
            Ok(Some(Command::SetDatum(Geodetic {
                lat_deg: 23.41576123,
                lon_deg: 123.0145612,
                h_m: 34.0
            })))
        );
        // Latitude first by mistake: 123° is no latitude.
        assert!(decode("set_lng_lat", b"[23.4, 123.0, 34]").is_err());
        assert!(decode("set_lng_lat", b"[123.0, 95.0, 34]").is_err());
        assert!(decode("set_lng_lat", b"[123.0, 23.0]").is_err());
    }

    #[test]
    fn decodes_safety_commands() {
        assert_eq!(decode("reset", b"{}"), Ok(Some(Command::Reset)));
        assert_eq!(decode("reset", b""), Ok(Some(Command::Reset)));
        assert_eq!(decode("stop", b" {} "), Ok(Some(Command::Stop)));
        assert!(decode("reset", br#"{"now":1}"#).is_err());
        assert_eq!(
            decode("estop", br#"{"engaged":true}"#),
            Ok(Some(Command::EmergencyStop { engaged: true }))
        );
        assert!(decode("estop", b"{}").is_err());
        assert!(decode("estop", br#"{"engaged":"yes"}"#).is_err());
    }

    #[test]
    fn decodes_navi_cmds() {
        assert_eq!(
            decode("set_navi_cmd", br#"{"cmd": "1", "distance": 100}"#),
            Ok(Some(Command::Move(MoveKind::Straight { distance_m: 1.0 })))
        );
        assert_eq!(
            decode("set_navi_cmd", br#"{"cmd": 2, "distance": 50}"#),
            Ok(Some(Command::Move(MoveKind::Straight { distance_m: -0.5 })))
        );
        assert_eq!(
            decode("set_navi_cmd", br#"{"cmd": "4", "distance": 90}"#),
            Ok(Some(Command::Move(MoveKind::Turn {
                angle_rad: -90f64.to_radians()
            })))
        );
        assert_eq!(
            decode("set_navi_cmd", br#"{"cmd": "5"}"#),
            Ok(Some(Command::CancelMotion))
        );
        for bad in [
            &br#"{"cmd": "6", "distance": 1}"#[..],
            br#"{"cmd": "1"}"#,
            br#"{"cmd": "1", "distance": -5}"#,
            br#"{"cmd": "1", "distance": 1e9}"#,
            br#"{"cmd": "3", "distance": 4000}"#,
            br#"{"cmd": true, "distance": 1}"#,
            br#"{"cmd": "1", "distance": "far"}"#,
            br#"{"cmd": "1", "distance": 1, "speed": 2}"#,
        ] {
            assert!(
                decode("set_navi_cmd", bad).is_err(),
                "{}",
                String::from_utf8_lossy(bad)
            );
        }
    }

    #[test]
    fn splits_console_lines() {
        assert_eq!(
            split_line("cmd_vel {\"linear\":{}}"),
            Some(("cmd_vel", "{\"linear\":{}}"))
        );
        assert_eq!(split_line("  # comment"), None);
        assert_eq!(split_line(""), None);
    }
}
