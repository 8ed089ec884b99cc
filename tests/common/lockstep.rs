//! The simulated vehicle stepped in lockstep with the engine, driven through the local
//! command channel, with what it outputs collected: the harness of the motion tests.

use chassisd::control::MotionResult;
use chassisd::devices::gnss::FixQuality;
use chassisd::engine::EngineOutput;
use chassisd::record::Record;
use chassisd::sim::lockstep::{Lockstep, PLANT_STEP, Sink};
use chassisd::sim::plant::{GnssCondition, PlantConfig};
use chassisd::time::Timestamp;
use chassisd::vehicle::{Localization, VehicleStatus};

/// RTK fixed, no offset.
pub const FIXED: GnssCondition = GnssCondition {
    quality: Some(FixQuality::RtkFixed),
    offset: (0.0, 0.0),
};

/// Sessions start here (2026-01-01T00:00:00Z).
pub const START: Timestamp = Timestamp::from_micros(1_767_225_600_000_000);

/// What the engine put out.
#[derive(Default)]
pub struct Collector {
    /// Motions that ended.
    pub results: Vec<MotionResult>,
    /// Command answers.
    pub answers: Vec<Result<(), String>>,
    /// Log events.
    pub events: Vec<String>,
    /// The last status.
    pub status: Option<Box<VehicleStatus>>,
}

impl Sink for Collector {
    fn record(&mut self, _: &Record) {}

    fn output(&mut self, output: EngineOutput) {
        match output {
            EngineOutput::MotionEnded(r) => self.results.push(r),
            EngineOutput::CommandResult { result, .. } => self.answers.push(result),
            EngineOutput::Event(e) => self.events.push(e.to_string()),
            EngineOutput::Status(s) => self.status = Some(s),
            _ => {}
        }
    }
}

/// The simulated vehicle and what it put out.
pub struct SimRun {
    /// The simulation.
    pub sim: Lockstep,
    /// Its outputs.
    pub sink: Collector,
}

impl SimRun {
    /// The built-in mower with noise `seed`, booted (3 s standing).
    pub fn booted(seed: u64) -> Self {
        let plant = PlantConfig::builtin().expect("plant");
        let mut v = Self::on(Lockstep::new(plant, seed, START).expect("sim"));
        v.run(3.0);
        v
    }

    /// [`SimRun::booted`], then standing until the fusion says it is located.
    pub fn located(seed: u64) -> Self {
        let mut v = Self::booted(seed);
        for _ in 0..30 {
            if v.status().localization == Localization::Good {
                return v;
            }
            v.run(1.0);
        }
        panic!("never located");
    }

    /// A harness on `sim`, as it is.
    pub fn on(sim: Lockstep) -> Self {
        Self {
            sim,
            sink: Collector::default(),
        }
    }

    /// Steps `seconds` with RTK fixed.
    pub fn run(&mut self, seconds: f64) {
        self.run_under(FIXED, seconds, false);
    }

    /// Steps under `gnss` for `seconds`, or until a motion ends when `until_result`.
    pub fn run_under(&mut self, gnss: GnssCondition, seconds: f64, until_result: bool) {
        for _ in 0..(seconds / PLANT_STEP.as_secs_f64()).round() as u64 {
            self.sim.step(gnss, &mut self.sink);
            if until_result && !self.sink.results.is_empty() {
                break;
            }
        }
    }

    /// Steps until an event containing `text` (at most `seconds`); whether it came.
    pub fn run_until_event(&mut self, text: &str, seconds: f64) -> bool {
        for _ in 0..(seconds / PLANT_STEP.as_secs_f64()).round() as u64 {
            self.sim.step(FIXED, &mut self.sink);
            if self.sink.events.iter().any(|e| e.contains(text)) {
                return true;
            }
        }
        false
    }

    /// Sends a local command; its answer.
    pub fn send(&mut self, topic: &str, payload: &str) -> Result<(), String> {
        self.sink.answers.clear();
        self.sim.command(topic, payload, &mut self.sink);
        self.sink.answers.pop().expect("an answer")
    }

    /// The last motion's result.
    pub fn result(&mut self) -> MotionResult {
        self.sink.results.pop().expect("the move ended")
    }

    /// True forward speed, m/s.
    pub fn speed(&self) -> f64 {
        self.sim.vehicle().truth().v
    }

    /// True position, m.
    pub fn truth_xy(&self) -> (f64, f64) {
        let t = self.sim.vehicle().truth();
        (t.x, t.y)
    }

    /// The last status.
    pub fn status(&self) -> &VehicleStatus {
        self.sink.status.as_deref().expect("a status")
    }
}
