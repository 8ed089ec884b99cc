//! `chassisd bench replay`: plain-log replay against gpsd's `gpsdecode` on the same bytes.
//!
//! The input is real receiver logs repeated up to a size: all of them concatenated (the
//! comparison the targets name), then each receiver alone, since the work per byte depends
//! on the receiver (a 1 Hz NMEA-only log gives ten status lines per kilobyte, a log full of
//! binary frames almost none). Each run is a child process of this binary's own `replay`,
//! output to /dev/null, timed on the wall clock (best of the runs); its peak memory comes
//! from its summary. The concatenated log is also replayed at a tenth of the size: peak
//! memory must not depend on the log's length.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::bench::error::{BenchError, invalid, io, missing};
use serde::Serialize;

/// The speed-up over gpsdecode the concatenated log must reach.
pub const TARGET_SPEEDUP: f64 = 5.0;
/// How much more peak memory the full log may take than a tenth of it, bytes.
pub const MEMORY_GROWTH_LIMIT: u64 = 2_000_000;

/// What to run.
#[derive(Debug, Clone)]
pub struct ReplayBenchOptions {
    /// Folder of receiver logs (`*.log`).
    pub data: PathBuf,
    /// Size each input is repeated up to, bytes.
    pub bytes: u64,
    /// Timed runs of each command; the fastest counts.
    pub runs: u32,
}

/// One input's figures.
#[derive(Debug, Clone, Serialize)]
pub struct InputFigures {
    /// `all` or the receiver log's name.
    pub input: String,
    /// Size, bytes.
    pub bytes: u64,
    /// chassisd replay, s.
    pub chassisd_s: f64,
    /// chassisd's peak resident memory, bytes.
    pub chassisd_peak_bytes: Option<u64>,
    /// gpsdecode on the same bytes, s (None without gpsdecode).
    pub gpsdecode_s: Option<f64>,
    /// gpsdecode's time over chassisd's.
    pub speedup: Option<f64>,
}

/// The figures.
#[derive(Debug, Clone, Serialize)]
pub struct ReplayReport {
    /// Every input, the concatenated log first.
    pub inputs: Vec<InputFigures>,
    /// Peak memory on a tenth of the concatenated log, bytes.
    pub tenth_peak_bytes: Option<u64>,
    /// Why gpsdecode was not compared, if it was not.
    pub gpsdecode_missing: Option<String>,
    /// Logs left out: their receivers send no NMEA position and no UBX NAV-PVT.
    pub skipped: Vec<String>,
    /// The targets met.
    pub pass: bool,
}

/// Runs the benchmark; `chassisd` is this program's path.
pub fn run(
    options: &ReplayBenchOptions,
    chassisd: &Path,
) -> crate::bench::error::Result<ReplayReport> {
    let (logs, skipped) = receiver_logs(&options.data)?;
    let dir = std::env::temp_dir().join(format!("chassisd-bench-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(invalid(format!("creating {}", dir.display())))?;
    let result = run_in(options, chassisd, &logs, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    result.map(|r| ReplayReport { skipped, ..r })
}

fn run_in(
    options: &ReplayBenchOptions,
    chassisd: &Path,
    logs: &[PathBuf],
    dir: &Path,
) -> crate::bench::error::Result<ReplayReport> {
    let gpsdecode_missing = super::missing_program("gpsdecode", "-V", "gpsd-clients");
    let mut inputs: Vec<(String, Vec<PathBuf>)> = vec![("all".into(), logs.to_vec())];
    for log in logs {
        let name = log.file_stem().map_or_else(
            || log.display().to_string(),
            |s| s.to_string_lossy().into_owned(),
        );
        inputs.push((name, vec![log.clone()]));
    }
    let mut figures = Vec::new();
    for (name, parts) in &inputs {
        let path = dir.join(format!("{name}.log"));
        let bytes = repeat_into(parts, options.bytes, &path)?;
        let (chassisd_s, chassisd_peak_bytes) = time_replay(chassisd, &path, options.runs)?;
        let gpsdecode_s = match gpsdecode_missing {
            None => Some(time_gpsdecode(&path, options.runs)?),
            Some(_) => None,
        };
        figures.push(InputFigures {
            input: name.clone(),
            bytes,
            chassisd_s,
            chassisd_peak_bytes,
            gpsdecode_s,
            speedup: gpsdecode_s.map(|g| g / chassisd_s),
        });
        std::fs::remove_file(&path).ok();
    }
    let tenth = dir.join("all-tenth.log");
    repeat_into(logs, options.bytes / 10, &tenth)?;
    let (_, tenth_peak_bytes) = time_replay(chassisd, &tenth, 1)?;
    let all = &figures[0];
    let fast_enough = all.speedup.is_none_or(|s| s >= TARGET_SPEEDUP);
    let flat = match (all.chassisd_peak_bytes, tenth_peak_bytes) {
        (Some(full), Some(tenth)) => full <= tenth + MEMORY_GROWTH_LIMIT,
        _ => false,
    };
    Ok(ReplayReport {
        inputs: figures,
        tenth_peak_bytes,
        gpsdecode_missing,
        skipped: Vec::new(),
        pass: fast_enough && flat,
    })
}

/// The `*.log` files in `dir` whose receivers send NMEA positions, sorted, and the names of
/// the others (binary protocols only, which chassisd does not decode yet).
fn receiver_logs(dir: &Path) -> crate::bench::error::Result<(Vec<PathBuf>, Vec<String>)> {
    let mut logs: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(invalid(format!(
            "reading the receiver logs in {}",
            dir.display()
        )))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "log"))
        .collect();
    logs.sort();
    let mut skipped = Vec::new();
    let mut nmea = Vec::new();
    for log in logs {
        let bytes = std::fs::read(&log).map_err(invalid(format!("reading {}", log.display())))?;
        if sends_nmea_positions(&bytes) || sends_nav_pvt(&bytes) {
            nmea.push(log);
        } else {
            skipped.push(format!(
                "{}: no NMEA position and no UBX NAV-PVT",
                log.display()
            ));
        }
    }
    if nmea.is_empty() {
        return Err(BenchError::Failed(format!(
            "no *.log receiver logs with NMEA positions or UBX NAV-PVT in {}",
            dir.display()
        )));
    }
    Ok((nmea, skipped))
}

/// Whether a log holds a u-blox NAV-PVT frame's header.
fn sends_nav_pvt(bytes: &[u8]) -> bool {
    bytes
        .windows(6)
        .any(|w| w == [0xb5, 0x62, 0x01, 0x07, 92, 0])
}

/// Whether a log holds an NMEA position sentence (GGA, RMC or GNS).
pub fn sends_nmea_positions(bytes: &[u8]) -> bool {
    bytes.split(|b| *b == b'\n').any(|line| {
        line.len() > 7
            && line[0] == b'$'
            && line[1..3].iter().all(u8::is_ascii_uppercase)
            && [&b"GGA,"[..], b"RMC,", b"GNS,"].contains(&&line[3..7])
    })
}

/// Writes `parts` one after the other, over and over, until `size` bytes are reached;
/// returns the size written.
fn repeat_into(parts: &[PathBuf], size: u64, path: &Path) -> crate::bench::error::Result<u64> {
    let contents = parts
        .iter()
        .map(|p| std::fs::read(p).map_err(invalid(format!("reading {}", p.display()))))
        .collect::<crate::bench::error::Result<Vec<Vec<u8>>>>()?;
    let round: u64 = contents.iter().map(|c| c.len() as u64).sum();
    if round == 0 {
        return Err(BenchError::Failed("the receiver logs are empty".into()));
    }
    let mut out = BufWriter::new(
        File::create(path).map_err(invalid(format!("creating {}", path.display())))?,
    );
    let mut written = 0;
    while written < size.max(1) {
        for c in &contents {
            out.write_all(c)
                .map_err(io(format!("writing {}", path.display())))?;
        }
        written += round;
    }
    out.flush()
        .map_err(io(format!("writing {}", path.display())))?;
    Ok(written)
}

/// Runs `once` `runs` times: the fastest wall time (s) and what that run returned.
fn fastest<T>(
    runs: u32,
    mut once: impl FnMut() -> crate::bench::error::Result<T>,
) -> crate::bench::error::Result<(f64, T)> {
    let mut best: Option<(Duration, T)> = None;
    for _ in 0..runs.max(1) {
        let start = Instant::now();
        let out = once()?;
        let took = start.elapsed();
        if best.as_ref().is_none_or(|(b, _)| took < *b) {
            best = Some((took, out));
        }
    }
    let (took, out) = best.ok_or_else(missing("no run"))?;
    Ok((took.as_secs_f64(), out))
}

/// chassisd's replay of `log`: the fastest of `runs` wall times (s), and that run's peak
/// memory.
fn time_replay(
    chassisd: &Path,
    log: &Path,
    runs: u32,
) -> crate::bench::error::Result<(f64, Option<u64>)> {
    fastest(runs, || {
        let out = Command::new(chassisd)
            .arg("replay")
            .arg(log)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .output()
            .map_err(invalid("running chassisd replay"))?;
        let stderr = String::from_utf8_lossy(&out.stderr);
        if !out.status.success() {
            return Err(BenchError::Failed(format!(
                "chassisd replay {} failed: {stderr}",
                log.display()
            )));
        }
        Ok(peak_from_summary(&stderr))
    })
}

/// The peak memory a replay summary reports ("peak memory 7.8 MB"), bytes.
pub fn peak_from_summary(stderr: &str) -> Option<u64> {
    let rest = stderr.rsplit_once("peak memory ")?.1;
    let mb: f64 = rest.split_whitespace().next()?.parse().ok()?;
    Some((mb * 1e6) as u64)
}

/// gpsdecode reading `log` on its standard input: the fastest of `runs`, s.
fn time_gpsdecode(log: &Path, runs: u32) -> crate::bench::error::Result<f64> {
    let (took, ()) = fastest(runs, || {
        let input = File::open(log).map_err(invalid(format!("opening {}", log.display())))?;
        let status = Command::new("gpsdecode")
            .stdin(input)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .map_err(invalid("running gpsdecode"))?;
        if !status.success() {
            return Err(BenchError::Failed(format!(
                "gpsdecode failed on {}: {status}",
                log.display()
            )));
        }
        Ok(())
    })?;
    Ok(took)
}

impl ReplayReport {
    /// Human-readable lines.
    pub fn table(&self) -> String {
        let mb = |b: Option<u64>| b.map_or("-".to_owned(), |b| format!("{:.1}", b as f64 / 1e6));
        let mut out = format!(
            "{:<24} {:>8} {:>11} {:>9} {:>9} {:>12} {:>8}\n",
            "input", "MB", "chassisd s", "MB/s", "peak MB", "gpsdecode s", "speedup"
        );
        for f in &self.inputs {
            out.push_str(&format!(
                "{:<24} {:>8.1} {:>11.3} {:>9.1} {:>9} {:>12} {:>8}\n",
                f.input,
                f.bytes as f64 / 1e6,
                f.chassisd_s,
                f.bytes as f64 / 1e6 / f.chassisd_s,
                mb(f.chassisd_peak_bytes),
                f.gpsdecode_s.map_or("-".to_owned(), |g| format!("{g:.3}")),
                f.speedup.map_or("-".to_owned(), |s| format!("{s:.2}x")),
            ));
        }
        out.push_str(&format!(
            "peak memory on a tenth of the concatenated log: {} MB (the full log may take {:.1} MB more)\n",
            mb(self.tenth_peak_bytes),
            MEMORY_GROWTH_LIMIT as f64 / 1e6
        ));
        if let Some(why) = &self.gpsdecode_missing {
            out.push_str(&format!("no comparison: {why}\n"));
        }
        for skipped in &self.skipped {
            out.push_str(&format!("left out: {skipped}\n"));
        }
        out
    }

    /// The one-line JSON summary.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_peak_from_a_summary() {
        let summary = "replay: 3 frames; skipped lines 0; peak memory 7.8 MB\n";
        assert_eq!(peak_from_summary(summary), Some(7_800_000));
        assert_eq!(peak_from_summary("replay: no figure"), None);
    }
}
