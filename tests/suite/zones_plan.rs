//! Plan-time zone checks through the whole engine on the simulated mower: a goal, a move, a
//! path and a mission whose way (the footprint's disc and the margin, or the braking way at
//! the motion's speed when that is more, swept along it) meets a keep-out zone, a wall or
//! the boundary is refused before it starts, naming the zone and the place; a way clear of
//! them all starts.

use crate::common;

use common::lockstep::SimRun;
use common::zones::{mower, mower_in_the_yard};

/// The x of "at (x, y) m" in a refusal.
fn place_x(refusal: &str) -> f64 {
    let at = refusal.split(" at (").nth(1).expect("a place");
    at.split(',')
        .next()
        .and_then(|x| x.parse().ok())
        .expect("x")
}

#[test]
fn a_way_into_a_zone_is_refused_naming_it_and_a_clear_one_starts() {
    let mut v = mower_in_the_yard("zones-plan", |_| {});
    let radius = 0.45f64.hypot(0.275) + 0.1;

    // Slowly straight through the pond (σ and the braking way within the margin): met one
    // disc's radius before its west edge.
    let refused = v
        .send("follow_path", r#"{"path": [0, 0, 10, 0], "speed": 0.2}"#)
        .unwrap_err();
    assert!(refused.contains("keep_out zone \"pond\""), "{refused}");
    let x = place_x(&refused);
    assert!((x - (4.0 - radius)).abs() < 0.03, "{refused}");
    // A goal cruises faster: the braking way at its speed is kept too, so it is met sooner.
    let refused = v
        .send("goal", r#"{"x": 10, "y": 0, "yaw": 0}"#)
        .unwrap_err();
    assert!(refused.contains("keep_out zone \"pond\""), "{refused}");
    assert!(place_x(&refused) < x - 0.05, "{refused}");
    let mission = r#"[{"action": "COVERAGE", "parameters": {"path": [1, 2, 1, 0, 8, 0]}}]"#;
    // Each kind of motion: into the pond ahead, backwards into the fence, north past the
    // tree, south off the lawn.
    for (topic, request, zone) in [
        (
            "set_navi_cmd",
            r#"{"cmd": "1", "distance": 500}"#,
            "keep_out zone \"pond\"",
        ),
        (
            "follow_path",
            r#"{"path": [2, 0, 8, 0], "speed": 0.5}"#,
            "keep_out zone \"pond\"",
        ),
        ("mission", mission, "keep_out zone \"pond\""),
        (
            "set_navi_cmd",
            r#"{"cmd": "2", "distance": 400}"#,
            "wall zone \"fence\"",
        ),
        (
            "follow_path",
            r#"{"path": [1, 3, 1, 8], "speed": 0.5}"#,
            "keep_out zone \"tree\"",
        ),
        (
            "goal",
            r#"{"x": 0, "y": -12, "yaw": 0}"#,
            "boundary zone \"lawn\"",
        ),
    ] {
        let refused = v.send(topic, request).unwrap_err();
        assert!(refused.contains(zone), "{topic} {request}: {refused}");
    }

    // Clear ways start and end where they should: a turn on the spot and back, then a goal
    // 2 m ahead, short of the pond.
    for (topic, request) in [
        ("set_navi_cmd", r#"{"cmd": "3", "distance": 90}"#),
        ("set_navi_cmd", r#"{"cmd": "4", "distance": 90}"#),
        ("goal", r#"{"x": 2, "y": 0, "yaw": 0}"#),
    ] {
        v.send(topic, request).expect("a clear way starts");
        v.run_under(common::lockstep::FIXED, 30.0, true);
        let result = v.result();
        assert!(
            matches!(result.outcome, chassisd::control::Outcome::Succeeded),
            "{request}: {result:?}"
        );
    }
    let (x, _) = v.truth_xy();
    assert!(
        (x - 2.0).abs() < 0.2 && x < 4.0 - 0.45,
        "at the goal, short of the pond: {x}"
    );
}

#[test]
fn with_zones_a_vehicle_not_yet_located_does_not_move_by_itself() {
    let mut v = mower("zones-unplaced", |_| {});
    v.run_under(
        chassisd::sim::plant::GnssCondition {
            quality: None,
            offset: (0.0, 0.0),
        },
        3.0,
        false,
    );
    let refused = v
        .send("set_navi_cmd", r#"{"cmd": "1", "distance": 50}"#)
        .unwrap_err();
    assert!(refused.contains("not located on them"), "{refused}");
}

/// A `/set_shape` request as the ROS1 node records it.
fn set_shape(v: &mut SimRun, id: u64, msg: &str) -> Result<(), String> {
    v.sink.answers.clear();
    let payload = chassisd::record::Payload::Command {
        topic: "/set_shape".into(),
        payload: bytes::Bytes::from(format!(r#"{{"id": {id}, "msg": {msg}}}"#)),
    };
    v.sim.input("ros1", payload, &mut v.sink);
    v.sink.answers.pop().expect("an answer")
}

/// The zones the status draws (what `/zones` publishes) at the next status tick.
fn drawn_next_tick(v: &mut SimRun) -> std::sync::Arc<[chassisd::zones::local::ZoneOutline]> {
    v.run(0.2);
    v.status()
        .envelope
        .clone()
        .and_then(|e| e.zones)
        .expect("placed")
}

#[test]
fn a_wall_added_at_run_time_refuses_a_way_through_it_until_it_is_removed() {
    let mut v = mower_in_the_yard("zones-edit", |_| {});
    let ahead = r#"{"path": [0, 0, 3, 0], "speed": 0.3}"#;
    let wall = r#"{"type": "lines", "shapeId": 0, "points": [{"x": 2, "y": -2, "z": 0},
        {"x": 2, "y": 2, "z": 0}], "radius": 0, "closed": false}"#;
    set_shape(&mut v, 1, wall).expect("the wall is added");
    assert!(
        v.sink
            .events
            .iter()
            .any(|e| e == "zones: wall zone \"virtual wall\" added (id 5)"),
        "{:?}",
        v.sink.events
    );
    // The status draws it from the next tick (what /zones publishes), where it was put.
    let drawn = drawn_next_tick(&mut v);
    let added = drawn.iter().find(|z| z.id == 5).expect("the wall drawn");
    let xs: Vec<f64> = added.lines[0].iter().map(|p| p.0).collect();
    assert!(xs.iter().all(|x| (x - 2.0).abs() < 1e-3), "{added:?}");
    let refused = v.send("follow_path", ahead).unwrap_err();
    assert!(refused.contains("wall zone \"virtual wall\""), "{refused}");
    let x = place_x(&refused);
    assert!(
        (x - (2.0 - 0.45f64.hypot(0.275) - 0.1)).abs() < 0.03,
        "{refused}"
    );
    // An id nobody has is refused, and changes nothing.
    let none = r#"{"type": "", "shapeId": 99, "points": [], "radius": 0, "closed": false}"#;
    assert!(
        set_shape(&mut v, 2, none)
            .unwrap_err()
            .contains("no zone has id 99")
    );
    let remove = r#"{"type": "", "shapeId": 5, "points": [], "radius": 0, "closed": false}"#;
    set_shape(&mut v, 3, remove).expect("removed");
    let drawn = drawn_next_tick(&mut v);
    assert!(drawn.iter().all(|z| z.id != 5), "no longer drawn");
    v.send("follow_path", ahead).expect("clear again");
}
