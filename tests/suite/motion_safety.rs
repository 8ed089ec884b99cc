//! The safety rules around closed-loop moves, on the simulated vehicle through the whole
//! path: every stop cause ends the move with its reason, and motion needs the deliberate
//! re-arm afterwards; a move never re-arms by itself.

use crate::common;

use chassisd::control::Outcome;
use chassisd::control::outcome::{AbortReason, CancelReason, LostDuring};
use chassisd::devices::gnss::FixQuality;
use chassisd::sim::lockstep::Lockstep;
use chassisd::sim::plant::{GnssCondition, LEFT_NODE, PlantConfig};
use common::lockstep::{FIXED, START, SimRun as Vehicle};

#[test]
fn a_software_estop_aborts_the_move_and_moves_need_a_re_arm() {
    let mut v = Vehicle::booted(7);
    v.send("set_navi_cmd", r#"{"cmd":"1","distance":300}"#)
        .expect("accepted");
    v.run(1.0);
    assert!(v.speed() > 0.3, "moving");
    v.send("estop", r#"{"engaged":true}"#).expect("engaged");
    v.run(0.05);
    let r = v.result();
    assert_eq!(
        r.outcome,
        Outcome::Aborted(AbortReason::SafetyStop(
            "software emergency stop engaged".into()
        ))
    );
    v.run(2.0);
    assert!(v.speed().abs() < 0.01, "stopped");
    v.send("estop", r#"{"engaged":false}"#).expect("released");
    // Releasing does not re-arm: a move is refused until the deliberate act.
    let refused = v
        .send("set_navi_cmd", r#"{"cmd":"1","distance":10}"#)
        .expect_err("latched");
    assert!(refused.contains("re-arm"), "{refused}");
    v.run(0.5);
    assert!(v.speed().abs() < 0.01, "still stopped");
    v.send("reset", "{}").expect("re-armed");
    v.run(0.1);
    v.send("set_navi_cmd", r#"{"cmd":"1","distance":10}"#)
        .expect("accepted after the re-arm");
    v.run(3.0);
    assert_eq!(v.result().outcome, Outcome::Succeeded);
}

#[test]
fn an_operator_stop_cancels_the_move_and_latches() {
    let mut v = Vehicle::booted(7);
    v.send("set_navi_cmd", r#"{"cmd":"3","distance":720}"#)
        .expect("accepted");
    v.run(1.0);
    v.send("stop", "{}").expect("stopped");
    v.run(0.02);
    assert_eq!(
        v.result().outcome,
        Outcome::Cancelled(CancelReason::StoppedByOperator)
    );
    v.run(1.5);
    assert!(v.sim.vehicle().truth().w.abs() < 0.01, "no longer turning");
    assert!(
        v.send("set_navi_cmd", r#"{"cmd":"3","distance":10}"#)
            .is_err()
    );
    // A zero velocity command is the deliberate act that re-arms.
    v.send("cmd_vel", r#"{"linear":{"x":0}}"#)
        .expect("re-armed");
    v.send("set_navi_cmd", r#"{"cmd":"3","distance":10}"#)
        .expect("accepted");
}

#[test]
fn a_velocity_command_takes_over_from_a_move_in_manual_mode() {
    let mut v = Vehicle::booted(7);
    v.send("set_navi_cmd", r#"{"cmd":"1","distance":300}"#)
        .expect("accepted");
    v.run(0.5);
    v.send("cmd_vel", r#"{"linear":{"x":0.2}}"#)
        .expect("manual velocity taken");
    v.run(0.02);
    assert_eq!(
        v.result().outcome,
        Outcome::Cancelled(CancelReason::VelocityCommand)
    );
    // The operator's command holds until its watchdog (0.5 s).
    v.run(0.4);
    assert!(
        (v.speed() - 0.2).abs() < 0.02,
        "follows the operator: {}",
        v.speed()
    );
}

#[test]
fn a_stop_request_ends_the_move_at_rest_without_latching() {
    let mut v = Vehicle::booted(7);
    v.send("set_navi_cmd", r#"{"cmd":"2","distance":300}"#)
        .expect("accepted");
    v.run(1.0);
    v.send("set_navi_cmd", r#"{"cmd":"5"}"#).expect("stop");
    v.run(0.02);
    assert_eq!(
        v.result().outcome,
        Outcome::Cancelled(CancelReason::StopRequested)
    );
    v.run(1.5);
    assert!(v.speed().abs() < 0.01, "at rest: {}", v.speed());
    // Not latched: the next move needs no re-arm.
    v.send("set_navi_cmd", r#"{"cmd":"1","distance":5}"#)
        .expect("accepted");
    v.run(2.0);
    assert_eq!(v.result().outcome, Outcome::Succeeded);
}

/// A goal is in the map frame: it needs the vehicle located, and ends with the reason when
/// the localisation is lost (here: the receiver loses its fix for good on loose ground, where
/// the wheels slip 2.5 % and the odom frame's uncertainty passes `locate_bound_m` within
/// metres; on the mower's grass it holds for more than the 100 m a goal may be away).
#[test]
fn a_goal_is_aborted_when_the_localisation_is_lost() {
    let mut plant = PlantConfig::builtin().expect("plant");
    plant.slip.sigma = 0.05;
    plant.slip.bias = [0.03, 0.02];
    let mut v = Vehicle::on(Lockstep::new(plant, 7, START).expect("sim"));
    v.run(3.0);
    let goal = r#"{"x":60.0,"y":0.0,"yaw":0.0}"#;
    let mut accepted = v.send("goal", goal);
    for _ in 0..30 {
        if accepted.is_ok() {
            break;
        }
        assert!(
            accepted.as_ref().is_err_and(|e| e.contains("not located")),
            "{accepted:?}"
        );
        v.run(1.0);
        accepted = v.send("goal", goal);
    }
    accepted.expect("accepted once located");
    v.run(3.0);
    assert!(v.speed().abs() > 0.1, "under way");
    let no_fix = GnssCondition {
        quality: None,
        offset: (0.0, 0.0),
    };
    v.run_under(no_fix, 40.0, true);
    let r = v.result();
    assert_eq!(
        r.outcome,
        Outcome::Aborted(AbortReason::LocalisationLost(LostDuring::Goal)),
        "{r}"
    );
    v.run_under(no_fix, 2.0, false);
    assert!(v.speed().abs() < 0.01, "stopped");
    // Without a location a new goal is refused with the reason.
    let refused = v.send("goal", goal).expect_err("not located");
    assert!(refused.contains("not located"), "{refused}");
}

/// Starts a straight path task `length` m ahead of `v` (located) in the map frame; the
/// path's end (map frame).
fn start_straight_task(v: &mut Vehicle, length: f64) -> (f64, f64) {
    let pose = v.status().pose;
    let (s, c) = pose.yaw.sin_cos();
    let end = (pose.x + length * c, pose.y + length * s);
    let request = format!(
        r#"{{"path":[{},{},{},{}],"speed":0.5}}"#,
        pose.x, pose.y, end.0, end.1
    );
    v.send("follow_path", &request).expect("the task starts");
    end
}

fn distance(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

/// PAUSE holds a task where it is under the operator's stop; CONTINUE is the deliberate act
/// that re-arms, and the task goes on from there to its end.
#[test]
fn a_paused_task_holds_and_continue_goes_on_to_its_end() {
    let mut v = Vehicle::located(7);
    let refused = v.send("continue", "{}").expect_err("nothing paused");
    assert!(refused.contains("no task is paused"), "{refused}");
    let end = start_straight_task(&mut v, 6.0);
    v.run(4.0);
    assert!(v.speed() > 0.3, "under way: {}", v.speed());
    v.send("pause", "{}").expect("paused");
    v.run(1.5);
    assert!(v.sink.results.is_empty(), "a pause does not end the task");
    assert!(v.speed().abs() < 0.01, "held at rest: {}", v.speed());
    let held = v.truth_xy();
    // Held: a move is refused under the operator's stop, and the vehicle stays put.
    assert!(
        v.send("set_navi_cmd", r#"{"cmd":"1","distance":10}"#)
            .is_err()
    );
    v.run(3.0);
    assert!(
        distance(held, v.truth_xy()) < 0.005,
        "stayed where it was paused"
    );
    v.send("continue", "{}").expect("goes on");
    v.run_under(FIXED, 30.0, true);
    let r = v.result();
    assert_eq!(r.outcome, Outcome::Succeeded, "{r}");
    v.run(1.0);
    let off = distance(end, v.truth_xy());
    assert!(off < 0.05, "ended {off} m from the path's end");
}

/// Below the configured GNSS quality (RTK fixed) a task waits at rest, and goes on when the
/// quality is back; the time waited does not count against its allowance.
#[test]
fn a_task_waits_at_rest_for_rtk_fixed_and_goes_on() {
    let mut v = Vehicle::located(7);
    let end = start_straight_task(&mut v, 6.0);
    v.run(4.0);
    assert!(v.speed() > 0.3, "under way");
    let float = GnssCondition {
        quality: Some(FixQuality::RtkFloat),
        offset: (0.0, 0.0),
    };
    v.run_under(float, 15.0, true);
    assert!(v.sink.results.is_empty(), "waiting, not ended");
    assert!(v.speed().abs() < 0.01, "waits at rest: {}", v.speed());
    v.run_under(FIXED, 30.0, true);
    let r = v.result();
    assert_eq!(r.outcome, Outcome::Succeeded, "{r}");
    v.run(1.0);
    assert!(distance(end, v.truth_xy()) < 0.05);
}

/// A task in the map frame ends with the reason when the localisation is lost.
#[test]
fn a_task_is_aborted_when_the_localisation_is_lost() {
    let mut v = Vehicle::located(7);
    start_straight_task(&mut v, 60.0);
    v.run(3.0);
    let no_fix = GnssCondition {
        quality: None,
        offset: (0.0, 0.0),
    };
    v.run_under(no_fix, 200.0, true);
    let r = v.result();
    assert!(
        matches!(&r.outcome, Outcome::Aborted(why) if matches!(why.root(), AbortReason::LocalisationLost(_) | AbortReason::GnssBelow { .. })),
        "{r}"
    );
    v.run_under(no_fix, 2.0, false);
    assert!(v.speed().abs() < 0.01, "stopped");
}

/// The root heartbeat is the control link: when it falls silent the move under way ends with
/// that cause, the vehicle stops, and moves stay refused until the deliberate re-arm; the
/// heartbeat coming back does not re-arm by itself. A mode switch cancels a move too.
#[test]
fn a_lost_control_link_aborts_the_move_and_needs_a_re_arm() {
    use chassisd::api::mqtt::MQTT_SOURCE;
    use chassisd::api::trajectory::MemoryStore;
    use chassisd::config::mqtt::{MqttConfig, RootDialectConfig};
    use chassisd::record::Payload;

    let mqtt = MqttConfig {
        root: Some(RootDialectConfig {
            vehicle_id: "sim".into(),
            heartbeat_timeout_s: 1.0,
            require_heartbeat: false,
            heartbeat_client_id: None,
        }),
        ..MqttConfig::default()
    };
    let plant = PlantConfig::builtin().expect("plant");
    let mut v = Vehicle::on(
        Lockstep::with_mqtt(
            plant,
            7,
            START,
            Some(mqtt),
            Box::new(MemoryStore::default()),
        )
        .expect("sim"),
    );
    let beat = |v: &mut Vehicle| {
        v.sim.input(
            MQTT_SOURCE,
            Payload::Command {
                topic: "/root/sim/heartbeat/set".into(),
                payload: br#"{"timestamp": "2026-01-01 00:00:00"}"#.to_vec().into(),
            },
            &mut v.sink,
        );
    };
    for _ in 0..30 {
        beat(&mut v);
        v.run(0.1);
    }
    v.send("set_navi_cmd", r#"{"cmd":"1","distance":500}"#)
        .expect("accepted");
    for _ in 0..10 {
        beat(&mut v);
        v.run(0.1);
    }
    assert!(v.speed() > 0.3, "under way");
    // Silence: the link is lost after 1 s.
    v.run_under(FIXED, 1.5, true);
    let r = v.result();
    assert_eq!(
        r.outcome,
        Outcome::Aborted(AbortReason::SafetyStop(
            "control link heartbeat lost".into()
        )),
        "{r}"
    );
    v.run(2.0);
    assert!(v.speed().abs() < 0.01, "stopped");
    for _ in 0..5 {
        beat(&mut v);
        v.run(0.1);
    }
    let refused = v
        .send("set_navi_cmd", r#"{"cmd":"1","distance":10}"#)
        .expect_err("still latched");
    assert!(refused.contains("re-arm"), "{refused}");
    v.send("reset", "{}").expect("re-armed");
    beat(&mut v);
    v.sink.results.clear();
    v.send("set_navi_cmd", r#"{"cmd":"1","distance":100}"#)
        .expect("accepted after the re-arm");
    beat(&mut v);
    v.run(0.3);
    // SWITCH_MODE to navigation: the switch ends the move under way.
    v.sim.input(
        MQTT_SOURCE,
        Payload::Command {
            topic: "/root/sim/cmd/navigation/set".into(),
            payload: br#"{"messageId": 1, "timestamp": "2026-01-01 00:00:00", "messageType": 6, "data": 0}"#
                .to_vec()
                .into(),
        },
        &mut v.sink,
    );
    v.run(0.05);
    assert_eq!(
        v.result().outcome,
        Outcome::Cancelled(CancelReason::ModeSwitched)
    );
}

/// A drive fault (an overcurrent on the left wheel's drive) during a move or a task: the
/// motion is aborted with the drive's fault as its reason, the vehicle stops, and motion is
/// refused until the deliberate reset clears the fault and re-arms.
#[test]
fn a_drive_fault_aborts_a_move_or_a_task_and_needs_a_reset() {
    let mut v = Vehicle::located(8);
    let overcurrent = 0x2310;
    for start in ["move", "task"] {
        v.sink.results.clear();
        match start {
            "move" => {
                v.send("set_navi_cmd", r#"{"cmd":"1","distance":400}"#)
                    .expect("the move starts");
            }
            _ => {
                start_straight_task(&mut v, 6.0);
            }
        }
        v.run(2.5);
        assert!(v.speed() > 0.3, "{start}: under way at {}", v.speed());
        v.sim
            .inject_drive_fault(LEFT_NODE, overcurrent, &mut v.sink);
        v.run_under(FIXED, 0.5, true);
        let r = v.result();
        assert!(
            matches!(&r.outcome, Outcome::Aborted(AbortReason::SafetyStop(cause)) if cause.starts_with("left: EMCY 0x2310")),
            "{start}: {r}"
        );
        v.run(2.0);
        assert!(v.speed().abs() < 0.01, "{start}: stopped at {}", v.speed());
        let refused = v
            .send("set_navi_cmd", r#"{"cmd":"1","distance":10}"#)
            .expect_err("latched by the fault");
        assert!(
            refused.contains("fault") || refused.contains("re-arm"),
            "{start}: {refused}"
        );
        let at_rest = v.truth_xy();
        v.run(1.0);
        assert!(
            distance(at_rest, v.truth_xy()) < 0.002,
            "{start}: stays put"
        );
        v.send("reset", "{}")
            .expect("the reset clears the fault and re-arms");
        v.run(1.5);
        v.send("set_navi_cmd", r#"{"cmd":"1","distance":10}"#)
            .unwrap_or_else(|e| panic!("{start}: accepted after the reset: {e}"));
        v.run_under(FIXED, 10.0, true);
        let r = v.result();
        assert_eq!(r.outcome, Outcome::Succeeded, "{start}: {r}");
    }
}
