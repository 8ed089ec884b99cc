//! `chassisd ntrip`.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;

use super::{block_on, seconds_arg};
use chassisd::devices::gnss::encode::GgaFix;
use chassisd::ntrip::request::Version;
use chassisd::ntrip::url::{NtripUrl, Password};
use chassisd::runtime::links::ntrip::{NtripSpec, fetch};

/// Fetch RTK corrections from an NTRIP caster with chassisd's client and write the valid
/// RTCM 3 frames, whole and in order, to a file or a serial port (a receiver); prints the
/// frames per message number at the end as JSON. For trying a caster and a mountpoint.
#[derive(clap::Args)]
pub struct Args {
    /// The caster: ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT (ntrips:// for TLS).
    url: String,
    /// A file with the password (its first line), instead of one in the URL.
    #[arg(long)]
    password_file: Option<PathBuf>,
    /// With ntrips://: the caster's certificate authority (PEM), trusted besides the
    /// system's roots.
    #[arg(long, value_name = "FILE")]
    ca_file: Option<PathBuf>,
    /// NTRIP version to ask for (a 1.0 answer is taken either way).
    #[arg(long, default_value = "2", value_parser = ["1", "2"])]
    version: String,
    /// Send the position as GGA every this many seconds (0: never).
    #[arg(long, default_value = "10")]
    gga_interval: f64,
    /// The position for the GGA: latitude, longitude (degrees), height (m).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    position: Option<Vec<f64>>,
    /// Drop a connection with no valid frame for this long, s.
    #[arg(long, default_value = "10", value_parser = seconds_arg)]
    timeout: Duration,
    /// Write the frames to this file ...
    #[arg(long, conflicts_with = "port")]
    out: Option<PathBuf>,
    /// ... or to this serial port.
    #[arg(long)]
    port: Option<String>,
    /// The port's baud rate.
    #[arg(long, default_value = "115200")]
    baud: u32,
    /// Stop after this long, s (default: at Ctrl-C).
    #[arg(long, value_parser = seconds_arg)]
    duration: Option<Duration>,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    let mut url = NtripUrl::parse(&a.url)?;
    if let Some(file) = &a.password_file {
        let text = std::fs::read_to_string(file)
            .with_context(|| format!("cannot read the password file {}", file.display()))?;
        url.password = Password::new(text.lines().next().unwrap_or("").trim_end());
    }
    anyhow::ensure!(
        a.gga_interval == 0.0 || (1.0..=3600.0).contains(&a.gga_interval),
        "--gga-interval must be 0 (none) or 1 to 3600 s"
    );
    let position = match a.position.as_deref() {
        Some(&[lat, lon, h]) => {
            anyhow::ensure!(
                (-90.0..=90.0).contains(&lat) && (-180.0..=180.0).contains(&lon) && h.is_finite(),
                "--position: latitude -90 to 90, longitude -180 to 180, a finite height"
            );
            Some(GgaFix::fallback(lat, lon, h))
        }
        Some(_) => anyhow::bail!("--position takes latitude,longitude,height"),
        None => None,
    };
    let url_tls = url.tls;
    let spec = NtripSpec {
        url,
        version: if a.version == "1" {
            Version::V1
        } else {
            Version::V2
        },
        gga_interval: (a.gga_interval > 0.0).then(|| Duration::from_secs_f64(a.gga_interval)),
        timeout: a.timeout,
        tls: if url_tls {
            Some(
                chassisd::ntrip::tls::client_config(a.ca_file.as_deref(), "--ca-file")
                    .map_err(anyhow::Error::msg)?,
            )
        } else {
            None
        },
        ca_setting: "--ca-file",
    };
    let report = block_on(1, async {
        let out: Box<dyn tokio::io::AsyncWrite + Unpin + Send> = match (&a.out, &a.port) {
            (Some(path), _) => Box::new(
                tokio::fs::File::create(path)
                    .await
                    .with_context(|| format!("cannot create {}", path.display()))?,
            ),
            (None, Some(port)) => {
                use tokio_serial::SerialPortBuilderExt;
                let serial = tokio_serial::new(port, a.baud)
                    .open_native_async()
                    .map_err(|e| {
                        let advice = chassisd::runtime::drivers::serial_open::advice(port, &e);
                        anyhow::anyhow!("cannot open {port}: {e}; {advice}")
                    })?;
                Box::new(serial)
            }
            (None, None) => Box::new(tokio::io::stdout()),
        };
        anyhow::Ok(fetch(spec, position, out, a.duration).await?)
    })??;
    eprintln!(
        "ntrip: {} frames ({} bytes) written, {} invalid bytes dropped, {} connects, {} GGA sent{}",
        report.frames,
        report.bytes,
        report.invalid_bytes,
        report.attempts,
        report.ggas_sent,
        report
            .last_error
            .as_deref()
            .map(|e| format!("; last: {e}"))
            .unwrap_or_default()
    );
    eprintln!("{}", serde_json::to_string(&report)?);
    Ok(report.frames > 0)
}
