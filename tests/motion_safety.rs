//! The safety rules around closed-loop moves, on the simulated vehicle through the whole
//! path: every stop cause ends the move with its reason, and motion needs the deliberate
//! re-arm afterwards; a move never re-arms by itself.

use chassisd::control::{MotionResult, Outcome};
use chassisd::devices::gnss::FixQuality;
use chassisd::engine::EngineOutput;
use chassisd::record::Record;
use chassisd::sim::lockstep::{Lockstep, PLANT_STEP, Sink};
use chassisd::sim::plant::{GnssCondition, PlantConfig};
use chassisd::time::Timestamp;

#[derive(Default)]
struct Collector {
    results: Vec<MotionResult>,
    answers: Vec<(String, Result<(), String>)>,
}

impl Sink for Collector {
    fn record(&mut self, _: &Record) {}

    fn output(&mut self, output: EngineOutput) {
        match output {
            EngineOutput::MotionEnded(r) => self.results.push(r),
            EngineOutput::CommandResult { topic, result, .. } => self.answers.push((topic, result)),
            _ => {}
        }
    }
}

const FIXED: GnssCondition = GnssCondition {
    quality: Some(FixQuality::RtkFixed),
    offset: (0.0, 0.0),
};

struct Vehicle {
    sim: Lockstep,
    sink: Collector,
}

impl Vehicle {
    /// The simulated mower, booted and standing still.
    fn new() -> Self {
        let plant = PlantConfig::builtin().expect("plant");
        let mut v = Self {
            sim: Lockstep::new(plant, 7, Timestamp::from_micros(1_767_225_600_000_000))
                .expect("sim"),
            sink: Collector::default(),
        };
        v.run(3.0);
        v
    }

    fn run(&mut self, seconds: f64) {
        self.run_under(FIXED, seconds, false);
    }

    /// Steps under `gnss` for `seconds`, or until a motion ends when `until_result`.
    fn run_under(&mut self, gnss: GnssCondition, seconds: f64, until_result: bool) {
        for _ in 0..(seconds / PLANT_STEP.as_secs_f64()).round() as u64 {
            self.sim.step(gnss, &mut self.sink);
            if until_result && !self.sink.results.is_empty() {
                break;
            }
        }
    }

    /// Sends a command; its answer.
    fn send(&mut self, topic: &str, payload: &str) -> Result<(), String> {
        self.sink.answers.clear();
        self.sim.command(topic, payload, &mut self.sink);
        self.sink.answers.pop().map(|(_, r)| r).expect("an answer")
    }

    fn result(&mut self) -> MotionResult {
        self.sink.results.pop().expect("the move ended")
    }

    fn speed(&self) -> f64 {
        self.sim.vehicle().truth().v
    }
}

#[test]
fn a_software_estop_aborts_the_move_and_moves_need_a_re_arm() {
    let mut v = Vehicle::new();
    v.send("set_navi_cmd", r#"{"cmd":"1","distance":300}"#)
        .expect("accepted");
    v.run(1.0);
    assert!(v.speed() > 0.3, "moving");
    v.send("estop", r#"{"engaged":true}"#).expect("engaged");
    v.run(0.05);
    let r = v.result();
    assert_eq!(
        r.outcome,
        Outcome::Aborted("safety stop: software emergency stop engaged".into())
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
    let mut v = Vehicle::new();
    v.send("set_navi_cmd", r#"{"cmd":"3","distance":720}"#)
        .expect("accepted");
    v.run(1.0);
    v.send("stop", "{}").expect("stopped");
    v.run(0.02);
    assert_eq!(
        v.result().outcome,
        Outcome::Cancelled("stopped by the operator".into())
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
    let mut v = Vehicle::new();
    v.send("set_navi_cmd", r#"{"cmd":"1","distance":300}"#)
        .expect("accepted");
    v.run(0.5);
    v.send("cmd_vel", r#"{"linear":{"x":0.2}}"#)
        .expect("manual velocity taken");
    v.run(0.02);
    assert_eq!(
        v.result().outcome,
        Outcome::Cancelled("a velocity command took over".into())
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
    let mut v = Vehicle::new();
    v.send("set_navi_cmd", r#"{"cmd":"2","distance":300}"#)
        .expect("accepted");
    v.run(1.0);
    v.send("set_navi_cmd", r#"{"cmd":"5"}"#).expect("stop");
    v.run(0.02);
    assert_eq!(
        v.result().outcome,
        Outcome::Cancelled("stop requested".into())
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
/// the localisation is lost (here: the receiver loses its fix for good).
#[test]
fn a_goal_is_aborted_when_the_localisation_is_lost() {
    let mut v = Vehicle::new();
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
    v.run_under(no_fix, 60.0, true);
    let r = v.result();
    assert_eq!(
        r.outcome,
        Outcome::Aborted("localisation lost during the goal".into()),
        "{r}"
    );
    v.run_under(no_fix, 2.0, false);
    assert!(v.speed().abs() < 0.01, "stopped");
    // Without a location a new goal is refused with the reason.
    let refused = v.send("goal", goal).expect_err("not located");
    assert!(refused.contains("not located"), "{refused}");
}
