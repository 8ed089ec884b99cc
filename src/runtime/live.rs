//! Live mode: drivers feed the engine task, which owns the core, ticks at 10 Hz and writes
//! base_status lines.

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use tokio::sync::mpsc;

use super::clock::RecordClock;
use super::recorder::Recorder;
use super::serial::{self, SerialSpec};
use crate::api::rtk::BaseStatus;
use crate::config::VehicleConfig;
use crate::core::{CoreConfig, Output};
use crate::devices::gnss::GnssStats;
use crate::engine::{Decoder, Engine};
use crate::record::{RecordingWriter, SourceKind, SourceMeta};

/// Records waiting for the engine before drivers wait.
const CHANNEL: usize = 1024;
/// How often fault counters are summarised in the log.
const SUMMARY_EVERY: Duration = Duration::from_secs(30);
/// Source name of the GNSS receiver.
pub const GNSS_SOURCE: &str = "gnss";

/// Options of `chassisd run`.
#[derive(Debug, Clone)]
pub struct LiveOptions {
    /// The vehicle configuration.
    pub config: VehicleConfig,
    /// Its TOML text, copied into recordings.
    pub config_text: Option<String>,
    /// Record every raw chunk into this folder.
    pub record: Option<PathBuf>,
}

/// Runs until SIGINT or SIGTERM, writing base_status lines to `out`.
pub async fn run(options: LiveOptions, mut out: impl Write) -> anyhow::Result<()> {
    let clock = RecordClock::start();
    let start = clock.now();
    let (tx, mut rx) = mpsc::channel(CHANNEL);
    let mut sources = Vec::new();
    let mut source_meta = Vec::new();
    if let Some(gnss) = &options.config.gnss {
        sources.push((GNSS_SOURCE.to_owned(), Decoder::Nmea));
        source_meta.push(SourceMeta {
            name: GNSS_SOURCE.into(),
            kind: SourceKind::Serial,
            file: format!("{GNSS_SOURCE}.log"),
            protocol: Some("nmea0183".into()),
        });
        let spec = SerialSpec {
            source: GNSS_SOURCE.into(),
            port: gnss.port.clone(),
            baud: gnss.baud,
            reconnect_max: gnss.reconnect_max(),
        };
        tokio::spawn(serial::run(spec, clock, tx.clone()));
    } else {
        tracing::warn!("no devices configured; status will show every sensor absent");
    }
    drop(tx);

    let mut recorder = match &options.record {
        Some(dir) => {
            let writer = RecordingWriter::create(
                dir,
                &options.config.vehicle.name,
                start,
                options.config_text.as_deref(),
                source_meta,
            )
            .with_context(|| format!("cannot start recording in {}", dir.display()))?;
            tracing::info!(folder = %dir.display(), "recording");
            Some(Recorder::start(writer))
        }
        None => None,
    };

    let mut engine = Engine::new(CoreConfig::from_vehicle(&options.config), &sources);
    engine.start_at(start);
    let mut outputs = Vec::new();
    let mut summary = tokio::time::interval(SUMMARY_EVERY);
    let mut reported: Vec<(String, GnssStats)> = Vec::new();
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .context("cannot install the SIGTERM handler")?;
    // With no device configured there is no driver, but status still ticks.
    let mut drivers_running = !sources.is_empty();
    let result = loop {
        let next_tick = engine.next_tick().unwrap_or_else(|| clock.now());
        tokio::select! {
            record = rx.recv(), if drivers_running => {
                let Some(mut record) = record else {
                    drivers_running = false;
                    continue;
                };
                record.t = engine.handle(&record, &mut outputs);
                if let Some(r) = recorder.as_mut() {
                    r.record(record);
                }
            }
            () = tokio::time::sleep_until(clock.instant_at(next_tick)) => {
                engine.advance_to(next_tick, &mut outputs);
            }
            _ = summary.tick() => {
                summarise_faults(&engine, &mut reported);
            }
            _ = tokio::signal::ctrl_c() => break Ok(()),
            _ = sigterm.recv() => break Ok(()),
        }
        if let Err(e) = write_statuses(&mut outputs, &mut out) {
            break Err(e).context("cannot write status output");
        }
    };
    // The ticks up to the stop, so a replay of the recording ends where this run ended.
    let end = clock.now();
    engine.advance_to(end, &mut outputs);
    let flushed = write_statuses(&mut outputs, &mut out);
    if let Some(r) = recorder {
        if r.dropped() > 0 {
            tracing::error!(dropped = r.dropped(), "recording is incomplete");
        }
        r.finish(end);
    }
    summarise_faults(&engine, &mut reported);
    result.and(flushed.context("cannot write status output"))
}

fn write_statuses(outputs: &mut Vec<Output>, out: &mut impl Write) -> std::io::Result<()> {
    if outputs.is_empty() {
        return Ok(());
    }
    for output in outputs.drain(..) {
        let Output::Status(status) = output;
        let mut line = BaseStatus::from_status(&status).to_json();
        line.push('\n');
        out.write_all(line.as_bytes())?;
    }
    out.flush()
}

/// Logs the GNSS fault counters when they changed since the last summary.
fn summarise_faults(engine: &Engine, reported: &mut Vec<(String, GnssStats)>) {
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
                + s.decode_errors
        };
        if faults(stats) != faults(&before) || f.bytes_skipped != b.bytes_skipped {
            tracing::warn!(
                device = %name,
                checksum_errors = f.checksum_errors - b.checksum_errors,
                missing_checksums = f.missing_checksum - b.missing_checksum,
                truncated = f.truncated - b.truncated,
                overlong = f.overlong - b.overlong,
                bytes_skipped = f.bytes_skipped - b.bytes_skipped,
                decode_errors = stats.decode_errors - before.decode_errors,
                last_decode_error = ?stats.last_decode_error.as_ref().map(|e| e.to_string()),
                "stream faults since the last summary"
            );
        }
    }
    *reported = now;
}
