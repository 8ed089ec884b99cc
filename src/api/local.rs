//! The local command channel: `chassisd run --commands-stdin` reads one command per line,
//! `TOPIC JSON`, for operators and tests before a network dialect is connected.
//!
//! `cmd_vel {"linear":{"x":0.3},"angular":{"z":0.1}}` is a velocity command in the shape
//! of ROS `geometry_msgs/Twist` (the `/cmd_vel` of ros1-navigation-interface.txt): `linear.x`
//! m/s forward, `angular.z` rad/s counter-clockwise; other components must be zero or absent.

use serde::Deserialize;

use crate::core::Command;

/// Topic of velocity commands.
pub const CMD_VEL: &str = "cmd_vel";
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

/// Decodes a command; `Ok(None)` for topics this channel does not know.
pub fn decode(topic: &str, payload: &[u8]) -> Result<Option<Command>, String> {
    if topic != CMD_VEL {
        return Ok(None);
    }
    if payload.len() > MAX_PAYLOAD {
        return Err(format!(
            "payload of {} bytes exceeds {MAX_PAYLOAD}",
            payload.len()
        ));
    }
    let twist: Twist = serde_json::from_slice(payload).map_err(|e| format!("cmd_vel: {e}"))?;
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
    Ok(Some(Command::Velocity {
        vx: twist.linear.x,
        wz: twist.angular.z,
    }))
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
    fn splits_console_lines() {
        assert_eq!(
            split_line("cmd_vel {\"linear\":{}}"),
            Some(("cmd_vel", "{\"linear\":{}}"))
        );
        assert_eq!(split_line("  # comment"), None);
        assert_eq!(split_line(""), None);
    }
}
