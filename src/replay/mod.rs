//! `chassisd replay`: a recording (or a plain NMEA log) through the same engine as live
//! mode, as fast as the machine allows, one base_status JSON line per tick; or, through
//! [`mcap`], into an MCAP file.

pub mod mcap;

use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

use crate::api::rtk::BaseStatus;
use crate::api::trajectory::{MemoryStore, Trajectory};
use crate::config::{ConfigError, VehicleConfig};
use crate::devices::gnss::GnssStats;
use crate::devices::gnss::rtcm::RtcmStats;
use crate::engine::EngineOutput;
use crate::engine::drivetrain::BusStats;
use crate::engine::{Decoder, Engine, EngineStats, RTCM_PROTOCOL, STATUS_PERIOD};
use crate::record::nmea_import::{IMPORT_SOURCE, ImportOptions, ImportReport, NmeaLogReader};
use crate::record::{Record, RecordError, RecordingReader, SkippedLine, SourceKind};
use crate::runtime::progress::Progress;
use crate::time::Timestamp;

/// Why a replay could not run.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The recording could not be opened or read.
    #[error(transparent)]
    Recording(#[from] RecordError),
    /// The configuration stored with the recording is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Writing the output failed (for example, a closed pipe).
    #[error("writing output: {0}")]
    Output(#[from] std::io::Error),
}

/// What a replay went through.
#[derive(Debug, Clone, Default)]
pub struct ReplaySummary {
    /// Engine counters (records by source, ticks).
    pub engine: EngineStats,
    /// Counters per NMEA source.
    pub gnss: Vec<(String, GnssStats)>,
    /// Counters per CAN interface.
    pub buses: Vec<(String, BusStats)>,
    /// The corrections relayed to the receiver, with `[ntrip]`.
    pub corrections: Option<RtcmStats>,
    /// Malformed recording lines that were skipped (the first hundred) and their count.
    pub skipped_lines: (Vec<SkippedLine>, u64),
    /// Records earlier than the one before them in their file (the first hundred; played
    /// all the same) and their count.
    pub out_of_order: (Vec<SkippedLine>, u64),
    /// A recording without a clean end: the last moment every file covers (the replay
    /// stopped there) and how many records after it were left out.
    pub cut: Option<(Timestamp, u64)>,
    /// Present when the input was a plain NMEA log.
    pub import: Option<ImportReport>,
    /// Sources in the recording that no decoder handles (name, protocol).
    pub sources_without_decoder: Vec<(String, String)>,
    /// First and last record times.
    pub span: Option<(Timestamp, Timestamp)>,
    /// `meta.toml`'s start or end that disagreed with the records, and what was used
    /// instead: a recording's metadata is a claim, checked against its records.
    pub span_corrections: Vec<String>,
    /// The process's peak resident memory at the end, bytes.
    pub peak_memory: Option<u64>,
}

/// The span of ticks run between two writes of their output.
const TICK_BATCH: std::time::Duration = std::time::Duration::from_secs(10);

/// How to replay.
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// Overrides the configuration stored with the recording.
    pub config: Option<VehicleConfig>,
    /// Adds `stamp` (the recorded time, s) to each line.
    pub stamped: bool,
    /// How a plain NMEA log is imported (its largest gap within a segment).
    pub import: ImportOptions,
    /// Where the corrections relayed to the receiver go (what live mode wrote to its port).
    pub corrections_out: Option<std::path::PathBuf>,
    /// Draw a progress bar on stderr when it is a terminal.
    pub progress: bool,
}

/// What takes a replay's engine outputs as they come.
pub trait Consumer {
    /// The configuration the engine runs and the serial sources that speak NMEA, before the
    /// first record.
    fn begin(&mut self, _vehicle: &VehicleConfig, _nmea_sources: &[String]) {}

    /// A record, as it goes into the engine (before the outputs it makes).
    fn record(&mut self, _record: &Record) -> std::io::Result<()> {
        Ok(())
    }

    /// Takes (drains) `outputs`; their times are the recorded times less `offset_ns`.
    fn take(&mut self, outputs: &mut Vec<EngineOutput>, offset_ns: i128) -> std::io::Result<()>;
}

/// Replays `path` (a recording folder or a plain NMEA log) and writes one base_status line
/// per tick to `out`.
pub fn replay(
    path: &Path,
    options: &ReplayOptions,
    out: &mut impl Write,
) -> Result<ReplaySummary, ReplayError> {
    let corrections = match &options.corrections_out {
        Some(file) => Some(std::io::BufWriter::new(std::fs::File::create(file)?)),
        None => None,
    };
    let mut output = Output {
        out,
        stamped: options.stamped,
        line: Vec::with_capacity(1024),
        json: Vec::with_capacity(1024),
        corrections,
    };
    let summary = replay_into(path, options, |_| {}, &mut output)?;
    output.out.flush()?;
    if let Some(c) = &mut output.corrections {
        c.flush()?;
    }
    Ok(summary)
}

/// Replays `path` through an engine that `setup` may adjust, handing every output to
/// `consumer`.
pub fn replay_into(
    path: &Path,
    options: &ReplayOptions,
    setup: impl FnOnce(&mut Engine),
    consumer: &mut impl Consumer,
) -> Result<ReplaySummary, ReplayError> {
    let config = options.config.as_ref();
    let mut summary = ReplaySummary::default();
    let mut span = SessionSpan::default();
    let mut trajectories = Vec::new();
    let (reader, vehicle, sources) = if path.is_dir() {
        let (meta, reader) = RecordingReader::open(path)?;
        if let Some(file) = &meta.trajectories {
            trajectories = read_trajectories(&path.join(file))?;
        }
        span = SessionSpan {
            start: meta.start_us.map(Timestamp::from_micros),
            end: meta.end_us.map(Timestamp::from_micros),
        };
        let stored = match &meta.vehicle_config {
            Some(file) => Some(VehicleConfig::load_within(&path.join(file), path)?),
            None => None,
        };
        let vehicle = config.cloned().or(stored).unwrap_or_default();
        let mut sources = Vec::new();
        for s in &meta.sources {
            match s.kind {
                // The engine relays corrections itself, when the configuration has [ntrip].
                SourceKind::Serial
                    if s.protocol.as_deref() == Some(RTCM_PROTOCOL) && vehicle.ntrip.is_some() => {}
                SourceKind::Serial => {
                    let protocol = s.protocol.clone().unwrap_or_default();
                    match Decoder::for_protocol(&protocol) {
                        Some(d) => sources.push((s.name.clone(), d)),
                        None => summary
                            .sources_without_decoder
                            .push((s.name.clone(), protocol)),
                    }
                }
                SourceKind::Can if !vehicle.can.iter().any(|c| c.interface == s.name) => {
                    summary.sources_without_decoder.push((
                        s.name.clone(),
                        "CAN interface not in the configuration".into(),
                    ))
                }
                SourceKind::Can | SourceKind::Commands => {}
            }
        }
        (Input::Recording(reader), vehicle, sources)
    } else {
        let reader = NmeaLogReader::open(path, options.import)?;
        (
            Input::Log(Box::new(reader)),
            config.cloned().unwrap_or_default(),
            vec![(IMPORT_SOURCE.to_owned(), Decoder::Nmea)],
        )
    };
    let nmea: Vec<String> = sources
        .iter()
        .filter(|(_, d)| matches!(d, Decoder::Nmea))
        .map(|(name, _)| name.clone())
        .collect();
    consumer.begin(&vehicle, &nmea);
    let store = Box::new(MemoryStore::with(trajectories));
    let mut engine = Engine::with_trajectories(&vehicle, &sources, store);
    setup(&mut engine);
    let progress = if options.progress {
        Progressing::of(path, &reader, span)
    } else {
        Progressing::none()
    };
    run(reader, engine, span, consumer, &mut summary, &progress)?;
    Ok(summary)
}

/// How far a replay has come: in recorded time between a recording's start and end, or in
/// bytes of a log.
struct Progressing {
    bar: Progress,
    /// The recording's start (time is counted from it), or none (bytes are counted).
    start: Option<Timestamp>,
}

/// Records between two updates of the bar.
const PROGRESS_EVERY: u64 = 1024;

impl Progressing {
    fn none() -> Self {
        Self {
            bar: Progress::none(),
            start: None,
        }
    }

    /// The bar of replaying `path` from `input`, when its length is known.
    fn of(path: &Path, input: &Input, span: SessionSpan) -> Self {
        let name = path.file_name().unwrap_or(path.as_os_str());
        let what = format!("replaying {}", name.to_string_lossy());
        match (input, span.start, span.end) {
            (Input::Recording(_), Some(start), Some(end)) if start < end => Self {
                bar: Progress::bar(&what, millis(end.saturating_since(start))),
                start: Some(start),
            },
            (Input::Log(_), _, _) => match std::fs::metadata(path) {
                Ok(m) => Self {
                    bar: Progress::bar(&what, m.len()),
                    start: None,
                },
                Err(_) => Self::none(),
            },
            // A recording cut short (no end in its meta.toml): its length is not known.
            _ => Self::none(),
        }
    }

    /// The replay has read up to `record` of `input`.
    fn at(&self, input: &Input, record: &Record) {
        if !self.bar.is_drawn() {
            return;
        }
        match (self.start, input) {
            (Some(start), _) => self.bar.set(millis(record.t.saturating_since(start))),
            (None, Input::Log(reader)) => self.bar.set(reader.bytes_read()),
            (None, Input::Recording(_)) => {}
        }
    }
}

fn millis(d: std::time::Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

/// Ticks up to `until` in batches of [`TICK_BATCH`], writing each batch's lines.
fn advance(
    engine: &mut Engine,
    until: Timestamp,
    outputs: &mut Vec<EngineOutput>,
    out: &mut impl Consumer,
    offset: i128,
) -> std::io::Result<()> {
    while let Some(next) = engine.next_tick().filter(|&next| next <= until) {
        engine.advance_to(until.min(next.saturating_add(TICK_BATCH)), outputs);
        out.take(outputs, offset)?;
    }
    Ok(())
}

/// Where records come from: a recording folder, or a plain log in segments.
enum Input {
    Recording(RecordingReader),
    Log(Box<NmeaLogReader>),
}

impl Iterator for Input {
    type Item = Record;

    fn next(&mut self) -> Option<Record> {
        match self {
            Input::Recording(r) => r.next(),
            Input::Log(r) => r.next(),
        }
    }
}

impl Input {
    /// The recorded time minus the engine's time for the last record read, ns.
    fn logged_offset_ns(&self) -> i128 {
        match self {
            Input::Recording(_) => 0,
            Input::Log(r) => r.logged_offset_ns(),
        }
    }
}

/// The status lines' destination.
struct Output<'a, W: Write> {
    out: &'a mut W,
    stamped: bool,
    line: Vec<u8>,
    /// The status object before its stamp goes in front.
    json: Vec<u8>,
    /// The corrections written to the receiver's port.
    corrections: Option<std::io::BufWriter<std::fs::File>>,
}

impl<W: Write> Consumer for Output<'_, W> {
    /// Writes the statuses among `outputs`, stamped with their time plus `offset_ns`.
    fn take(&mut self, outputs: &mut Vec<EngineOutput>, offset_ns: i128) -> std::io::Result<()> {
        for output in outputs.drain(..) {
            let status = match output {
                EngineOutput::Status(status) => status,
                EngineOutput::SerialTx { bytes, .. } => {
                    if let Some(c) = &mut self.corrections {
                        c.write_all(&bytes)?;
                    }
                    continue;
                }
                _ => continue,
            };
            self.line.clear();
            if self.stamped {
                let nanos = i128::from(status.time.as_nanos()) + offset_ns;
                let micros = nanos.div_euclid(1_000);
                let _ = write!(
                    self.line,
                    "{{\"stamp\":{}.{:06},",
                    micros.div_euclid(1_000_000),
                    micros.rem_euclid(1_000_000)
                );
                BaseStatus::from_status(&status).write_json(&mut self.json);
                // The object's own '{' gives way to the stamp's.
                self.line
                    .extend_from_slice(self.json.get(1..).unwrap_or_default());
                self.json.clear();
            } else {
                BaseStatus::from_status(&status).write_json(&mut self.line);
            }
            self.line.push(b'\n');
            self.out.write_all(&self.line)?;
        }
        Ok(())
    }
}

/// The largest trajectories file read, bytes: the store's limit of points written as JSON
/// (some 60 bytes each) fits with room; a larger file is refused with the reason, never read
/// whole into memory.
const MAX_TRAJECTORIES_BYTES: u64 = 256 << 20;

/// The trajectories a recording stored at its start.
fn read_trajectories(path: &Path) -> Result<Vec<Trajectory>, ReplayError> {
    let text = crate::record::read_small(path, MAX_TRAJECTORIES_BYTES)?;
    serde_json::from_str(&text).map_err(|e| {
        ReplayError::Recording(RecordError::Meta {
            path: path.to_owned(),
            message: format!("trajectories: {e}"),
        })
    })
}

/// How long before its first record a session may have started (the devices' first link
/// events come within moments; an hour allows a session that waited for all of them).
const MAX_LEAD: std::time::Duration = std::time::Duration::from_secs(3600);
/// How long after its last record a session may have ended (devices silent to the end).
const MAX_TAIL: std::time::Duration = std::time::Duration::from_secs(3600);

/// Start and end of a live session, as its recording's meta stores them.
#[derive(Debug, Clone, Copy, Default)]
struct SessionSpan {
    start: Option<Timestamp>,
    end: Option<Timestamp>,
}

fn run(
    mut input: Input,
    mut engine: Engine,
    session: SessionSpan,
    out: &mut impl Consumer,
    summary: &mut ReplaySummary,
    progress: &Progressing,
) -> Result<(), ReplayError> {
    engine.check_recorded_transmissions();
    let mut records: u64 = 0;
    let mut outputs = Vec::new();
    let mut span: Option<(Timestamp, Timestamp)> = None;
    // Ticks before a record belong to the segment of the record before it.
    let mut offset = 0;
    while let Some(record) = input.next() {
        if span.is_none() {
            // The session's start, where the records bear it out; else the first record's.
            let start = match session.start {
                Some(start)
                    if start <= record.t && record.t.saturating_since(start) <= MAX_LEAD =>
                {
                    start
                }
                Some(start) => {
                    summary.span_corrections.push(format!(
                        "start_us {} disagrees with the first record at {}: the replay starts there",
                        start.as_micros(),
                        record.t.as_micros()
                    ));
                    record.t
                }
                None => record.t,
            };
            engine.start_at(start);
        }
        // The ticks of a long gap leave in batches, so memory does not grow with it.
        let before = Timestamp::from_nanos(record.t.as_nanos().saturating_sub(1));
        advance(&mut engine, before, &mut outputs, out, offset)?;
        out.record(&record)?;
        let t = engine.handle(&record, &mut outputs);
        span = Some(span.map_or((t, t), |(first, _)| (first, t)));
        out.take(&mut outputs, offset)?;
        offset = input.logged_offset_ns();
        records += 1;
        if records.is_multiple_of(PROGRESS_EVERY) {
            progress.at(&input, &record);
        }
    }
    // Tick to the session's recorded end, else to where an unclean end's files all end,
    // else to the period boundary after the last record.
    let cut = match &input {
        Input::Recording(reader) => reader.cut().map(|(until, _)| until),
        Input::Log(_) => None,
    };
    let last = span.map(|(_, last)| last.ceil_to(STATUS_PERIOD));
    let claimed_end = match (session.end, span) {
        (Some(end), Some((_, last_record)))
            if end < last_record || end.saturating_since(last_record) > MAX_TAIL =>
        {
            summary.span_corrections.push(format!(
                "end_us {} disagrees with the last record at {}: the replay ends there",
                end.as_micros(),
                last_record.as_micros()
            ));
            Some(last_record)
        }
        // No record to bear the span out: ticked through only when it is short.
        (Some(end), None) => match session.start {
            Some(start) if start <= end && end.saturating_since(start) <= MAX_TAIL => {
                engine.start_at(start);
                Some(end)
            }
            _ => {
                summary.span_corrections.push(format!(
                    "the span claimed ({:?} to {} µs) has no record in it and is not ticked through",
                    session.start.map(Timestamp::as_micros),
                    end.as_micros()
                ));
                None
            }
        },
        (end, _) => end,
    };
    let end = claimed_end.or(cut).or(last);
    if let Some(end) = end {
        advance(&mut engine, end, &mut outputs, out, offset)?;
    }
    engine.finish();
    summary.engine = engine.stats().clone();
    summary.gnss = engine
        .gnss_stats()
        .map(|(name, stats)| (name.to_owned(), stats))
        .collect();
    summary.buses = engine
        .bus_stats()
        .map(|(name, stats)| (name.to_owned(), stats.clone()))
        .collect();
    summary.corrections = engine.corrections_stats().cloned();
    match &input {
        Input::Recording(reader) => {
            let (skipped, count) = reader.skipped();
            summary.skipped_lines = (skipped.to_vec(), count);
            let (late, count) = reader.out_of_order();
            summary.out_of_order = (late.to_vec(), count);
            summary.cut = reader.cut();
        }
        Input::Log(reader) => summary.import = Some(reader.report().clone()),
    }
    summary.span = span;
    summary.peak_memory = crate::runtime::host::peak_memory_bytes();
    Ok(())
}

impl ReplaySummary {
    /// The one-line summary printed on stderr.
    pub fn one_line(&self) -> String {
        let mut s = String::new();
        let frames: u64 = self.engine.records_by_source.values().sum();
        let _ = write!(s, "replay: {frames} frames (");
        join(
            &mut s,
            self.engine
                .records_by_source
                .iter()
                .map(|(k, v)| format!("{k} {v}")),
        );
        let _ = write!(s, "), {} status lines", self.engine.ticks);
        for (name, g) in &self.gnss {
            let f = &g.framer;
            let _ = write!(
                s,
                "; {name}: {} sentences and {} UBX frames (",
                f.sentences, f.ubx_frames
            );
            join(
                &mut s,
                g.sentences_by_kind.iter().map(|(k, v)| format!("{k} {v}")),
            );
            let _ = write!(
                s,
                "), checksum errors {}, missing checksums {}, truncated {}, overlong {}, \
                 UBX checksum errors {}, bytes skipped {} of {}, decode errors {}",
                f.checksum_errors,
                f.missing_checksum,
                f.truncated,
                f.overlong,
                f.ubx_checksum_errors,
                f.bytes_skipped,
                f.bytes_in,
                g.decode_errors
            );
            if let Some(e) = &g.last_decode_error {
                let _ = write!(s, " (last: {e})");
            }
            let c = &g.corrections;
            if c.total() > 0 {
                let _ = write!(
                    s,
                    "; RTCM messages the receiver reports: used {}, not used {}, unstated {}, \
                     CRC failed {}",
                    c.used, c.not_used, c.unstated, c.crc_failed
                );
            }
        }
        if let Some(c) = &self.corrections {
            let _ = write!(
                s,
                "; corrections: {} RTCM frames ({} bytes) to the receiver (",
                c.frames, c.frame_bytes
            );
            join(
                &mut s,
                c.by_type.iter().map(|(number, n)| format!("{number} {n}")),
            );
            let _ = write!(s, "), {} invalid bytes dropped", c.invalid_bytes);
        }
        if self.engine.undecoded > 0 {
            let _ = write!(s, "; {} frames without a decoder", self.engine.undecoded);
        }
        if self.engine.commands_without_dialect > 0 {
            let _ = write!(
                s,
                "; {} commands from channels without a dialect",
                self.engine.commands_without_dialect
            );
        }
        if self.engine.commands > 0 {
            let _ = write!(
                s,
                "; {} commands ({} refused)",
                self.engine.commands, self.engine.commands_rejected
            );
        }
        if self.engine.queries > 0 {
            let _ = write!(s, "; {} queries answered", self.engine.queries);
        }
        for (bus, b) in &self.buses {
            let _ = write!(
                s,
                "; {bus}: {} frames received, {} sent, {} error frames",
                b.rx, b.tx, b.error_frames
            );
            if let Some(e) = &b.last_error {
                let _ = write!(s, " (last: {e})");
            }
        }
        if self.engine.tx_matched + self.engine.tx_mismatched > 0 {
            let _ = write!(
                s,
                "; recorded transmissions: {} reproduced, {} differ",
                self.engine.tx_matched, self.engine.tx_mismatched
            );
        }
        if self.engine.reordered > 0 {
            let _ = write!(s, "; {} records re-timed", self.engine.reordered);
        }
        if let Some(import) = self.import.as_ref().filter(|i| i.jump_count > 0) {
            let _ = write!(
                s,
                "; {} clock jumps, each starting a new segment (",
                import.jump_count
            );
            join(
                &mut s,
                import
                    .jumps
                    .iter()
                    .map(|j| format!("line {}: {} to {}", j.line, j.from, j.to)),
            );
            if import.jumps.len() as u64 != import.jump_count {
                s.push_str(", ...");
            }
            s.push(')');
        }
        if let Some(e) = self.import.as_ref().and_then(|i| i.read_error.as_ref()) {
            let _ = write!(s, "; the log ended early: {e}");
        }
        let _ = write!(s, "; skipped lines {}", self.skipped_lines.1);
        if self.out_of_order.1 > 0 {
            let _ = write!(s, "; records out of time order {}", self.out_of_order.1);
        }
        if let Some((until, left_out)) = self.cut {
            let _ = write!(
                s,
                "; no clean end (the recorder was stopped abruptly): replayed up to ({until}), \
                 the last moment every file covers, {left_out} records after it left out"
            );
        }
        if let Some(bytes) = self.peak_memory {
            let _ = write!(s, "; peak memory {:.1} MB", bytes as f64 / 1e6);
        }
        s
    }
}

fn join(s: &mut String, items: impl Iterator<Item = String>) {
    for (i, item) in items.enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        s.push_str(&item);
    }
}
