//! `chassisd replay`.

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;

use super::seconds_arg;
use chassisd::config::VehicleConfig;
use chassisd::record::nmea_import::ImportOptions;
use chassisd::replay::{self, ReplayOptions};

/// Replay a recording folder or a plain NMEA log; print one base_status JSON line per
/// 100 ms of recorded time.
#[derive(clap::Args)]
pub struct Args {
    /// Recording folder (with meta.toml) or NMEA text log.
    path: PathBuf,
    /// Vehicle configuration to use instead of the one stored with the recording.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Add `stamp`, the recorded time in seconds, to each line (for analysis; the lines
    /// then leave the protocol's schema).
    #[arg(long)]
    stamped: bool,
    /// In a plain NMEA log, a forward step of the clock longer than this (seconds)
    /// starts a new segment instead of ticking through the gap.
    #[arg(long, default_value = "10", value_parser = seconds_arg)]
    max_gap: Duration,
    /// Accept records that go back in time within a file, and regenerated transmissions
    /// that differ from the recorded ones (both are reported either way; without this
    /// the replay exits 1).
    #[arg(long)]
    lenient: bool,
    /// Write the RTCM corrections the replayed run relays to the receiver (whole valid
    /// frames, in order: what live mode wrote to the receiver's port) to FILE.
    #[arg(long, value_name = "FILE")]
    corrections_out: Option<PathBuf>,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    let options = ReplayOptions {
        config: a.config.map(|p| VehicleConfig::load(&p)).transpose()?,
        stamped: a.stamped,
        import: ImportOptions { max_gap: a.max_gap },
        corrections_out: a.corrections_out,
        progress: true,
    };
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::with_capacity(1 << 16, stdout.lock());
    let summary = replay::replay(&a.path, &options, &mut out)
        .with_context(|| format!("replay of {}", a.path.display()))?;
    out.flush()?;
    Ok(report(&summary, a.lenient))
}

/// Prints what the replay went through on stderr; whether it passes (records out of order
/// and transmissions that differ fail it unless `lenient`).
pub fn report(summary: &replay::ReplaySummary, lenient: bool) -> bool {
    for skip in &summary.skipped_lines.0 {
        eprintln!("skipped {}:{}: {}", skip.file, skip.line, skip.reason);
    }
    for late in &summary.out_of_order.0 {
        eprintln!(
            "out of time order {}:{}: {}",
            late.file, late.line, late.reason
        );
    }
    for (name, protocol) in &summary.sources_without_decoder {
        eprintln!("source {name:?} is not decoded ({protocol}); its frames are counted only");
    }
    if let Some(import) = &summary.import
        && !import.date_known
    {
        eprintln!("no RMC or ZDA date in the log; 1970-01-01 assumed");
    }
    for correction in &summary.span_corrections {
        eprintln!("meta.toml: {correction}");
    }
    eprintln!("{}", summary.one_line());
    let late = summary.out_of_order.1;
    if late > 0 && !lenient {
        eprintln!(
            "{late} records go back in time within their file: the recording was \
             edited or its clock stepped; exit status 1 (--lenient accepts them)"
        );
    }
    let differ = summary.engine.tx_mismatched;
    if differ > 0 && !lenient {
        eprintln!(
            "{differ} transmissions differ from the recording's: this chassisd does \
             not drive the vehicle as the recorded one did; exit status 1 (--lenient \
             accepts them)"
        );
    }
    (late == 0 && differ == 0) || lenient
}
