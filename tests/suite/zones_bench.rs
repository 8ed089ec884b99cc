//! `chassisd bench envelope` through the real binary, shortened (100 approaches, 5 minutes
//! of coverage, 30 plans each way): both plant files over three seeds meet every target,
//! and so do plausible plants made from them (a slower, wider mower whose drives brake on a
//! longer ramp; a delivery robot whose receiver runs at 2 Hz).

use crate::common;

use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// Runs the shortened benchmark on `plant` with `seed`; its JSON summary, after checking
/// it passed.
fn bench(plant: &Path, seed: u64) -> serde_json::Value {
    let mut args: Vec<OsString> = [
        "bench",
        "envelope",
        "--seed",
        &seed.to_string(),
        "--approaches",
        "100",
        "--minutes",
        "5",
        "--plans",
        "30",
    ]
    .iter()
    .map(OsString::from)
    .collect();
    args.extend(["--plant".into(), plant.into()]);
    common::passing_bench(&args, &format!("{} seed {seed}", plant.display()))
}

fn shipped(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("devices")
        .join(name)
}

#[test]
fn both_plants_meet_every_target_over_three_seeds() {
    for plant in ["plant.mower.toml", "plant.delivery.toml"] {
        for seed in 1..=3 {
            let summary = bench(&shipped(plant), seed);
            let approaches = &summary["approaches"];
            assert_eq!(approaches["incursions"], 0, "{summary}");
            assert!(approaches["manual_stops"].as_u64() > Some(20), "{summary}");
            assert!(approaches["with_jumps"].as_u64() > Some(20), "{summary}");
            assert_eq!(summary["plans"]["refused"], 30, "{summary}");
            assert_eq!(summary["coverage"]["pauses"], 0, "{summary}");
        }
    }
    // The mower's blade was on at gate closings, and went off within a control period.
    let summary = bench(&shipped("plant.mower.toml"), 4);
    assert!(summary["blade"]["closings"].as_u64() > Some(3), "{summary}");
}

/// `plant` with `edits` applied to its TOML text, written to a file of its own.
fn variant(plant: &str, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(shipped(plant)).expect("plant file");
    for (from, to) in edits {
        assert!(text.contains(from), "{plant} has no {from:?}");
        text = text.replacen(from, to, 1);
    }
    let dir = common::tempdir(name);
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).expect("variant written");
    path
}

#[test]
fn plausible_plants_meet_every_target_too() {
    let heavy = variant(
        "plant.mower.toml",
        "heavy-mower",
        &[
            (
                "footprint = { front_m = 0.45, rear_m = 0.20, width_m = 0.55 }",
                "footprint = { front_m = 0.70, rear_m = 0.40, width_m = 0.90 }",
            ),
            ("accel_rpm_per_s = 4000.0", "accel_rpm_per_s = 1500.0"),
            ("time_constant_s = 0.05", "time_constant_s = 0.15"),
        ],
    );
    bench(&heavy, 5);
    let slow_receiver = variant(
        "plant.delivery.toml",
        "delivery-2hz",
        &[("rate_hz = 5.0", "rate_hz = 2.0")],
    );
    bench(&slow_receiver, 6);
}
