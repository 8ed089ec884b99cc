//! The calibration file (`calib/<vehicle>.toml`), written by `chassisd calibrate` and read
//! when a vehicle configuration is loaded. Each value it holds replaces the configuration's
//! value of the same key.
//!
//! ```toml
//! [chassis]
//! track_m = 0.4213                                  # a plain value, or a table:
//! wheel_radius_m = { value = [0.1102, 0.1123], date = "2026-11-24T09:12:03Z",
//!   method = "...", residuals = { rms_mm = 4.1 }, verdict = "ok" }
//! [imu]
//! gyro_bias_rps = [0.0, 0.0, 0.0035]                # sensor frame, rad/s
//! mounting_rpy_deg = [0.4, -0.2, 0.0]               # roll and pitch measured, yaw kept
//! [gnss]
//! antenna = [0.5, 0.0]                              # x forward, y left, m
//! heading_offset_deg = 2.0                          # receiver heading - vehicle heading
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::chassis::WheelRadius;
use super::{ConfigError, VehicleConfig, check_range};

/// `calib/<vehicle>.toml`: where a vehicle's calibration file is, relative to its
/// configuration, unless the configuration names another. Characters a file name should not
/// hold become `_`.
pub fn default_path(vehicle: &str) -> PathBuf {
    let name: String = vehicle
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    let name = name.trim_start_matches('.');
    Path::new("calib").join(format!(
        "{}.toml",
        if name.is_empty() { "vehicle" } else { name }
    ))
}

/// A calibrated value: plain, or with how and when it was found.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Entry<T> {
    /// With its provenance.
    Measured(Measured<T>),
    /// Just the value (written by hand).
    Plain(T),
}

/// A value with the date, the method, the fit's residuals and a verdict.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Measured<T> {
    /// The value.
    pub value: T,
    /// When it was measured (RFC 3339, UTC).
    pub date: String,
    /// How.
    pub method: String,
    /// Figures of the fit: named residuals and counts.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub residuals: BTreeMap<String, f64>,
    /// "ok", or what makes the value doubtful.
    pub verdict: String,
}

impl<T> Entry<T> {
    /// The value.
    pub fn value(&self) -> &T {
        match self {
            Self::Measured(m) => &m.value,
            Self::Plain(v) => v,
        }
    }

    /// " (method, date)" when known.
    fn provenance(&self) -> String {
        match self {
            Self::Measured(m) => format!(" ({}, {})", m.method, m.date),
            Self::Plain(_) => String::new(),
        }
    }
}

/// `[chassis]` of the calibration file.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ChassisCalibration {
    /// Rolling radius of each wheel, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_radius_m: Option<Entry<WheelRadius>>,
    /// Effective track, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub track_m: Option<Entry<f64>>,
}

/// `[imu]` of the calibration file.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ImuCalibration {
    /// Gyro bias in the sensor frame, rad/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro_bias_rps: Option<Entry<[f64; 3]>>,
    /// Mounting roll, pitch (from gravity) and yaw (kept from the configuration), degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mounting_rpy_deg: Option<Entry<[f64; 3]>>,
}

/// `[gnss]` of the calibration file.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GnssCalibration {
    /// Antenna in the vehicle frame: x forward, y left, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub antenna: Option<Entry<[f64; 2]>>,
    /// Dual-antenna heading minus the vehicle's heading, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading_offset_deg: Option<Entry<f64>>,
}

/// A calibration file.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationFile {
    /// The drive train.
    #[serde(default, skip_serializing_if = "is_default")]
    pub chassis: ChassisCalibration,
    /// The IMU.
    #[serde(default, skip_serializing_if = "is_default")]
    pub imu: ImuCalibration,
    /// The GNSS receiver.
    #[serde(default, skip_serializing_if = "is_default")]
    pub gnss: GnssCalibration,
}

fn is_default<T: Default + PartialEq>(v: &T) -> bool {
    *v == T::default()
}

impl CalibrationFile {
    /// Reads and checks a calibration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = super::read_text(path)?;
        Self::from_toml(&text, path)
    }

    /// Parses and checks calibration TOML; `file` names it in errors.
    pub fn from_toml(text: &str, file: &Path) -> Result<Self, ConfigError> {
        let calib: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            file: file.to_owned(),
            message: e.to_string(),
        })?;
        calib.validate(file)?;
        Ok(calib)
    }

    /// The file as TOML.
    pub fn to_toml(&self) -> String {
        // Plain data structures always serialise.
        toml::to_string(self).unwrap_or_default()
    }

    fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if let Some(r) = &self.chassis.wheel_radius_m {
            for v in [r.value().left, r.value().right] {
                check_range(file, "chassis.wheel_radius_m", v, 0.01..=2.0, "m")?;
            }
        }
        if let Some(t) = &self.chassis.track_m {
            check_range(file, "chassis.track_m", *t.value(), 0.05..=5.0, "m")?;
        }
        if let Some(b) = &self.imu.gyro_bias_rps {
            for (i, v) in b.value().iter().enumerate() {
                let key = format!("imu.gyro_bias_rps[{i}]");
                check_range(file, &key, *v, -0.5..=0.5, "rad/s")?;
            }
        }
        if let Some(m) = &self.imu.mounting_rpy_deg {
            for (i, v) in m.value().iter().enumerate() {
                let key = format!("imu.mounting_rpy_deg[{i}]");
                check_range(file, &key, *v, -180.0..=180.0, "degrees")?;
            }
        }
        if let Some(a) = &self.gnss.antenna {
            for (i, v) in a.value().iter().enumerate() {
                let key = format!("gnss.antenna[{i}]");
                check_range(file, &key, *v, -10.0..=10.0, "m")?;
            }
        }
        if let Some(h) = &self.gnss.heading_offset_deg {
            check_range(
                file,
                "gnss.heading_offset_deg",
                *h.value(),
                -180.0..=180.0,
                "degrees",
            )?;
        }
        Ok(())
    }

    /// Puts the values into `config` where it has the section they belong to; returns one
    /// line per value in force, and one per value without a section to go to.
    pub fn apply(&self, config: &mut VehicleConfig) -> Vec<String> {
        let mut lines = Vec::new();
        let mut note = |key: &str, shown: String, provenance: String, used: bool| {
            lines.push(if used {
                format!("{key} = {shown}{provenance}")
            } else {
                format!("{key} = {shown} not used: the configuration has no such section")
            });
        };
        if let Some(e) = &self.chassis.wheel_radius_m {
            let r = *e.value();
            let shown = format!("[{:.5}, {:.5}] m", r.left, r.right);
            let chassis = config.chassis.as_mut();
            note(
                "chassis.wheel_radius_m",
                shown,
                e.provenance(),
                chassis.is_some(),
            );
            if let Some(c) = chassis {
                c.wheel_radius_m = r;
            }
        }
        if let Some(e) = &self.chassis.track_m {
            let chassis = config.chassis.as_mut();
            let shown = format!("{:.5} m", e.value());
            note("chassis.track_m", shown, e.provenance(), chassis.is_some());
            if let Some(c) = chassis {
                c.track_m = *e.value();
            }
        }
        if let Some(e) = &self.imu.gyro_bias_rps {
            let b = e.value();
            let shown = format!("[{:.6}, {:.6}, {:.6}] rad/s", b[0], b[1], b[2]);
            let imu = config.imu.as_mut();
            note("imu.gyro_bias_rps", shown, e.provenance(), imu.is_some());
            if let Some(i) = imu {
                i.gyro_bias_rps = *b;
            }
        }
        if let Some(e) = &self.imu.mounting_rpy_deg {
            let m = e.value();
            let shown = format!("[{:.3}, {:.3}, {:.3}]°", m[0], m[1], m[2]);
            let imu = config.imu.as_mut();
            note("imu.mounting_rpy_deg", shown, e.provenance(), imu.is_some());
            if let Some(i) = imu {
                i.mounting_rpy_deg = *m;
            }
        }
        if let Some(e) = &self.gnss.antenna {
            let [x, y] = *e.value();
            let gnss = config.gnss.as_mut();
            note(
                "gnss.antenna",
                format!("[{x:.4}, {y:.4}] m"),
                e.provenance(),
                gnss.is_some(),
            );
            if let Some(g) = gnss {
                g.antenna.x = x;
                g.antenna.y = y;
            }
        }
        if let Some(e) = &self.gnss.heading_offset_deg {
            let gnss = config.gnss.as_mut();
            let shown = format!("{:.3}°", e.value());
            note(
                "gnss.heading_offset_deg",
                shown,
                e.provenance(),
                gnss.is_some(),
            );
            if let Some(g) = gnss {
                g.heading_offset_deg = *e.value();
            }
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_and_measured_values_both_read() {
        let text = r#"
[chassis]
track_m = 0.43
wheel_radius_m = { value = [0.11, 0.112], date = "2026-11-24T09:00:00Z", method = "runs", residuals = { rms_mm = 3.0 }, verdict = "ok" }
[gnss]
heading_offset_deg = 2.0
"#;
        let c = CalibrationFile::from_toml(text, Path::new("c.toml")).expect("valid");
        assert_eq!(*c.chassis.track_m.as_ref().expect("track").value(), 0.43);
        let r = *c.chassis.wheel_radius_m.as_ref().expect("radius").value();
        assert_eq!((r.left, r.right), (0.11, 0.112));
        // Written and read back unchanged.
        let again = CalibrationFile::from_toml(&c.to_toml(), Path::new("c.toml")).expect("ok");
        assert_eq!(again, c);
    }

    #[test]
    fn a_value_out_of_range_names_the_file_and_key() {
        let e = CalibrationFile::from_toml("[chassis]\ntrack_m = 9.0\n", Path::new("c.toml"))
            .expect_err("out of range");
        let text = e.to_string();
        assert!(
            text.contains("c.toml") && text.contains("chassis.track_m"),
            "{text}"
        );
        let e = CalibrationFile::from_toml("[chassis]\ntrackm = 0.4\n", Path::new("c.toml"))
            .expect_err("unknown key");
        assert!(e.to_string().contains("trackm"), "{e}");
    }
}
