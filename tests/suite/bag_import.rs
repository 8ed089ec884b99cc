//! `chassisd import`: the Husky's and the car's shared data written as bags by PyPI rosbags
//! (tests/mcap/write_bag.py: the Husky as a ROS1 bag, the car as a ROS 2 bag in MCAP),
//! imported, and replayed: the run follows the one of chassisd's own converter's recording
//! of the same data (bench::real), so it meets the same figures. A bag without the needed
//! topics is refused by name.

use std::path::{Path, PathBuf};
use std::process::Command;

use chassisd::bench::real::recording::{BOOT_S, START};
use chassisd::bench::real::{comma2k19, husky_test1};

use crate::common;

/// `write_bag.py VEHICLE DATA FORMAT OUT`, stamped on the converter's time line.
fn write_bag(vehicle: &str, data: &Path, format: &str, out: &Path) {
    write_bag_of(vehicle, data, format, out, &[]);
}

/// [`write_bag`] with only `topics` (all with none named).
fn write_bag_of(vehicle: &str, data: &Path, format: &str, out: &Path, topics: &[&str]) {
    let start = START.as_nanos() + (BOOT_S * 1e9) as u64;
    let mut script = Command::new(common::venv_python());
    script
        .arg(common::repo().join("tests/mcap/write_bag.py"))
        .args([
            vehicle,
            data.to_str().unwrap(),
            format,
            out.to_str().unwrap(),
        ])
        .arg(start.to_string());
    if !topics.is_empty() {
        script.arg(topics.join(","));
    }
    assert!(script.status().expect("write_bag.py").success());
}

/// `chassisd import BAG --out OUT ARGS`: its stderr.
fn import(bag: &Path, out: &Path, args: &[&str]) -> String {
    let o = Command::new(common::chassisd())
        .arg("import")
        .arg(bag)
        .arg("--out")
        .arg(out)
        .args(args)
        .output()
        .expect("chassisd import");
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{stderr}");
    stderr
}

/// The map poses (t, x, y) of `chassisd replay --stamped DIR`, once placed in the map.
fn track(dir: &Path) -> Vec<(f64, f64, f64)> {
    let out = Command::new(common::chassisd())
        .args(["replay", "--stamped"])
        .arg(dir)
        .output()
        .expect("chassisd replay");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|v| v["nav"]["locate"] != "LOCATE_UNINIT")
        .map(|v| {
            let f = |k: &str| v["pose"][k].as_f64().unwrap();
            (v["stamp"].as_f64().unwrap(), f("x"), f("y"))
        })
        .collect()
}

/// How far the imported run's track is from the converter's at the same times: RMS and
/// the largest, m; and how many status lines both have.
fn compared(imported: &[(f64, f64, f64)], converted: &[(f64, f64, f64)]) -> (f64, f64, usize) {
    let by_time: std::collections::HashMap<i64, (f64, f64)> = converted
        .iter()
        .map(|(t, x, y)| ((t * 10.0).round() as i64, (*x, *y)))
        .collect();
    let d: Vec<f64> = imported
        .iter()
        .filter_map(|(t, x, y)| {
            let (cx, cy) = by_time.get(&((t * 10.0).round() as i64))?;
            Some((x - cx).hypot(y - cy))
        })
        .collect();
    let rms = (d.iter().map(|v| v * v).sum::<f64>() / d.len().max(1) as f64).sqrt();
    (rms, d.iter().copied().fold(0.0, f64::max), d.len())
}

#[test]
fn a_husky_ros1_bag_imports_to_the_run_of_chassisds_own_recording() {
    let dir = common::tempdir("import-husky");
    let data = common::shared_data("ekf/husky-test1");
    let bag = dir.join("husky.bag");
    write_bag("husky", &data, "ros1", &bag);
    let stderr = import(
        &bag,
        &dir.join("imported"),
        &[
            "--odometry-track-m",
            "0.555",
            "--track-m",
            "0.739",
            "--wheel-radius-m",
            "0.165",
            "--imu-rpy-deg",
            "90,0,-90",
        ],
    );
    // Found by type, and said so.
    assert!(
        stderr.contains("/gps/fix (989 messages, the bag's only topic of its type)"),
        "{stderr}"
    );
    assert!(stderr.contains("imu_rate_hz: 30.0"), "{stderr}");
    husky_test1::write_recording(&data, husky_test1::Course::None, &dir.join("converted")).unwrap();
    let (imported, converted) = (track(&dir.join("imported")), track(&dir.join("converted")));
    let (rms, max, n) = compared(&imported, &converted);
    eprintln!("husky: {n} statuses compared, RMS {rms:.4} m, largest {max:.4} m");
    assert!(
        n + 10 >= converted.len() && n > 3000,
        "{n} of {}",
        converted.len()
    );
    // The same frames as the converter writes: the same run.
    assert!(rms < 0.01 && max < 0.05, "RMS {rms} m, largest {max} m");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_cars_ros2_bag_imports_to_the_run_of_chassisds_own_recording() {
    let dir = common::tempdir("import-car");
    let data = common::shared_data("ekf/comma2k19-rav4");
    let bag = dir.join("car");
    write_bag("comma", &data, "ros2", &bag);
    let settings = dir.join("rav4.toml");
    std::fs::write(
        &settings,
        "odometry_track_m = 1.57\nwheel_radius_m = 0.362\nantenna_m = [1.3, 0.0]\n\
         imu_rpy_deg = [180.0, 0.0, 0.0]\ngnss_latency_s = 0.085\n",
    )
    .unwrap();
    let stderr = import(
        &bag,
        &dir.join("imported"),
        &["--config", settings.to_str().unwrap()],
    );
    assert!(stderr.contains("ROS 2, MCAP with CDR"), "{stderr}");
    assert!(stderr.contains("/ublox/fix_velocity"), "{stderr}");
    comma2k19::write_recording(&data, &dir.join("converted")).unwrap();
    let (imported, converted) = (track(&dir.join("imported")), track(&dir.join("converted")));
    let (rms, max, n) = compared(&imported, &converted);
    eprintln!("car: {n} statuses compared, RMS {rms:.4} m, largest {max:.4} m");
    assert!(
        n + 10 >= converted.len() && n > 500,
        "{n} of {}",
        converted.len()
    );
    // The bag has the fixes' arrival times, not the receiver's own UTC, and the IMU's rate
    // is the bag's (104 Hz): 7 cm RMS, 29 cm at most, when this was written.
    assert!(rms < 0.2 && max < 0.6, "RMS {rms} m, largest {max} m");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bag_without_the_needed_topics_is_refused_by_name() {
    let dir = common::tempdir("import-refused");
    let data = common::shared_data("ekf/comma2k19-rav4");
    let bag = dir.join("car");
    write_bag("comma", &data, "ros2", &bag);
    let out = Command::new(common::chassisd())
        .args(["import"])
        .arg(&bag)
        .arg("--out")
        .arg(dir.join("x"))
        .args(["--imu-topic", "/wheels/odom"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("imu_topic names /wheels/odom, which holds no IMU samples"),
        "{stderr}"
    );
    assert!(
        stderr.contains("/wheels/odom (nav_msgs/msg/Odometry"),
        "{stderr}"
    );
    assert!(!dir.join("x").exists());
    // A bag of the receiver alone: what is missing, and what it has.
    let fixes = dir.join("fixes.bag");
    write_bag_of(
        "husky",
        &common::shared_data("ekf/husky-test1"),
        "ros1",
        &fixes,
        &["/gps/fix"],
    );
    let (code, stderr) = refused(&fixes, &dir);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains(
            "the bag lacks sensor_msgs/Imu (the gyro), nav_msgs/Odometry (the wheels); it has: \
             /gps/fix (sensor_msgs/NavSatFix, 989 messages)"
        ),
        "{stderr}"
    );
    // Not a bag at all.
    let junk: PathBuf = dir.join("junk.bag");
    std::fs::write(&junk, b"#ROSBAG V1.2\nnot this").unwrap();
    let out = Command::new(common::chassisd())
        .args(["import"])
        .arg(&junk)
        .arg("--out")
        .arg(dir.join("y"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("neither a ROS1 bag"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `chassisd import BAG`: its exit code and stderr (it must not succeed).
fn refused(bag: &Path, dir: &Path) -> (Option<i32>, String) {
    let out = Command::new(common::chassisd())
        .arg("import")
        .arg(bag)
        .arg("--out")
        .arg(dir.join("never"))
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_bag_claiming_huge_chunks_is_refused_before_anything_is_allocated() {
    let dir = common::tempdir("import-hostile");
    // A ROS1 bag whose first chunk claims 4 GB once decompressed.
    let bag = dir.join("husky.bag");
    write_bag(
        "husky",
        &common::shared_data("ekf/husky-test1"),
        "ros1",
        &bag,
    );
    let mut bytes = std::fs::read(&bag).unwrap();
    let chunk = bytes
        .windows(4)
        .position(|w| w == b"op=\x05")
        .expect("a chunk");
    let size = chunk
        + bytes[chunk..]
            .windows(5)
            .position(|w| w == b"size=")
            .unwrap()
        + 5;
    bytes[size..size + 4].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    std::fs::write(&bag, &bytes).unwrap();
    let (code, stderr) = refused(&bag, &dir);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("claims 4294967280 bytes"), "{stderr}");
    // A ROS 2 bag (MCAP) whose first chunk claims to be a terabyte long.
    let car = dir.join("car");
    write_bag(
        "comma",
        &common::shared_data("ekf/comma2k19-rav4"),
        "ros2",
        &car,
    );
    let file = std::fs::read_dir(&car)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .unwrap();
    let mut bytes = std::fs::read(&file).unwrap();
    // Magic (8), then records of an opcode and a length (9): the first chunk (opcode 6).
    let mut at = 8;
    while bytes[at] != 0x06 {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        at += 9 + len;
    }
    bytes[at + 1..at + 9].copy_from_slice(&(1u64 << 40).to_le_bytes());
    std::fs::write(&file, &bytes).unwrap();
    let (code, stderr) = refused(&car, &dir);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("exceeds limit"), "{stderr}");
    assert!(!dir.join("never").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
