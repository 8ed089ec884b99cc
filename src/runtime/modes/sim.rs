//! `chassisd sim`: the simulated vehicle in real time through the live engine. The plant and
//! the engine run in lockstep (see [`crate::sim::lockstep`]), paced by the wall clock;
//! base_status lines go to standard output at 10 Hz, and the session can be recorded, so a
//! simulated drive becomes a replay fixture.

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use crate::runtime::error::io;
use tokio::sync::{mpsc, watch};

use crate::api::rtk::BaseStatus;
use crate::api::trajectory::MemoryStore;
use crate::config::mqtt::{DialectName, MqttConfig};
use crate::devices::gnss::FixQuality;
use crate::engine::{EngineOutput, EngineStats};
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::heap;
use crate::runtime::modes::live::read_commands;
use crate::runtime::recorder::Recorder;
use crate::runtime::session::{self, Links};
use crate::runtime::status_out::StatusOut;
use crate::runtime::trajectory_writer;
use crate::sim::lockstep::{self, Lockstep, PLANT_STEP, Sections, Sink};
use crate::sim::plant::{GnssCondition, PlantConfig, Truth};
use crate::sim::scenario::Scenario;
use crate::time::Timestamp;
use crate::vehicle::chassis::CONTROL_PERIOD;

/// How often the simulation catches up with the wall clock: every control tick.
const PACE: Duration = CONTROL_PERIOD;
/// How long after each control tick's time the simulation catches up: the plant's step
/// that ends at the tick, and a little for the timer.
const PACE_AFTER_TICK: Duration = Duration::from_micros(1500);
/// Without a scenario, the receiver keeps an RTK-fixed solution.
pub(crate) const RTK_FIXED: GnssCondition = GnssCondition {
    quality: Some(FixQuality::RtkFixed),
    offset: (0.0, 0.0),
};
/// A GNSS outage: the receiver sends nothing.
const NO_GNSS: GnssCondition = GnssCondition {
    quality: None,
    offset: (0.0, 0.0),
};
/// Commands waiting for the simulation.
const COMMAND_QUEUE: usize = 256;

/// Options of `chassisd sim`.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// The vehicle.
    pub plant: PlantConfig,
    /// Noise seed.
    pub seed: u64,
    /// Record the session into this new folder.
    pub record: Option<PathBuf>,
    /// Read `TOPIC JSON` commands from standard input.
    pub commands_stdin: bool,
    /// Drive this scripted scenario (commands and GNSS conditions) and stop at its end.
    pub scenario: Option<Scenario>,
    /// Stop after this much simulated time.
    pub duration: Option<Duration>,
    /// Speak the MQTT dialects of this configuration (its broker embedded or not).
    pub mqtt: Option<MqttConfig>,
    /// Join a ROS1 graph as a node.
    pub ros1: Option<crate::config::ros1::Ros1Config>,
    /// Join a ROS 2 domain as a node.
    pub ros2: Option<crate::config::ros2::Ros2Config>,
    /// Serve the rosbridge WebSocket topics.
    pub websocket: Option<crate::config::websocket::WebsocketConfig>,
    /// A benchmark's hold on the run: faults to inject, truth to read back.
    pub handle: Option<SimHandle>,
    /// RTK corrections from a caster (`--ntrip URL`): the simulated receiver then holds
    /// RTK fixed only while they arrive.
    pub ntrip: Option<crate::config::ntrip::NtripConfig>,
    /// The zones the vehicle keeps to (`--zones FILE`).
    pub zones: Option<crate::config::zones::ZonesConfig>,
}

/// Faults a benchmark injects into a running simulation; each holds while set.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimFaults {
    /// The receiver sends nothing.
    pub gnss_outage: bool,
    /// The IMU sends nothing.
    pub imu_stall: bool,
    /// The wheel drives send no heartbeats (their motors still obey).
    pub drive_heartbeats_lost: bool,
    /// The CAN interface is down.
    pub bus_down: bool,
}

/// A benchmark's hold on a running simulation.
#[derive(Debug, Clone)]
pub struct SimHandle {
    /// The faults to apply, read every pacing tick.
    pub faults: watch::Receiver<SimFaults>,
    /// What the benchmark reads back, written every pacing tick.
    pub probe: watch::Sender<SimProbe>,
}

/// The simulated vehicle as a benchmark reads it back.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SimProbe {
    /// The true state.
    pub truth: Truth,
    /// Both wheel drives are commanded to stop (zero targets, quick stop or disabled).
    pub wheels_commanded_to_stop: bool,
}

impl SimHandle {
    /// A handle, with the sender of its faults and the receiver of its probe.
    pub fn new() -> (Self, watch::Sender<SimFaults>, watch::Receiver<SimProbe>) {
        let (fault_tx, faults) = watch::channel(SimFaults::default());
        let (probe, probe_rx) = watch::channel(SimProbe::default());
        (Self { faults, probe }, fault_tx, probe_rx)
    }
}

/// Applies `faults` where they differ from what the simulation has.
fn apply_faults(sim: &mut Lockstep, now: SimFaults, was: &mut SimFaults, sink: &mut impl Sink) {
    if now.imu_stall != was.imu_stall {
        sim.vehicle_mut().set_imu_stalled(now.imu_stall);
    }
    if now.drive_heartbeats_lost != was.drive_heartbeats_lost {
        sim.vehicle_mut()
            .set_drive_heartbeats(!now.drive_heartbeats_lost);
    }
    if now.bus_down != was.bus_down {
        sim.set_bus_up(!now.bus_down, sink);
    }
    *was = now;
}

/// Status lines to `out` (from its own thread), records to the recorder, the rest to the
/// links.
struct Output {
    out: StatusOut,
    recorder: Option<Recorder>,
    links: Links,
}

impl Sink for Output {
    fn record(&mut self, record: &Record) {
        if let Some(r) = self.recorder.as_mut() {
            r.record(record.clone());
        }
    }

    fn output(&mut self, output: EngineOutput) {
        // Frames go to the simulated drives inside the lockstep, not here.
        if let Some(EngineOutput::Status(status)) = self.links.route(output) {
            let mut line = BaseStatus::from_status(&status).to_json();
            line.push('\n');
            self.out.send(line);
        }
    }
}

/// Runs until the scenario or duration ends, or SIGINT or SIGTERM. The simulated vehicle's
/// loop is marked as `run`'s is: a panic in it ends the process, one elsewhere is contained
/// (`panics`).
pub async fn run(
    options: SimOptions,
    out: impl Write + Send + 'static,
) -> crate::runtime::error::Result<()> {
    crate::runtime::panics::install(Vec::new());
    crate::runtime::panics::safety_relevant(run_marked(options, out)).await
}

async fn run_marked(
    options: SimOptions,
    out: impl Write + Send + 'static,
) -> crate::runtime::error::Result<()> {
    let clock = RecordClock::start();
    let start = clock.now();
    let config = crate::config::VehicleConfig {
        mqtt: options.mqtt.clone(),
        ..Default::default()
    };
    // A simulated session keeps trajectories in memory unless a folder is configured.
    let trajectory_writer::OpenedStore {
        store,
        snapshot,
        writer,
    } = trajectory_writer::open(&config, Box::new(MemoryStore::default()))?;
    let sections = Sections {
        mqtt: options.mqtt.clone(),
        ntrip: options.ntrip.clone(),
        zones: options.zones.clone(),
    };
    let mut sim =
        Lockstep::with_sections(options.plant.clone(), options.seed, start, sections, store)?;
    session::log_zones(sim.config());
    heap::spawn();
    let (tx, mut commands) = mpsc::channel(COMMAND_QUEUE);
    // The plant's configuration with the session's sections, and the links the options ask
    // for.
    let mut config = sim.config().clone();
    config.ros1 = options.ros1.clone();
    config.ros2 = options.ros2.clone();
    config.websocket = options.websocket.clone();
    let broker = session::start_broker(&config)?;
    let mut sources = lockstep::sources(&options.plant);
    let links = Links::start(sim.engine_mut(), &config, broker, clock, &tx, &mut sources)?;
    let recorder = match &options.record {
        Some(dir) => Some(session::start_recorder(
            dir,
            sim.config(),
            start,
            sources,
            snapshot.as_deref(),
        )?),
        None => None,
    };
    let mut commands_open = options.commands_stdin || links.any();
    let mut sink = Output {
        out: StatusOut::start(out),
        recorder,
        links,
    };
    if options.commands_stdin {
        tokio::spawn(read_commands(clock, tx));
    } else {
        drop(tx);
    }
    crate::runtime::stderr::line(start_line(&options, sim.config().vehicle.name.as_str()));
    let end =
        run_length(options.duration, options.scenario.as_ref()).map(|d| start.saturating_add(d));
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .map_err(io("cannot install the SIGTERM handler"))?;
    // One SIGINT stream for the whole loop: a `ctrl_c()` made afresh each turn misses a
    // signal that arrives between two turns.
    let mut sigint = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::interrupt())
        .map_err(io("cannot install the SIGINT handler"))?;
    // Each catch-up just after a control tick's time, so what the tick publishes goes out
    // within some 2 ms of its stamp, rather than up to a whole period later by the phase
    // the timer happened to start in.
    let first = clock
        .now()
        .ceil_to(CONTROL_PERIOD)
        .saturating_add(PACE_AFTER_TICK);
    let mut pace = tokio::time::interval_at(clock.instant_at(first), PACE);
    pace.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut summary = Summary::new(sim.vehicle().truth());
    let mut faults = SimFaults::default();
    let mut scripted = Script::new(options.scenario.as_ref());
    'run: loop {
        tokio::select! {
            _ = pace.tick() => {
                let now = clock.now();
                if let Some(h) = &options.handle {
                    let wanted = *h.faults.borrow();
                    apply_faults(&mut sim, wanted, &mut faults, &mut sink);
                }
                let gnss = if faults.gnss_outage { NO_GNSS } else { RTK_FIXED };
                while sim.time().saturating_add(PLANT_STEP) <= now {
                    if end.is_some_and(|end| sim.time() >= end) {
                        // `--duration` wins over the scenario's own length.
                        summary.ended = if options.duration.is_some() { Ended::Duration } else { Ended::Scenario };
                        break 'run;
                    }
                    match &options.scenario {
                        Some(scenario) if scripted.drives() => sim.step_scripted(scenario, &mut sink),
                        Some(scenario) => sim.step_conditions(scenario, &mut sink),
                        None => sim.step(gnss, &mut sink),
                    }
                    summary.track(sim.vehicle().truth());
                }
                sink.links.update_position(sim.engine().gnss_fix());
                if let Some(h) = &options.handle {
                    h.probe.send_replace(SimProbe {
                        truth: sim.vehicle().truth(),
                        wheels_commanded_to_stop: sim.vehicle().wheels_commanded_to_stop(),
                    });
                }
            }
            command = commands.recv(), if commands_open => match command {
                // Commands and link events take the simulation's time.
                Some(record) => {
                    if matches!(record.payload, Payload::Command { .. }) && crate::runtime::panics::inject("control") {
                        panic!("injected panic ({}=control)", crate::runtime::panics::INJECT_PANIC);
                    }
                    let taken_before = taken(sim.engine().stats());
                    let command = match &record.payload {
                        Payload::Command { topic, .. } => Some(topic.clone()),
                        _ => None,
                    };
                    sim.input(&record.source, record.payload, &mut sink);
                    if let Some(topic) = command
                        && taken(sim.engine().stats()) > taken_before
                    {
                        scripted.operator_took(&record.source, &topic);
                    }
                }
                None => commands_open = false,
            },
            _ = sigint.recv() => break,
            _ = sigterm.recv() => break,
        }
        if let Some(e) = sink.out.take_error() {
            finish(sink.recorder.take(), sim.time());
            return Err(io("cannot write status output")(e));
        }
    }
    finish(sink.recorder.take(), sim.time());
    sink.out.finish(Duration::from_millis(500));
    let elapsed = sim.time().saturating_since(start);
    crate::runtime::stderr::line(summary.line(&options, elapsed, sim.engine().stats()));
    // The simulation holds the trajectory queue; once it is gone the writer drains and ends.
    drop(sim);
    if let Some(writer) = writer {
        writer.finish(Duration::from_millis(500));
    }
    Ok(())
}

/// Whether a scenario's script still drives: it yields, for the rest of the run, to the
/// first command an operator's link sends that the vehicle takes (a goal, a velocity, a
/// heartbeat); its GNSS conditions and the run's length go on.
struct Script {
    /// The scenario's name while it drives.
    driving: Option<String>,
}

impl Script {
    fn new(scenario: Option<&Scenario>) -> Self {
        Self {
            driving: scenario.map(|s| s.name.to_owned()),
        }
    }

    fn drives(&self) -> bool {
        self.driving.is_some()
    }

    /// An operator's command from `source` on `topic` was taken.
    fn operator_took(&mut self, source: &str, topic: &str) {
        if let Some(name) = self.driving.take() {
            tracing::info!(
                scenario = %name, %source, %topic,
                "an operator's command was taken: the scenario's scripted driving stops for \
                 the rest of the run (its GNSS conditions and length go on)"
            );
        }
    }
}

/// Commands the engine took (received, not refused).
fn taken(stats: &crate::engine::EngineStats) -> u64 {
    stats.commands.saturating_sub(stats.commands_rejected)
}

/// How long a simulation runs: `--duration` wins over the scenario's own length; neither
/// means until stopped.
pub(crate) fn run_length(
    duration: Option<Duration>,
    scenario: Option<&Scenario>,
) -> Option<Duration> {
    duration.or(scenario.map(|s| Duration::from_secs_f64(s.duration_s())))
}

/// The line a person reads first: what runs, where to watch it, how to stop it.
fn start_line(options: &SimOptions, vehicle: &str) -> String {
    let mut line = format!(
        "chassisd sim: simulated vehicle {vehicle:?} (seed {})",
        options.seed
    );
    if let Some(s) = &options.scenario {
        line += &format!(
            ", scenario {} ({:.0} s: {})",
            s.name,
            s.duration_s(),
            s.about
        );
    }
    if let Some(d) = options.duration {
        line += &format!(", for {:.1} s", d.as_secs_f64());
    }
    line += "; base_status JSON lines on stdout";
    if let Some(m) = &options.mqtt {
        let rtk = m.link_of(DialectName::Rtk).unwrap_or(m.first());
        line += &format!(
            " and over MQTT (watch: mosquitto_sub -h {} -p {} -t base_status)",
            rtk.host, rtk.port
        );
        if let Some(device) = &m.device {
            let link = m.link_of(DialectName::Device).unwrap_or(m.first());
            // A goal is one message: pasted once, it drives the vehicle to (2, 1) m facing
            // north; the answer comes on the goal's ack topic when it ends.
            let mut about = format!("answered on device/{}/goal/ack", device.serial_number);
            if options.scenario.is_some() {
                about += ", and the scenario's scripted driving stops at the first command taken";
            }
            if options.zones.is_some() {
                about += ", taken once the log says \"GNSS gate open\"";
            }
            line += &format!(
                "; drive it to x 2 m, y 1 m facing north ({about}): mosquitto_pub -h {} -p {} -t device/{}/goal -m '{{\"msg_id\": \"1\", \"timestamp\": 1757403776, \"data\": {{\"x\": 2.0, \"y\": 1.0, \"z\": 0.7071}}}}'",
                link.host, link.port, device.serial_number
            );
        }
    }
    if let Some(r) = &options.ros1 {
        line += &format!(
            "; ROS1 node {} on {} (watch: rostopic echo /tracked_pose)",
            r.node_name, r.master_uri
        );
    }
    if let Some(r) = &options.ros2 {
        line += &format!(
            "; ROS 2 node {} on this machine (watch: ros2 topic echo /odom)",
            r.node_name
        );
    }
    if let Some(w) = &options.websocket {
        line += &format!(
            "; live page: http://{0}/ (rosbridge WebSocket on ws://{0}/)",
            w.bind
        );
    }
    if let Some(dir) = &options.record {
        line += &format!("; recording into {}", dir.display());
    }
    line + "; Ctrl-C stops"
}

/// Why the simulation ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ended {
    Scenario,
    Duration,
    Stopped,
}

/// What the closing line sums up.
struct Summary {
    ended: Ended,
    start: Truth,
    last: Truth,
    distance_m: f64,
}

impl Summary {
    fn new(start: Truth) -> Self {
        Self {
            ended: Ended::Stopped,
            start,
            last: start,
            distance_m: 0.0,
        }
    }

    fn track(&mut self, now: Truth) {
        self.distance_m += (now.x - self.last.x).hypot(now.y - self.last.y);
        self.last = now;
    }

    fn line(&self, options: &SimOptions, elapsed: Duration, stats: &EngineStats) -> String {
        let why = match (self.ended, &options.scenario) {
            (Ended::Scenario, Some(s)) => format!("scenario {} complete", s.name),
            (Ended::Duration, _) | (Ended::Scenario, None) => "duration reached".to_owned(),
            (Ended::Stopped, _) => "stopped".to_owned(),
        };
        let mut line = format!(
            "chassisd sim: {why} after {:.1} s simulated; drove {:.1} m, ending ({:.3}, {:.3}) m from the start, heading {:.0}°, {:.3} m of it random wheel slip no odometry sees; {} commands ({} refused), {} status lines",
            elapsed.as_secs_f64(),
            self.distance_m,
            self.last.x - self.start.x,
            self.last.y - self.start.y,
            self.last.yaw.to_degrees().rem_euclid(360.0),
            self.last.unseen_slip_m - self.start.unseen_slip_m,
            stats.commands,
            stats.commands_rejected,
            stats.ticks,
        );
        if let Some(dir) = &options.record {
            line += &format!("; recorded in {}", dir.display());
        }
        line
    }
}

fn finish(recorder: Option<Recorder>, end: Timestamp) {
    if let Some(r) = recorder {
        if r.dropped() > 0 {
            tracing::error!(dropped = r.dropped(), "recording is incomplete");
        }
        r.finish(end);
    }
}
