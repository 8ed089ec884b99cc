//! `chassisd calibrate` through the real binary, on recordings of the simulated vehicle made
//! with `chassisd sim --fast --scenario calibration --record`. Both shipped plants get the
//! same errors through `[configured]`: the right wheel 2 % larger than configured, the track
//! 3 % wider, a gyro bias of 0.2 °/s the configuration does not know, the antenna 0.3 m ahead
//! of where the configuration puts it, and (where the receiver has two antennas) a 2°
//! heading offset. Calibration recovers each within its target, and with the file loaded
//! the control benchmark, which misses its targets on the miscalibrated vehicle, passes.
//! Data that cannot support a result is refused with the reason.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use chassisd::sim::lockstep::Lockstep;
use chassisd::sim::plant::PlantConfig;
use chassisd::sim::scenario::{CALIBRATION_STILL_S, Scenario};
use common::lockstep::START;

/// The true gyro bias, rad/s.
const TRUE_GYRO_BIAS: f64 = 0.2 * std::f64::consts::PI / 180.0;
/// The receiver's true heading offset, degrees.
const TRUE_HEADING_OFFSET: f64 = 2.0;

/// A shipped plant with the errors injected; the plant file's path and the plant.
fn miscalibrated(name: &str, dir: &Path) -> (PathBuf, PlantConfig) {
    let text = std::fs::read_to_string(common::repo().join(format!("devices/plant.{name}.toml")))
        .expect("plant file");
    let mut t: toml::Table = toml::from_str(&text).expect("plant TOML");
    let geometry = t["geometry"].as_table_mut().expect("[geometry]");
    let r = geometry["wheel_radius_m"].as_float().expect("one radius");
    let track = geometry["track_m"].as_float().expect("track");
    let antenna: Vec<f64> = geometry["antenna"]
        .as_array()
        .expect("antenna")
        .iter()
        .map(|v| v.as_float().expect("number"))
        .collect();
    geometry.insert(
        "wheel_radius_m".into(),
        toml::Value::try_from([r, r * 1.02]).expect("array"),
    );
    t["imu"]
        .as_table_mut()
        .expect("[imu]")
        .insert("gyro_bias_rps".into(), TRUE_GYRO_BIAS.into());
    t["gnss"]
        .as_table_mut()
        .expect("[gnss]")
        .insert("heading_offset_deg".into(), TRUE_HEADING_OFFSET.into());
    let configured = format!(
        "wheel_radius_m = {r}\ntrack_m = {}\nantenna = [{}, {}]\ngyro_bias_rps = [0.0, 0.0, 0.0]\n",
        track * 0.97,
        antenna[0] - 0.3,
        antenna[1]
    );
    t.insert(
        "configured".into(),
        toml::Value::Table(toml::from_str(&configured).expect("configured")),
    );
    let path = dir.join(format!("plant.{name}.miscalibrated.toml"));
    std::fs::write(&path, toml::to_string(&t).expect("serialises")).expect("written");
    let plant = PlantConfig::load(&path).expect("a valid plant");
    (path, plant)
}

fn run(args: &[&str], paths: &[&Path]) -> Output {
    let mut c = Command::new(common::chassisd());
    c.args(args);
    for p in paths {
        c.arg(p);
    }
    c.output().expect("chassisd runs")
}

fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `chassisd sim --fast ARGS [--plant PLANT] --record DIR`, which must succeed.
fn sim_fast(args: &[&str], plant: Option<&Path>, dir: &Path) -> Output {
    let mut c = Command::new(common::chassisd());
    c.args(["sim", "--fast"]).args(args);
    if let Some(p) = plant {
        c.arg("--plant").arg(p);
    }
    let o = c.arg("--record").arg(dir).output().expect("chassisd runs");
    assert!(o.status.success(), "{}", text(&o));
    o
}

/// Records the calibration scenario of `plant` with `seed` into `dir`.
fn record(plant: &Path, seed: u64, dir: &Path) {
    let seed = seed.to_string();
    sim_fast(
        &["--scenario", "calibration", "--seed", &seed],
        Some(plant),
        dir,
    );
}

/// `calibrate PROCEDURE --from DIR --out FILE`.
fn calibrate(procedure: &str, from: &Path, out: &Path) -> Output {
    run(
        &["calibrate", procedure, "--from"],
        &[from, Path::new("--out"), out],
    )
}

fn value(t: &toml::Table, section: &str, key: &str) -> toml::Value {
    let entry = t[section]
        .get(key)
        .unwrap_or_else(|| panic!("{section}.{key} in {t}"));
    match entry.get("value") {
        Some(v) => v.clone(),
        None => entry.clone(),
    }
}

fn floats(v: &toml::Value) -> Vec<f64> {
    match v {
        toml::Value::Array(a) => a.iter().map(|x| x.as_float().expect("number")).collect(),
        other => vec![other.as_float().expect("number")],
    }
}

/// The true mean gyro bias between `from` and `to` s of the run: the plant's bias walks, so
/// the bias a standstill sees is the one it should find.
fn true_bias(plant: &PlantConfig, seed: u64, from: f64, to: f64) -> f64 {
    let mut sim = Lockstep::new(plant.clone(), seed, START).expect("lockstep");
    let scenario = Scenario::calibration();
    let mut sink = common::lockstep::Collector::default();
    let (mut sum, mut n) = (0.0, 0u32);
    while sim.time().saturating_since(START).as_secs_f64() < to {
        sim.step_scripted(&scenario, &mut sink);
        if sim.time().saturating_since(START).as_secs_f64() >= from {
            sum += sim.vehicle().gyro_bias();
            n += 1;
        }
    }
    sum / f64::from(n.max(1))
}

/// Calibrates `name` from a recording with `seed` and checks every value against the truth;
/// the calibration file.
fn calibrates(name: &str, seed: u64) -> PathBuf {
    let dir = common::tempdir(&format!("calibrate-{name}-{seed}"));
    let (plant_file, plant) = miscalibrated(name, &dir);
    let rec = dir.join("rec");
    record(&plant_file, seed, &rec);
    let out = dir.join("calib.toml");
    for procedure in ["imu", "odometry", "gnss"] {
        let o = calibrate(procedure, &rec, &out);
        assert!(o.status.success(), "calibrate {procedure}: {}", text(&o));
    }
    // Each procedure drew its report beside the file.
    for (procedure, title) in [("imu", "bias"), ("odometry", "radii"), ("gnss", "antenna")] {
        let plot =
            std::fs::read_to_string(dir.join(format!("calib.{procedure}.svg"))).expect("the plot");
        assert!(plot.contains("<svg") && plot.contains(title), "{procedure}");
    }
    let file: toml::Table =
        toml::from_str(&std::fs::read_to_string(&out).expect("written")).expect("TOML");
    let g = &plant.geometry;
    let slip = plant.slip.bias;
    // What a wheel turn carries the vehicle on this ground: radius times (1 + systematic slip).
    let truth = [
        g.wheel_radius_m.left * (1.0 + slip[0]),
        g.wheel_radius_m.right * (1.0 + slip[1]),
    ];
    let radius = floats(&value(&file, "chassis", "wheel_radius_m"));
    for (found, truth) in radius.iter().zip(truth) {
        let error = (found / truth - 1.0).abs();
        assert!(
            error < 1e-3,
            "{name}: radius {found} against {truth}: {error:.5}"
        );
    }
    let track = floats(&value(&file, "chassis", "track_m"))[0];
    assert!(
        (track / g.track_m - 1.0).abs() < 5e-3,
        "{name}: track {track} against {}",
        g.track_m
    );
    let antenna = floats(&value(&file, "gnss", "antenna"));
    let miss = (antenna[0] - g.antenna[0]).hypot(antenna[1] - g.antenna[1]);
    assert!(
        miss < 0.02,
        "{name}: antenna {antenna:?} against {:?}",
        g.antenna
    );
    let bias = floats(&value(&file, "imu", "gyro_bias_rps"));
    let residuals = &file["imu"]["gyro_bias_rps"]["residuals"];
    let span = (
        residuals["still_from_s"].as_float().expect("span"),
        residuals["still_to_s"].as_float().expect("span"),
    );
    assert!(
        span.1 <= CALIBRATION_STILL_S && span.1 - span.0 >= 20.0,
        "{span:?}"
    );
    let truth = true_bias(&plant, seed, span.0, span.1);
    assert!(
        (bias[2] - truth).abs().to_degrees() < 0.01,
        "{name}: gyro bias {} against {truth} rad/s",
        bias[2]
    );
    let mounting = floats(&value(&file, "imu", "mounting_rpy_deg"));
    assert!(
        mounting.iter().all(|a| a.abs() < 0.1),
        "a level IMU: {mounting:?}"
    );
    if plant.gnss.dual_antenna {
        let offset = floats(&value(&file, "gnss", "heading_offset_deg"))[0];
        assert!(
            (offset - TRUE_HEADING_OFFSET).abs() < 0.2,
            "{name}: heading offset {offset}"
        );
    } else {
        assert!(file["gnss"].get("heading_offset_deg").is_none());
    }
    // Every value carries its provenance.
    let entry = file["chassis"]["wheel_radius_m"]
        .as_table()
        .expect("a table");
    for key in ["date", "method", "verdict"] {
        assert!(entry.contains_key(key), "{key} in {entry:?}");
    }
    out
}

/// The control benchmark on the miscalibrated plant: whether it passed.
fn control_passes(name: &str, calibration: Option<&Path>) -> bool {
    let dir = common::tempdir(&format!("calibrate-control-{name}"));
    let (plant_file, _) = miscalibrated(name, &dir);
    let mut c = Command::new(common::chassisd());
    c.args(["bench", "control", "--seed", "1", "--plant"])
        .arg(&plant_file);
    if let Some(f) = calibration {
        c.arg("--calibration").arg(f);
    }
    c.output().expect("chassisd runs").status.success()
}

#[test]
fn the_mower_is_calibrated_and_controls_again() {
    let file = calibrates("mower", 1);
    assert!(
        !control_passes("mower", None),
        "miscalibrated, it should miss"
    );
    assert!(control_passes("mower", Some(&file)));
    calibrates("mower", 3);
}

#[test]
fn the_delivery_vehicle_is_calibrated_and_controls_again() {
    let file = calibrates("delivery", 1);
    assert!(control_passes("delivery", Some(&file)));
    calibrates("delivery", 3);
}

#[test]
fn data_that_cannot_support_a_result_is_refused() {
    let dir = common::tempdir("calibrate-refusals");
    let (plant, _) = miscalibrated("mower", &dir);
    // The straight scenario stands still for 5 s only.
    let straight = dir.join("straight");
    sim_fast(&["--scenario", "straight"], Some(&plant), &straight);
    let out = dir.join("c.toml");
    let o = calibrate("imu", &straight, &out);
    assert!(!o.status.success());
    assert!(text(&o).contains("longest still span"), "{}", text(&o));
    // Standing still the whole time: nothing to fit the wheels on.
    let still = dir.join("still");
    sim_fast(&["--duration", "40"], Some(&plant), &still);
    let o = calibrate("odometry", &still, &out);
    assert!(!o.status.success());
    assert!(text(&o).contains("too short"), "{}", text(&o));
    // RTK float or worse for most of the run.
    let float = dir.join("float");
    sim_fast(&["--scenario", "float"], Some(&plant), &float);
    let o = calibrate("gnss", &float, &out);
    assert!(!o.status.success());
    assert!(text(&o).contains("RTK is not fixed"), "{}", text(&o));
    // Nothing was written by the refusals.
    assert!(!out.exists());
}

#[test]
fn a_fast_recording_replays_to_the_same_lines() {
    let dir = common::tempdir("calibrate-fast-replay");
    let rec = dir.join("rec");
    let o = sim_fast(&["--scenario", "turns"], None, &rec);
    let live = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(live.lines().count() > 1000, "10 lines a simulated second");
    let replayed = common::replay(&rec);
    assert!(replayed.status.success(), "{}", text(&replayed));
    assert_eq!(String::from_utf8_lossy(&replayed.stdout), live);
}

/// `chassisd run` reads the calibration file beside its configuration and logs each value in
/// force with its method and date.
#[test]
fn the_daemon_logs_the_calibration_in_force() {
    let dir = common::tempdir("calibrate-daemon");
    let link = dir.join("gnss-port");
    let _port = common::pty::Port::open_at(&link);
    std::fs::create_dir_all(dir.join("calib")).expect("calib folder");
    std::fs::write(
        dir.join("vehicle.toml"),
        format!(
            "[vehicle]\nname = \"field-mower\"\n\n[gnss]\nport = \"{}\"\n",
            link.display()
        ),
    )
    .expect("config");
    std::fs::write(
        dir.join("calib/field-mower.toml"),
        "[gnss]\nheading_offset_deg = 1.5\n\n[gnss.antenna]\nvalue = [0.31, -0.02]\n\
         date = \"2026-11-24T09:00:00Z\"\nmethod = \"antenna circles\"\nverdict = \"ok\"\n",
    )
    .expect("calibration");
    let mut daemon = common::process::Proc::start(&[
        "run".as_ref(),
        "--config".as_ref(),
        dir.join("vehicle.toml").as_os_str(),
    ]);
    let wait = std::time::Duration::from_secs(10);
    daemon.wait_log(wait, "calibration file read");
    daemon.wait_log(
        wait,
        "calibration: gnss.antenna = [0.3100, -0.0200] m (antenna circles, 2026-11-24T09:00:00Z)",
    );
    daemon.wait_log(wait, "calibration: gnss.heading_offset_deg = 1.500°");
    // Running (its signal handlers in place) once the receiver's port is open.
    daemon.wait_log(wait, "ready");
    daemon.stop();
}

/// `calibrate imu --config` with no recording: it collects from a HiPNUC IMU on a
/// pseudo-terminal (100 Hz, standing still with a known gyro bias), keeps the recording,
/// and fits it.
#[test]
fn imu_calibrates_live_from_a_serial_imu() {
    use chassisd::devices::imu::hipnuc;
    use std::io::Write;
    use std::sync::atomic::{AtomicBool, Ordering};

    let dir = common::tempdir("calibrate-live-imu");
    let link = dir.join("imu-port");
    let mut port = common::pty::Port::open_at(&link);
    let bias_dps = [0.1f32, -0.2, 0.3];
    let running = std::sync::Arc::new(AtomicBool::new(true));
    let flag = running.clone();
    let imu = std::thread::spawn(move || {
        let mut ms: u32 = 0;
        while flag.load(Ordering::Relaxed) {
            // A little alternating noise, as a real sensor never reads one value twice.
            let noise = if ms.is_multiple_of(20) { 0.004 } else { -0.004 };
            let gyro = bias_dps.map(|b| b + noise);
            let packet = hipnuc::packet_91(ms, [0.0, 0.0, 1.0], gyro, [1.0, 0.0, 0.0, 0.0]);
            let _ = port.master.write_all(&hipnuc::frame(&packet));
            ms += 10;
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    });
    let config = dir.join("vehicle.toml");
    std::fs::write(
        &config,
        format!(
            "[vehicle]\nname = \"live-imu\"\n\n[imu]\nport = \"{}\"\nprotocol = \"hipnuc\"\n",
            link.display()
        ),
    )
    .expect("config");
    let out = dir.join("calib/live-imu.toml");
    let kept = dir.join("collected");
    let o = Command::new(common::chassisd())
        .args([
            "calibrate",
            "imu",
            "--still",
            "5",
            "--collect",
            "9",
            "--config",
        ])
        .arg(&config)
        .arg("--record")
        .arg(&kept)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("chassisd runs");
    running.store(false, Ordering::Relaxed);
    imu.join().expect("imu thread");
    assert!(o.status.success(), "{}", text(&o));
    let file: toml::Table =
        toml::from_str(&std::fs::read_to_string(&out).expect("calibration written")).expect("TOML");
    let bias = floats(&value(&file, "imu", "gyro_bias_rps"));
    for (found, truth) in bias.iter().zip(bias_dps) {
        let error_dps = found.to_degrees() - f64::from(truth);
        assert!(error_dps.abs() < 0.01, "{bias:?} against {bias_dps:?} °/s");
    }
    assert!(
        kept.join("0001/imu.log").exists(),
        "the collected recording is kept"
    );
}
