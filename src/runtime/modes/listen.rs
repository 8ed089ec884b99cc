//! `chassisd record`: every device's raw bytes and frames, and every command sent to the
//! vehicle over MQTT, into a rotating recording. Listen-only: no engine runs, so nothing is
//! decoded, commanded or transmitted.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use crate::runtime::error::{RuntimeError, invalid, io};
use tokio::sync::mpsc;

use crate::config::VehicleConfig;
use crate::engine::{Decoder, Engine};
use crate::record::segments::{Progress, Rotation, SegmentedWriter};
use crate::record::{Payload, SourceMeta};
use crate::runtime::clock::RecordClock;
use crate::runtime::drivers;
use crate::runtime::links::mqtt_observe;
use crate::runtime::mcap_sink::WithMcap;
use crate::runtime::recorder::Recorder;
use crate::vehicle::LinkState;

/// Records waiting for the recorder loop before drivers wait.
const CHANNEL: usize = 4096;
/// How often the progress line is redrawn on a terminal.
const REDRAW_EVERY: Duration = Duration::from_millis(250);
/// How often the progress is logged when standard error is no terminal (journald).
const LOG_EVERY: Duration = Duration::from_secs(60);

/// Options of `chassisd record`.
#[derive(Debug, Clone)]
pub struct ListenOptions {
    /// The vehicle configuration whose devices are recorded.
    pub config: VehicleConfig,
    /// The new folder that receives the segments.
    pub out: PathBuf,
    /// When a segment ends, and how many are kept.
    pub rotation: Rotation,
    /// Stop after this long (otherwise at SIGINT or SIGTERM).
    pub duration: Option<Duration>,
    /// Draw a progress line (standard error is a terminal).
    pub progress: bool,
    /// Write each segment's records as an MCAP file too (`recording.mcap` in its folder).
    pub mcap: bool,
}

/// What a recording session wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ListenSummary {
    /// Records written.
    pub records: u64,
    /// Bytes of records written.
    pub bytes: u64,
    /// The last segment's number.
    pub segments: u64,
    /// Segments removed to stay within the count kept.
    pub removed: u64,
    /// Records lost because the disk did not keep up.
    pub dropped: u64,
    /// How long it recorded.
    pub span: Duration,
    /// Why it stopped.
    pub stopped_by: &'static str,
}

impl ListenSummary {
    /// One line for the terminal or the log.
    pub fn line(&self) -> String {
        format!(
            "recorded {} records ({}) in {:.1} s into {} segment(s), {} removed, {} dropped; stopped by {}",
            self.records,
            indicatif::HumanBytes(self.bytes),
            self.span.as_secs_f64(),
            self.segments,
            self.removed,
            self.dropped,
            self.stopped_by
        )
    }
}

/// Records until SIGINT, SIGTERM or the duration's end.
pub async fn run(options: ListenOptions) -> crate::runtime::error::Result<ListenSummary> {
    let config = &options.config;
    if !config.has_devices() {
        return Err(RuntimeError::Failed(
            "the configuration names no device ([gnss], [imu] or a [[can]] interface), so \
             there is nothing to record"
                .into(),
        ));
    }
    let clock = RecordClock::start();
    let start = clock.now();
    let (tx, mut rx) = mpsc::channel(CHANNEL);
    let devices = drivers::start(config, clock, &tx, drivers::Mode::Listen);
    // Held for the session: a CAN driver ends when its transmit queue closes. Nothing is
    // ever queued.
    let _can_tx = devices.can_tx;
    let mut sources: Vec<SourceMeta> = devices.sources;
    if let Some(m) = &config.mqtt {
        let engine = Engine::new(config, &devices.decoders);
        for link in &m.links {
            if link.embedded_broker {
                tracing::warn!(
                    link = %link.name,
                    "the link's broker is chassisd run's embedded one, and none runs while \
                     recording; its MQTT commands are not recorded"
                );
                continue;
            }
            // The topics `chassisd run` would take commands on, on this link.
            let topics = engine.subscriptions(Some(&m.dialects_of(link)));
            let source = link.source();
            sources.push(SourceMeta::commands(&source, &format!("{source}.log")));
            mqtt_observe::spawn(link, &config.vehicle.name, topics, clock, tx.clone())?;
        }
    }
    if config.ros1.is_some() {
        tracing::warn!("ros1: the node is chassisd run's; ROS1 commands are not recorded");
    }
    if config.ros2.is_some() {
        tracing::warn!("ros2: the node is chassisd run's; ROS 2 commands are not recorded");
    }
    drop(tx);
    // The stored configuration says how the bus was used: a replay then decodes it as the
    // monitor it was, transmitting nothing.
    let mut as_recorded = config.clone();
    for bus in &mut as_recorded.can {
        bus.listen_only = true;
    }
    let nmea_sources: Vec<String> = sources
        .iter()
        .filter(|s| s.protocol.as_deref() == Some(Decoder::Nmea.protocol()))
        .map(|s| s.name.clone())
        .collect();
    let writer = SegmentedWriter::create(
        &options.out,
        &config.vehicle.name,
        start,
        Some(&as_recorded.to_effective_toml()),
        sources,
        options.rotation,
    )
    .map_err(invalid(format!(
        "cannot start recording in {}",
        options.out.display()
    )))?;
    let progress = writer.progress();
    let mut recorder = if options.mcap {
        let with_mcap =
            WithMcap::new(writer, options.out.clone(), nmea_sources).map_err(invalid(format!(
                "cannot start the MCAP file in {}",
                options.out.display()
            )))?;
        Recorder::start(with_mcap)
    } else {
        Recorder::start(writer)
    };
    tracing::info!(folder = %options.out.display(), max_bytes = options.rotation.max_bytes,
        max_span_s = options.rotation.max_span.as_secs_f64(), keep = ?options.rotation.keep,
        "recording, listen-only: nothing is sent to any device");

    let mut display = Display::new(options.progress, progress.clone());
    let mut links: BTreeMap<String, LinkState> = BTreeMap::new();
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .map_err(io("cannot install the SIGTERM handler"))?;
    let mut sigint = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::interrupt())
        .map_err(io("cannot install the SIGINT handler"))?;
    let end = options.duration.map(|d| tokio::time::Instant::now() + d);
    let mut redraw = tokio::time::interval(REDRAW_EVERY);
    let mut drivers_running = true;
    let stopped_by = loop {
        tokio::select! {
            record = rx.recv(), if drivers_running => {
                let Some(record) = record else {
                    drivers_running = false;
                    continue;
                };
                if let Payload::Link(state) = record.payload {
                    links.insert(record.source.clone(), state);
                }
                recorder.record(record);
            }
            _ = redraw.tick() => display.show(clock.now().saturating_since(start), &links),
            () = sleep_until(end) => break "duration",
            _ = sigint.recv() => break "SIGINT",
            _ = sigterm.recv() => break "SIGTERM",
        }
    };
    let stop = clock.now();
    let dropped = recorder.dropped();
    if dropped > 0 {
        tracing::error!(dropped, "recording is incomplete: the disk did not keep up");
    }
    recorder.finish(stop);
    display.finish();
    Ok(ListenSummary {
        records: progress.records.load(Ordering::Relaxed),
        bytes: progress.bytes.load(Ordering::Relaxed),
        segments: progress.segment.load(Ordering::Relaxed),
        removed: progress.removed.load(Ordering::Relaxed),
        dropped,
        span: stop.saturating_since(start),
        stopped_by,
    })
}

/// Sleeps until `end`, or for ever.
async fn sleep_until(end: Option<tokio::time::Instant>) {
    match end {
        Some(end) => tokio::time::sleep_until(end).await,
        None => std::future::pending().await,
    }
}

/// The progress: a line redrawn on a terminal, or a log line now and then.
struct Display {
    bar: Option<indicatif::ProgressBar>,
    counters: Arc<Progress>,
    logged: Duration,
}

impl Display {
    fn new(terminal: bool, counters: Arc<Progress>) -> Self {
        let bar = terminal.then(|| {
            let bar = indicatif::ProgressBar::new_spinner();
            bar.set_style(
                indicatif::ProgressStyle::with_template(
                    "{spinner} recording {elapsed_precise} {msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
            );
            bar
        });
        Self {
            bar,
            counters,
            logged: Duration::ZERO,
        }
    }

    fn show(&mut self, elapsed: Duration, links: &BTreeMap<String, LinkState>) {
        let c = &self.counters;
        let records = c.records.load(Ordering::Relaxed);
        let bytes = c.bytes.load(Ordering::Relaxed);
        let segment = c.segment.load(Ordering::Relaxed);
        let devices = links
            .iter()
            .map(|(name, state)| {
                let state = match state {
                    LinkState::Up => "up",
                    LinkState::Down => "DOWN",
                };
                format!("{name} {state}")
            })
            .collect::<Vec<_>>()
            .join(", ");
        match &self.bar {
            Some(bar) => bar.set_message(format!(
                "· segment {segment:04} · {records} records · {} · {devices}",
                indicatif::HumanBytes(bytes)
            )),
            None if elapsed >= self.logged + LOG_EVERY => {
                self.logged = elapsed;
                tracing::info!(
                    elapsed_s = elapsed.as_secs(),
                    records,
                    bytes,
                    segment,
                    %devices,
                    "recording"
                );
            }
            None => {}
        }
    }

    fn finish(self) {
        if let Some(bar) = self.bar {
            bar.finish_and_clear();
        }
    }
}
