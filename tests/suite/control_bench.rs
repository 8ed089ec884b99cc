//! The control benchmark through the real binary: both plant files, and copies of them whose
//! receivers run at 1 Hz, over several seeds, meet every target. And the figure its distance
//! target is scored on, the truth error less the plant's random slip, is sound: the slip the
//! plant reports is exactly what separates its truth from the wheels' odometry.

use crate::common;

use chassisd::sim::lockstep::Lockstep;
use chassisd::sim::plant::PlantConfig;
use common::lockstep::{START, SimRun};
use std::ffi::OsString;
use std::path::Path;

/// Runs `bench control` on `plant` with `seed`; its JSON summary, after checking it passed.
fn bench(plant: &Path, seed: u64) -> serde_json::Value {
    let mut args: Vec<OsString> = ["bench", "control", "--seed", &seed.to_string()]
        .iter()
        .map(OsString::from)
        .collect();
    args.extend(["--plant".into(), plant.into()]);
    common::passing_bench(&args, &format!("{} seed {seed}", plant.display()))
}

/// The figures of every distance move: (truth error, unseen slip, scored error), m.
fn distance_moves(summary: &serde_json::Value) -> Vec<(f64, f64, f64)> {
    summary["moves"]
        .as_array()
        .expect("moves")
        .iter()
        .filter(|m| m["turn"] == false)
        .map(|m| {
            let f = |k: &str| m[k].as_f64().unwrap_or(f64::NAN);
            (f("truth_error"), f("unseen_slip_m"), f("scored_error"))
        })
        .collect()
}

#[test]
fn both_plants_meet_every_target_over_ten_seeds() {
    for plant in ["plant.mower.toml", "plant.delivery.toml"] {
        let path = common::repo().join("devices").join(plant);
        for seed in 1..=10 {
            let summary = bench(&path, seed);
            for (truth, slip, scored) in distance_moves(&summary) {
                // The scored error is the truth error with the slip taken out, no more.
                assert!(
                    slip.is_finite() && slip != 0.0,
                    "{plant} {seed}: slip {slip}"
                );
                assert!(
                    scored <= truth + slip.abs() + 1e-9 && truth <= scored + slip.abs() + 1e-9,
                    "{plant} {seed}: truth {truth} slip {slip} scored {scored}"
                );
            }
        }
    }
}

#[test]
fn both_plants_meet_every_target_with_1_hz_receivers() {
    let dir = common::tempdir("control-bench-1hz");
    for plant in ["plant.mower.toml", "plant.delivery.toml"] {
        let text = std::fs::read_to_string(common::repo().join("devices").join(plant))
            .expect("plant file");
        let mut config: toml::Table = toml::from_str(&text).expect("plant parses");
        config["gnss"]
            .as_table_mut()
            .expect("[gnss]")
            .insert("rate_hz".into(), toml::Value::Float(1.0));
        let copy = dir.join(plant);
        std::fs::write(&copy, toml::to_string(&config).expect("plant serialises"))
            .expect("plant copy");
        for seed in 1..=5 {
            bench(&copy, seed);
        }
    }
}

#[test]
fn the_unseen_slip_is_what_separates_truth_from_the_wheels() {
    for seed in [1, 2, 3] {
        let mut plant = PlantConfig::builtin().expect("plant");
        plant.slip.sigma = 0.05;
        plant.slip.bias = [0.0, 0.0];
        let mut v = SimRun::on(Lockstep::new(plant, seed, START).expect("sim"));
        v.run(3.0);
        let odom_at = |v: &SimRun| {
            let o = v.status().odom.expect("odometry");
            (o.x, o.y)
        };
        let (truth0, odom0, slip0) = (
            v.truth_xy(),
            odom_at(&v),
            v.sim.vehicle().truth().unseen_slip_m,
        );
        for _ in 0..40 {
            v.send("cmd_vel", r#"{"linear":{"x":0.5},"angular":{"z":0.0}}"#)
                .expect("cmd_vel taken");
            v.run(0.1);
        }
        v.run(1.5);
        let (truth1, odom1) = (v.truth_xy(), odom_at(&v));
        let slip = v.sim.vehicle().truth().unseen_slip_m - slip0;
        let truth = (truth1.0 - truth0.0).hypot(truth1.1 - truth0.1);
        let odom = (odom1.0 - odom0.0).hypot(odom1.1 - odom0.1);
        // 5 % slip redrawn every 100 ms over about 2 m: some 11 mm 1σ.
        assert!(
            (truth - slip - odom).abs() < 0.5e-3,
            "seed {seed}: truth {truth:.4} m, odometry {odom:.4} m, unseen slip {slip:.4} m"
        );
        assert!(slip.abs() > 1e-4, "seed {seed}: slip {slip}");
    }
}
