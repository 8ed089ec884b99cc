//! WitMotion's standard serial protocol (WT901, WT61 and kin): 11-byte frames `0x55 TYPE
//! D0..D7 SUM`, SUM the low byte of the sum of the first ten, four little-endian i16 per
//! frame. 0x51 acceleration (±16 g), 0x52 angular rate (±2000 °/s), 0x53 angles (±180°),
//! 0x59 quaternion. A sample is produced on each angular-rate frame, with the latest
//! acceleration and orientation.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::{G, ImuSample, ImuStats};
use crate::time::Timestamp;

/// Frame length.
pub const FRAME_LEN: usize = 11;
/// Acceleration frame.
pub const ACCEL: u8 = 0x51;
/// Angular-rate frame.
pub const GYRO: u8 = 0x52;
/// Euler-angle frame.
pub const ANGLE: u8 = 0x53;
/// Quaternion frame.
pub const QUATERNION: u8 = 0x59;

/// The checksum byte of a frame's first ten bytes.
pub fn checksum(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |a, b| a.wrapping_add(*b))
}

/// A WitMotion frame for `kind` with four values (for simulators and tests).
pub fn frame(kind: u8, values: [i16; 4]) -> [u8; FRAME_LEN] {
    let mut f = [0u8; FRAME_LEN];
    f[0] = 0x55;
    f[1] = kind;
    for (i, v) in values.iter().enumerate() {
        f[2 + 2 * i..4 + 2 * i].copy_from_slice(&v.to_le_bytes());
    }
    f[10] = checksum(&f[..10]);
    f
}

/// Incremental decoder.
#[derive(Debug, Clone, Default)]
pub struct WitMotion {
    buf: Vec<u8>,
    accel: Option<Vector3<f64>>,
    orientation: Option<UnitQuaternion<f64>>,
    stats: ImuStats,
}

impl WitMotion {
    /// A decoder with nothing received.
    pub fn new() -> Self {
        Self::default()
    }

    /// Counters so far.
    pub fn stats(&self) -> ImuStats {
        self.stats
    }

    /// Feeds a chunk read at `rx`.
    pub fn push(&mut self, rx: Timestamp, bytes: &[u8], mut on_sample: impl FnMut(ImuSample)) {
        self.stats.bytes_in += bytes.len() as u64;
        self.buf.extend_from_slice(bytes);
        let mut at = 0;
        while self.buf.len() - at >= FRAME_LEN {
            let f = &self.buf[at..at + FRAME_LEN];
            if f[0] != 0x55 || !(0x50..=0x5F).contains(&f[1]) {
                at += 1;
                self.stats.bytes_skipped += 1;
                continue;
            }
            if checksum(&f[..10]) != f[10] {
                // A 0x55 inside other data, or a corrupted frame: slide by one byte.
                self.stats.checksum_errors += 1;
                self.stats.bytes_skipped += 1;
                at += 1;
                continue;
            }
            let mut frame = [0u8; FRAME_LEN];
            frame.copy_from_slice(f);
            at += FRAME_LEN;
            self.stats.frames += 1;
            if let Some(sample) = self.apply(rx, &frame) {
                self.stats.samples += 1;
                on_sample(sample);
            }
        }
        self.buf.drain(..at);
    }

    fn apply(&mut self, rx: Timestamp, f: &[u8; FRAME_LEN]) -> Option<ImuSample> {
        let v = |i: usize| f64::from(i16::from_le_bytes([f[2 + 2 * i], f[3 + 2 * i]])) / 32768.0;
        match f[1] {
            ACCEL => self.accel = Some(Vector3::new(v(0), v(1), v(2)) * 16.0 * G),
            ANGLE => {
                let (r, p, y) = (v(0) * 180.0, v(1) * 180.0, v(2) * 180.0);
                self.orientation = Some(UnitQuaternion::from_euler_angles(
                    r.to_radians(),
                    p.to_radians(),
                    y.to_radians(),
                ));
            }
            QUATERNION => {
                let q = Quaternion::new(v(0), v(1), v(2), v(3));
                if q.norm() > 0.5 {
                    self.orientation = Some(UnitQuaternion::from_quaternion(q));
                }
            }
            GYRO => {
                let gyro = Vector3::new(v(0), v(1), v(2)) * 2000f64.to_radians();
                return Some(ImuSample {
                    rx,
                    accel: self.accel?,
                    gyro,
                    orientation: self.orientation,
                });
            }
            _ => {}
        }
        None
    }
}
