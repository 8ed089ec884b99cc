//! Live mode: drivers feed the engine task, which owns the core, runs the 10 ms control loop,
//! sends the drives' frames, and writes a base_status line every 100 ms.

use crate::runtime::links::input_lines::{InputLine, InputLines, MAX_LINE_BYTES};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use crate::runtime::error::{RuntimeError, io};
use bytes::Bytes;
use tokio::sync::mpsc;

use crate::api::local;
use crate::api::rtk::BaseStatus;
use crate::api::trajectory::Unconfigured;
use crate::config::VehicleConfig;
use crate::devices::gnss::GnssStats;
use crate::engine::{Engine, EngineOutput, PROCESS_SOURCE};
use crate::record::{Payload, Record, SourceMeta};
use crate::runtime::clock::RecordClock;
use crate::runtime::drivers;
use crate::runtime::drivers::can::CanTx;
use crate::runtime::drivers::serial_tx::SerialTx;
use crate::runtime::heap;
use crate::runtime::notify::{InjectedStall, ServiceManager};
use crate::runtime::panics;
use crate::runtime::recorder::Recorder;
use crate::runtime::session::{self, Links};
use crate::runtime::status_out::StatusOut;
use crate::runtime::trajectory_writer;
use crate::sim::scenario::Scenario;
use crate::time::Timestamp;
use crate::vehicle::LinkState;
use crate::vehicle::chassis::status_bits;

/// Records waiting for the engine before drivers wait.
const CHANNEL: usize = 4096;
/// How often fault counters are summarised in the log.
const SUMMARY_EVERY: Duration = Duration::from_secs(30);
/// How long the stop frames on exit may take to leave.
const STOP_FLUSH: Duration = Duration::from_millis(500);
/// Devices still down this long after start: systemd hears READY anyway, with their names.
const READY_GRACE: Duration = Duration::from_secs(10);
pub use crate::runtime::drivers::{GNSS_SOURCE, IMU_SOURCE};
/// Source name of the local command channel.
pub const STDIN_SOURCE: &str = crate::engine::LOCAL_COMMANDS;

/// Options of `chassisd run`.
#[derive(Debug, Clone)]
pub struct LiveOptions {
    /// The vehicle configuration.
    pub config: VehicleConfig,
    /// Record every raw chunk, frame and command into this folder.
    pub record: Option<PathBuf>,
    /// Read `TOPIC JSON` commands from standard input.
    pub commands_stdin: bool,
    /// Drive this scripted pattern on the local command channel, then stop (`chassisd
    /// calibrate --drive`). A safety stop on the way ends the run with an error.
    pub pattern: Option<Scenario>,
}

/// A scripted pattern's velocity commands go out this often (well inside any command
/// timeout).
const PATTERN_COMMAND_EVERY: Duration = Duration::from_millis(100);
/// Stops that end a scripted pattern once the drives have been enabled: each one means a
/// person or a fault stopped the vehicle, and the pattern must not go on by itself.
const PATTERN_ABORTS: u32 = status_bits::FAULT
    | status_bits::HEARTBEAT_LOST
    | status_bits::ESTOP
    | status_bits::BUS_DOWN
    | status_bits::COMMAND_TIMEOUT
    | status_bits::CONTROL_LINK_LOST;

/// Says which calibrated values are in force, and from which file.
fn log_calibration(config: &crate::config::VehicleConfig) {
    match &config.calibration_in_force {
        Some((file, lines)) => {
            tracing::info!(file = %file.display(), "calibration file read");
            for line in lines {
                tracing::info!("calibration: {line}");
            }
        }
        None => tracing::info!(
            "no calibration file: the configuration's own geometry and biases are in force"
        ),
    }
}

/// Runs until SIGINT or SIGTERM, writing base_status lines to `out` (from a thread of its
/// own: a stalled `out` never holds up the control loop). The whole loop is safety-relevant
/// code: a panic in it quick-stops the drives and ends the process (`panics`).
pub async fn run(
    options: LiveOptions,
    out: impl Write + Send + 'static,
) -> crate::runtime::error::Result<()> {
    panics::safety_relevant(run_marked(options, out)).await
}

async fn run_marked(
    options: LiveOptions,
    out: impl Write + Send + 'static,
) -> crate::runtime::error::Result<()> {
    options
        .config
        .require_devices(std::path::Path::new("the configuration"))?;
    log_calibration(&options.config);
    session::log_zones(&options.config);
    let broker = session::start_broker(&options.config)?;
    let mut out = StatusOut::start(out);
    let clock = RecordClock::start();
    let start = clock.now();
    heap::spawn();
    let (tx, mut rx) = mpsc::channel(CHANNEL);
    let config = &options.config;
    let devices = drivers::start(config, clock, &tx, drivers::Mode::Drive);
    let sources = devices.decoders;
    let mut source_meta = devices.sources;
    let can_tx = devices.can_tx;
    let serial_tx = devices.serial_tx;
    if !config.drive.is_empty() {
        source_meta.push(SourceMeta::commands(
            PROCESS_SOURCE,
            &format!("{PROCESS_SOURCE}.log"),
        ));
    }
    if options.commands_stdin || options.pattern.is_some() {
        source_meta.push(SourceMeta::commands(STDIN_SOURCE, "commands.log"));
    }
    if options.commands_stdin {
        tokio::spawn(read_commands(clock, tx.clone()));
    }
    let mut pattern = options
        .pattern
        .clone()
        .map(|p| tokio::spawn(drive_pattern(p, clock, tx.clone())));
    if config
        .mqtt
        .as_ref()
        .is_some_and(|m| m.rtk.as_ref().is_some_and(|r| r.trajectory_dir.is_none()))
    {
        tracing::warn!("mqtt.rtk.trajectory_dir is not set: trajectory commands will be refused");
    }
    let trajectories = trajectory_writer::open(config, Box::new(Unconfigured))?;
    let mut engine = Engine::with_trajectories(config, &sources, trajectories.store);
    engine.start_at(start);
    panics::install(engine.drivetrain().stop_frames());
    let mut links = Links::start(&mut engine, config, broker, clock, &tx, &mut source_meta)?;
    let drivers_running = !source_meta.is_empty();
    drop(tx);

    let mut recorder = match &options.record {
        Some(dir) => Some(session::start_recorder(
            dir,
            config,
            start,
            source_meta,
            trajectories.snapshot.as_deref(),
        )?),
        None => None,
    };

    // What must come up before systemd hears READY: each device, and the broker.
    let mut expected = devices.names;
    if let Some(m) = &config.mqtt {
        expected.extend(m.links.iter().map(|l| l.source()));
    }
    let mut service = ServiceManager::new(expected, READY_GRACE, std::time::Instant::now());
    let mut stall = InjectedStall::from_env(std::time::Instant::now());
    if let Some(w) = service.watchdog() {
        tracing::info!(
            period_s = w.as_secs_f64(),
            "systemd watchdog on: fed from the control loop"
        );
    }

    let mut outputs = Vec::new();
    let mut summary = tokio::time::interval(SUMMARY_EVERY);
    let mut reported: Vec<(String, GnssStats)> = Vec::new();
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .map_err(io("cannot install the SIGTERM handler"))?;
    // One SIGINT stream for the whole loop: a `ctrl_c()` made afresh each turn misses a
    // signal that arrives between two turns.
    let mut sigint = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::interrupt())
        .map_err(io("cannot install the SIGINT handler"))?;
    let mut drivers_running = drivers_running;
    // Under a pattern: whether the drives have been enabled yet.
    let mut enabled_seen = false;
    let result = loop {
        let next_tick = engine.next_tick().unwrap_or_else(|| clock.now());
        let mut now = None;
        tokio::select! {
            record = rx.recv(), if drivers_running => {
                let Some(mut record) = record else {
                    drivers_running = false;
                    continue;
                };
                if let Payload::Link(LinkState::Up) = record.payload {
                    service.link_up(&record.source, std::time::Instant::now());
                }
                if matches!(record.payload, Payload::Command { .. }) && panics::inject("control") {
                    panic!("injected panic ({}=control)", panics::INJECT_PANIC);
                }
                record.t = engine.handle(&record, &mut outputs);
                now = Some(record.t);
                if let Some(r) = recorder.as_mut() {
                    r.record(record);
                }
            }
            () = tokio::time::sleep_until(clock.instant_at(next_tick)) => {
                engine.advance_to(next_tick, &mut outputs);
                now = Some(next_tick);
                // Fed here only: a core that stops ticking stops the pings.
                service.tick(std::time::Instant::now());
                if stall.is_some_and(|s| s.block_if_due(std::time::Instant::now())) {
                    stall = None;
                }
            }
            _ = summary.tick() => {
                summarise_faults(&engine, &can_tx, &mut reported);
            }
            _ = sigint.recv() => break Ok("SIGINT"),
            _ = sigterm.recv() => break Ok("SIGTERM"),
            _ = finished(&mut pattern) => break Ok("pattern complete"),
        }
        let t = now.unwrap_or_else(|| clock.now());
        links.update_position(engine.gnss_fix());
        let bits = dispatch(
            &mut outputs,
            t,
            (&can_tx, &serial_tx),
            &mut links,
            recorder.as_mut(),
            &mut out,
        );
        if let Some(e) = out.take_error() {
            break Err(io("cannot write status output")(e));
        }
        if let (Some(_), Some(bits)) = (&pattern, bits) {
            enabled_seen |= bits & status_bits::ENABLED != 0;
            if enabled_seen && bits & PATTERN_ABORTS != 0 {
                break Err(RuntimeError::Failed(format!(
                    "the vehicle was stopped ({}); the pattern is abandoned. Clear the \
                     cause and start again",
                    status_bits::describe(bits & PATTERN_ABORTS)
                )));
            }
        }
    };
    if let Some(p) = pattern.take() {
        p.abort();
    }
    service.stopping(match &result {
        Ok(signal) => signal,
        Err(_) => "error",
    });
    // The ticks up to the stop, so a replay of the recording ends where this run ended; then
    // every drive quick-stops with zero targets, recorded so the replay does the same, and
    // those frames leave before the process does.
    let end = clock.now();
    engine.advance_to(end, &mut outputs);
    let shutdown = Record {
        t: end,
        source: PROCESS_SOURCE.into(),
        payload: Payload::Command {
            topic: "shutdown".into(),
            payload: Bytes::from(match &result {
                Ok(signal) => *signal,
                Err(_) => "error",
            }),
        },
    };
    if !config.drive.is_empty() {
        let t = engine.handle(&shutdown, &mut outputs);
        if let Some(r) = recorder.as_mut() {
            r.record(Record { t, ..shutdown });
        }
    }
    dispatch(
        &mut outputs,
        end,
        (&can_tx, &serial_tx),
        &mut links,
        recorder.as_mut(),
        &mut out,
    );
    for (bus, q) in &can_tx {
        if !q.flush(STOP_FLUSH).await {
            tracing::error!(device = %bus, "the stop frames did not all leave before exit");
        }
    }
    if let Some(r) = recorder {
        if r.dropped() > 0 {
            tracing::error!(dropped = r.dropped(), "recording is incomplete");
        }
        r.finish(end);
    }
    summarise_faults(&engine, &can_tx, &mut reported);
    // The engine holds the trajectory queue; once it is gone the writer drains and ends.
    drop(engine);
    if let Some(writer) = trajectories.writer {
        writer.finish(STOP_FLUSH);
    }
    if let Ok(signal) = &result {
        tracing::info!(%signal, "stopped: drives quick-stopped, targets zero");
    }
    if out.dropped() > 0 {
        tracing::warn!(
            dropped = out.dropped(),
            "status lines dropped (output not read)"
        );
    }
    out.finish(STOP_FLUSH);
    result.map(|_| ())
}

/// Routes the engine's outputs: the links' to them, status lines to `out`, frames to their
/// interface (and the recording). Returns the drive train's status bits of the
/// last status, if there was one.
fn dispatch(
    outputs: &mut Vec<EngineOutput>,
    t: Timestamp,
    (can_tx, serial_tx): (&BTreeMap<String, CanTx>, &BTreeMap<String, SerialTx>),
    links: &mut Links,
    mut recorder: Option<&mut Recorder>,
    out: &mut StatusOut,
) -> Option<u32> {
    let mut bits = None;
    for output in outputs.drain(..) {
        let Some(output) = links.route(output) else {
            continue;
        };
        match output {
            EngineOutput::Status(status) => {
                bits = status.chassis.as_ref().map(|c| c.status_bits).or(bits);
                let mut line = BaseStatus::from_status(&status).to_json();
                line.push('\n');
                out.send(line);
            }
            EngineOutput::CanTx { bus, frame } => {
                if let Some(r) = recorder.as_deref_mut() {
                    r.record(Record {
                        t,
                        source: bus.clone(),
                        payload: Payload::CanTx(frame.into()),
                    });
                }
                if let Some(q) = can_tx.get(&bus) {
                    q.send(frame);
                }
            }
            // Not recorded: a replay writes the same bytes from the recorded stream.
            EngineOutput::SerialTx { port, bytes } => {
                if let Some(q) = serial_tx.get(&port) {
                    q.send(bytes);
                }
            }
            _ => {}
        }
    }
    bits
}

/// Sends the pattern's velocity command every [`PATTERN_COMMAND_EVERY`] on the local
/// command channel, from its start to its end.
async fn drive_pattern(pattern: Scenario, clock: RecordClock, tx: mpsc::Sender<Record>) {
    let start = tokio::time::Instant::now();
    let mut every = tokio::time::interval(PATTERN_COMMAND_EVERY);
    loop {
        every.tick().await;
        let s = start.elapsed().as_secs_f64();
        if s >= pattern.duration_s() {
            return;
        }
        let (v, w) = pattern.command_at(s);
        let record = Record {
            t: clock.now(),
            source: STDIN_SOURCE.into(),
            payload: Payload::Command {
                topic: "cmd_vel".into(),
                payload: Bytes::from(format!(r#"{{"linear":{{"x":{v}}},"angular":{{"z":{w}}}}}"#)),
            },
        };
        if tx.send(record).await.is_err() {
            return;
        }
    }
}

/// Resolves when the pattern's task has ended; never without one.
async fn finished(pattern: &mut Option<tokio::task::JoinHandle<()>>) {
    match pattern {
        Some(task) => {
            let _ = task.await;
        }
        None => std::future::pending().await,
    }
}

/// Reads `TOPIC JSON` lines from standard input as commands. A line that is not UTF-8 or
/// longer than [`MAX_LINE_BYTES`] is refused with a warning, and reading goes on.
pub(crate) async fn read_commands(clock: RecordClock, tx: mpsc::Sender<Record>) {
    let mut lines = InputLines::new(
        tokio::io::BufReader::new(tokio::io::stdin()),
        MAX_LINE_BYTES,
    );
    loop {
        let line = match lines.next().await {
            Ok(Some(InputLine::Text(line))) => line,
            Ok(Some(InputLine::NotUtf8(number))) => {
                tracing::warn!(line = number, "standard input: line refused, not UTF-8");
                continue;
            }
            Ok(Some(InputLine::TooLong(number, bytes))) => {
                tracing::warn!(
                    line = number,
                    bytes,
                    limit = MAX_LINE_BYTES,
                    "standard input: line refused, too long"
                );
                continue;
            }
            Ok(None) => return,
            Err(e) => {
                tracing::warn!(error = %e, "standard input unreadable; no more commands");
                return;
            }
        };
        let Some((topic, payload)) = local::split_line(&line) else {
            continue;
        };
        let record = Record {
            t: clock.now(),
            source: STDIN_SOURCE.into(),
            payload: Payload::Command {
                topic: topic.to_owned(),
                payload: Bytes::copy_from_slice(payload.as_bytes()),
            },
        };
        if tx.send(record).await.is_err() {
            return;
        }
    }
}

/// Logs the fault counters when they changed since the last summary.
fn summarise_faults(
    engine: &Engine,
    can_tx: &BTreeMap<String, CanTx>,
    reported: &mut Vec<(String, GnssStats)>,
) {
    let now: Vec<(String, GnssStats)> = engine
        .gnss_stats()
        .map(|(n, s)| (n.to_owned(), s))
        .collect();
    for (name, stats) in &now {
        let before = reported
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, s)| s.clone())
            .unwrap_or_default();
        let f = &stats.framer;
        let b = &before.framer;
        let faults = |s: &GnssStats| {
            s.framer.checksum_errors
                + s.framer.missing_checksum
                + s.framer.truncated
                + s.framer.overlong
                + s.framer.ubx_checksum_errors
                + s.corrections.crc_failed
                + s.decode_errors
        };
        if faults(stats) != faults(&before) || f.bytes_skipped != b.bytes_skipped {
            tracing::warn!(
                device = %name,
                checksum_errors = f.checksum_errors - b.checksum_errors,
                missing_checksums = f.missing_checksum - b.missing_checksum,
                truncated = f.truncated - b.truncated,
                overlong = f.overlong - b.overlong,
                ubx_checksum_errors = f.ubx_checksum_errors - b.ubx_checksum_errors,
                rtcm_crc_failed_at_receiver =
                    stats.corrections.crc_failed - before.corrections.crc_failed,
                bytes_skipped = f.bytes_skipped - b.bytes_skipped,
                decode_errors = stats.decode_errors - before.decode_errors,
                last_decode_error = ?stats.last_decode_error.as_ref().map(|e| e.to_string()),
                "stream faults since the last summary"
            );
        }
    }
    *reported = now;
    for (bus, stats) in engine.bus_stats() {
        let dropped = can_tx.get(bus).map_or(0, CanTx::dropped);
        if stats.error_frames > 0 || dropped > 0 || stats.estop_malformed > 0 {
            tracing::warn!(
                device = %bus,
                error_frames = stats.error_frames,
                estop_malformed = stats.estop_malformed,
                last_error = ?stats.last_error,
                frames_dropped = dropped,
                "CAN faults so far"
            );
        }
    }
    for (bus, name, node) in engine.drivetrain().nodes() {
        if let Some(fault) = node.fault() {
            tracing::warn!(device = %bus, drive = %name, node = node.node().get(), %fault, "drive fault latched");
        }
    }
}
