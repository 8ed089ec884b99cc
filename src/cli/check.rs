//! `chassisd check`.

use std::path::PathBuf;

use super::block_on;
use chassisd::config::{ReceiverKind, VehicleConfig};
use chassisd::devices::gnss::ubx::config::Layers;
use chassisd::runtime::modes::check;

/// Check a vehicle configuration and probe each of its devices once: serial ports
/// (valid sentences or frames), a u-blox receiver's firmware (MON-VER), CAN interfaces
/// (up), drives (an SDO read), the BMS and the broker. Prints a table with ok or the reason
/// and the fix; exits 1 when a probe failed, 78 when the configuration is wrong.
#[derive(clap::Args)]
pub struct Args {
    /// Vehicle configuration (TOML).
    #[arg(long)]
    config: PathBuf,
    /// Also set a u-blox receiver (gnss.receiver = "ublox") to send what chassisd reads:
    /// UBX out, RTCM in, NAV-PVT, NAV-HPPOSLLH, NAV-COV, NAV-RELPOSNED, NAV-DOP and
    /// RXM-RTCM once per epoch; in RAM only (lost at power off) unless --flash.
    #[arg(long)]
    configure: bool,
    /// With --configure: write flash too, so the settings survive a power cycle.
    #[arg(long, requires = "configure")]
    flash: bool,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    let vehicle = VehicleConfig::load(&a.config)?;
    println!("configuration {}: ok", a.config.display());
    let layers = match (a.configure, a.flash) {
        (false, _) => None,
        (true, false) => Some(Layers::Ram),
        (true, true) => Some(Layers::RamAndFlash),
    };
    if layers.is_some()
        && vehicle
            .gnss
            .as_ref()
            .is_none_or(|g| g.receiver != ReceiverKind::Ublox)
    {
        anyhow::bail!(
            "--configure sets a u-blox receiver, and the configuration names none; \
             set gnss.receiver = \"ublox\""
        );
    }
    let probes = block_on(1, check::run(&vehicle, layers))?;
    print!("{}", check::table(&probes));
    Ok(probes.iter().all(|p| p.result.is_ok()))
}
