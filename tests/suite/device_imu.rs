//! IMU decoders on fixed bytes worked from the vendor documents (WitMotion's standard
//! protocol; HiPNUC's frame with its CRC-16 computed by the vendor's published algorithm),
//! resynchronisation after garbage, and the mounting rotation.

use chassisd::devices::imu::hipnuc::HiPnuc;
use chassisd::devices::imu::witmotion::WitMotion;
use chassisd::devices::imu::{G, ImuSample, Mounting};
use chassisd::time::Timestamp;

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// WitMotion: 1 g on z (2048 of ±16 g), 26.00 °C; 90 °/s about z (1475 of ±2000 °/s).
const WIT_ACCEL: &str = "5551000000000008280AE0";
const WIT_GYRO: &str = "555200000000C30500006F";

fn wit_stream() -> Vec<u8> {
    let mut s = hex(WIT_ACCEL);
    s.extend(hex(WIT_GYRO));
    s
}

#[test]
fn witmotion_frames_decode_to_si() {
    let mut d = WitMotion::new();
    let mut samples = Vec::new();
    d.push(Timestamp::from_micros(5), &wit_stream(), |s| {
        samples.push(s)
    });
    assert_eq!(samples.len(), 1);
    let s = samples[0];
    assert!(close(s.accel.z, G, 1e-9), "{}", s.accel);
    assert!(close(
        s.gyro.z,
        1475.0 / 32768.0 * 2000f64.to_radians(),
        1e-12
    ));
    assert!(close(s.gyro.z.to_degrees(), 90.0, 0.05));
    assert_eq!(s.rx, Timestamp::from_micros(5));
    assert_eq!(d.stats().checksum_errors, 0);
}

#[test]
fn witmotion_resynchronises_after_garbage_and_split_reads() {
    let mut stream = vec![0x55, 0x55, 0x51, 0x00, 0xFF, 0x12];
    stream.extend(wit_stream());
    // A frame with a bad checksum in between is dropped.
    let mut bad = hex(WIT_GYRO);
    bad[10] ^= 0xFF;
    stream.extend(bad);
    stream.extend(wit_stream());
    let mut d = WitMotion::new();
    let mut n = 0;
    for chunk in stream.chunks(3) {
        d.push(Timestamp::default(), chunk, |_| n += 1);
    }
    assert_eq!(n, 2);
    assert!(d.stats().checksum_errors >= 1);
    assert!(d.stats().bytes_skipped >= 6);
}

/// A HiPNUC 0x91 packet: acceleration (0, 0.5, 1.0) g, rate (1.5, -2, 90) °/s, identity
/// quaternion, timestamp 123456 ms; CRC 0xCE2D.
const HIPNUC_91: &str = "5AA54C002DCE910100000000000040E20100000000000000003F0000803F0000C03F000000C00000B4420000000000000000000000000000000000000000000000000000803F000000000000000000000000";
/// Legacy items: 0xA0 acceleration (0, 0, 1000 mg), 0xB0 rate (0, 0, 90.0 °/s), 0xD1
/// quaternion (a 90° yaw).
const HIPNUC_LEGACY: &str =
    "5AA51F00B019A000000000E803B0000000008403D1F304353F0000000000000000F304353F";

#[test]
fn hipnuc_0x91_packet() {
    let mut d = HiPnuc::new();
    let mut samples = Vec::new();
    d.push(Timestamp::default(), &hex(HIPNUC_91), |s| samples.push(s));
    assert_eq!(samples.len(), 1, "{:?}", d.stats());
    let s = samples[0];
    assert!(close(s.accel.y, 0.5 * G, 1e-6) && close(s.accel.z, G, 1e-6));
    assert!(close(s.gyro.x, 1.5f64.to_radians(), 1e-7));
    assert!(close(s.gyro.y, -2f64.to_radians(), 1e-7));
    assert!(close(s.gyro.z, 90f64.to_radians(), 1e-6));
    assert!(s.orientation.unwrap().angle() < 1e-9);
}

#[test]
fn hipnuc_legacy_items() {
    let mut d = HiPnuc::new();
    let mut samples = Vec::new();
    d.push(Timestamp::default(), &hex(HIPNUC_LEGACY), |s| {
        samples.push(s)
    });
    let s = samples[0];
    assert!(close(s.accel.z, G, 1e-9));
    assert!(close(s.gyro.z.to_degrees(), 90.0, 1e-9));
    let (_, _, yaw) = s.orientation.unwrap().euler_angles();
    assert!(close(yaw.to_degrees(), 90.0, 1e-4));
}

#[test]
fn hipnuc_rejects_bad_crc_and_resynchronises() {
    let mut good = hex(HIPNUC_91);
    let mut bad = good.clone();
    bad[20] ^= 0x01;
    let mut stream = vec![0x5A, 0xA5, 0xFF, 0xFF, 0x00, 0x5A];
    stream.extend(bad);
    stream.append(&mut good);
    let mut d = HiPnuc::new();
    let mut n = 0;
    for chunk in stream.chunks(7) {
        d.push(Timestamp::default(), chunk, |_| n += 1);
    }
    assert_eq!(n, 1);
    assert_eq!(d.stats().checksum_errors, 1);
}

#[test]
fn mounting_rotates_into_the_vehicle_frame_and_removes_bias() {
    // Sensor mounted yawed 90° (its x points along the vehicle's y), with a 0.01 rad/s z
    // bias.
    let m = Mounting::from_rpy_deg([0.0, 0.0, 90.0], [0.0, 0.0, 0.01]);
    let s = ImuSample {
        rx: Timestamp::default(),
        accel: nalgebra::Vector3::new(1.0, 0.0, G),
        gyro: nalgebra::Vector3::new(0.0, 0.0, 0.51),
        orientation: None,
    };
    let v = m.apply(&s);
    assert!(close(v.accel.x, 0.0, 1e-12) && close(v.accel.y, 1.0, 1e-12));
    assert!(close(v.gyro.z, 0.5, 1e-12));
    assert!(v.is_plausible());
    let dead = ImuSample {
        accel: nalgebra::Vector3::zeros(),
        ..s
    };
    assert!(!dead.is_plausible(), "no gravity: a dead accelerometer");
}

#[test]
fn the_calibration_file_replaces_the_configured_bias() {
    let dir = std::env::temp_dir().join(format!("chassisd-imu-calib-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("calib")).unwrap();
    let config = r#"
[vehicle]
name = "mower"
calibration = "calib/imu.toml"

[imu]
port = "/dev/ttyUSB1"
protocol = "hipnuc"
gyro_bias_rps = [0.1, 0.1, 0.1]
"#;
    std::fs::write(dir.join("vehicle.toml"), config).unwrap();
    std::fs::write(
        dir.join("calib/imu.toml"),
        "[imu]\ngyro_bias_rps = { value = [0.001, -0.002, 0.003], date = \"2026-11-22\", \
         method = \"60 s at rest\", verdict = \"ok\" }\nmounting_rpy_deg = [1.0, -2.0, 0.0]\n",
    )
    .unwrap();
    let loaded = chassisd::config::VehicleConfig::load(&dir.join("vehicle.toml")).unwrap();
    let (file, lines) = loaded.calibration_in_force.clone().expect("read");
    assert!(file.ends_with("calib/imu.toml"));
    assert!(
        lines.iter().any(|l| l.contains("60 s at rest")),
        "{lines:?}"
    );
    let imu = loaded.imu.expect("imu section");
    assert_eq!(imu.gyro_bias_rps, [0.001, -0.002, 0.003]);
    assert_eq!(imu.mounting_rpy_deg, [1.0, -2.0, 0.0]);
    // The effective configuration carries the bias, not the file name.
    assert!(!loaded_text(&dir).contains("calibration"));

    std::fs::write(
        dir.join("calib/imu.toml"),
        "[imu]\ngyro_bias_rps = [0.0, 0.0, 9.0]\n",
    )
    .unwrap();
    let err = chassisd::config::VehicleConfig::load(&dir.join("vehicle.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("imu.toml") && err.contains("gyro_bias_rps[2]"),
        "{err}"
    );
    std::fs::remove_file(dir.join("calib/imu.toml")).unwrap();
    let err = chassisd::config::VehicleConfig::load(&dir.join("vehicle.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("imu.toml") && err.contains("vehicle.calibration"),
        "{err}"
    );

    // Without the key, calib/<name>.toml beside the configuration is read when it exists.
    std::fs::write(
        dir.join("vehicle.toml"),
        config.replace("calibration = \"calib/imu.toml\"\n", ""),
    )
    .unwrap();
    assert!(
        chassisd::config::VehicleConfig::load(&dir.join("vehicle.toml"))
            .unwrap()
            .calibration_in_force
            .is_none()
    );
    std::fs::write(
        dir.join("calib/mower.toml"),
        "[imu]\ngyro_bias_rps = [0.0, 0.0, 0.004]\n",
    )
    .unwrap();
    let loaded = chassisd::config::VehicleConfig::load(&dir.join("vehicle.toml")).unwrap();
    assert_eq!(loaded.imu.expect("imu").gyro_bias_rps, [0.0, 0.0, 0.004]);
    std::fs::remove_dir_all(&dir).ok();
}

fn loaded_text(dir: &std::path::Path) -> String {
    chassisd::config::VehicleConfig::load(&dir.join("vehicle.toml"))
        .unwrap()
        .to_effective_toml()
}
