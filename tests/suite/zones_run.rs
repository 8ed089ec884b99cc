//! Zones and the GNSS gate at run time, through the whole engine on the simulated mower in
//! the yard (tests/common/zones.rs: the pond's west edge at x = 4 m):
//! - a manual jog towards the pond stops short of it and latches with the zone; a zero
//!   command re-arms, driving on towards it stops again before it can reach it, backing
//!   away drives;
//! - the status shows the zones in the map frame and the vehicle's margin (σ and the
//!   braking way) against its clearance from the nearest zone, as it approaches;
//! - under `zones.manual = "warn"` the jog drives on and the driver is told once;
//! - the gate: a float fix stops the blade in the same control tick and holds a mission at
//!   rest; it goes on by itself after `zones.resume_after_s` of RTK fixed, and a flickering
//!   fix keeps it held.

use crate::common;

use chassisd::config::zones::ManualPolicy;
use chassisd::devices::gnss::FixQuality;
use chassisd::sim::plant::GnssCondition;
use common::lockstep::{FIXED, SimRun};
use common::zones::mower_in_the_yard;

/// The pond's west edge, m.
const POND_X: f64 = 4.0;
/// The built-in mower's front edge ahead of its axle, m.
const FRONT_M: f64 = 0.45;

const FLOAT: GnssCondition = GnssCondition {
    quality: Some(FixQuality::RtkFloat),
    offset: (0.0, 0.0),
};

/// Jogs at `speed` m/s (a command every 0.1 s) for `seconds`; the farthest true x reached
/// and the last answer.
fn jog(v: &mut SimRun, speed: f64, seconds: f64) -> (f64, Result<(), String>) {
    let command = format!(r#"{{"linear": {{"x": {speed}}}, "angular": {{"z": 0}}}}"#);
    let mut answer = Ok(());
    let mut farthest = v.truth_xy().0;
    for _ in 0..(seconds * 10.0) as usize {
        answer = v.send("cmd_vel", &command);
        v.run(0.1);
        farthest = farthest.max(v.truth_xy().0);
    }
    (farthest, answer)
}

#[test]
fn the_status_shows_the_zones_and_the_margin_against_the_clearance() {
    let mut v = mower_in_the_yard("zones-status", |_| {});
    // The next status, after the tick the gate opened in.
    v.run(0.2);
    let at_rest = v.status().envelope.clone().expect("zones configured");
    assert!(at_rest.gate_closed.is_none());
    let zones = at_rest.zones.clone().expect("placed");
    let names: Vec<&str> = zones.iter().map(|z| z.name.as_str()).collect();
    assert_eq!(names, ["lawn", "pond", "fence", "tree"]);
    // The pond's outline in the map frame: its west edge at x = 4 m.
    let pond_x = zones[1].lines[0]
        .iter()
        .map(|p| p.0)
        .fold(f64::INFINITY, f64::min);
    assert!((pond_x - POND_X).abs() < 0.01, "{pond_x}");
    // At rest the margin is σ alone.
    let sigma = at_rest.sigma_m.expect("placed");
    assert!(sigma > 0.0 && sigma < 0.1, "{sigma}");
    assert_eq!(at_rest.margin_m(), Some(sigma + at_rest.braking_m));
    assert!(at_rest.braking_m < 1e-3, "{at_rest:?}");
    // Nearest at the start: the fence 3 m west, less the footprint.
    let nearest = at_rest.nearest.clone().expect("zones");
    assert_eq!(nearest.name, "fence");
    assert!(
        (nearest.clearance_m - (3.0 - at_rest.footprint_m)).abs() < 0.1,
        "{nearest:?}"
    );
    // The same zones, not drawn again, while nothing changes.
    v.run(1.0);
    let later = v.status().envelope.clone().expect("zones");
    assert!(std::sync::Arc::ptr_eq(
        &zones,
        &later.zones.expect("placed")
    ));

    // Driving east: the braking way joins the margin, and the pond comes nearest.
    let mut moving = None;
    for _ in 0..120 {
        v.send("cmd_vel", r#"{"linear": {"x": 0.5}, "angular": {"z": 0}}"#)
            .ok();
        v.run(0.1);
        let e = v.status().envelope.clone().expect("zones");
        if v.speed() > 0.45 && moving.is_none() {
            moving = Some(e);
        }
    }
    let moving = moving.expect("reached 0.45 m/s");
    // At 0.45 m/s: the reaction's way and 0.05 m braking at the mower's 2 m/s².
    assert!(moving.braking_m > 0.05, "{moving:?}");
    assert!(
        moving.margin_m().expect("placed") > at_rest.margin_m().expect("placed") + 0.05,
        "{moving:?}"
    );
    // Stopped short of the pond: the footprint outside it, the pond nearest and within
    // what a way towards it would need.
    let stopped = v.status().envelope.clone().expect("zones");
    let pond = stopped.nearest.clone().expect("zones");
    assert_eq!(pond.name, "pond");
    assert!(pond.clearance_m > 0.0, "{stopped:?}");
    assert!(pond.clearance_m < 0.6, "{stopped:?}");
}

#[test]
fn a_jog_towards_the_pond_stops_short_and_only_backing_away_drives() {
    let mut v = mower_in_the_yard("zones-jog", |_| {});
    let (farthest, answer) = jog(&mut v, 0.5, 12.0);
    let refused = answer.expect_err("refused once stopped");
    assert!(refused.contains("pond"), "{refused}");
    assert!(
        v.sink
            .events
            .iter()
            .any(|e| e.starts_with("stopping: the keep_out zone \"pond\"")),
        "{:?}",
        v.sink.events
    );
    // Never in, and not far short: the disc (0.53 m) and a braking way of some 0.15 m.
    assert!(farthest + FRONT_M < POND_X, "in the pond: {farthest}");
    assert!(farthest > POND_X - 1.0, "stopped too early: {farthest}");
    assert!(v.speed().abs() < 0.01, "at rest: {}", v.speed());

    // A zero command re-arms; forward again creeps on only as far as it can still stop,
    // three times over.
    for _ in 0..3 {
        v.send("cmd_vel", r#"{"linear": {"x": 0}, "angular": {"z": 0}}"#)
            .expect("a zero command re-arms at rest");
        let (again, answer) = jog(&mut v, 0.5, 3.0);
        assert!(again + FRONT_M < POND_X, "in the pond: {again}");
        assert!(answer.is_err(), "stopped again");
    }

    // Backing away drives.
    v.send("cmd_vel", r#"{"linear": {"x": 0}, "angular": {"z": 0}}"#)
        .expect("re-armed");
    let before = v.truth_xy().0;
    let (_, answer) = jog(&mut v, -0.3, 2.0);
    answer.expect("backing away is taken");
    let after = v.truth_xy().0;
    assert!(
        after < before - 0.3,
        "did not back away: {before} → {after}"
    );
}

#[test]
fn under_warn_a_manual_driver_is_told_once_and_drives_on() {
    let mut v = mower_in_the_yard("zones-warn", |z| z.manual = ManualPolicy::Warn);
    let (farthest, answer) = jog(&mut v, 0.5, 10.0);
    answer.expect("never refused");
    assert!(farthest + FRONT_M > POND_X, "stopped: {farthest}");
    let warned = v
        .sink
        .events
        .iter()
        .filter(|e| e.contains("zones.manual = \"warn\""))
        .count();
    assert_eq!(warned, 1, "{:?}", v.sink.events);
}

#[test]
fn a_float_fix_stops_the_blade_in_the_same_tick_and_holds_the_mission_until_fixed_again() {
    let mut v = mower_in_the_yard("zones-gate", |_| {});
    let mission = r#"[{"action": "OPEN_CUTTER", "parameters": {}},
        {"action": "COVERAGE", "parameters": {"path": [0, 0, 3, 0, 3, 3, 0, 3]}},
        {"action": "CLOSE_CUTTER", "parameters": {}}]"#;
    v.send("mission", mission).expect("the mission starts");
    v.run(3.0);
    assert!(v.sink.events.iter().any(|e| e == "cutter on"));
    assert!(v.speed() > 0.1, "covering: {}", v.speed());

    // Float: the gate closes, and the blade stops in that very step.
    v.sink.events.clear();
    let mut closed_at = None;
    for step in 0..100 {
        v.sim.step(FLOAT, &mut v.sink);
        if v.sink
            .events
            .iter()
            .any(|e| e.starts_with("GNSS gate closed"))
        {
            assert!(
                v.sink.events.iter().any(|e| e == "cutter off"),
                "the blade still runs: {:?}",
                v.sink.events
            );
            closed_at = Some(step);
            break;
        }
    }
    assert!(closed_at.is_some(), "the gate never closed");
    // Held at rest: the mission neither moves nor ends.
    v.run_under(FLOAT, 5.0, false);
    assert!(v.speed().abs() < 0.01, "still moving: {}", v.speed());
    let (x, y) = v.truth_xy();
    v.run_under(FLOAT, 5.0, false);
    let (x2, y2) = v.truth_xy();
    assert!((x2 - x).hypot(y2 - y) < 0.01, "moved while held");
    assert!(v.sink.results.is_empty(), "{:?}", v.sink.results);

    // Fixed, but flickering to float every 4 s: still held.
    v.sink.events.clear();
    for _ in 0..5 {
        v.run(4.0);
        v.run_under(FLOAT, 0.2, false);
    }
    assert!(
        !v.sink
            .events
            .iter()
            .any(|e| e.starts_with("GNSS gate open")),
        "{:?}",
        v.sink.events
    );
    assert!(v.speed().abs() < 0.01, "moving on a flickering fix");

    // Fixed for good: it goes on after the resume time, blade first.
    assert!(v.run_until_event("GNSS gate open", 11.0), "never opened");
    v.run(1.0);
    assert!(v.sink.events.iter().any(|e| e == "cutter on"));
    assert!(v.speed() > 0.05, "did not go on: {}", v.speed());
    v.run_under(FIXED, 60.0, true);
    let result = v.result();
    assert!(
        matches!(result.outcome, chassisd::control::Outcome::Succeeded),
        "{result:?}"
    );
}

#[test]
fn while_the_gate_is_closed_nothing_autonomous_starts_and_manual_driving_goes_on() {
    let mut v = mower_in_the_yard("zones-gate-start", |_| {});
    v.run_under(FLOAT, 1.0, false);
    let refused = v
        .send("goal", r#"{"x": 2, "y": 0, "yaw": 0}"#)
        .expect_err("refused while float");
    assert!(refused.contains("GNSS gate is closed"), "{refused}");
    assert!(refused.contains("zones.min_quality"), "{refused}");
    let before = v.truth_xy().0;
    let command = r#"{"linear": {"x": -0.3}, "angular": {"z": 0}}"#;
    for _ in 0..10 {
        v.send("cmd_vel", command).expect("manual driving goes on");
        v.run_under(FLOAT, 0.1, false);
    }
    assert!(v.truth_xy().0 < before - 0.1, "did not drive");
}
