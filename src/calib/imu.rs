//! IMU calibration from standing still: the gyro bias on three axes (the mean rate at rest),
//! and the mounting's roll and pitch from the direction of gravity. The vehicle must stand
//! on level ground; the yaw of the mounting cannot be seen from gravity and is kept.

use nalgebra::Vector3;

use super::data::{Dataset, ImuPoint};
use super::{Refusal, refuse};

/// Data is judged still or moving in blocks this long, s.
const BLOCK_S: f64 = 1.0;
/// A block is still when each gyro axis varies less than this (1σ), rad/s ...
const STILL_GYRO_STD: f64 = 0.01;
/// ... its mean rate is under this (a bias is never larger), rad/s ...
const STILL_GYRO_MEAN: f64 = 0.05;
/// ... each accelerometer axis varies less than this (1σ), m/s² ...
const STILL_ACCEL_STD: f64 = 0.2;
/// ... and no wheel turned more than this, rad (a tenth of a millimetre on most wheels).
const STILL_WHEEL_RAD: f64 = 0.002;
/// The first and last block of a still span are left out (the vehicle settling), s.
const MARGIN_S: f64 = 1.0;

/// What standing still gave.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuResult {
    /// Gyro bias in the sensor frame, rad/s.
    pub gyro_bias_rps: [f64; 3],
    /// Mounting roll and pitch, degrees.
    pub roll_deg: f64,
    /// Mounting pitch, degrees.
    pub pitch_deg: f64,
    /// The still span used: start and end, s since the start of the data.
    pub span: (f64, f64),
    /// Samples averaged.
    pub samples: usize,
    /// The gyro's spread at rest (1σ per axis), rad/s.
    pub gyro_std_rps: [f64; 3],
    /// The 1σ uncertainty of each bias axis, rad/s.
    pub bias_sigma_rps: [f64; 3],
}

/// The longest span in which the vehicle stood still: start and end, s.
pub fn longest_still_span(data: &Dataset) -> Option<(f64, f64)> {
    let first = data.imu.first()?.t;
    let last = data.imu.last()?.t;
    let blocks = ((last - first) / BLOCK_S).floor() as usize;
    let mut best: Option<(f64, f64)> = None;
    let mut run_start: Option<f64> = None;
    let mut imu_from = 0;
    for b in 0..=blocks {
        let (t0, t1) = (first + b as f64 * BLOCK_S, first + (b + 1) as f64 * BLOCK_S);
        let still = b < blocks && block_is_still(data, t0, t1, &mut imu_from);
        match (still, run_start) {
            (true, None) => run_start = Some(t0),
            (false, Some(s)) => {
                if best.is_none_or(|(a, z)| t0 - s > z - a) {
                    best = Some((s, t0));
                }
                run_start = None;
            }
            _ => {}
        }
    }
    best
}

/// Whether the vehicle stood still in `[t0, t1)`; `from` is where to look in the IMU data.
fn block_is_still(data: &Dataset, t0: f64, t1: f64, from: &mut usize) -> bool {
    while data.imu.get(*from).is_some_and(|p| p.t < t0) {
        *from += 1;
    }
    let block: Vec<&ImuPoint> = data.imu[*from..].iter().take_while(|p| p.t < t1).collect();
    if block.len() < 3 {
        return false;
    }
    let (gyro_mean, gyro_std) = mean_std(block.iter().map(|p| p.gyro));
    let (_, accel_std) = mean_std(block.iter().map(|p| p.accel));
    let imu_still = gyro_std.max() < STILL_GYRO_STD
        && gyro_mean.amax() < STILL_GYRO_MEAN
        && accel_std.max() < STILL_ACCEL_STD;
    imu_still && !wheels_turned(data, t0, t1)
}

/// Whether either wheel turned in `[t0, t1]` (false without wheel data).
fn wheels_turned(data: &Dataset, t0: f64, t1: f64) -> bool {
    let start = data.wheels.partition_point(|w| w.t < t0);
    let mut inside = data.wheels[start..].iter().take_while(|w| w.t <= t1);
    let Some(first) = inside.next() else {
        return false;
    };
    inside.any(|w| {
        (w.left - first.left).abs() > STILL_WHEEL_RAD
            || (w.right - first.right).abs() > STILL_WHEEL_RAD
    })
}

/// Mean and standard deviation per axis.
fn mean_std(values: impl Iterator<Item = Vector3<f64>> + Clone) -> (Vector3<f64>, Vector3<f64>) {
    let n = values.clone().count().max(1) as f64;
    let mean = values.clone().fold(Vector3::zeros(), |a, v| a + v) / n;
    let var = values.fold(Vector3::zeros(), |a, v| {
        let d = v - mean;
        a + d.component_mul(&d)
    }) / n;
    (mean, var.map(f64::sqrt))
}

/// The bias and mounting from the longest still span, which must last `min_still_s`.
pub fn calibrate(data: &Dataset, min_still_s: f64) -> Result<ImuResult, Refusal> {
    if data.imu.is_empty() {
        return Err(refuse(
            "the data holds no IMU samples",
            "record with the IMU connected ([imu] in the configuration)",
        ));
    }
    let Some((start, end)) = longest_still_span(data) else {
        return Err(refuse(
            "the vehicle never stood still",
            &format!("let it stand still for {min_still_s:.0} s, on level ground, drives holding"),
        ));
    };
    let (a, z) = (start + MARGIN_S, end - MARGIN_S);
    if z - a < min_still_s {
        return Err(refuse(
            &format!(
                "the vehicle moved: the longest still span is {:.1} s (from {start:.1} s), \
                 {min_still_s:.0} s are needed",
                (z - a).max(0.0)
            ),
            &format!("let it stand still for {min_still_s:.0} s without touching it"),
        ));
    }
    let used: Vec<&ImuPoint> = data.imu.iter().filter(|p| p.t >= a && p.t < z).collect();
    let (gyro, gyro_std) = mean_std(used.iter().map(|p| p.gyro));
    let (accel, _) = mean_std(used.iter().map(|p| p.accel));
    let n = used.len() as f64;
    // Specific force at rest is gravity, up: in the sensor frame it shows the mounting's
    // roll and pitch (rotation sensor -> vehicle = Rz(yaw) Ry(pitch) Rx(roll)).
    let roll = accel.y.atan2(accel.z);
    let pitch = (-accel.x).atan2(accel.y.hypot(accel.z));
    Ok(ImuResult {
        gyro_bias_rps: [gyro.x, gyro.y, gyro.z],
        roll_deg: roll.to_degrees(),
        pitch_deg: pitch.to_degrees(),
        span: (a, z),
        samples: used.len(),
        gyro_std_rps: [gyro_std.x, gyro_std.y, gyro_std.z],
        bias_sigma_rps: [gyro_std.x, gyro_std.y, gyro_std.z].map(|s| s / n.sqrt()),
    })
}
