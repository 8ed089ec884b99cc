//! Root MISSION on the simulated mower (its yard: a Daly BMS on the drives' bus that charges
//! on the dock, and a CiA 402 blade drive), through the local command channel and
//! the whole engine: every action runs in order, the blade runs during the coverage only, and
//! the mission ends charging on the dock; a mission stops its blade when it fails.

use crate::common;

use chassisd::sim::plant::PlantConfig;
use chassisd::vehicle::status::Navigation;
use common::lockstep::SimRun as Vehicle;

#[test]
fn a_mission_with_every_action_runs_in_order_and_ends_charging_on_the_dock() {
    let plant = PlantConfig::builtin().expect("plant");
    assert!(plant.yard.is_some(), "the built-in mower has a yard");
    let mut v = Vehicle::located(11);
    let p = v.status().pose;
    let (s, c) = p.yaw.sin_cos();
    // Points `ahead` and `left` of where the vehicle stands, flat as the spec writes them.
    let at = |ahead: f64, left: f64| {
        format!(
            "{:.3}, {:.3}",
            p.x + ahead * c - left * s,
            p.y + ahead * s + left * c
        )
    };
    let mission = format!(
        r#"[
        {{"action": "MOVE_TO_POSITION", "parameters": {{"path": [{}, {}]}}}},
        {{"action": "WAIT", "parameters": {{"seconds": 2}}}},
        {{"action": "OPEN_CUTTER", "parameters": {{"cutter": true}}}},
        {{"action": "COVERAGE", "parameters": {{"path": [{}, {}, {}, {}]}}}},
        {{"action": "CLOSE_CUTTER", "parameters": {{"cutter": false}}}},
        {{"action": "CHARGING", "parameters": {{"time": 3}}}}
    ]"#,
        at(0.0, 0.0),
        at(1.0, 0.0),
        at(1.0, 0.0),
        at(3.0, 0.0),
        at(3.0, 0.5),
        at(1.0, 0.5),
    );
    v.send("mission", &mission).expect("the mission starts");
    assert!(
        v.run_until_event("mission step 1 (WAIT) started", 30.0),
        "{:?}",
        v.sink.events
    );
    assert!(!v.sim.vehicle().cutter_on());
    assert!(
        v.run_until_event("mission step 3 (COVERAGE) started", 5.0),
        "{:?}",
        v.sink.events
    );
    v.run(3.0);
    assert!(
        v.sim.vehicle().cutter_on(),
        "the blade runs during the coverage"
    );
    assert_eq!(v.status().navigation, Navigation::Running);
    assert!(
        v.run_until_event("mission step 4 (CLOSE_CUTTER) done", 60.0),
        "{:?}",
        v.sink.events
    );
    // The blade drive brakes its disc to rest.
    v.run(1.5);
    assert!(
        v.sim.vehicle().blade_rpm().abs() < 1.0,
        "the blade stops after the coverage"
    );
    assert!(
        v.run_until_event("mission succeeded", 120.0),
        "{:?}",
        v.sink.events
    );
    let steps: Vec<&String> = v
        .sink
        .events
        .iter()
        .filter(|e| e.starts_with("mission step"))
        .collect();
    assert_eq!(steps.len(), 12, "{steps:?}");
    assert!(steps[11].contains("step 5 (CHARGING) done"), "{steps:?}");
    // The Daly BMS is polled one quantity at a time: the current is at most 2.5 s old.
    v.run(3.0);
    let dock = v.sim.config().mission.and_then(|m| m.dock).expect("a dock");
    let truth = v.sim.vehicle().truth();
    let off = (truth.x - dock[0]).hypot(truth.y - dock[1]);
    assert!(off < 0.05, "{off} m from the dock");
    assert!(v.sim.vehicle().docked());
    assert_eq!(v.status().navigation, Navigation::Succeeded);
    let battery = v.status().battery.expect("a BMS");
    assert!(
        battery.reading.current_a.is_some_and(|a| a > 0.0),
        "charging: {battery:?}"
    );
}

#[test]
fn a_failed_mission_stops_the_blade_and_bad_missions_are_refused() {
    let mut v = Vehicle::located(11);
    let refused = v
        .send("mission", r#"[{"action": "FLY", "parameters": {}}]"#)
        .expect_err("unknown action");
    assert!(refused.contains("FLY"), "{refused}");
    let refused = v.send("mission", "[]").expect_err("no steps");
    assert!(refused.contains("at least one step"), "{refused}");
    // A coverage that starts 50 m away cannot start: the mission fails with the reason, and
    // the blade it opened stops.
    let p = v.status().pose;
    let mission = format!(
        r#"[{{"action": "OPEN_CUTTER", "parameters": {{}}}},
            {{"action": "COVERAGE", "parameters": {{"path": [{}, {}, {}, {}]}}}}]"#,
        p.x + 50.0,
        p.y,
        p.x + 60.0,
        p.y
    );
    v.send("mission", &mission).expect("the mission starts");
    assert!(
        v.run_until_event("mission aborted", 2.0),
        "{:?}",
        v.sink.events
    );
    let end = v
        .sink
        .events
        .iter()
        .find(|e| e.contains("mission aborted"))
        .unwrap();
    assert!(end.contains("task_max_approach_m"), "{end}");
    v.run(0.1);
    assert!(
        !v.sim.vehicle().cutter_on(),
        "the blade stopped with the mission"
    );
    assert_eq!(v.status().navigation, Navigation::Failed);
    // A stop cancels a mission waiting, and nothing runs after it.
    v.send("mission", r#"[{"action": "WAIT", "parameters": {"seconds": 5}}, {"action": "OPEN_CUTTER", "parameters": {}}]"#)
        .expect("the mission starts");
    v.run(1.0);
    v.send("stop", "{}").expect("stopped");
    assert!(
        v.run_until_event("mission cancelled", 1.0),
        "{:?}",
        v.sink.events
    );
    v.run(6.0);
    assert!(
        !v.sim.vehicle().cutter_on(),
        "the cancelled mission's cutter step never ran"
    );
}

#[test]
fn a_mission_of_many_instant_steps_is_bounded_and_spread_over_ticks() {
    use chassisd::control::mission::{MAX_STEPS, MAX_STEPS_PER_TICK};
    let mut v = Vehicle::located(11);
    let wait = r#"{"action": "WAIT", "parameters": {"seconds": 0}}"#;
    let steps = |n: usize| format!("[{}]", vec![wait; n].join(","));
    // 20,000 steps once ran in one tick: 40,001 notifies, most dropped with the end's.
    let refused = v
        .send("mission", &steps(MAX_STEPS + 1))
        .expect_err("over the step limit");
    assert!(
        refused.contains(&format!("at most {MAX_STEPS} steps")),
        "{refused}"
    );
    v.sink.events.clear();
    v.send("mission", &steps(MAX_STEPS))
        .expect("the mission starts");
    // One plant step (1 ms) at a time: no control tick emits more than a few steps' notifies.
    let mut most_in_a_tick = 0;
    for _ in 0..30_000 {
        let before = v.sink.events.len();
        v.sim.step(common::lockstep::FIXED, &mut v.sink);
        most_in_a_tick = most_in_a_tick.max(v.sink.events.len() - before);
        if v.sink.events.iter().any(|e| e == "mission succeeded") {
            break;
        }
    }
    let mission_events: Vec<&String> = v
        .sink
        .events
        .iter()
        .filter(|e| e.starts_with("mission"))
        .collect();
    assert_eq!(mission_events.len(), 2 * MAX_STEPS + 1);
    assert_eq!(
        mission_events.last().map(|e| e.as_str()),
        Some("mission succeeded")
    );
    assert!(
        most_in_a_tick <= 2 * MAX_STEPS_PER_TICK + 1,
        "{most_in_a_tick} events in one tick"
    );
}
