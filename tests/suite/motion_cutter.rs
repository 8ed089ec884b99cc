//! The cutter of root MISSION's OPEN_CUTTER and CLOSE_CUTTER on the simulated mower, through
//! the whole engine: a CiA 402 blade drive runs at its configured speed and stops on a pause,
//! a safety stop and when chassisd is gone; a switch-frame cutter follows the same rules.

use crate::common;

use chassisd::sim::lockstep::{Lockstep, PLANT_STEP};
use chassisd::sim::plant::PlantConfig;
use common::lockstep::{FIXED, START, SimRun as Vehicle};

/// The mission that opens the cutter and keeps the mower standing for a while.
const CUT_AND_WAIT: &str = r#"[{"action": "OPEN_CUTTER", "parameters": {"cutter": true}},
    {"action": "WAIT", "parameters": {"seconds": 60}}]"#;

/// The located mower of the built-in plant with `plant` changed by `edit`.
fn located_with(seed: u64, edit: impl FnOnce(&mut PlantConfig)) -> Vehicle {
    let mut plant = PlantConfig::builtin().expect("plant");
    edit(&mut plant);
    let mut v = Vehicle::on(Lockstep::new(plant, seed, START).expect("sim"));
    v.run(3.0);
    v
}

fn blade_rpm(v: &Vehicle) -> f64 {
    v.sim.vehicle().blade_rpm()
}

#[test]
fn the_blade_drive_runs_at_its_speed_and_stops_on_pause_safety_stop_and_daemon_loss() {
    let mut v = Vehicle::located(5);
    let yard = v.sim.vehicle().plant().yard.expect("a yard");
    let speed = yard.blade_rpm;
    assert!(
        v.sim.vehicle().blade_drive().is_some(),
        "the mower's blade is a drive"
    );
    assert_eq!(blade_rpm(&v), 0.0);

    v.send("mission", CUT_AND_WAIT).expect("the mission starts");
    v.run(2.0);
    assert!(
        (blade_rpm(&v) - speed).abs() < 0.02 * speed,
        "{} r/min against {speed}",
        blade_rpm(&v)
    );
    assert!(
        v.sink.events.iter().any(|e| e == "cutter on"),
        "{:?}",
        v.sink.events
    );

    // PAUSE holds the mission and stops the blade; CONTINUE, the deliberate act, restarts it.
    v.send("pause", "{}").expect("paused");
    v.run(2.0);
    assert!(blade_rpm(&v).abs() < 1.0, "{} r/min paused", blade_rpm(&v));
    v.send("continue", "{}").expect("goes on");
    v.run(2.0);
    assert!(
        (blade_rpm(&v) - speed).abs() < 0.02 * speed,
        "{}",
        blade_rpm(&v)
    );

    // A safety stop stops the blade and switches the cutter off for good: the re-arm does
    // not restart it, and the mission is over.
    v.send("estop", r#"{"engaged":true}"#).expect("engaged");
    v.run(2.0);
    assert!(
        blade_rpm(&v).abs() < 1.0,
        "{} r/min after the e-stop",
        blade_rpm(&v)
    );
    assert!(
        v.sink.events.iter().any(|e| e.contains("mission aborted")),
        "{:?}",
        v.sink.events
    );
    v.send("estop", r#"{"engaged":false}"#).expect("released");
    v.run(0.5);
    v.send("reset", "{}").expect("re-armed");
    v.run(2.0);
    assert!(
        blade_rpm(&v).abs() < 1.0,
        "{} r/min after the re-arm",
        blade_rpm(&v)
    );

    // chassisd dies with the blade at speed: the drive misses chassisd's heartbeat and stops
    // the blade by itself within its master timeout and its quick-stop ramp.
    v.send("mission", CUT_AND_WAIT).expect("the mission starts");
    v.run(2.0);
    assert!(
        (blade_rpm(&v) - speed).abs() < 0.02 * speed,
        "{}",
        blade_rpm(&v)
    );
    let unattended_s = 1.5;
    for _ in 0..(unattended_s / PLANT_STEP.as_secs_f64()) as u64 {
        v.sim.step_unattended(FIXED);
    }
    let blade = v.sim.vehicle().blade_drive().expect("the blade drive");
    assert_eq!(blade.master_losses(), 1);
    assert!(
        blade_rpm(&v).abs() < 1.0,
        "{} r/min 1 s after",
        blade_rpm(&v)
    );
}

#[test]
fn a_switch_frame_cutter_follows_the_same_rules() {
    let mut v = located_with(6, |plant| {
        let yard = plant.yard.as_mut().expect("a yard");
        yard.blade_node = None;
        yard.cutter_can_id = Some(0x6A0);
    });
    for _ in 0..30 {
        if v.status().localization == chassisd::vehicle::Localization::Good {
            break;
        }
        v.run(1.0);
    }
    assert!(v.sim.vehicle().blade_drive().is_none());
    v.send("mission", CUT_AND_WAIT).expect("the mission starts");
    v.run(0.5);
    assert!(v.sim.vehicle().cutter_on(), "the on frame went out");
    v.send("pause", "{}").expect("paused");
    v.run(0.5);
    assert!(
        !v.sim.vehicle().cutter_on(),
        "paused: the off frame went out"
    );
    v.send("continue", "{}").expect("goes on");
    v.run(0.5);
    assert!(v.sim.vehicle().cutter_on(), "continued: on again");
    // Cancelling the mission does not finish it: the blade stops.
    v.send("stop", "{}").expect("stopped");
    v.run(0.5);
    assert!(!v.sim.vehicle().cutter_on(), "stopped with the mission");
}
