//! The ROS messages of the WebSocket topics as rosbridge JSON, in ROS 2's shapes (the spec
//! names ROS 2 topics: a header's stamp is `sec` and `nanosec`, no `seq`). Frames follow
//! REP-103 (x forward, y left, z up; yaw counter-clockwise) and REP-105 (`map`, `odom`,
//! `base_link`). A value the vehicle does not know is `null` (JSON has no NaN), where a ROS
//! node would send NaN.

use serde_json::{Value, json};

use super::parts::{ERROR, OK, WARN, diagnostic, header};
use crate::api::ros1::odometry::{OdometryCovariance, UNMEASURED};
use crate::api::ros1::{ros_time, yaw_quaternion};
use crate::api::rtk::status::{locate_name, navigation_name};
use crate::devices::gnss::FixQuality;
use crate::fusion::odometry::OdomPose;
use crate::time::Timestamp;
use crate::vehicle::MqttLinkStatus;
use crate::vehicle::chassis::status_bits;
use crate::vehicle::corrections::CorrectionsStatus;
use crate::vehicle::{Localization, Navigation, VehicleStatus};

pub use crate::api::ros1::{BASE_FRAME, MAP_FRAME, ODOM_FRAME};

fn planar_pose(x: f64, y: f64, yaw: f64) -> Value {
    let [qx, qy, qz, qw] = yaw_quaternion(yaw);
    json!({
        "position": {"x": x, "y": y, "z": 0.0},
        "orientation": {"x": qx, "y": qy, "z": qz, "w": qw},
    })
}

/// `/pose` (geometry_msgs/PoseWithCovarianceStamped): the fused pose in `map` with its
/// covariance; `None` until the vehicle is placed in the map (before that its pose is the
/// `odom` frame's, which `/odom` carries).
pub fn pose(status: &VehicleStatus) -> Option<Value> {
    if status.localization == Localization::Uninitialized {
        return None;
    }
    let c = status.pose_covariance?;
    let mut covariance = [0.0; 36];
    covariance[0] = c.xx;
    covariance[1] = c.xy;
    covariance[6] = c.xy;
    covariance[7] = c.yy;
    // z, roll and pitch are not estimated.
    for i in [14, 21, 28] {
        covariance[i] = UNMEASURED;
    }
    covariance[35] = c.yaw;
    let p = status.pose;
    Some(json!({
        "header": header(status.time, MAP_FRAME),
        "pose": {"pose": planar_pose(p.x, p.y, p.yaw), "covariance": covariance.to_vec()},
    }))
}

/// One geometry_msgs/TransformStamped: `child` placed at `pose` (x, y, yaw) in `parent`.
fn transform(t: Timestamp, parent: &str, child: &str, pose: (f64, f64, f64)) -> Value {
    let [qx, qy, qz, qw] = yaw_quaternion(pose.2);
    json!({
        "header": header(t, parent),
        "child_frame_id": child,
        "transform": {
            "translation": {"x": pose.0, "y": pose.1, "z": 0.0},
            "rotation": {"x": qx, "y": qy, "z": qz, "w": qw},
        },
    })
}

/// `/tf` (tf2_msgs/TFMessage): map→odom, the correction GNSS estimates, once the vehicle is
/// placed, and odom→base_link, the dead reckoning, once the drives report (REP-105: the map
/// pose is the two composed). `None` while neither frame exists.
pub fn tf(status: &VehicleStatus) -> Option<Value> {
    let t = status.time;
    let mut transforms = Vec::new();
    if let Some(f) = status.frames {
        let (c, o) = (f.map_to_odom, f.odom_to_base);
        transforms.push(transform(t, MAP_FRAME, ODOM_FRAME, (c.x, c.y, c.yaw)));
        transforms.push(transform(t, ODOM_FRAME, BASE_FRAME, (o.x, o.y, o.yaw)));
    } else if let Some(o) = status.odom {
        transforms.push(transform(t, ODOM_FRAME, BASE_FRAME, (o.x, o.y, o.yaw)));
    }
    (!transforms.is_empty()).then(|| json!({ "transforms": transforms }))
}

/// `/odom` (nav_msgs/Odometry): the wheels-and-gyro pose in `odom`, speeds in `base_link`.
pub fn odometry(t: Timestamp, pose: &OdomPose, covariance: &OdometryCovariance) -> Value {
    json!({
        "header": header(t, ODOM_FRAME),
        "child_frame_id": BASE_FRAME,
        "pose": {
            "pose": planar_pose(pose.x, pose.y, pose.yaw),
            "covariance": covariance.pose.to_vec(),
        },
        "twist": {
            "twist": {
                "linear": {"x": pose.v, "y": 0.0, "z": 0.0},
                "angular": {"x": 0.0, "y": 0.0, "z": pose.w},
            },
            "covariance": covariance.twist.to_vec(),
        },
    })
}

/// sensor_msgs/BatteryState's power supply status.
const CHARGING: u8 = 1;
const DISCHARGING: u8 = 2;
const UNKNOWN_STATUS: u8 = 0;
/// Its power supply health: unknown, good.
const HEALTH_UNKNOWN: u8 = 0;
const HEALTH_GOOD: u8 = 1;
/// Its technology: unknown (the BMS does not say).
const TECHNOLOGY_UNKNOWN: u8 = 0;

/// `/battery_state` (sensor_msgs/BatteryState); `None` without a BMS.
pub fn battery_state(status: &VehicleStatus) -> Option<Value> {
    let battery = status.battery?;
    let r = &battery.reading;
    let supply = match r.current_a {
        _ if battery.stale => UNKNOWN_STATUS,
        Some(a) if a > 0.0 => CHARGING,
        Some(_) => DISCHARGING,
        None => UNKNOWN_STATUS,
    };
    let health = if battery.stale || r.rx.is_none() {
        HEALTH_UNKNOWN
    } else {
        HEALTH_GOOD
    };
    Some(json!({
        "header": header(status.time, BASE_FRAME),
        "voltage": r.voltage_v,
        "temperature": r.temperature_c,
        "current": r.current_a,
        "charge": r.remaining_capacity_ah,
        "capacity": null,
        "design_capacity": null,
        "percentage": r.soc_pct.map(|p| p / 100.0),
        "power_supply_status": supply,
        "power_supply_health": health,
        "power_supply_technology": TECHNOLOGY_UNKNOWN,
        "present": r.rx.is_some(),
        "cell_voltage": [],
        "cell_temperature": [],
        "location": "",
        "serial_number": "",
    }))
}

/// The RTK corrections' status: their age is what the safety envelope gates on.
fn corrections_diagnostic(c: &CorrectionsStatus) -> Value {
    let (level, message) = match (c.fresh, c.connected) {
        (true, _) => (OK, "arriving"),
        (false, true) => (
            ERROR,
            "stale: the caster is connected and sends no valid frame",
        ),
        (false, false) => (ERROR, "stale: not connected to the caster"),
    };
    diagnostic(
        level,
        "rtk corrections",
        message,
        &[
            (
                "age_s",
                c.age_s
                    .map_or_else(|| "never".into(), |a| format!("{a:.1}")),
            ),
            ("stale_after_s", format!("{:.0}", c.stale_after_s)),
            ("connected", c.connected.to_string()),
            ("frames", c.frames.to_string()),
            ("bytes", c.bytes.to_string()),
        ],
    )
}

/// One MQTT link: up, or down (a warning: the vehicle's own watchdogs act on silence).
fn mqtt_link_diagnostic(link: &MqttLinkStatus) -> Value {
    let since = link.since.map_or_else(
        || "never".into(),
        |t| format!("{:.3}", t.as_nanos() as f64 * 1e-9),
    );
    diagnostic(
        if link.up { OK } else { WARN },
        &format!("mqtt link {}", link.name),
        if link.up {
            "connected"
        } else {
            "not connected to its broker"
        },
        &[("up", link.up.to_string()), ("since_s", since)],
    )
}

/// `/diagnostics` (diagnostic_msgs/DiagnosticArray): one status each for the receiver, the
/// IMU, the drive train, the RTK corrections (with `[ntrip]`), each MQTT link, the battery
/// and the localisation.
pub fn diagnostics(status: &VehicleStatus) -> Value {
    let g = &status.gnss;
    let mut all = vec![diagnostic(
        if !g.ok {
            ERROR
        } else if g.quality == FixQuality::RtkFixed {
            OK
        } else {
            WARN
        },
        "gnss",
        if g.ok { "fix" } else { "no valid fix" },
        &[("quality", g.quality.to_string())],
    )];
    all.push(diagnostic(
        if status.imu_ok { OK } else { WARN },
        "imu",
        if status.imu_ok {
            "fresh samples"
        } else {
            "no fresh plausible sample (or none configured)"
        },
        &[],
    ));
    if let Some(c) = &status.chassis {
        let stopped = STOPPING_BITS;
        // A latched stop (a zone, an obstacle, a watchdog) is a warning until it re-arms.
        let level = if c.status_bits & stopped != 0 {
            ERROR
        } else if c.ok && c.stop_reason.is_none() {
            OK
        } else {
            WARN
        };
        all.push(diagnostic(
            level,
            "drive train",
            &drive_train_words(c.status_bits, c.stop_reason.as_deref()),
            &[
                ("state", status_bits::describe(c.status_bits)),
                ("status_bits", c.status_bits.to_string()),
                ("vx", format!("{:.3}", c.vx)),
                ("wz", format!("{:.3}", c.wz)),
            ],
        ));
    }
    if let Some(c) = &status.corrections {
        all.push(corrections_diagnostic(c));
    }
    all.extend(status.mqtt_links.iter().map(mqtt_link_diagnostic));
    if let Some(e) = &status.envelope {
        all.push(super::envelope::status(e));
    }
    if let Some(b) = &status.battery {
        let level = if b.stale || b.reading.alarms != 0 {
            WARN
        } else {
            OK
        };
        all.push(diagnostic(
            level,
            "battery",
            if b.stale {
                "no reading within the stale timeout"
            } else if b.reading.alarms != 0 {
                "alarm"
            } else {
                "ok"
            },
            &[
                ("alarms", format!("{:#x}", b.reading.alarms)),
                (
                    "soc_pct",
                    b.reading
                        .soc_pct
                        .map_or_else(|| "unknown".into(), |s| format!("{s:.1}")),
                ),
            ],
        ));
    }
    all.push(diagnostic(
        match status.localization {
            Localization::Good => OK,
            Localization::Lost => WARN,
            Localization::Uninitialized => WARN,
        },
        "localization",
        match status.localization {
            Localization::Good => "located",
            Localization::Lost => "pose beyond its bounds",
            Localization::Uninitialized => "not placed in the map yet",
        },
        &[("nav.locate", locate_name(status.localization).into())],
    ));
    let navigation = navigation_name(status.navigation);
    all.push(diagnostic(
        if status.navigation == Navigation::Failed {
            WARN
        } else {
            OK
        },
        "navigation",
        match status.navigation {
            Navigation::Idle => "idle",
            Navigation::Running => "under way",
            Navigation::Succeeded => "the last motion succeeded",
            Navigation::Failed => "the last motion failed",
        },
        &[("nav.status", navigation.into())],
    ));
    json!({"header": header(status.time, ""), "status": all})
}

/// The status bits that stop the drive train.
const STOPPING_BITS: u32 = status_bits::FAULT
    | status_bits::HEARTBEAT_LOST
    | status_bits::ESTOP
    | status_bits::BUS_DOWN
    | status_bits::CONTROL_LINK_LOST;

/// The drive train's state in plain words: why it is stopped, or what it does now.
fn drive_train_words(bits: u32, stop_reason: Option<&str>) -> String {
    if let Some(reason) = stop_reason {
        return format!("stopped: {reason}");
    }
    let faults = bits & STOPPING_BITS;
    if faults != 0 {
        return format!("stopped: {}", status_bits::describe(faults));
    }
    let words = if bits & status_bits::NOT_READY != 0 {
        "a drive is not ready (booting or unreachable)"
    } else if bits & status_bits::RESETTING != 0 {
        "resetting a drive fault"
    } else if bits & status_bits::MOVING != 0 {
        "driving"
    } else if bits & status_bits::ENABLED != 0 {
        "ready, standing (no velocity command)"
    } else {
        "ready (power stage off until the first command)"
    };
    words.to_owned()
}

/// rcl_interfaces/msg/Log's level of an event.
const LOG_INFO: u8 = 20;

/// `/rosout` (rcl_interfaces/msg/Log): one of the engine's events (a drive up, a fault, a
/// motion's end), as ROS 2 nodes log theirs.
pub fn log(t: Timestamp, text: &str) -> Value {
    let (sec, nanosec) = ros_time(t);
    json!({
        "stamp": {"sec": sec, "nanosec": nanosec},
        "level": LOG_INFO,
        "name": "chassisd",
        "msg": text,
        "file": "",
        "function": "",
        "line": 0,
    })
}

/// `/plan` (nav_msgs/Path) in `map`: the points of the move, goal or task under way, each
/// facing the next.
pub fn path(t: Timestamp, points: &[(f64, f64)]) -> Value {
    let poses: Vec<Value> = points
        .iter()
        .enumerate()
        .map(|(i, &(x, y))| {
            // Towards the next point; the last one keeps the direction it was reached in.
            let toward = |(ax, ay): (f64, f64), (bx, by): (f64, f64)| {
                ((ax, ay) != (bx, by)).then(|| (by - ay).atan2(bx - ax))
            };
            let yaw = points
                .get(i + 1)
                .and_then(|&next| toward((x, y), next))
                .or_else(|| i.checked_sub(1).and_then(|j| toward(points[j], (x, y))))
                .unwrap_or(0.0);
            json!({"header": header(t, MAP_FRAME), "pose": planar_pose(x, y, yaw)})
        })
        .collect();
    json!({"header": header(t, MAP_FRAME), "poses": poses})
}

/// The goal (x, y in m, yaw in rad, map frame) of a `/goal_pose` message
/// (geometry_msgs/PoseStamped): its frame must be `map` (or empty, taken as `map`), its
/// orientation a rotation about z.
pub fn goal_from_pose_stamped(msg: &Value) -> Result<(f64, f64, f64), String> {
    let frame = msg
        .pointer("/header/frame_id")
        .and_then(Value::as_str)
        .unwrap_or("");
    if !(frame.is_empty() || frame == MAP_FRAME) {
        return Err(format!(
            "a goal in frame {frame:?} cannot be reached: give it in \"map\""
        ));
    }
    let number = |pointer: &str, default: Option<f64>| -> Result<f64, String> {
        match msg.pointer(pointer) {
            Some(v) => v
                .as_f64()
                .filter(|f| f.is_finite())
                .ok_or_else(|| format!("{pointer} must be a finite number")),
            None => default.ok_or_else(|| format!("{pointer} is missing")),
        }
    };
    let x = number("/pose/position/x", None)?;
    let y = number("/pose/position/y", None)?;
    let qx = number("/pose/orientation/x", Some(0.0))?;
    let qy = number("/pose/orientation/y", Some(0.0))?;
    let qz = number("/pose/orientation/z", Some(0.0))?;
    let qw = number("/pose/orientation/w", Some(1.0))?;
    let norm = (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
    if (norm - 1.0).abs() > 0.01 {
        return Err(format!(
            "/pose/orientation is not a unit quaternion (norm {norm:.3})"
        ));
    }
    if (qx * qx + qy * qy).sqrt() > 0.02 {
        return Err("/pose/orientation must be a rotation about z (a planar goal)".into());
    }
    Ok((x, y, 2.0 * qz.atan2(qw)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The diagnostic status of `name` in `status`'s `/diagnostics`.
    fn part(status: &VehicleStatus, name: &str) -> Option<Value> {
        diagnostics(status)["status"]
            .as_array()?
            .iter()
            .find(|d| d["name"] == format!("chassisd: {name}"))
            .cloned()
    }

    /// People read the drive train's state in words, never bit names that sound like faults
    /// when all is well.
    #[test]
    fn the_drive_train_speaks_plain_words() {
        use status_bits::*;
        assert_eq!(
            drive_train_words(ENABLED | COMMAND_TIMEOUT, None),
            "ready, standing (no velocity command)"
        );
        assert_eq!(drive_train_words(ENABLED | MOVING, None), "driving");
        assert_eq!(
            drive_train_words(ENABLED | ESTOP, Some("emergency stop body pressed")),
            "stopped: emergency stop body pressed"
        );
        assert_eq!(
            drive_train_words(BUS_DOWN | AWAITING_COMMAND, None),
            "stopped: CAN interface down"
        );
        assert!(drive_train_words(NOT_READY, None).contains("not ready"));
    }

    #[test]
    fn a_latched_stop_is_a_warning_with_its_reason_and_the_envelope_has_its_own_status() {
        use crate::vehicle::chassis::ChassisStatus;
        let mut status = VehicleStatus {
            chassis: Some(ChassisStatus {
                ok: true,
                ..Default::default()
            }),
            ..Default::default()
        };
        assert_eq!(part(&status, "drive train").unwrap()["level"], OK);
        let reason = "the keep_out zone \"pond\" is in the braking way";
        if let Some(c) = &mut status.chassis {
            c.stop_reason = Some(reason.into());
        }
        let drives = part(&status, "drive train").unwrap();
        assert_eq!(
            (drives["level"].clone(), drives["message"].clone()),
            (json!(WARN), json!(format!("stopped: {reason}")))
        );
        assert!(
            part(&status, "safety envelope").is_none(),
            "none without zones"
        );
        status.envelope = Some(crate::vehicle::envelope::EnvelopeStatus {
            gate_closed: None,
            zones: None,
            nearest: None,
            footprint_m: 0.5,
            sigma_m: None,
            braking_m: 0.0,
        });
        assert_eq!(part(&status, "safety envelope").unwrap()["level"], WARN);
    }

    #[test]
    fn each_mqtt_link_is_a_diagnostic_of_its_own() {
        let mut status = VehicleStatus::default();
        let link = |name: &str, up, since_us: Option<u64>| MqttLinkStatus {
            name: name.into(),
            up,
            since: since_us.map(crate::time::Timestamp::from_micros),
        };
        status.mqtt_links = vec![
            link("site", true, Some(1_500_000)),
            link("platform", false, None),
        ];
        let all = diagnostics(&status)["status"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        let of = |name: &str| {
            all.iter()
                .find(|d| d["name"] == format!("chassisd: mqtt link {name}"))
                .cloned()
                .unwrap_or_else(|| panic!("{name}: {all:?}"))
        };
        let (site, platform) = (of("site"), of("platform"));
        assert_eq!(
            (site["level"].clone(), site["message"].clone()),
            (json!(OK), json!("connected"))
        );
        assert_eq!(platform["level"], WARN);
        assert_eq!(site["values"][1]["value"], "1.500");
        assert_eq!(platform["values"][1]["value"], "never");
    }

    #[test]
    fn the_corrections_age_is_a_diagnostic_of_its_own() {
        let mut status = VehicleStatus::default();
        let statuses = |s: &VehicleStatus| {
            diagnostics(s)["status"]
                .as_array()
                .cloned()
                .unwrap_or_default()
        };
        let named = |s: &VehicleStatus| {
            statuses(s)
                .into_iter()
                .find(|d| d["name"] == "chassisd: rtk corrections")
        };
        assert!(named(&status).is_none(), "none without [ntrip]");
        let mut c = CorrectionsStatus {
            connected: true,
            age_s: Some(2.5),
            fresh: true,
            frames: 40,
            bytes: 9000,
            stale_after_s: 10.0,
        };
        status.corrections = Some(c);
        let d = named(&status).expect("the corrections' status");
        assert_eq!(d["level"], OK);
        let age = d["values"]
            .as_array()
            .and_then(|v| v.iter().find(|kv| kv["key"] == "age_s"))
            .map(|kv| kv["value"].clone());
        assert_eq!(age, Some(json!("2.5")));
        c.fresh = false;
        c.connected = false;
        status.corrections = Some(c);
        let d = named(&status).expect("the corrections' status");
        assert_eq!(d["level"], ERROR);
        assert!(
            d["message"]
                .as_str()
                .unwrap_or_default()
                .contains("not connected")
        );
    }

    #[test]
    fn a_goal_pose_becomes_a_goal() {
        let msg = json!({
            "header": {"frame_id": "map", "stamp": {"sec": 0, "nanosec": 0}},
            "pose": {"position": {"x": 2.0, "y": 1.0, "z": 0.0},
                     "orientation": {"x": 0.0, "y": 0.0, "z": std::f64::consts::FRAC_1_SQRT_2,
                                     "w": std::f64::consts::FRAC_1_SQRT_2}},
        });
        let (x, _, yaw) = goal_from_pose_stamped(&msg).unwrap();
        assert_eq!(x, 2.0);
        assert!((yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-6);
    }

    #[test]
    fn goals_that_cannot_be_reached_are_refused_with_the_reason() {
        let refuse = |msg: Value| goal_from_pose_stamped(&msg).unwrap_err();
        assert!(
            refuse(json!({"header": {"frame_id": "odom"}, "pose": {"position": {"x": 1, "y": 1}}}))
                .contains("\"map\"")
        );
        assert!(refuse(json!({"pose": {"position": {"x": 1}}})).contains("/pose/position/y"));
        assert!(refuse(json!({"pose": {"position": {"x": 1, "y": "a"}}})).contains("finite"));
        assert!(refuse(json!({"pose": {"position": {"x": 1, "y": 1}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 2}}})).contains("unit quaternion"));
        assert!(refuse(json!({"pose": {"position": {"x": 1, "y": 1}, "orientation": {"x": 1, "y": 0, "z": 0, "w": 0}}})).contains("about z"));
    }

    #[test]
    fn a_path_faces_along_itself() {
        let p = path(
            Timestamp::from_micros(1_500_000),
            &[(0.0, 0.0), (0.0, 1.0), (0.0, 2.0)],
        );
        let poses = p["poses"].as_array().unwrap();
        assert_eq!(poses.len(), 3);
        for pose in poses {
            // Facing north: yaw π/2.
            let qz = pose["pose"]["orientation"]["z"].as_f64().unwrap();
            assert!(
                (qz - (std::f64::consts::FRAC_PI_4).sin()).abs() < 1e-9,
                "{pose}"
            );
        }
        assert_eq!(
            p["header"]["stamp"],
            json!({"sec": 1, "nanosec": 500_000_000})
        );
        assert_eq!(p["header"]["frame_id"], "map");
    }
}
