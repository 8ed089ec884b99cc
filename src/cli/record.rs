//! `chassisd record`.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Duration;

use super::{block_on, seconds_arg};
use chassisd::config::VehicleConfig;
use chassisd::record::segments::Rotation;
use chassisd::runtime::modes::listen::{self, ListenOptions};

/// Record every raw frame of every device, and every command sent to the vehicle over
/// MQTT, without driving anything (listen-only: no engine, nothing transmitted). Writes
/// segments DIR/0001, DIR/0002, … (each a recording that replays on its own), rotated by
/// size or time; the oldest beyond --keep are removed. Stops at SIGINT or SIGTERM.
#[derive(clap::Args)]
pub struct Args {
    /// Vehicle configuration (TOML).
    #[arg(long)]
    config: PathBuf,
    /// New folder for the segments.
    #[arg(long)]
    out: PathBuf,
    /// A segment ends once it holds this many megabytes (10^6 bytes).
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u64).range(1..))]
    segment_mb: u64,
    /// A segment ends once it spans this many seconds.
    #[arg(long, default_value = "3600", value_parser = seconds_arg)]
    segment_s: Duration,
    /// Keep at most this many segments, removing the oldest (0: keep all).
    #[arg(long, default_value_t = 48)]
    keep: usize,
    /// Stop after this many seconds.
    #[arg(long, value_parser = seconds_arg)]
    duration: Option<Duration>,
    /// Also write each segment as an MCAP file (recording.mcap in the segment's folder: the
    /// raw chunks, NMEA sentences, CAN frames and commands on a channel per source, as
    /// `chassisd export` writes them), its chunks on disk at least every second.
    #[arg(long)]
    mcap: bool,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    let options = ListenOptions {
        config: VehicleConfig::load(&a.config)?,
        out: a.out,
        rotation: Rotation {
            max_bytes: a.segment_mb.saturating_mul(1_000_000),
            max_span: a.segment_s,
            keep: (a.keep > 0).then_some(a.keep),
        },
        duration: a.duration,
        progress: std::io::stderr().is_terminal(),
        mcap: a.mcap,
    };
    let summary = block_on(1, listen::run(options))??;
    eprintln!("{}", summary.line());
    Ok(summary.dropped == 0)
}
