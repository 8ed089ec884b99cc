//! `[mission]`: how root MISSION steps run (path speed, the dock for CHARGING), and
//! `[cutter]`: the blade actuator OPEN_CUTTER and CLOSE_CUTTER switch, as a CAN frame with
//! its on and off data.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{ConfigError, VehicleConfig, check_range};
use crate::control::goal::GoalPose;

/// `[mission]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct MissionConfig {
    /// Speed of MOVE_TO_POSITION and COVERAGE paths, m/s (default 0.5; the motion speed
    /// limit caps it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_mps: Option<f64>,
    /// The charging dock: x, y (m, map frame) and the heading to dock with (degrees,
    /// counter-clockwise from east). Without one CHARGING fails with the reason.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dock: Option<[f64; 3]>,
    /// CHARGING fails when the BMS has not reported charging for this long (after docking, or
    /// since it last did), s (default 60).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub charge_timeout_s: Option<f64>,
}

/// The settings missions run with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MissionSettings {
    /// Path speed, m/s.
    pub speed_mps: f64,
    /// The dock pose (map frame).
    pub dock: Option<GoalPose>,
    /// How long to wait for charging at the dock, s.
    pub charge_timeout_s: f64,
}

impl MissionConfig {
    /// The settings.
    pub fn settings(&self) -> MissionSettings {
        MissionSettings {
            speed_mps: self.speed_mps.unwrap_or(0.5),
            dock: self.dock.map(|[x, y, heading]| GoalPose {
                x,
                y,
                yaw: crate::fusion::ekf::wrap(heading.to_radians()),
            }),
            charge_timeout_s: self.charge_timeout_s.unwrap_or(60.0),
        }
    }

    /// Checks the values.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if let Some(v) = self.speed_mps {
            check_range(file, "mission.speed_mps", v, 0.01..=10.0, "m/s")?;
        }
        if let Some(v) = self.charge_timeout_s {
            check_range(file, "mission.charge_timeout_s", v, 1.0..=86_400.0, "s")?;
        }
        if let Some(dock) = self.dock
            && !dock.iter().all(|v| v.is_finite())
        {
            return Err(ConfigError::invalid(
                file,
                "mission.dock",
                "holds a value that is not a finite number".to_owned(),
                "give [x, y, heading]: metres east and north, degrees",
            ));
        }
        Ok(())
    }
}

/// `[cutter]`: a frame switches the blade on, another off.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CutterConfig {
    /// The CAN interface (one of `[[can]]`).
    pub bus: String,
    /// The frame's identifier.
    pub can_id: u32,
    /// A 29-bit identifier.
    #[serde(default)]
    pub extended: bool,
    /// The data that switches it on (at most 8 bytes).
    pub on: Vec<u8>,
    /// The data that switches it off (at most 8 bytes).
    pub off: Vec<u8>,
}

impl CutterConfig {
    /// The frame that switches the cutter `on` or off.
    pub fn frame(&self, on: bool) -> Option<crate::devices::can::Frame> {
        let data = if on { &self.on } else { &self.off };
        if self.extended {
            crate::devices::can::Frame::extended(self.can_id, data)
        } else {
            crate::devices::can::Frame::standard(self.can_id, data)
        }
    }

    /// Checks it against the vehicle's buses.
    pub fn validate(&self, vehicle: &VehicleConfig, file: &Path) -> Result<(), ConfigError> {
        let invalid =
            |key: &str, problem: String, fix: &str| ConfigError::invalid(file, key, problem, fix);
        if !vehicle.can.iter().any(|c| c.interface == self.bus) {
            return Err(invalid(
                "cutter.bus",
                format!("{:?} is not a configured [[can]] interface", self.bus),
                "name one of the [[can]] interfaces",
            ));
        }
        if self.frame(true).is_none() || self.frame(false).is_none() {
            return Err(invalid(
                "cutter",
                format!(
                    "can_id {:#x} or its data does not make a CAN frame",
                    self.can_id
                ),
                "use an identifier up to 0x7FF (0x1FFFFFFF with extended = true) and at most 8 \
                 bytes of on and off data",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_a_cutter_frame() {
        let s = MissionConfig::default().settings();
        assert_eq!(s.speed_mps, 0.5);
        assert_eq!(s.charge_timeout_s, 60.0);
        assert!(s.dock.is_none());
        let docked = MissionConfig {
            dock: Some([1.0, 2.0, 90.0]),
            ..MissionConfig::default()
        }
        .settings();
        let dock = docked.dock.expect("a dock");
        assert!((dock.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let cutter: CutterConfig =
            toml::from_str("bus = \"can0\"\ncan_id = 0x300\non = [1, 0xFF]\noff = [0]")
                .expect("cutter");
        let on = cutter.frame(true).expect("a frame");
        assert_eq!((on.id(), on.data()), (0x300, &[1u8, 0xFF][..]));
        let too_long = CutterConfig {
            on: vec![0; 9],
            ..cutter
        };
        assert!(too_long.frame(true).is_none());
    }
}
