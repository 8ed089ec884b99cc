//! `chassisd sim --fast`: the simulated vehicle and the engine in lockstep as fast as the
//! machine allows, with no wall clock and no MQTT. base_status lines go to the output per
//! 100 ms of simulated time, and a recording of the run replays to the same lines.

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use crate::runtime::error::{RuntimeError, invalid, io};

use crate::api::rtk::BaseStatus;
use crate::engine::EngineOutput;
use crate::record::{Record, RecordError, RecordingWriter};
use crate::runtime::clock::RecordClock;
use crate::sim::lockstep::{self, Lockstep, Sink};
use crate::sim::plant::PlantConfig;
use crate::sim::scenario::Scenario;

/// Options of `chassisd sim --fast`.
#[derive(Debug, Clone)]
pub struct FastOptions {
    /// The vehicle.
    pub plant: PlantConfig,
    /// Noise seed.
    pub seed: u64,
    /// Drive this scenario to its end.
    pub scenario: Option<Scenario>,
    /// Stop after this much simulated time (wins over the scenario's length).
    pub duration: Option<Duration>,
    /// Record the run into this new folder.
    pub record: Option<PathBuf>,
}

/// What a fast run did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FastSummary {
    /// Simulated time, s.
    pub simulated_s: f64,
    /// Wall time, s.
    pub wall_s: f64,
    /// Status lines written.
    pub lines: u64,
}

impl FastSummary {
    /// The closing line.
    pub fn line(&self) -> String {
        format!(
            "chassisd sim --fast: {:.1} s simulated in {:.2} s ({:.0}x real time), {} status lines",
            self.simulated_s,
            self.wall_s,
            self.simulated_s / self.wall_s.max(1e-9),
            self.lines
        )
    }
}

/// Status lines to `out`, records to the recording.
struct FastSink<W: Write> {
    out: W,
    recording: Option<RecordingWriter>,
    lines: u64,
    error: Option<RuntimeError>,
}

impl<W: Write> Sink for FastSink<W> {
    fn record(&mut self, record: &Record) {
        if let Some(w) = self.recording.as_mut()
            && let Err(e) = w.write(record)
        {
            self.fail(invalid("cannot write the recording")(e));
        }
    }

    fn output(&mut self, output: EngineOutput) {
        if let EngineOutput::Status(status) = output {
            let mut line = BaseStatus::from_status(&status).to_json();
            line.push('\n');
            if let Err(e) = self.out.write_all(line.as_bytes()) {
                self.fail(io("cannot write status output")(e));
            }
            self.lines += 1;
        }
    }
}

impl<W: Write> FastSink<W> {
    fn fail(&mut self, e: RuntimeError) {
        self.error.get_or_insert(e);
        // Nothing more is written once one write failed.
        self.recording = None;
    }
}

/// Runs the simulation to the end of the scenario or the duration.
pub fn run(options: FastOptions, out: impl Write) -> Result<FastSummary, RuntimeError> {
    if options.scenario.is_none() && options.duration.is_none() {
        return Err(RuntimeError::Failed(
            "sim --fast runs to an end: give --scenario NAME or --duration SECONDS".into(),
        ));
    }
    let started = Instant::now();
    let start = RecordClock::start().now();
    let mut sim = Lockstep::new(options.plant.clone(), options.seed, start)?;
    let recording = match &options.record {
        Some(dir) => Some(
            RecordingWriter::create(
                dir,
                &sim.config().vehicle.name,
                start,
                Some(&sim.config().to_effective_toml()),
                lockstep::sources(&options.plant),
            )
            .map_err(invalid(format!(
                "cannot start recording in {}",
                dir.display()
            )))?,
        ),
        None => None,
    };
    let mut sink = FastSink {
        out: std::io::BufWriter::with_capacity(1 << 16, out),
        recording,
        lines: 0,
        error: None,
    };
    let length =
        crate::runtime::modes::sim::run_length(options.duration, options.scenario.as_ref());
    let end = start.saturating_add(length.unwrap_or_default());
    while sim.time() < end && sink.error.is_none() {
        match &options.scenario {
            Some(s) => sim.step_scripted(s, &mut sink),
            None => sim.step(crate::runtime::modes::sim::RTK_FIXED, &mut sink),
        }
    }
    if let Some(e) = sink.error.take() {
        return Err(e);
    }
    sink.out.flush().map_err(io("cannot write status output"))?;
    if let Some(w) = sink.recording.take() {
        w.finish(sim.time())
            .map_err(|e: RecordError| invalid("cannot finish the recording")(e))?;
    }
    Ok(FastSummary {
        simulated_s: sim.time().saturating_since(start).as_secs_f64(),
        wall_s: started.elapsed().as_secs_f64(),
        lines: sink.lines,
    })
}
