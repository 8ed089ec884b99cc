//! `jackal-test2`: 61 s of a Clearpath Jackal's wheel odometry and IMU without GNSS
//! (robot_localization's regression bag), against the upstream filter's final position.
//!
//! The Jackal's controller computed the recorded yaw rate from the wheel speeds with a
//! separation of 0.37559 m × 1.5 (its `wheel_separation_multiplier`), so that gives the
//! wheel speeds back. Skid steering slips in turns: the wheels' yaw rate is 1.84 times the
//! gyro's, so the configured track is the controller's separation times that ratio. The data
//! never stands still: the drives' boot is the only standstill, and the simulated gyro reads
//! exactly zero there, so the odom frame keeps the data's gyro as it is, as the reference
//! filter does.

use std::path::Path;

use crate::bench::error::{BenchError, Result};
use crate::config::chassis::WheelRadius;
use crate::sim::plant::{ForcedMotion, PlantConfig};

use super::data::{columns, sample_at, wheel_to_gyro_ratio};
use super::recording::{self, Forced};
use super::{Figure, Scratch};

/// The controller's wheel separation: the Jackal's 0.37559 m times its multiplier 1.5.
const CONTROLLER_SEPARATION_M: f64 = 0.37559 * 1.5;
/// The Jackal's wheel radius, m.
const WHEEL_RADIUS_M: f64 = 0.098;
/// The upstream reference: final position in its odom frame, m.
const REFERENCE: (f64, f64) = (1.02, 3.43);
/// That frame's heading at start: the IMU's absolute yaw at the first sample, rad.
const REFERENCE_START_YAW: f64 = 0.362;
/// The target, m (the upstream tolerance is 0.138 m, for a filter that also fuses the IMU's
/// orientation).
const TARGET_M: f64 = 0.3;

/// The figures of `dir`.
pub fn figures(dir: &Path) -> Result<Vec<Figure>> {
    let mut odom = columns(&dir.join("odom.csv"), &["t", "vx", "wz"])?;
    let mut gyro = columns(&dir.join("imu.csv"), &["t", "wz"])?;
    let (Some(o), Some(g)) = (odom.first(), gyro.first()) else {
        return Err(BenchError::Failed(format!(
            "{}: empty files",
            dir.display()
        )));
    };
    let t0 = o[0].min(g[0]);
    for row in odom.iter_mut().chain(gyro.iter_mut()) {
        row[0] -= t0;
    }
    let ratio = wheel_to_gyro_ratio(&odom, &gyro);
    let track = CONTROLLER_SEPARATION_M * ratio;
    let mut plant = PlantConfig::builtin()?;
    plant.name = "jackal-test2".into();
    plant.geometry.wheel_radius_m = WheelRadius::both(WHEEL_RADIUS_M);
    plant.geometry.track_m = track;
    plant.imu.rate_hz = 50.0;
    plant.imu.gyro_bias_rps = 0.0;
    plant.imu.gyro_noise_rps = 0.0;
    plant.slip.bias = [0.0, 0.0];
    plant.slip.sigma = 0.0;
    let motion = odom
        .iter()
        .map(|o| {
            (
                o[0],
                ForcedMotion {
                    v: o[1],
                    // Wheel speeds differ by the recorded yaw rate times the controller's
                    // separation; the configured track turns that into the wheels' yaw rate.
                    wheel_yaw_rate: o[2] * CONTROLLER_SEPARATION_M / track,
                    gyro_z: sample_at(&gyro, o[0])[1],
                },
            )
        })
        .collect();
    let forced = Forced {
        plant,
        localization: toml::Table::new(),
        motion,
    };
    let scratch = Scratch::new("jackal")?;
    recording::write(scratch.path(), &forced, &[])?;
    let ticks = recording::replay(scratch.path(), &[])?;
    let error =
        ticks
            .iter()
            .rev()
            .find_map(|k| k.odom_latest)
            .map_or(f64::INFINITY, |(x, y, _)| {
                // The odom frame starts at yaw 0, the reference's at the IMU's first yaw.
                let (s, c) = REFERENCE_START_YAW.sin_cos();
                (c * x - s * y - REFERENCE.0).hypot(s * x + c * y - REFERENCE.1)
            });
    Ok(vec![Figure {
        vehicle: "jackal-test2".into(),
        name: "no GNSS: the odom frame's end to the upstream filter's".into(),
        value: error,
        target: TARGET_M,
        naive: None,
        unit: "m",
    }])
}
