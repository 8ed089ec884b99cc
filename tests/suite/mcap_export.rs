//! `chassisd export --mcap`: every fixture (and a plain receiver log) exported and read back
//! by an independent reader, PyPI's mcap (tests/mcap/check_export.py): the schemas are the
//! well-known ones and every message meets its channel's schema, the raw frames' count,
//! times and bytes are the recording's, each status's position is the last /gnss/fix before
//! it, the base_status messages are replay's lines, messages run in time order per channel,
//! and the summary's statistics are right.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common;

/// Exports `input` (with `extra` arguments), replays it stamped, and has the reader check
/// the file (`zones`: the GeoJSON /zones must carry); its report.
fn exported_and_checked(input: &Path, extra: &[&str], zones: Option<&Path>) -> serde_json::Value {
    let dir = common::tempdir("mcap-export");
    let file = dir.join("out.mcap");
    let export = Command::new(common::chassisd())
        .arg("export")
        .arg(input)
        .arg("--mcap")
        .arg(&file)
        .args(extra)
        .output()
        .expect("chassisd export");
    let stderr = String::from_utf8_lossy(&export.stderr);
    assert!(
        export.status.success(),
        "export of {}: {stderr}",
        input.display()
    );
    assert!(stderr.contains("export: "), "{stderr}");
    let replay = Command::new(common::chassisd())
        .arg("replay")
        .arg("--stamped")
        .arg(input)
        .args(extra.iter().filter(|a| **a != "--lenient"))
        .arg("--lenient")
        .output()
        .expect("chassisd replay");
    assert!(replay.status.success());
    let lines = dir.join("replay.jsonl");
    std::fs::write(&lines, &replay.stdout).unwrap();
    let mut check = Command::new(common::venv_python());
    check
        .arg(common::repo().join("tests/mcap/check_export.py"))
        .arg(&file)
        .arg(input)
        .arg(&lines);
    if let Some(zones) = zones {
        check.arg(zones);
    }
    let out = check.output().expect("check_export.py");
    assert!(
        out.status.success(),
        "{}: {}",
        input.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let report = serde_json::from_slice(&out.stdout).expect("the reader's report");
    let _ = std::fs::remove_dir_all(&dir);
    report
}

#[test]
fn every_fixture_and_a_receiver_log_export_to_a_file_an_independent_reader_checks() {
    let mut fixtures: Vec<PathBuf> = std::fs::read_dir(common::repo().join("fixtures"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("meta.toml").exists())
        .collect();
    fixtures.sort();
    assert!(fixtures.len() >= 4, "{fixtures:?}");
    for fixture in &fixtures {
        // ros-legacy's transmissions differ on purpose (an older chassisd's recording).
        let report = exported_and_checked(fixture, &["--lenient"], None);
        let raw = report["raw_sources_compared"].as_object().unwrap();
        assert!(!raw.is_empty(), "{}: {report}", fixture.display());
        // What the fixtures hold shows on its channel: a receiver's fixes and the fused pose,
        // the CAN frames, the commands and their answers.
        let channels = &report["channels"];
        let name = fixture.file_name().unwrap().to_string_lossy();
        match name.as_ref() {
            "rtk-drive" | "sim-drive" | "ros-legacy" => {
                for topic in ["/gnss/fix", "/fused/fix", "/fused/pose", "/tf"] {
                    assert!(
                        channels[topic].as_u64() > Some(10),
                        "{name}: {topic}: {report}"
                    );
                }
                assert!(
                    report["statuses_with_a_fix_compared"].as_u64() > Some(90),
                    "{name}: {report}"
                );
            }
            "can-drive" => {
                assert!(channels["/raw/vcan0"].as_u64() > Some(5000), "{report}");
                assert_eq!(channels["/commands/results"], 60, "{report}");
                assert!(channels["/status/battery"].as_u64() > Some(10), "{report}");
            }
            _ => {}
        }
    }
    // Plain receiver logs (no recording folder, so no raw check): UBX alone, and NMEA with
    // its sentences as text.
    let ubx = common::shared_gnss_dir().join("ublox-zed-f9p-rtk.log");
    let report = exported_and_checked(&ubx, &[], None);
    assert_eq!(report["channels"]["/gnss/fix"], 10, "{report}");
    let nmea = common::shared_gnss_dir().join("skytraq-PX1172RH_DS.log");
    let report = exported_and_checked(&nmea, &[], None);
    assert!(
        report["channels"]["/gnss/fix"].as_u64() > Some(5),
        "{report}"
    );
    assert!(
        report["channels"]["/raw/gnss/nmea"].as_u64() > Some(50),
        "{report}"
    );
}

#[test]
fn the_zones_in_force_are_on_the_map_and_the_documented_layout_finds_its_topics() {
    let dir = common::tempdir("mcap-zones");
    // The simulated mower with all its parts (receiver, IMU, drives, battery), 20 s.
    let fixture = dir.join("mower");
    let sim = Command::new(common::chassisd())
        .args(["sim", "--fast", "--duration", "20", "--record"])
        .arg(&fixture)
        .output()
        .expect("chassisd sim");
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    // A boundary round the mower's datum (47.397742, 8.545594), and a keep-out circle in it.
    let zones = r#"{"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"kind": "boundary", "name": "yard"},
         "geometry": {"type": "Polygon", "coordinates": [[[8.5446, 47.3972], [8.5466, 47.3972],
            [8.5466, 47.3982], [8.5446, 47.3982], [8.5446, 47.3972]]]}},
        {"type": "Feature", "properties": {"kind": "keep_out", "name": "tree", "radius_m": 1.5},
         "geometry": {"type": "Point", "coordinates": [8.5460, 47.3979]}}]}"#;
    std::fs::write(dir.join("zones.geojson"), zones).unwrap();
    let mut config = std::fs::read_to_string(fixture.join("vehicle.toml")).unwrap();
    config.push_str(
        "\n[zones]\nfile = \"zones.geojson\"\nfootprint = { front_m = 0.5, rear_m = 0.3, width_m = 0.6 }\n",
    );
    std::fs::write(dir.join("vehicle.toml"), config).unwrap();
    // What chassisd holds of them: its own GeoJSON of the set.
    let expected = dir.join("expected.geojson");
    let set = chassisd::zones::ZoneSet::from_geojson(zones).unwrap();
    std::fs::write(&expected, set.to_geojson()).unwrap();
    let config = dir.join("vehicle.toml");
    let report = exported_and_checked(
        &fixture,
        &["--config", config.to_str().unwrap()],
        Some(&expected),
    );
    assert_eq!(report["channels"]["/zones"], 1, "{report}");
    assert_eq!(report["zones_compared"], true, "{report}");
    // The layout docs/ offers opens topics this file has: every topic a panel names.
    let layout: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(common::repo().join("docs/foxglove-layout.json")).unwrap(),
    )
    .unwrap();
    let mut named = Vec::new();
    layout_topics(&layout["configById"], &mut named);
    assert!(named.len() >= 8, "{named:?}");
    for topic in &named {
        assert!(
            report["channels"].get(topic).is_some(),
            "the layout names {topic}: {report}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_export_benchmark_runs_and_reports_on_a_short_synthetic_recording() {
    // The benchmark's own run is an hour of the simulated vehicle; a minute here. Its speed
    // target is the benchmark's to judge (a loaded test machine is no measure of speed):
    // here it runs, reports each figure, and the memory target holds.
    let out = Command::new(common::chassisd())
        .args(["bench", "export", "--seconds", "60", "--fixtures"])
        .arg(common::repo().join("fixtures"))
        .output()
        .expect("chassisd bench export");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let summary: serde_json::Value =
        serde_json::from_str(stdout.lines().last().unwrap_or_default()).expect("JSON last");
    let recordings = summary["recordings"].as_array().unwrap();
    assert_eq!(recordings.len(), 2, "{summary}");
    let synthetic = &recordings[1];
    assert_eq!(synthetic["span_s"], 60.0, "{summary}");
    assert!(synthetic["messages"].as_u64() > Some(50_000), "{summary}");
    for r in recordings {
        assert!(r["times_real_time"].as_f64() > Some(0.0), "{summary}");
        assert!(r["peak_bytes"].as_u64() < Some(64_000_000), "{summary}");
    }
}

/// The topics a Foxglove layout's panels name (keys and values starting with `/`, a message
/// path cut at its first `.`).
fn layout_topics(value: &serde_json::Value, out: &mut Vec<String>) {
    match value {
        serde_json::Value::String(text) => take_topic(text, out),
        serde_json::Value::Array(items) => items.iter().for_each(|v| layout_topics(v, out)),
        serde_json::Value::Object(map) => {
            for (key, v) in map {
                take_topic(key, out);
                layout_topics(v, out);
            }
        }
        _ => {}
    }
}

/// The topic of `text` when it is a topic or a message path.
fn take_topic(text: &str, out: &mut Vec<String>) {
    if let Some(path) = text.strip_prefix('/') {
        let topic = format!("/{}", path.split('.').next().unwrap_or_default());
        if !out.contains(&topic) {
            out.push(topic);
        }
    }
}
