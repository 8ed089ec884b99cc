//! What any channel may ask of the core, typed: the checks a request passes whichever
//! protocol carries it (the local channel, the ROS1 node, the rosbridge clients), so the same
//! request is refused for the same reason on each, and no channel re-encodes another's.

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::control::MoveKind;
use crate::control::goal::GoalPose;
use crate::control::mission::{MAX_STEPS, MissionStep};
use crate::fusion::planar::wrap;
use crate::vehicle::Command;

/// Longest move forward or back, cm (100 m).
pub const MAX_MOVE_CM: f64 = 10_000.0;
/// Largest turn, degrees (ten turns).
pub const MAX_TURN_DEG: f64 = 3_600.0;

/// A ROS `geometry_msgs/Vector3` as JSON; a missing component is zero.
#[derive(Debug, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Vector3 {
    /// x.
    #[serde(default)]
    pub x: f64,
    /// y.
    #[serde(default)]
    pub y: f64,
    /// z.
    #[serde(default)]
    pub z: f64,
}

/// A ROS `geometry_msgs/Twist` as JSON; a missing vector is zero.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Twist {
    /// m/s.
    #[serde(default)]
    pub linear: Vector3,
    /// rad/s.
    #[serde(default)]
    pub angular: Vector3,
}

impl Twist {
    /// The twist of these components.
    pub fn new(linear: [f64; 3], angular: [f64; 3]) -> Self {
        let v = |[x, y, z]: [f64; 3]| Vector3 { x, y, z };
        Self {
            linear: v(linear),
            angular: v(angular),
        }
    }
}

/// A velocity command: a differential drive follows only linear x and angular z, and
/// every other component must be zero.
pub fn velocity(twist: &Twist) -> Result<Command, String> {
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

/// `/set_navi_cmd`: `cmd` 1 forward, 2 back (`distance` in cm), 3 left, 4 right (degrees),
/// 5 stop. `cmd` is the service's string; a JSON number is taken too.
pub fn navi_cmd(cmd: &Value, distance: Option<f64>) -> Result<Command, String> {
    let code = match cmd {
        Value::String(s) => s.trim().parse::<u8>().ok(),
        Value::Number(n) => n.as_u64().and_then(|n| u8::try_from(n).ok()),
        _ => None,
    };
    let Some(code @ 1..=5) = code else {
        return Err(format!(
            "set_navi_cmd: cmd must be \"1\" (forward), \"2\" (back), \"3\" (left), \"4\" \
             (right) or \"5\" (stop), not {cmd}"
        ));
    };
    if code == 5 {
        return Ok(Command::CancelMotion);
    }
    let Some(distance) = distance else {
        return Err(
            "set_navi_cmd: distance is needed (cm for cmd 1 and 2, degrees for 3 and 4)".into(),
        );
    };
    let max = if code <= 2 { MAX_MOVE_CM } else { MAX_TURN_DEG };
    if !(0.0..=max).contains(&distance) {
        return Err(format!(
            "set_navi_cmd: distance {distance} is outside 0..={max} {}",
            if code <= 2 { "cm" } else { "degrees" }
        ));
    }
    Ok(Command::Move(match code {
        1 => MoveKind::Straight {
            distance_m: distance / 100.0,
        },
        2 => MoveKind::Straight {
            distance_m: -distance / 100.0,
        },
        3 => MoveKind::Turn {
            angle_rad: distance.to_radians(),
        },
        _ => MoveKind::Turn {
            angle_rad: -distance.to_radians(),
        },
    }))
}

/// A goal pose in the map frame (m, m, rad), untagged; `topic` names the request in the
/// refusal.
pub fn goal(topic: &str, x: f64, y: f64, yaw: f64) -> Result<Command, String> {
    if ![x, y, yaw].iter().all(|v| v.is_finite()) {
        return Err(format!("{topic}: x, y and yaw must be finite"));
    }
    Ok(Command::Goal {
        goal: GoalPose {
            x,
            y,
            yaw: wrap(yaw),
        },
        tag: None,
    })
}

/// The yaw (rad) of an orientation quaternion `[x, y, z, w]`, as INIT_POSITION takes it: its
/// values finite and its norm within 0.5–1.5 (a hand-typed quaternion is seldom exactly
/// unit); `None` otherwise. A planar vehicle keeps only the rotation about z.
pub fn quaternion_yaw([qx, qy, qz, qw]: [f64; 4]) -> Option<f64> {
    let norm = (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
    ([qx, qy, qz, qw].iter().all(|v| v.is_finite()) && (0.5..=1.5).contains(&norm))
        .then(|| (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz)))
}

/// The charging action: a mission of one CHARGING step (to the dock, then until the BMS
/// reports charging), untagged.
pub fn charge() -> Command {
    Command::Mission {
        steps: std::sync::Arc::new(vec![MissionStep::Charge(0.0)]),
        tag: None,
    }
}

/// `command` with `tag` on it when it is a mission or a goal without one (so its owner can
/// tell its end).
pub fn tagged(command: Command, tag: crate::control::MotionTag) -> Command {
    match command {
        Command::Mission { steps, tag: None } => Command::Mission {
            steps,
            tag: Some(tag),
        },
        Command::Goal { goal, tag: None } => Command::Goal {
            goal,
            tag: Some(tag),
        },
        other => other,
    }
}

/// A mission's steps (root's MISSION `data`, the local channel's `mission`): an array of `{action, parameters}` steps.
///
/// - MOVE_TO_POSITION and COVERAGE: `path` `[x0, y0, x1, y1, ...]`, m in the map frame,
///   followed in order (the vehicle drives to the first point first);
/// - WAIT: `seconds` ≥ 0;
/// - OPEN_CUTTER and CLOSE_CUTTER: `cutter` true and false (optional; it must match);
/// - CHARGING: `time`, s charged before the step is done (0: done once charging).
pub fn mission_steps(data: &Value) -> Result<Vec<MissionStep>, String> {
    const ACTIONS: [&str; 6] = [
        "MOVE_TO_POSITION",
        "WAIT",
        "OPEN_CUTTER",
        "CLOSE_CUTTER",
        "COVERAGE",
        "CHARGING",
    ];
    let Some(steps) = data.as_array() else {
        return Err("data must be an array of steps".to_owned());
    };
    if steps.is_empty() {
        return Err("a mission needs at least one step".to_owned());
    }
    if steps.len() > MAX_STEPS {
        return Err(format!(
            "a mission has at most {MAX_STEPS} steps, this one {}: split it",
            steps.len()
        ));
    }
    let mut out = Vec::with_capacity(steps.len());
    for (i, step) in steps.iter().enumerate() {
        let action = step.get("action").and_then(Value::as_str).unwrap_or("");
        let Some(parameters) = step.get("parameters").filter(|p| p.is_object()) else {
            return Err(format!(
                "step {i}: needs an action (one of {}) and parameters",
                ACTIONS.join(", ")
            ));
        };
        let bad = |what: &str| format!("step {i} ({action}): {what}");
        let seconds = |key: &str| {
            parameters
                .get(key)
                .and_then(Value::as_f64)
                .filter(|s| (0.0..=86_400.0).contains(s))
                .ok_or_else(|| {
                    bad(&format!(
                        "{key} must be a number of seconds from 0 to 86400"
                    ))
                })
        };
        let path = || {
            let values: Option<Vec<f64>> = parameters
                .get("path")
                .and_then(Value::as_array)
                .and_then(|a| a.iter().map(Value::as_f64).collect());
            let values = values
                .ok_or_else(|| bad("path must be an array of numbers [x0, y0, x1, y1, ...]"))?;
            super::path_points(&values).map_err(|e| bad(&e))
        };
        let cutter = |want: bool| match parameters.get("cutter") {
            None => Ok(MissionStep::Cutter(want)),
            Some(v) if v.as_bool() == Some(want) => Ok(MissionStep::Cutter(want)),
            Some(_) => Err(bad(&format!("cutter must be {want} (or absent)"))),
        };
        out.push(match action {
            "MOVE_TO_POSITION" => MissionStep::MoveTo(path()?),
            "COVERAGE" => MissionStep::Coverage(path()?),
            "WAIT" => MissionStep::Wait(seconds("seconds")?),
            "OPEN_CUTTER" => cutter(true)?,
            "CLOSE_CUTTER" => cutter(false)?,
            "CHARGING" => MissionStep::Charge(seconds("time")?),
            _ => {
                return Err(format!(
                    "step {i}: action {action:?} is not one of {}",
                    ACTIONS.join(", ")
                ));
            }
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn velocities_a_differential_drive_cannot_follow_are_refused() {
        let ok = Twist::new([0.3, 0.0, 0.0], [0.0, 0.0, 0.2]);
        assert_eq!(velocity(&ok), Ok(Command::Velocity { vx: 0.3, wz: 0.2 }));
        let sideways = Twist::new([0.3, 0.5, 0.0], [0.0; 3]);
        assert!(velocity(&sideways).unwrap_err().contains("linear.x"));
        let nan = Twist::new([f64::NAN, 0.0, 0.0], [0.0; 3]);
        assert!(velocity(&nan).unwrap_err().contains("finite"));
    }

    #[test]
    fn navi_cmds_take_the_specs_codes_and_bounds() {
        assert_eq!(navi_cmd(&json!("5"), None), Ok(Command::CancelMotion));
        assert_eq!(
            navi_cmd(&json!(" 2 "), Some(20.0)),
            Ok(Command::Move(MoveKind::Straight { distance_m: -0.2 }))
        );
        assert!(
            navi_cmd(&json!("9"), Some(1.0))
                .unwrap_err()
                .contains("not \"9\"")
        );
        assert!(
            navi_cmd(&json!(1), None)
                .unwrap_err()
                .contains("distance is needed")
        );
        assert!(
            navi_cmd(&json!("3"), Some(MAX_TURN_DEG + 1.0))
                .unwrap_err()
                .contains("outside")
        );
    }

    #[test]
    fn goals_must_be_finite_and_tags_go_on_missions_and_goals_only() {
        assert!(goal("goal", f64::INFINITY, 0.0, 0.0).is_err());
        let tag = crate::control::MotionTag {
            owner: "ros1",
            id: 0,
        };
        let g = tagged(goal("goal", 1.0, 2.0, 7.0).unwrap(), tag);
        assert!(matches!(g, Command::Goal { tag: Some(t), goal } if t == tag && goal.yaw < 7.0));
        assert!(matches!(
            tagged(charge(), tag),
            Command::Mission { tag: Some(_), .. }
        ));
        assert_eq!(tagged(Command::Stop, tag), Command::Stop);
    }
}
