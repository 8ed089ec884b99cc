//! `chassisd check`.

use std::path::PathBuf;

use super::block_on;
use chassisd::config::VehicleConfig;
use chassisd::runtime::modes::check;

/// Check a vehicle configuration and probe each of its devices once: serial ports
/// (valid sentences or frames), CAN interfaces (up), drives (an SDO read), the BMS and
/// the broker. Prints a table with ok or the reason and the fix; exits 1 when a probe
/// failed, 78 when the configuration is wrong.
#[derive(clap::Args)]
pub struct Args {
    /// Vehicle configuration (TOML).
    #[arg(long)]
    config: PathBuf,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    let vehicle = VehicleConfig::load(&a.config)?;
    println!("configuration {}: ok", a.config.display());
    let probes = block_on(1, check::run(&vehicle))?;
    print!("{}", check::table(&probes));
    Ok(probes.iter().all(|p| p.result.is_ok()))
}
