//! A still vehicle stays still: the simulated vehicle (its biased, noisy gyro included)
//! drives, stops, and stands for 60 s without GNSS. The published pose may not move by more
//! than 1 cm, whether it is the map pose (GNSS was there before the outage) or the odom
//! frame's (no fix ever).

use crate::common;

use chassisd::devices::gnss::FixQuality;
use chassisd::engine::EngineOutput;
use chassisd::record::Record;
use chassisd::sim::lockstep::{Lockstep, PLANT_STEP, Sink};
use chassisd::sim::plant::{GnssCondition, PlantConfig};
use chassisd::time::Timestamp;
use chassisd::vehicle::VehicleStatus;

#[derive(Default)]
struct Statuses(Vec<VehicleStatus>);

impl Sink for Statuses {
    fn record(&mut self, _: &Record) {}

    fn output(&mut self, output: EngineOutput) {
        if let EngineOutput::Status(s) = output {
            self.0.push(*s);
        }
    }
}

/// Drives 20 s (GNSS as `fix` gives it), stops, stands 60 s without GNSS; returns the
/// largest distance and turn of the published pose from where it stood 2 s after the stop.
fn standstill(plant_file: &str, fix: Option<FixQuality>) -> (f64, f64, String) {
    let text = std::fs::read_to_string(common::repo().join(plant_file)).expect("plant");
    let plant = PlantConfig::from_toml(&text, std::path::Path::new(plant_file)).expect("plant");
    let start = Timestamp::from_micros(1_767_225_600_000_000);
    let mut sim = Lockstep::new(plant, 7, start).expect("lockstep");
    let mut sink = Statuses::default();
    let steps_per_s = (1.0 / PLANT_STEP.as_secs_f64()).round() as u64;
    for k in 0..(84 * steps_per_s) {
        let s = k / steps_per_s;
        if k % 100 == 0 && (1..21).contains(&s) {
            let w = if s > 10 { 0.3 } else { 0.0 };
            sim.command(
                "cmd_vel",
                &format!(r#"{{"linear":{{"x":0.5}},"angular":{{"z":{w}}}}}"#),
                &mut sink,
            );
        }
        let quality = if s < 20 { fix } else { None };
        sim.step(
            GnssCondition {
                quality,
                offset: (0.0, 0.0),
            },
            &mut sink,
        );
    }
    let still_from = start.as_nanos() + 23_000_000_000;
    let still: Vec<&VehicleStatus> = sink
        .0
        .iter()
        .filter(|s| s.time.as_nanos() >= still_from)
        .collect();
    assert!(still.len() >= 600, "{} statuses", still.len());
    let first = still[0].pose;
    let moved = still
        .iter()
        .map(|s| (s.pose.x - first.x).hypot(s.pose.y - first.y))
        .fold(0.0, f64::max);
    let turned = still
        .iter()
        .map(|s| (s.pose.yaw - first.yaw).abs())
        .fold(0.0, f64::max);
    let locate = format!("{:?}", still[still.len() - 1].localization);
    (moved, turned, locate)
}

#[test]
fn a_still_vehicle_stays_still_without_gnss() {
    for plant in ["devices/plant.mower.toml", "devices/plant.delivery.toml"] {
        for fix in [Some(FixQuality::RtkFixed), Some(FixQuality::Single), None] {
            let (moved, turned, locate) = standstill(plant, fix);
            println!(
                "{plant}, GNSS {fix:?} then none: still 60 s, pose moved {:.4} m, turned {:.4}°, {locate}",
                moved,
                turned.to_degrees()
            );
            assert!(moved < 0.01, "{plant} {fix:?}: moved {moved} m");
            assert!(
                turned < 0.1f64.to_radians(),
                "{plant} {fix:?}: turned {turned} rad"
            );
            if fix.is_none() {
                assert_eq!(locate, "Uninitialized", "the odom frame's pose");
            }
        }
    }
}
