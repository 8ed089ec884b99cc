//! `chassisd sim`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use super::{
    block_on, ensure_ros1_built, find_scenario, load_calibration, load_plant, ntrip_override,
    scenario_names, seconds_arg, sim_mqtt,
};
use chassisd::config::ros1::Ros1Config;
use chassisd::config::websocket::WebsocketConfig;
use chassisd::config::zones::ZonesConfig;
use chassisd::runtime::modes::sim::{self, SimOptions};
use chassisd::runtime::modes::sim_fast::{self, FastOptions};

/// Run the simulated vehicle in real time through the live engine (no hardware): print
/// base_status JSON lines at 10 Hz.
#[derive(clap::Args)]
pub struct Args {
    /// Plant file (default: the built-in devices/plant.mower.toml).
    #[arg(long)]
    plant: Option<PathBuf>,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Record the session (every frame, command and transmission) into this new folder.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Read commands from standard input, one `TOPIC JSON` per line.
    #[arg(long)]
    commands_stdin: bool,
    /// Drive a scripted scenario (also those of `chassisd bench fusion`) and stop at its
    /// end. Each starts with 5 s standing still and 10 s straight.
    #[arg(long, value_parser = scenario_names())]
    scenario: Option<String>,
    /// Stop after this many seconds.
    #[arg(long, value_parser = seconds_arg)]
    duration: Option<Duration>,
    /// Use the MQTT broker at HOST:PORT instead of starting one on 127.0.0.1:1883.
    #[arg(long, value_name = "HOST:PORT", conflicts_with = "no_mqtt")]
    mqtt: Option<String>,
    /// Port of the embedded broker on 127.0.0.1 (default 1883).
    #[arg(long, conflicts_with_all = ["mqtt", "no_mqtt"])]
    broker_port: Option<u16>,
    /// No MQTT at all.
    #[arg(long)]
    no_mqtt: bool,
    /// Keep the rtk dialect's trajectories in this folder (default: in memory).
    #[arg(long, conflicts_with = "no_mqtt")]
    trajectory_dir: Option<PathBuf>,
    /// Join the ROS1 graph of this master as a node (ros1-navigation-interface.txt),
    /// e.g. http://127.0.0.1:11311.
    #[arg(long, value_name = "URI")]
    ros_master: Option<String>,
    /// Join ROS 2 (DDS) as a node with the default `[ros2]` (domain ROS_DOMAIN_ID or 0,
    /// this machine only, commands taken).
    #[arg(long, conflicts_with = "fast")]
    ros2: bool,
    /// Serve the rosbridge v2 WebSocket topics (device-mqtt-api.md) on ADDR, e.g.
    /// 127.0.0.1:9090.
    #[arg(long, value_name = "ADDR", conflicts_with = "fast")]
    websocket: Option<String>,
    /// Run in lockstep as fast as the machine allows: no wall clock, no MQTT, no
    /// standard input. Needs --scenario or --duration; --record works as without it.
    /// Not with the links that need the wall clock: --websocket, --ntrip, --zones.
    #[arg(long, conflicts_with_all = ["mqtt", "broker_port", "commands_stdin", "trajectory_dir", "ros_master"])]
    fast: bool,
    /// A calibration file for the simulated vehicle's configuration (as `[vehicle]
    /// calibration` names one on a real vehicle).
    #[arg(long, value_name = "FILE")]
    calibration: Option<PathBuf>,
    /// Fetch RTK corrections from this NTRIP caster
    /// (ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT): the simulated receiver then holds
    /// RTK fixed only while they arrive.
    #[arg(long, value_name = "URL", conflicts_with = "fast")]
    ntrip: Option<String>,
    /// Keep the vehicle to the zones of this GeoJSON file (boundaries, keep-out zones,
    /// walls), with the plant's footprint.
    #[arg(long, value_name = "FILE", conflicts_with = "fast")]
    zones: Option<PathBuf>,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    let mut plant = load_plant(a.plant)?;
    plant.calibration = load_calibration(a.calibration.as_deref())?;
    // Driven at the plant's own speed (a car drives the laps at ten times a mower's).
    let scenario = a
        .scenario
        .map(|name| find_scenario(&name))
        .transpose()?
        .map(|s| s.at_speed(plant.drive.scenario_speed));
    if a.fast {
        let options = FastOptions {
            plant,
            seed: a.seed,
            scenario,
            duration: a.duration,
            record: a.record,
        };
        let summary = sim_fast::run(options, std::io::stdout().lock())?;
        eprintln!("{}", summary.line());
        return Ok(true);
    }
    let ros1 = a.ros_master.map(|uri| Ros1Config::with_master(&uri));
    if let Some(r) = &ros1 {
        r.validate(Path::new("--ros-master"))?;
    }
    let websocket = a.websocket.map(|bind| WebsocketConfig::with_bind(&bind));
    if let Some(w) = &websocket {
        w.validate(Path::new("--websocket"))?;
    }
    ensure_ros1_built(ros1.is_some())?;
    let ros2 = a.ros2.then(chassisd::config::ros2::Ros2Config::default);
    super::ensure_ros2(ros2.as_ref(), Path::new("--ros2"))?;
    let mut mqtt = (!a.no_mqtt)
        .then(|| sim_mqtt(a.mqtt.as_deref()))
        .transpose()?;
    if let (Some(m), Some(port)) = (mqtt.as_mut(), a.broker_port) {
        m.first_mut().port = port;
    }
    if let Some(rtk) = mqtt.as_mut().and_then(|m| m.rtk.as_mut()) {
        rtk.trajectory_dir = a.trajectory_dir.map(|d| d.to_string_lossy().into_owned());
    }
    // A ROS node's publishing gets a worker of its own beside the simulation.
    let threads = if ros1.is_some() || ros2.is_some() {
        2
    } else {
        1
    };
    let footprint = plant.geometry.footprint();
    let options = SimOptions {
        plant,
        seed: a.seed,
        record: a.record,
        commands_stdin: a.commands_stdin,
        scenario,
        duration: a.duration,
        mqtt,
        ros1,
        ros2,
        websocket,
        handle: None,
        ntrip: a.ntrip.map(|url| ntrip_override(None, &url)).transpose()?,
        zones: a
            .zones
            .map(|file| ZonesConfig::from_file(&file, footprint))
            .transpose()?,
    };
    block_on(threads, sim::run(options, std::io::stdout()))??;
    Ok(true)
}
