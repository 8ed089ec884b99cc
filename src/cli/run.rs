//! `chassisd run`.

use std::path::{Path, PathBuf};

use super::{block_on, ensure_ros1_built, ensure_ros2, ntrip_override};
use chassisd::config::{ConfigError, VehicleConfig};
use chassisd::runtime::modes::live::{self, LiveOptions};

/// Run live on the configured devices; print base_status JSON lines at 10 Hz.
#[derive(clap::Args)]
pub struct Args {
    /// Vehicle configuration (TOML).
    #[arg(long)]
    config: PathBuf,
    /// Record every raw chunk, frame and command into this new folder.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Read commands from standard input, one `TOPIC JSON` per line
    /// (e.g. `cmd_vel {"linear":{"x":0.2},"angular":{"z":0}}`).
    #[arg(long)]
    commands_stdin: bool,
    /// Join the ROS1 graph of this master as a node (ros1-navigation-interface.txt),
    /// over the configuration's `[ros1]` master_uri.
    #[arg(long, value_name = "URI")]
    ros_master: Option<String>,
    /// Join ROS 2 (DDS) as a node: the configuration's `[ros2]`, or its defaults (domain
    /// ROS_DOMAIN_ID or 0, this machine only).
    #[arg(long)]
    ros2: bool,
    /// Serve the rosbridge v2 WebSocket topics on ADDR (e.g. 127.0.0.1:9090), over the
    /// configuration's `[websocket]` bind.
    #[arg(long, value_name = "ADDR")]
    websocket: Option<String>,
    /// Fetch RTK corrections from this NTRIP caster
    /// (ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT), over the configuration's `[ntrip]`
    /// url.
    #[arg(long, value_name = "URL")]
    ntrip: Option<String>,
    /// Keep the vehicle to the zones of this GeoJSON file, over the configuration's
    /// `[zones]` file (its footprint and thresholds kept: the section is needed).
    #[arg(long, value_name = "FILE")]
    zones: Option<PathBuf>,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    let mut vehicle = VehicleConfig::load(&a.config)?;
    if a.ros2 && vehicle.ros2.is_none() {
        vehicle.ros2 = Some(Default::default());
    }
    ensure_ros2(vehicle.ros2.as_ref(), &a.config)?;
    vehicle.require_devices(&a.config)?;
    if let Some(url) = a.ntrip {
        vehicle.ntrip = Some(ntrip_override(vehicle.ntrip.take(), &url)?);
    }
    if let Some(file) = a.zones {
        let Some(mut zones) = vehicle.zones.take() else {
            return Err(ConfigError::invalid(
                &a.config,
                "zones",
                "--zones needs the vehicle's outline, and the configuration has no [zones]",
                "add [zones] with footprint = { front_m, rear_m, width_m }",
            )
            .into());
        };
        zones.file = Some(file.clone());
        zones.geojson = None;
        zones.load(Path::new("."), &file)?;
        vehicle.zones = Some(zones);
    }
    if let Some(bind) = a.websocket {
        let mut w = vehicle.websocket.take().unwrap_or_default();
        w.bind = bind;
        w.validate(Path::new("--websocket"))?;
        vehicle.websocket = Some(w);
    }
    if let Some(uri) = a.ros_master {
        let mut ros1 = vehicle.ros1.take().unwrap_or_default();
        ros1.master_uri = uri;
        ros1.validate(Path::new("--ros-master"))?;
        vehicle.ros1 = Some(ros1);
    }
    ensure_ros1_built(vehicle.ros1.is_some())?;
    let options = LiveOptions {
        config: vehicle,
        record: a.record,
        commands_stdin: a.commands_stdin,
        pattern: None,
    };
    block_on(2, live::run(options, std::io::stdout()))??;
    Ok(true)
}
