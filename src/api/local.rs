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
//! Safety:
//! - `stop {}` stops and latches, as an operator's stop;
//! - `estop {"engaged":true}` engages the software emergency stop (latches), `{"engaged":false}`
//!   releases it (which does not re-arm);
//! - `reset {}` re-arms a latched stop once its cause has cleared, resetting drive faults (a
//!   zero `cmd_vel` does the same).

use serde::Deserialize;

use crate::core::Command;
use crate::fusion::geodesy::Geodetic;

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
/// Largest payload accepted, bytes.
pub const MAX_PAYLOAD: usize = 4096;

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct Vector3 {
    #[serde(default)]
    x: f64,
    #[serde(default)]
    y: f64,
    #[serde(default)]
    z: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Twist {
    #[serde(default)]
    linear: Vector3,
    #[serde(default)]
    angular: Vector3,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct EStop {
    engaged: bool,
}

/// An empty JSON object (or nothing at all).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Empty {}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Pose {
    x: f64,
    y: f64,
    yaw: f64,
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
    ]
    .contains(&topic)
    {
        return Ok(None);
    }
    if payload.len() > MAX_PAYLOAD {
        return Err(format!(
            "payload of {} bytes exceeds {MAX_PAYLOAD}",
            payload.len()
        ));
    }
    let parse_error = |e: serde_json::Error| format!("{topic}: {e}");
    match topic {
        CMD_VEL => velocity(serde_json::from_slice(payload).map_err(parse_error)?).map(Some),
        INIT_RTK_DATA => Ok(Some(Command::ZeroLocalFrame)),
        STOP | RESET => {
            if !payload.iter().all(u8::is_ascii_whitespace) {
                serde_json::from_slice::<Empty>(payload).map_err(parse_error)?;
            }
            Ok(Some(if topic == STOP {
                Command::Stop
            } else {
                Command::Reset
            }))
        }
        ESTOP => {
            let e: EStop = serde_json::from_slice(payload).map_err(parse_error)?;
            Ok(Some(Command::EmergencyStop { engaged: e.engaged }))
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

fn velocity(twist: Twist) -> Result<Command, String> {
    if twist.linear.y != 0.0
        || twist.linear.z != 0.0
        || twist.angular.x != 0.0
        || twist.angular.y != 0.0
    {
        return Err(
            "cmd_vel: a differential drive moves only along linear.x and turns about angular.z"
                .into(),
        );
    }
    if !twist.linear.x.is_finite() || !twist.angular.z.is_finite() {
        return Err("cmd_vel: velocities must be finite".into());
    }
    Ok(Command::Velocity {
        vx: twist.linear.x,
        wz: twist.angular.z,
    })
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
    fn splits_console_lines() {
        assert_eq!(
            split_line("cmd_vel {\"linear\":{}}"),
            Some(("cmd_vel", "{\"linear\":{}}"))
        );
        assert_eq!(split_line("  # comment"), None);
        assert_eq!(split_line(""), None);
    }
}
