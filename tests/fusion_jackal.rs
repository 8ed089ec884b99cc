//! The `odom` frame on a real robot's data: 61 s of a Clearpath Jackal's wheel odometry and
//! IMU (`../shared/data/ekf/jackal-test2`, from robot_localization's regression bag) played
//! through the simulated drives and IMU as real frames, recorded, replayed by the chassisd
//! binary, and the final pose compared with the upstream filter's reference.
//!
//! The recording: the simulator's drives are back-driven at the wheel speeds the data
//! implies, and its IMU reads the data's gyro, so every number reaches the core through the
//! CiA 402 and HiPNUC decoders as it would on the vehicle.
//!
//! The track: the Jackal's controller computed the recorded yaw rate from the wheel speeds
//! with a separation of 0.37559 m × 1.5 (its `wheel_separation_multiplier`), so that gives
//! the wheel speeds back. Skid steering slips in turns: the wheels' yaw rate is 1.84 times
//! the gyro's (least squares over the samples turning faster than 0.2 rad/s), so the
//! vehicle's configured track is the controller's separation times that ratio, the
//! effective track that makes the wheels turn the vehicle as the gyro saw it.

mod common;

use std::path::Path;

use chassisd::record::RecordingWriter;
use chassisd::sim::lockstep::{self, Lockstep, PLANT_STEP};
use chassisd::sim::plant::{ForcedMotion, GnssCondition, PlantConfig};
use chassisd::time::Timestamp;
use common::lockstep::Recorder;
use common::{csv_columns, sample_at, wheel_to_gyro_ratio};

/// The controller's wheel separation: the Jackal's 0.37559 m times its multiplier 1.5.
const CONTROLLER_SEPARATION_M: f64 = 0.37559 * 1.5;
/// The Jackal's wheel radius, m.
const WHEEL_RADIUS_M: f64 = 0.098;
/// The upstream reference: final position in its odom frame, and its tolerance, m.
const REFERENCE: (f64, f64) = (1.02, 3.43);
const UPSTREAM_TOLERANCE_M: f64 = 0.138;
/// That frame's heading at start: the IMU's absolute yaw at the first sample, rad.
const REFERENCE_START_YAW: f64 = 0.362;
/// The target of the issue, m.
const TARGET_M: f64 = 0.3;
/// The drives boot before the data starts, s.
const BOOT_S: f64 = 3.0;

#[test]
fn the_odom_frame_ends_where_the_reference_filter_does() {
    let dir = common::shared_data("ekf/jackal-test2");
    let odom = csv_columns(&dir.join("odom.csv"), &["t", "vx", "wz"]);
    let imu = csv_columns(&dir.join("imu.csv"), &["t", "wz"]);
    let ratio = wheel_to_gyro_ratio(&odom, &imu);
    let track = CONTROLLER_SEPARATION_M * ratio;

    let plant_text = std::fs::read_to_string(common::repo().join("devices/plant.mower.toml"))
        .expect("plant file")
        .replace("name = \"sim-mower\"", "name = \"jackal-data\"")
        .replace(
            "wheel_radius_m = 0.11",
            &format!("wheel_radius_m = {WHEEL_RADIUS_M}"),
        )
        .replace("track_m = 0.42", &format!("track_m = {track}"))
        .replace("rate_hz = 100.0", "rate_hz = 50.0")
        .replace("gyro_bias_rps = 0.003", "gyro_bias_rps = 0.0")
        // The data never stands still: the drives' boot is the only standstill, and the
        // simulated gyro reads exactly zero there, so the odom frame keeps the data's gyro
        // as it is (as the reference filter does) rather than a bias made of noise.
        .replace("gyro_noise_rps = 0.002", "gyro_noise_rps = 0.0")
        .replace("bias = [0.006, 0.004]", "bias = [0.0, 0.0]");
    let plant = PlantConfig::from_toml(&plant_text, Path::new("jackal-data")).expect("plant");
    let start = Timestamp::from_micros(1_767_225_600_000_000);
    let mut sim = Lockstep::new(plant.clone(), 1, start).expect("lockstep");
    let recording = common::tempdir("jackal").join("rec");
    let writer = RecordingWriter::create(
        &recording,
        "jackal-data",
        start,
        Some(&sim.config().to_effective_toml()),
        lockstep::sources(&plant),
    )
    .expect("recording");
    let mut sink = Recorder { writer };

    let (t0, t_end) = (odom[0][0], odom[odom.len() - 1][0]);
    let steps = ((BOOT_S + t_end - t0) / PLANT_STEP.as_secs_f64()).round() as u64;
    let no_fix = GnssCondition {
        quality: None,
        offset: (0.0, 0.0),
    };
    for k in 0..steps {
        let s = k as f64 * PLANT_STEP.as_secs_f64();
        if s >= BOOT_S {
            let td = t0 + (s - BOOT_S);
            let o = sample_at(&odom, td);
            sim.vehicle_mut().force_motion(Some(ForcedMotion {
                v: o[1],
                // Wheel speeds differ by the recorded yaw rate times the controller's
                // separation; the configured track turns that into the wheels' yaw rate.
                wheel_yaw_rate: o[2] * CONTROLLER_SEPARATION_M / track,
                gyro_z: sample_at(&imu, td)[1],
            }));
        }
        sim.step(no_fix, &mut sink);
    }
    // The recording ends where the lockstep stopped: a replay runs the control loop to
    // its end, and ticks past the last recorded one would transmit frames never recorded.
    sink.writer.finish(sim.time()).expect("recording closed");

    let out = common::replay(&recording);
    let last: serde_json::Value = String::from_utf8_lossy(&out.stdout)
        .lines()
        .last()
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .expect("status lines");
    assert_eq!(
        last["nav"]["locate"], "LOCATE_UNINIT",
        "no GNSS: the odom frame"
    );
    let (x, y) = (
        last["pose"]["x"].as_f64().unwrap(),
        last["pose"]["y"].as_f64().unwrap(),
    );
    // Our odom frame starts at yaw 0, the reference's at the IMU's first yaw.
    let (s, c) = REFERENCE_START_YAW.sin_cos();
    let (rx, ry) = (c * x - s * y, s * x + c * y);
    let error = (rx - REFERENCE.0).hypot(ry - REFERENCE.1);
    println!(
        "jackal-test2: wheel/gyro yaw-rate ratio {ratio:.3}, track {track:.3} m; odom frame ends \
         at ({rx:.3}, {ry:.3}) m, {error:.3} m from the reference ({:.2}, {:.2}) \
         (target {TARGET_M} m, upstream tolerance {UPSTREAM_TOLERANCE_M} m)",
        REFERENCE.0, REFERENCE.1
    );
    assert!((1.7..2.0).contains(&ratio), "ratio {ratio}");
    assert!(error < TARGET_M, "{error:.3} m from the reference");
    std::fs::remove_dir_all(recording.parent().unwrap()).ok();
}
