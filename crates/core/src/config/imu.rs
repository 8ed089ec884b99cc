//! `[imu]`: an IMU on a serial port, its mounting and its calibration.

use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::{ConfigError, check_range};
use crate::devices::imu::Mounting;

/// Wire protocol of an IMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ImuProtocol {
    /// WitMotion standard protocol (0x55 frames).
    Witmotion,
    /// HiPNUC protocol (0x5A 0xA5 frames).
    Hipnuc,
}

impl ImuProtocol {
    /// The protocol name in recordings.
    pub fn name(self) -> &'static str {
        match self {
            Self::Witmotion => "witmotion",
            Self::Hipnuc => "hipnuc",
        }
    }
}

/// `[imu]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ImuConfig {
    /// Serial device.
    pub port: String,
    /// Baud rate.
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// Wire protocol.
    pub protocol: ImuProtocol,
    /// Rotation from the sensor frame to the vehicle frame: roll, pitch, yaw, degrees.
    #[serde(default)]
    pub mounting_rpy_deg: [f64; 3],
    /// Gyro bias in the sensor frame, rad/s; the calibration file's replaces it.
    #[serde(default)]
    pub gyro_bias_rps: [f64; 3],
    /// No plausible sample for this long: the IMU is not ok, s.
    #[serde(default = "default_timeout")]
    pub timeout_s: f64,
    /// Longest wait between reconnect attempts, s.
    #[serde(default = "default_reconnect")]
    pub reconnect_max_s: f64,
    /// Accelerometer noise, 1σ m/s² (`/imu/data`'s covariance; the gyro's is
    /// `localization.gyro_noise_rps`).
    #[serde(default = "default_accel_noise")]
    pub accel_noise_mps2: f64,
    /// The sensor's own orientation estimate, 1σ degrees (`/imu/data`'s covariance).
    #[serde(default = "default_orientation_noise")]
    pub orientation_noise_deg: f64,
}

fn default_baud() -> u32 {
    115_200
}
fn default_timeout() -> f64 {
    0.5
}
fn default_reconnect() -> f64 {
    5.0
}
/// A MEMS accelerometer's noise at a 100 Hz output rate (some 5 mg).
fn default_accel_noise() -> f64 {
    0.05
}
/// What WitMotion and HiPNUC modules state for their fused angles in motion.
fn default_orientation_noise() -> f64 {
    1.0
}

impl ImuConfig {
    /// The mounting rotation and bias.
    pub fn mounting(&self) -> Mounting {
        Mounting::from_rpy_deg(self.mounting_rpy_deg, self.gyro_bias_rps)
    }

    /// The stale timeout.
    pub fn timeout(&self) -> Duration {
        Duration::from_secs_f64(self.timeout_s)
    }

    /// Checks ranges.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if self.port.trim().is_empty() {
            return Err(ConfigError::invalid(
                file,
                "imu.port",
                "is empty",
                "set the serial device",
            ));
        }
        if !super::STANDARD_BAUDS.contains(&self.baud) {
            return Err(ConfigError::invalid(
                file,
                "imu.baud",
                format!("{} is not a standard rate", self.baud),
                "use one of 4800 ... 921600",
            ));
        }
        check_range(
            file,
            "imu.accel_noise_mps2",
            self.accel_noise_mps2,
            1e-6..=10.0,
            "m/s²",
        )?;
        check_range(
            file,
            "imu.orientation_noise_deg",
            self.orientation_noise_deg,
            1e-4..=180.0,
            "degrees",
        )?;
        for (i, a) in self.mounting_rpy_deg.iter().enumerate() {
            check_range(
                file,
                &format!("imu.mounting_rpy_deg[{i}]"),
                *a,
                -360.0..=360.0,
                "degrees",
            )?;
        }
        for (i, b) in self.gyro_bias_rps.iter().enumerate() {
            check_range(
                file,
                &format!("imu.gyro_bias_rps[{i}]"),
                *b,
                -0.5..=0.5,
                "rad/s",
            )?;
        }
        check_range(file, "imu.timeout_s", self.timeout_s, 0.01..=10.0, "s")?;
        check_range(
            file,
            "imu.reconnect_max_s",
            self.reconnect_max_s,
            0.05..=300.0,
            "s",
        )
    }
}
