//! `chassisd can-sim`.

use std::path::PathBuf;

use super::block_on;
use chassisd::config::VehicleConfig;

/// Simulate the CAN devices of a vehicle configuration (drives, BMS) on its CAN
/// interfaces, e.g. vcan0. Standard input takes fault injections; see docs/simulator.md.
#[derive(clap::Args)]
pub struct Args {
    /// Vehicle configuration whose [[can]], [[drive]] and [bms] are simulated.
    #[arg(long)]
    config: PathBuf,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    let vehicle = VehicleConfig::load(&a.config)?;
    block_on(1, chassisd::runtime::modes::can_sim::run(vehicle))??;
    Ok(true)
}
