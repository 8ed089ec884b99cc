//! The local frame commands through the whole path, on the simulated vehicle: re-zeroing
//! at the vehicle (init_rtk_data), setting the pose (INIT_POSITION) and moving the datum
//! (SET_LNG_LAT), with the simulator's truth as the reference.

use chassisd::devices::gnss::FixQuality;
use chassisd::engine::EngineOutput;
use chassisd::fusion::planar::wrap;
use chassisd::geodesy::Enu;
use chassisd::record::Record;
use chassisd::sim::lockstep::{Lockstep, Sink};
use chassisd::sim::plant::{GnssCondition, PlantConfig, Truth};
use chassisd::time::Timestamp;
use chassisd::vehicle::VehicleStatus;
use nalgebra::Vector3;

#[derive(Default)]
struct Collect {
    statuses: Vec<VehicleStatus>,
    results: Vec<Result<(), String>>,
}

impl Sink for Collect {
    fn record(&mut self, _: &Record) {}
    fn output(&mut self, output: EngineOutput) {
        match output {
            EngineOutput::Status(s) => self.statuses.push(*s),
            EngineOutput::CommandResult { result, .. } => self.results.push(result),
            _ => {}
        }
    }
}

const FIXED: GnssCondition = GnssCondition {
    quality: Some(FixQuality::RtkFixed),
    offset: (0.0, 0.0),
};

struct Drive {
    sim: Lockstep,
    out: Collect,
}

impl Drive {
    fn new() -> Drive {
        let plant = PlantConfig::builtin().expect("built-in plant");
        let start = Timestamp::from_micros(1_767_225_600_000_000);
        Drive {
            sim: Lockstep::new(plant, 7, start).expect("simulated vehicle"),
            out: Collect::default(),
        }
    }

    /// Drives at (v, w) for `seconds`, a command every 100 ms.
    fn run(&mut self, seconds: f64, v: f64, w: f64) {
        let twist = format!(r#"{{"linear":{{"x":{v}}},"angular":{{"z":{w}}}}}"#);
        for k in 0..(seconds * 1000.0).round() as u64 {
            if k % 100 == 0 {
                self.sim.command("cmd_vel", &twist, &mut self.out);
            }
            self.sim.step(FIXED, &mut self.out);
        }
    }

    fn command(&mut self, topic: &str, payload: &str) -> Result<(), String> {
        self.sim.command(topic, payload, &mut self.out);
        self.out.results.pop().expect("an answer")
    }

    /// The next status after now, and the truth at its time.
    fn status(&mut self) -> (VehicleStatus, Truth) {
        self.out.statuses.clear();
        while self.out.statuses.is_empty() {
            self.sim.step(FIXED, &mut self.out);
        }
        (self.out.statuses[0].clone(), self.sim.vehicle().truth())
    }
}

fn warmed_up() -> Drive {
    let mut d = Drive::new();
    d.run(2.0, 0.0, 0.0);
    d.run(12.0, 0.8, 0.1);
    d
}

/// Where the truth `now` reads in a frame that placed the truth `then` at `pose`.
fn in_frame(then: Truth, pose: (f64, f64, f64), now: Truth) -> (f64, f64, f64) {
    let rotation = wrap(pose.2 - then.yaw);
    let (s, c) = rotation.sin_cos();
    let (dx, dy) = (now.x - then.x, now.y - then.y);
    (
        pose.0 + c * dx - s * dy,
        pose.1 + s * dx + c * dy,
        wrap(now.yaw + rotation),
    )
}

fn assert_pose(status: &VehicleStatus, expected: (f64, f64, f64), tolerance_m: f64) {
    let p = status.pose;
    assert!(
        (p.x - expected.0).hypot(p.y - expected.1) < tolerance_m
            && wrap(p.yaw - expected.2).abs() < 0.01,
        "pose {p:?}, expected {expected:?}"
    );
}

#[test]
fn init_rtk_data_zeroes_the_frame_at_the_vehicle() {
    let mut d = warmed_up();
    let (before, _) = d.status();
    assert!(
        before.pose.x.hypot(before.pose.y) > 5.0,
        "{:?}",
        before.pose
    );
    let at_command = d.sim.vehicle().truth();
    assert_eq!(d.command("init_rtk_data", "{}"), Ok(()));
    let zero = (0.0, 0.0, at_command.yaw);
    let (zeroed, now) = d.status();
    assert_pose(&zeroed, in_frame(at_command, zero, now), 0.05);
    // Driving on, the pose is the travel since the zero, in ENU axes.
    d.run(10.0, 1.0, 0.0);
    let (after, now) = d.status();
    assert_pose(&after, in_frame(at_command, zero, now), 0.05);
}

#[test]
fn init_position_sets_the_pose_and_gnss_keeps_it() {
    let mut d = warmed_up();
    let at_command = d.sim.vehicle().truth();
    assert_eq!(
        d.command("init_position", r#"{"x":10.0,"y":-5.0,"yaw":1.0}"#),
        Ok(())
    );
    let pose = (10.0, -5.0, 1.0);
    let (set, now) = d.status();
    assert_pose(&set, in_frame(at_command, pose, now), 0.05);
    // On for 10 s: the pose moves in the new frame, and RTK fixes keep confirming it rather
    // than pulling it back.
    d.run(10.0, 1.0, 0.05);
    let (after, now) = d.status();
    assert_pose(&after, in_frame(at_command, pose, now), 0.1);
    assert_eq!(after.localization, chassisd::vehicle::Localization::Good);
    assert_eq!(
        d.command("init_position", r#"{"x":1.0,"y":"north","yaw":0}"#)
            .map_err(|e| e.contains("init_position")),
        Err(true)
    );
}

#[test]
fn set_lng_lat_moves_the_datum() {
    let mut d = warmed_up();
    let plant = PlantConfig::builtin().expect("built-in plant");
    // A datum 100 m north and 20 m west of the plant's.
    let datum = Enu::new(plant.datum()).to_geodetic(&Vector3::new(-20.0, 100.0, 0.0));
    let payload = format!("[{}, {}, {}]", datum.lon_deg, datum.lat_deg, datum.h_m);
    assert_eq!(d.command("set_lng_lat", &payload), Ok(()));
    let (moved, truth) = d.status();
    assert_pose(&moved, (truth.x + 20.0, truth.y - 100.0, truth.yaw), 0.05);
    assert!(d.command("set_lng_lat", "[8.5, 123.0, 0]").is_err());
}
