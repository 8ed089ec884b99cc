//! `chassisd export`.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;

use super::seconds_arg;
use chassisd::config::VehicleConfig;
use chassisd::record::nmea_import::ImportOptions;
use chassisd::replay::{ReplayOptions, mcap};

/// Replay a recording folder (or a plain NMEA log) through the engine into an MCAP file for
/// Foxglove: every raw serial chunk, NMEA sentence, CAN frame and command on a channel of its
/// source (/raw/...), and what chassisd made of them in Foxglove's schemas (/gnss/fix,
/// /fused/fix, /fused/pose, /tf, /zones, /plan, /events) and as JSON (/status/...). The
/// topics are listed in docs/foxglove.md.
#[derive(clap::Args)]
pub struct Args {
    /// Recording folder (with meta.toml) or NMEA text log.
    path: PathBuf,
    /// The MCAP file to write (replaced if it exists).
    #[arg(long, value_name = "FILE")]
    mcap: PathBuf,
    /// Vehicle configuration to use instead of the one stored with the recording.
    #[arg(long)]
    config: Option<PathBuf>,
    /// In a plain NMEA log, a forward step of the clock longer than this (seconds)
    /// starts a new segment instead of ticking through the gap.
    #[arg(long, default_value = "10", value_parser = seconds_arg)]
    max_gap: Duration,
    /// Accept records that go back in time within a file, and regenerated transmissions
    /// that differ from the recorded ones (as `replay --lenient`).
    #[arg(long)]
    lenient: bool,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    let options = ReplayOptions {
        config: a.config.map(|p| VehicleConfig::load(&p)).transpose()?,
        stamped: false,
        import: ImportOptions { max_gap: a.max_gap },
        corrections_out: None,
        progress: true,
    };
    let (summary, written) = mcap::export(&a.path, &options, &a.mcap)
        .with_context(|| format!("export of {} to {}", a.path.display(), a.mcap.display()))?;
    let pass = super::replay::report(&summary, a.lenient);
    eprintln!(
        "export: {} messages ({:.1} MB of JSON) in {} ({:.1} MB)",
        written.messages,
        written.message_bytes as f64 / 1e6,
        a.mcap.display(),
        written.file_bytes as f64 / 1e6
    );
    Ok(pass)
}
