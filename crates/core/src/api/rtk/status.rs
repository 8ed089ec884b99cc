//! Dialect `rtk` (rtk-mqtt-protocol.md): the `base_status` report.
//!
//! Every key of the protocol's example is always present, in the protocol's units:
//! degrees for `rtk.angle` (0 = north, clockwise) and `rtk.latitude/longitude`, metres and
//! radians (ENU) for `pose`, m/s and rad/s for `robot`. Absent devices (no BMS, no drives,
//! and the IMU and lidar chassisd does not drive yet) report zeros and a `false` sensor
//! flag, so a consumer can tell "absent" from "zero". `sensor.gnss` is an addition to the
//! protocol. `bms.status`, `bms.error` and `robot.robot_status` are bit sets documented in
//! docs/protocols/mqtt.md.

use serde::Serialize;

use crate::vehicle::{Localization, Navigation, VehicleStatus};

/// The `base_status` object.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BaseStatus {
    /// Battery.
    pub bms: Bms,
    /// Navigation.
    pub nav: Nav,
    /// Local pose.
    pub pose: Pose,
    /// Chassis.
    pub robot: Robot,
    /// GNSS.
    pub rtk: Rtk,
    /// Sensor health flags.
    pub sensor: Sensor,
}

/// `bms`: battery management system.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Bms {
    /// Current, A (positive = charging).
    pub current: f64,
    /// Error bit set.
    pub error: u32,
    /// Remaining capacity, Ah.
    pub remaining_capacity: f64,
    /// State of charge, %.
    pub soc: f64,
    /// Status code.
    pub status: u32,
    /// Temperature, °C.
    pub tem: f64,
    /// Pack voltage, V.
    pub voltage: f64,
}

/// `nav`: localisation and navigation state.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Nav {
    /// `LOCATE_UNINIT`, `LOCATE_TRUE` or `LOCATE_FALSE`.
    pub locate: &'static str,
    /// Stopped for an obstacle.
    pub obstacle: bool,
    /// `NAV_FREE`, `NAV_RUN`, `NAV_SUCCESS` or `NAV_ERROR`.
    pub status: &'static str,
}

/// `pose`: local ENU pose.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Pose {
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Yaw, rad, counter-clockwise from east.
    pub yaw: f64,
}

/// `robot`: chassis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Robot {
    /// Battery charge, %.
    pub power: f64,
    /// Chassis status bit set.
    pub robot_status: u32,
    /// Forward speed, m/s.
    pub vx: f64,
    /// Lateral speed, m/s.
    pub vy: f64,
    /// Yaw rate, rad/s.
    pub vz: f64,
}

/// `nav.locate`'s value for `localization`.
pub fn locate_name(localization: Localization) -> &'static str {
    match localization {
        Localization::Uninitialized => "LOCATE_UNINIT",
        Localization::Good => "LOCATE_TRUE",
        Localization::Lost => "LOCATE_FALSE",
    }
}

/// `nav.status`'s value for `navigation`.
pub fn navigation_name(navigation: Navigation) -> &'static str {
    match navigation {
        Navigation::Idle => "NAV_FREE",
        Navigation::Running => "NAV_RUN",
        Navigation::Succeeded => "NAV_SUCCESS",
        Navigation::Failed => "NAV_ERROR",
    }
}

/// `rtk`: GNSS fix.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Rtk {
    /// Heading, degrees (0 = north, clockwise).
    pub angle: f64,
    /// Latitude, degrees.
    pub latitude: f64,
    /// Longitude, degrees.
    pub longitude: f64,
    /// 0 none, 1 single, 2 DGPS, 4 RTK fixed, 5 RTK float.
    pub status: u8,
}

/// `sensor`: health flags (`true` = working).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Sensor {
    /// GNSS link up with a fresh valid fix (chassisd addition).
    pub gnss: bool,
    /// IMU.
    pub imu: bool,
    /// Lidar.
    pub laser: bool,
    /// Chassis (motor drives).
    pub robot: bool,
}

impl BaseStatus {
    /// The report for a core status snapshot.
    pub fn from_status(status: &VehicleStatus) -> Self {
        let gnss = &status.gnss;
        let battery = status
            .battery
            .map(|b| (b.reading, b.reading.status_bits(b.stale)));
        let reading = battery.map(|(r, _)| r).unwrap_or_default();
        let chassis = status.chassis.clone().unwrap_or_default();
        Self {
            bms: Bms {
                current: num(reading.current_a.unwrap_or(0.0)),
                error: reading.alarms,
                remaining_capacity: num(reading.remaining_capacity_ah.unwrap_or(0.0)),
                soc: num(reading.soc_pct.unwrap_or(0.0)),
                status: battery.map_or(0, |(_, bits)| bits),
                tem: num(reading.temperature_c.unwrap_or(0.0)),
                voltage: num(reading.voltage_v.unwrap_or(0.0)),
            },
            nav: Nav {
                locate: locate_name(status.localization),
                obstacle: status.obstacle_stop,
                status: navigation_name(status.navigation),
            },
            pose: Pose {
                x: num(status.pose.x),
                y: num(status.pose.y),
                yaw: num(status.pose.yaw),
            },
            robot: Robot {
                power: num(reading.soc_pct.unwrap_or(0.0)),
                robot_status: chassis.status_bits,
                vx: num(chassis.vx),
                vy: 0.0,
                vz: num(chassis.wz),
            },
            rtk: Rtk {
                angle: num(gnss.heading_deg),
                latitude: num(gnss.latitude_deg),
                longitude: num(gnss.longitude_deg),
                status: gnss.quality.rtk_status(),
            },
            sensor: Sensor {
                gnss: gnss.ok,
                imu: status.imu_ok,
                laser: false,
                robot: chassis.ok,
            },
        }
    }

    /// One line of JSON (no trailing newline).
    pub fn to_json(&self) -> String {
        let mut out = Vec::with_capacity(JSON_CAPACITY);
        self.write_json(&mut out);
        String::from_utf8(out).unwrap_or_default()
    }

    /// Appends the JSON object to `out` (a buffer kept across calls saves growing one per
    /// status).
    pub fn write_json(&self, out: &mut Vec<u8>) {
        // Serialising plain structs of numbers, bools and static strings into memory
        // cannot fail.
        let _ = serde_json::to_writer(out, self);
    }
}

/// Room for one base_status object, which is about 450 bytes.
const JSON_CAPACITY: usize = 640;

/// A number JSON can carry: NaN and infinities become 0, and negative zero is written 0.
fn num(v: f64) -> f64 {
    if v.is_finite() { v + 0.0 } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::Timestamp;
    use crate::vehicle::{CoreConfig, Input, Output, Vehicle};

    /// The key tree of the protocol's example, plus `sensor.gnss`.
    const SPEC_KEYS: &[&str] = &[
        "bms.current",
        "bms.error",
        "bms.remaining_capacity",
        "bms.soc",
        "bms.status",
        "bms.tem",
        "bms.voltage",
        "nav.locate",
        "nav.obstacle",
        "nav.status",
        "pose.x",
        "pose.y",
        "pose.yaw",
        "robot.power",
        "robot.robot_status",
        "robot.vx",
        "robot.vy",
        "robot.vz",
        "rtk.angle",
        "rtk.latitude",
        "rtk.longitude",
        "rtk.status",
        "sensor.gnss",
        "sensor.imu",
        "sensor.laser",
        "sensor.robot",
    ];

    #[test]
    fn has_every_key_of_the_protocol() {
        let mut v = Vehicle::new(CoreConfig::default());
        let Some(Output::Status(s)) = v.handle(Timestamp::from_micros(0), Input::Tick).pop() else {
            panic!("no status");
        };
        let json: serde_json::Value =
            serde_json::from_str(&BaseStatus::from_status(&s).to_json()).expect("valid JSON");
        let mut keys = Vec::new();
        for (group, inner) in json.as_object().expect("object") {
            for (key, value) in inner.as_object().expect("nested object") {
                assert!(!value.is_object() && !value.is_null(), "{group}.{key}");
                keys.push(format!("{group}.{key}"));
            }
        }
        assert_eq!(keys, SPEC_KEYS);
        assert_eq!(json["nav"]["locate"], "LOCATE_UNINIT");
        assert_eq!(json["nav"]["status"], "NAV_FREE");
        assert_eq!(json["rtk"]["status"], 0);
    }
}
