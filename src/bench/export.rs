//! `chassisd bench export`: how fast `chassisd export --mcap` turns a recording into an MCAP
//! file, and in how much memory: the longest recording among the fixtures, and a synthetic
//! one of the simulated vehicle (`chassisd sim --fast --record`, an hour by default). Each
//! export is a child process of the daemon's binary, timed on the wall clock; its peak memory
//! comes from its summary.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::bench::error::{BenchError, Result, io};
use crate::bench::real::Scratch;
use crate::bench::replay::peak_from_summary;
use crate::record::RecordingReader;

/// The export must run at least this many times faster than the recording's span.
pub const TARGET_SPEED: f64 = 100.0;
/// Its peak resident memory must stay under this, bytes, whatever the length.
pub const TARGET_PEAK_BYTES: u64 = 64_000_000;

/// One recording's figures.
#[derive(Debug, Clone, Serialize)]
pub struct ExportFigures {
    /// What was exported.
    pub recording: String,
    /// Its span, s.
    pub span_s: f64,
    /// Its files, bytes.
    pub recording_bytes: u64,
    /// The export's wall time, s.
    pub export_s: f64,
    /// Span over wall time.
    pub times_real_time: f64,
    /// Messages written.
    pub messages: u64,
    /// The MCAP file, bytes.
    pub mcap_bytes: u64,
    /// The recording's bytes read per second of export, MB/s.
    pub input_mb_per_s: f64,
    /// The export's peak resident memory, bytes.
    pub peak_bytes: Option<u64>,
}

impl ExportFigures {
    /// Whether it meets the targets.
    pub fn pass(&self) -> bool {
        self.times_real_time >= TARGET_SPEED
            && self.peak_bytes.is_some_and(|p| p <= TARGET_PEAK_BYTES)
    }
}

/// Every recording's figures.
#[derive(Debug, Clone, Serialize)]
pub struct ExportReport {
    /// The fixture, then the synthetic recording.
    pub recordings: Vec<ExportFigures>,
    /// Whether every one met the targets.
    pub pass: bool,
}

impl ExportReport {
    /// The table for a person.
    pub fn table(&self) -> String {
        let mut s = String::from(
            "| recording | span | recording MB | export s | × real time | messages | MCAP MB | MB/s in | peak MB |\n|---|---|---|---|---|---|---|---|---|\n",
        );
        for f in &self.recordings {
            s += &format!(
                "| {} | {:.0} s | {:.1} | {:.2} | {:.0} | {} | {:.1} | {:.1} | {} |\n",
                f.recording,
                f.span_s,
                f.recording_bytes as f64 / 1e6,
                f.export_s,
                f.times_real_time,
                f.messages,
                f.mcap_bytes as f64 / 1e6,
                f.input_mb_per_s,
                f.peak_bytes
                    .map_or("?".into(), |p| format!("{:.1}", p as f64 / 1e6)),
            );
        }
        s += &format!(
            "targets: at least {TARGET_SPEED:.0}× real time, peak memory at most {:.0} MB\n",
            TARGET_PEAK_BYTES as f64 / 1e6
        );
        s
    }

    /// The last line: JSON.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// Exports the longest recording in `fixtures` and a synthetic recording of `synthetic`
/// simulated time with the daemon `chassisd`.
pub fn run(chassisd: &Path, fixtures: &Path, synthetic: Duration) -> Result<ExportReport> {
    let scratch = Scratch::new("export")?;
    let mut recordings = Vec::new();
    if let Some(fixture) = longest(fixtures) {
        recordings.push(export(chassisd, &fixture, scratch.path())?);
    }
    let sim = scratch.path().join("synthetic");
    let status = Command::new(chassisd)
        .args(["sim", "--fast", "--duration"])
        .arg(synthetic.as_secs().to_string())
        .arg("--record")
        .arg(&sim)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .map_err(io("running chassisd sim --fast"))?;
    if !status.success() {
        return Err(BenchError::Failed(format!(
            "chassisd sim --fast --record failed ({status})"
        )));
    }
    recordings.push(export(chassisd, &sim, scratch.path())?);
    let pass = recordings.iter().all(ExportFigures::pass);
    Ok(ExportReport { recordings, pass })
}

/// The recording folder in `dir` with the longest span.
fn longest(dir: &Path) -> Option<PathBuf> {
    std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter_map(|p| Some((span_s(&p)?, p)))
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, p)| p)
}

/// A recording's span from its metadata, s.
fn span_s(dir: &Path) -> Option<f64> {
    let (meta, _) = RecordingReader::open(dir).ok()?;
    Some((meta.end_us? - meta.start_us?) as f64 * 1e-6)
}

/// The bytes of the files in `dir`.
fn folder_bytes(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok()?.metadata().ok())
                .filter(|m| m.is_file())
                .map(|m| m.len())
                .sum()
        })
        .unwrap_or(0)
}

/// `chassisd export RECORDING --mcap` into `scratch`, timed.
fn export(chassisd: &Path, recording: &Path, scratch: &Path) -> Result<ExportFigures> {
    let span = span_s(recording).ok_or_else(|| {
        BenchError::Failed(format!("{}: no span in its meta.toml", recording.display()))
    })?;
    let file = scratch.join("export.mcap");
    let started = Instant::now();
    let out = Command::new(chassisd)
        .arg("export")
        .arg(recording)
        .arg("--mcap")
        .arg(&file)
        .arg("--lenient")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .map_err(io("running chassisd export"))?;
    let export_s = started.elapsed().as_secs_f64();
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        return Err(BenchError::Failed(format!(
            "chassisd export {}: {stderr}",
            recording.display()
        )));
    }
    let messages = stderr
        .rsplit_once("export: ")
        .and_then(|(_, rest)| rest.split(' ').next()?.parse().ok())
        .unwrap_or(0);
    let recording_bytes = folder_bytes(recording);
    let mcap_bytes = std::fs::metadata(&file).map_or(0, |m| m.len());
    let _ = std::fs::remove_file(&file);
    Ok(ExportFigures {
        recording: recording
            .file_name()
            .map_or("?".into(), |n| n.to_string_lossy().into_owned()),
        span_s: span,
        recording_bytes,
        export_s,
        times_real_time: span / export_s.max(1e-9),
        messages,
        mcap_bytes,
        input_mb_per_s: recording_bytes as f64 / 1e6 / export_s.max(1e-9),
        peak_bytes: peak_from_summary(&stderr),
    })
}
