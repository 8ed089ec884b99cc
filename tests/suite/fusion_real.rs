//! Issue 47's test: every real vehicle's recording in `../shared/data/ekf` (the Husky with
//! and without a course, the comma2k19 car, the Jackal) replayed through the whole core by
//! `chassisd bench real`, each figure within its target: the pose no further from the truth
//! (or the fixes) than the fixes themselves, every GNSS outage no worse than a naive dead
//! reckoning, a parked vehicle still, wild fixes ignored. Then the binary's `replay` of the
//! Husky's recording ends where the library's replay does.

use crate::common;

use chassisd::bench::real::{husky_test1, recording};

#[test]
fn every_real_vehicle_meets_its_targets_through_the_core() {
    let ekf = common::shared_data("ekf");
    let summary = common::passing_bench(
        &[
            "bench".as_ref(),
            "real".as_ref(),
            "--data".as_ref(),
            ekf.as_os_str(),
        ],
        "the real recordings",
    );
    let figures = summary["figures"].as_array().expect("figures");
    for vehicle in [
        "husky-test1",
        "husky-test1, course from the fixes",
        "comma2k19-rav4",
        "jackal-test2",
    ] {
        assert!(
            figures.iter().any(|f| f["vehicle"] == vehicle),
            "{vehicle} missing: {summary}"
        );
    }
    for f in figures {
        println!(
            "{} | {} | {:.3} {} (target {:.3}{})",
            f["vehicle"].as_str().unwrap_or_default(),
            f["name"].as_str().unwrap_or_default(),
            f["value"].as_f64().unwrap_or(f64::NAN),
            f["unit"].as_str().unwrap_or_default(),
            f["target"].as_f64().unwrap_or(f64::NAN),
            f["naive"]
                .as_f64()
                .map_or(String::new(), |n| format!(", naive {n:.3}"))
        );
    }
}

#[test]
fn the_binary_replays_the_husky_recording_to_the_librarys_end() {
    let dir = common::tempdir("husky").join("rec");
    let gnss = husky_test1::write_recording(
        &common::shared_data("ekf/husky-test1"),
        husky_test1::Course::FromFixes,
        &dir,
    )
    .expect("recording written");
    let library_end = recording::replay(&dir, &gnss)
        .expect("replayed")
        .last()
        .and_then(|k| k.map)
        .expect("placed");
    let out = common::replay(&dir);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last: serde_json::Value =
        serde_json::from_str(stdout.lines().last().expect("status lines")).expect("JSON");
    // SBAS fixes (1σ 0.8 m) never bring the position within `locate_bound_m` (0.5 m).
    assert_eq!(last["nav"]["locate"], "LOCATE_FALSE", "{last}");
    let binary_end = (
        last["pose"]["x"].as_f64().unwrap(),
        last["pose"]["y"].as_f64().unwrap(),
    );
    assert!(
        (binary_end.0 - library_end.0).hypot(binary_end.1 - library_end.1) < 0.05,
        "binary {binary_end:?}, library {library_end:?}"
    );
    std::fs::remove_dir_all(dir.parent().unwrap()).ok();
}
