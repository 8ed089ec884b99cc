//! IMUs on a serial port: WitMotion (0x55 frames, sum checksum) and HiPNUC (0x5A 0xA5 frames,
//! CRC-16). Both framers resynchronise after garbage and produce [`ImuSample`]s in SI units,
//! rotated into the vehicle frame with the gyro bias removed.

pub mod hipnuc;
pub mod witmotion;

use nalgebra::{UnitQuaternion, Vector3};

use crate::time::Timestamp;

/// Standard gravity, m/s² (the "g" IMUs report in).
pub const G: f64 = 9.806_65;

/// One IMU measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// Host receive time.
    pub rx: Timestamp,
    /// Specific force, m/s².
    pub accel: Vector3<f64>,
    /// Angular rate, rad/s.
    pub gyro: Vector3<f64>,
    /// The sensor's own orientation estimate, when it sends one.
    pub orientation: Option<UnitQuaternion<f64>>,
}

impl ImuSample {
    /// Whether the values are physically plausible: finite, with a specific force between
    /// 0.2 g and 8 g (a working accelerometer always feels gravity) and rates under
    /// 2000 °/s.
    pub fn is_plausible(&self) -> bool {
        let a = self.accel.norm();
        self.accel
            .iter()
            .chain(self.gyro.iter())
            .all(|v| v.is_finite())
            && (0.2 * G..=8.0 * G).contains(&a)
            && self.gyro.norm() < 2000f64.to_radians()
    }
}

/// Counters of an IMU stream.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ImuStats {
    /// Bytes fed in.
    pub bytes_in: u64,
    /// Frames with a valid checksum.
    pub frames: u64,
    /// Frames whose checksum or CRC did not match.
    pub checksum_errors: u64,
    /// Bytes skipped while hunting for a frame.
    pub bytes_skipped: u64,
    /// Samples produced.
    pub samples: u64,
}

/// Maps sensor-frame samples into the vehicle frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mounting {
    /// Rotation from the sensor frame to the vehicle frame.
    pub rotation: UnitQuaternion<f64>,
    /// Gyro bias in the sensor frame, rad/s (from calibration).
    pub gyro_bias: Vector3<f64>,
}

impl Default for Mounting {
    fn default() -> Self {
        Self {
            rotation: UnitQuaternion::identity(),
            gyro_bias: Vector3::zeros(),
        }
    }
}

impl Mounting {
    /// A mounting from roll, pitch, yaw (degrees, sensor to vehicle) and a gyro bias.
    pub fn from_rpy_deg(rpy: [f64; 3], gyro_bias: [f64; 3]) -> Self {
        Self {
            rotation: UnitQuaternion::from_euler_angles(
                rpy[0].to_radians(),
                rpy[1].to_radians(),
                rpy[2].to_radians(),
            ),
            gyro_bias: Vector3::from(gyro_bias),
        }
    }

    /// The sample in the vehicle frame, bias removed.
    pub fn apply(&self, s: &ImuSample) -> ImuSample {
        ImuSample {
            rx: s.rx,
            accel: self.rotation * s.accel,
            gyro: self.rotation * (s.gyro - self.gyro_bias),
            orientation: s.orientation.map(|q| q * self.rotation.inverse()),
        }
    }
}

/// An IMU protocol decoder.
#[derive(Debug, Clone)]
pub enum ImuDecoder {
    /// WitMotion.
    WitMotion(witmotion::WitMotion),
    /// HiPNUC.
    HiPnuc(hipnuc::HiPnuc),
}

impl ImuDecoder {
    /// Feeds a chunk read at `rx`; `on_sample` sees each complete sample (sensor frame).
    pub fn push(&mut self, rx: Timestamp, bytes: &[u8], on_sample: impl FnMut(ImuSample)) {
        match self {
            Self::WitMotion(d) => d.push(rx, bytes, on_sample),
            Self::HiPnuc(d) => d.push(rx, bytes, on_sample),
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> ImuStats {
        match self {
            Self::WitMotion(d) => d.stats(),
            Self::HiPnuc(d) => d.stats(),
        }
    }
}
