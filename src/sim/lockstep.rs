//! The simulated vehicle and the chassisd engine in lockstep: the plant advances 1 ms at a
//! time, its frames go through the engine's decoders and core, and the frames the engine sends
//! go back to the simulated drives. Every record the engine saw is handed out with the time
//! it saw it, so a recording of them replays to the same output.

use std::collections::VecDeque;
use std::path::Path;
use std::time::Duration;

use bytes::Bytes;

use super::plant::{
    GnssCondition, LEFT_NODE, PlantConfig, RIGHT_NODE, SIM_BUS, SIM_CONFIG_NAME, SimVehicle,
};
use super::scenario::Scenario;
use crate::api::mqtt::MQTT_SOURCE;
use crate::api::trajectory::{MemoryStore, TrajectoryStore};
use crate::config::chassis::ProfileRef;
use crate::config::localization::LocalizationConfig;
use crate::config::mission::{CutterConfig, MissionConfig};
use crate::config::mqtt::MqttConfig;
use crate::config::ntrip::NtripConfig;
use crate::config::zones::ZonesConfig;
use crate::config::{ConfigError, VehicleConfig};
use crate::devices::bms::profile::{BmsProfile, CurrentAboveOffset, DalyProfile};
use crate::devices::canopen::NodeId;
use crate::devices::cia402::DriveProfile;
use crate::devices::gnss::FixQuality;
use crate::engine::{Decoder, Engine, EngineOutput, HOST_SOURCE, LOCAL_COMMANDS};
use crate::record::{Payload, Record, SourceMeta};
use crate::time::Timestamp;
use crate::vehicle::LinkState;

/// The plant's time step.
pub const PLANT_STEP: Duration = Duration::from_millis(1);
/// A scripted drive sends its velocity command every this many steps (100 ms) ...
const SCRIPT_COMMAND_EVERY: u64 = 100;
/// ... from this time on, s.
const SCRIPT_COMMANDS_FROM_S: f64 = 1.0;
/// Source name of the GNSS receiver.
pub use crate::engine::GNSS_SOURCE;
/// Source name of the simulated IMU.
pub const IMU_SOURCE: &str = crate::sources::IMU;

/// The drive profile of the simulated drives.
const DRIVE_PROFILE: &str = include_str!("../../devices/cia402-generic.toml");

/// Where a lockstep run's records and outputs go.
pub trait Sink {
    /// A record the engine processed (with the time it saw), or a frame it sent (`CanTx`).
    fn record(&mut self, record: &Record);
    /// A status, event or command answer.
    fn output(&mut self, output: EngineOutput);
}

/// Passes everything on but the answers to a scenario's own commands: ten a second of the
/// script talking to itself would bury what a person needs to see, so they go to the debug
/// log, labelled as the scenario's.
struct ScriptSink<'a, S: Sink>(&'a mut S);

impl<S: Sink> Sink for ScriptSink<'_, S> {
    fn record(&mut self, record: &Record) {
        self.0.record(record);
    }

    fn output(&mut self, output: EngineOutput) {
        match output {
            EngineOutput::CommandResult { topic, result, .. } => match result {
                Ok(()) => tracing::debug!(%topic, "scenario command accepted"),
                Err(reason) => tracing::debug!(%topic, %reason, "scenario command refused"),
            },
            other => self.0.output(other),
        }
    }
}

/// The odom frame's error of a plant as the map filter models it (random walks), which an
/// integrator fits on their vehicle's data as docs/fusion.md shows for a real robot.
struct OdomError {
    along: f64,
    /// The random slip's part of `along`, m²/m.
    random_along: f64,
    across: f64,
    yaw: f64,
    heading_walk: f64,
}

impl OdomError {
    /// The span the random walks are matched at (an outage of 30 s), at the scenarios' speed
    /// (the laps', times the plant's scenario speed).
    const SPAN_S: f64 = 30.0;

    fn of(plant: &PlantConfig) -> Self {
        let speed = plant.drive.scenario_speed.clamp(0.1, 100.0);
        let slip = &plant.slip;
        // Random slip, redrawn every 100 ms on each wheel: a random walk in distance. The
        // systematic slip is a scale the map filter estimates; what its estimate leaves grows
        // with the distance, not its root: matched over the span at a tenth of the slip.
        let random = slip.sigma.powi(2) / 2.0 * 0.1 * speed;
        let systematic = (0.1 * (slip.bias[0] + slip.bias[1]) / 2.0).powi(2) * speed * Self::SPAN_S;
        // The gyro's white noise is its angle random walk; its bias's walk is configured as
        // such (`gyro_bias_walk`).
        let imu = &plant.imu;
        let walk = imu.gyro_noise_rps.powi(2) / imu.rate_hz.max(1.0);
        Self {
            along: random + systematic,
            random_along: random,
            across: random,
            // The gyro turns the odom frame; the simulated one has no scale error, so nothing
            // grows per radian turned (the configuration takes at least 1e-7).
            yaw: 0.0,
            heading_walk: walk.sqrt(),
        }
    }
}

/// The chassisd configuration of a simulated vehicle: its GNSS receiver and IMU, and one
/// generic CiA 402 drive per wheel (nodes 1 and 2) on the simulated bus. The receiver's and
/// gyro's noise figures go into `[localization]` as an integrator copies a datasheet's.
pub fn vehicle_config(plant: &PlantConfig) -> Result<VehicleConfig, ConfigError> {
    let file = Path::new(SIM_CONFIG_NAME);
    let g = &plant.geometry;
    // A miscalibrated vehicle's configuration holds what it believes, not the truth.
    let believed = &plant.configured;
    let radius = believed.wheel_radius_m.unwrap_or(g.wheel_radius_m);
    let antenna = believed.antenna.unwrap_or(g.antenna);
    let [lat, lon, h] = plant.datum;
    let odom = OdomError::of(plant);
    let text = format!(
        r#"
[vehicle]
name = "{name}"

[gnss]
port = "sim:gnss"
cog_min_speed_mps = 0.3

[gnss.antenna]
x = {ax}
y = {ay}
z = 0.0

[localization]
datum = [{lat}, {lon}, {h}]
gnss_latency_s = {latency}
heading_sigma_deg = {heading_sigma}
gnss_correlated_fraction = {correlated}
rtk_correlated_fraction = {rtk_correlated}
gnss_correlation_time_s = {correlation_time}
gnss_correlation_distance_m = {correlation_distance}
wheel_scale_walk = {scale_walk}
gnss_velocity_sigma_mps = {velocity_sigma}
gyro_noise_rps = {gyro_noise}
heading_walk = {heading_walk}
gyro_bias_walk = {gyro_bias_walk}
odom_along_m2_per_m = {odom_along}
wheel_slip_m2_per_m = {wheel_slip}
odom_across_m2_per_m = {odom_across}
odom_yaw_rad2_per_rad = {odom_yaw}

[imu]
port = "sim:imu"
protocol = "{imu}"

[chassis]
wheel_radius_m = {radius}
track_m = {track}
max_speed_mps = {max_speed}
max_yaw_rate_rps = {max_yaw_rate}
max_accel_mps2 = {max_accel}
max_decel_mps2 = {max_decel}
max_yaw_accel_rps2 = 3.0
cmd_timeout_s = 0.5

[wheels.left]
direction = 1
gear_ratio = {gear}

[wheels.right]
direction = 1
gear_ratio = {gear}

[[can]]
interface = "{bus}"

[[drive]]
name = "left"
profile = "cia402-generic.toml"
bus = "{bus}"
node = {left}
wheels = ["left"]

[[drive]]
name = "right"
profile = "cia402-generic.toml"
bus = "{bus}"
node = {right}
wheels = ["right"]
"#,
        name = plant.name.replace(['"', '\\'], "_"),
        ax = antenna[0],
        ay = antenna[1],
        latency = plant.gnss.latency_s,
        heading_sigma = plant.gnss.heading_sigma_deg.max(0.01),
        correlated = plant
            .gnss
            .correlated_fraction
            .at(FixQuality::Dgps)
            .min(0.95),
        rtk_correlated = plant
            .gnss
            .correlated_fraction
            .at(FixQuality::RtkFixed)
            .min(0.95),
        correlation_time = plant.gnss.correlation_time_s.clamp(1.0, 3600.0),
        // A receiver fitted by time alone (the Husky's) leaves chassisd its default: an
        // integrator does not know how their fixes decorrelate as the antenna moves, and
        // assuming it faster than it is costs less than slower (docs/fusion.md).
        correlation_distance = plant
            .gnss
            .correlation_distance_m
            .unwrap_or_else(|| LocalizationConfig::default().gnss_correlation_distance_m)
            .clamp(0.1, 100_000.0),
        // The same for the wheels' scale: the ground a plant names, else chassisd's default.
        scale_walk = if plant.slip.scale_walk > 0.0 {
            plant.slip.scale_walk
        } else {
            LocalizationConfig::default().wheel_scale_walk
        },
        velocity_sigma = plant.gnss.velocity_sigma_mps.clamp(0.001, 1.0),
        gyro_noise = plant.imu.gyro_noise_rps.clamp(1e-5, 0.5),
        heading_walk = odom.heading_walk.clamp(1e-5, 0.1),
        gyro_bias_walk = believed
            .gyro_bias_walk
            .unwrap_or(plant.imu.gyro_bias_walk)
            .clamp(0.0, 1e-2),
        odom_along = odom.along.clamp(1e-7, 1.0),
        wheel_slip = odom.random_along.clamp(1e-7, 1.0),
        odom_across = odom.across.clamp(1e-7, 1.0),
        odom_yaw = odom.yaw.clamp(1e-7, 1.0),
        imu = plant.imu.protocol.name(),
        radius = format_args!("[{}, {}]", radius.left, radius.right),
        track = believed.track_m.unwrap_or(g.track_m),
        max_speed = plant.drive.max_speed_mps,
        max_yaw_rate = plant.drive.max_yaw_rate_rps,
        max_accel = plant.drive.max_accel_mps2,
        max_decel = plant.drive.max_decel_mps2,
        gear = g.gear_ratio,
        bus = SIM_BUS,
        left = LEFT_NODE.get(),
        right = RIGHT_NODE.get(),
    );
    let mut config: VehicleConfig = toml::from_str(&text).map_err(|e| ConfigError::Parse {
        file: file.to_owned(),
        message: e.to_string(),
    })?;
    if let (Some(imu), Some(bias)) = (config.imu.as_mut(), believed.gyro_bias_rps) {
        imu.gyro_bias_rps = bias;
    }
    let profile = drive_profile()?;
    for drive in &mut config.drive {
        drive.profile = ProfileRef::Inline(Box::new(profile.clone()));
    }
    if let Some(yard) = plant.yard {
        // The yard's pack, dock and blade, configured as an integrator would.
        config.bms = Some(crate::config::chassis::BmsConfig {
            profile: ProfileRef::Inline(Box::new(BmsProfile::Daly(DalyProfile {
                name: "simulated Daly".into(),
                host_address: 0x40,
                current_above_offset: CurrentAboveOffset::Charge,
            }))),
            bus: SIM_BUS.into(),
            address: yard.bms_address,
            poll_hz: 2.0,
            stale_s: 3.0,
        });
        config.mission = Some(MissionConfig {
            dock: Some(yard.dock),
            ..MissionConfig::default()
        });
        config.cutter = Some(match (yard.blade_node, yard.cutter_can_id) {
            (Some(node), _) => {
                let mut blade = config.drive[0].clone();
                blade.name = BLADE_DRIVE.into();
                blade.node = node;
                blade.wheels.clear();
                config.drive.push(blade);
                CutterConfig {
                    drive: Some(BLADE_DRIVE.into()),
                    rpm: Some(yard.blade_rpm),
                    ..CutterConfig::default()
                }
            }
            (None, can_id) => CutterConfig {
                bus: Some(SIM_BUS.into()),
                can_id,
                on: Some(vec![1]),
                off: Some(vec![0]),
                ..CutterConfig::default()
            },
        });
    }
    if let Some(calib) = &plant.calibration {
        let lines = calib.apply(&mut config);
        config.calibration_in_force = Some(("<given calibration>".into(), lines));
    }
    config.validate(file)?;
    Ok(config)
}

/// The name of the simulated blade's drive.
pub const BLADE_DRIVE: &str = "blade";

/// The profile of the simulated drives.
pub fn drive_profile() -> Result<DriveProfile, ConfigError> {
    Ok(DriveProfile::from_toml(
        DRIVE_PROFILE,
        Path::new("cia402-generic.toml"),
    )?)
}

/// The sources of a simulated session, as a recording lists them.
pub fn sources(plant: &PlantConfig) -> Vec<SourceMeta> {
    vec![
        SourceMeta::serial(GNSS_SOURCE, Decoder::Nmea.protocol()),
        SourceMeta::serial(IMU_SOURCE, Decoder::Imu(plant.imu.protocol).protocol()),
        SourceMeta::can(SIM_BUS),
        SourceMeta::commands(LOCAL_COMMANDS, "commands.log"),
        SourceMeta::commands(MQTT_SOURCE, &format!("{MQTT_SOURCE}.log")),
        SourceMeta::commands(HOST_SOURCE, &format!("{HOST_SOURCE}.log")),
    ]
}

/// Configuration sections a simulated session adds to the plant's own.
#[derive(Debug, Clone, Default)]
pub struct Sections {
    /// The MQTT broker and dialects.
    pub mqtt: Option<MqttConfig>,
    /// RTK corrections from a caster.
    pub ntrip: Option<NtripConfig>,
    /// The zones, read.
    pub zones: Option<ZonesConfig>,
}

/// The plant and the engine, stepped together.
pub struct Lockstep {
    vehicle: SimVehicle,
    engine: Engine,
    config: VehicleConfig,
    t: Timestamp,
    steps: u64,
    queue: VecDeque<Record>,
    outputs: Vec<EngineOutput>,
    replies: Vec<Record>,
    /// The simulated CAN interface is down: no frame crosses it either way.
    bus_down: bool,
}

impl Lockstep {
    /// A vehicle on `plant` with noise from `seed`, at rest at the datum at `start`.
    pub fn new(plant: PlantConfig, seed: u64, start: Timestamp) -> Result<Self, ConfigError> {
        Self::with_mqtt(plant, seed, start, None, Box::new(MemoryStore::default()))
    }

    /// [`Lockstep::new`], speaking the dialects of `mqtt`, trajectories kept in
    /// `trajectories`.
    pub fn with_mqtt(
        plant: PlantConfig,
        seed: u64,
        start: Timestamp,
        mqtt: Option<MqttConfig>,
        trajectories: Box<dyn TrajectoryStore>,
    ) -> Result<Self, ConfigError> {
        let sections = Sections {
            mqtt,
            ..Sections::default()
        };
        Self::with_sections(plant, seed, start, sections, trajectories)
    }

    /// [`Lockstep::new`], with `sections` added to the plant's configuration: the dialects
    /// of `mqtt`, RTK corrections from the caster of `ntrip` (the simulated receiver then
    /// holds RTK only while they arrive), the zones of `zones`; trajectories kept in
    /// `trajectories`.
    pub fn with_sections(
        plant: PlantConfig,
        seed: u64,
        start: Timestamp,
        sections: Sections,
        trajectories: Box<dyn TrajectoryStore>,
    ) -> Result<Self, ConfigError> {
        let mut config = vehicle_config(&plant)?;
        let file = Path::new(SIM_CONFIG_NAME);
        if let Some(m) = sections.mqtt {
            m.validate(file)?;
            config.mqtt = Some(m);
        }
        if let Some(n) = sections.ntrip {
            n.validate(file)?;
            config.ntrip = Some(n);
        }
        if let Some(z) = sections.zones {
            z.validate(file)?;
            config.zones = Some(z);
        }
        let decoders = [
            (GNSS_SOURCE.to_owned(), Decoder::Nmea),
            (IMU_SOURCE.to_owned(), Decoder::Imu(plant.imu.protocol)),
        ];
        let mut engine = Engine::with_trajectories(&config, &decoders, trajectories);
        engine.start_at(start);
        // The devices are connected from the start, as live drivers report them.
        let queue = [GNSS_SOURCE, IMU_SOURCE, SIM_BUS]
            .into_iter()
            .map(|source| Record {
                t: start,
                source: source.into(),
                payload: Payload::Link(LinkState::Up),
            })
            .collect();
        let mut vehicle = SimVehicle::new(plant, &config, seed, start)?;
        if let Some(n) = &config.ntrip {
            vehicle.expect_corrections(n.timeout());
        }
        Ok(Self {
            vehicle,
            engine,
            config,
            t: start,
            steps: 0,
            queue,
            outputs: Vec::new(),
            replies: Vec::new(),
            bus_down: false,
        })
    }

    /// The chassisd configuration the engine runs.
    pub fn config(&self) -> &VehicleConfig {
        &self.config
    }

    /// The simulated vehicle.
    pub fn vehicle(&self) -> &SimVehicle {
        &self.vehicle
    }

    /// The simulated vehicle, to disturb it.
    pub fn vehicle_mut(&mut self) -> &mut SimVehicle {
        &mut self.vehicle
    }

    /// The engine.
    pub fn engine(&self) -> &Engine {
        &self.engine
    }

    /// The engine, to set what it emits.
    pub fn engine_mut(&mut self) -> &mut Engine {
        &mut self.engine
    }

    /// Simulated time.
    pub fn time(&self) -> Timestamp {
        self.t
    }

    /// A `TOPIC JSON` command on the local command channel, now.
    pub fn command(&mut self, topic: &str, payload: &str, sink: &mut impl Sink) {
        let payload = Payload::Command {
            topic: topic.to_owned(),
            payload: Bytes::copy_from_slice(payload.as_bytes()),
        };
        self.input(LOCAL_COMMANDS, payload, sink);
    }

    /// Any record from `source` (a command, a link event), now.
    pub fn input(&mut self, source: &str, payload: Payload, sink: &mut impl Sink) {
        self.queue.push_back(Record {
            t: self.t,
            source: source.into(),
            payload,
        });
        self.drain(sink);
    }

    /// Plant steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Advances one plant step of `scenario`: its velocity command every 100 ms (once the
    /// drives have had a second to boot), its gyro drift and its GNSS condition.
    pub fn step_scripted(&mut self, scenario: &Scenario, sink: &mut impl Sink) {
        let s = self.steps as f64 * PLANT_STEP.as_secs_f64();
        if self.steps.is_multiple_of(SCRIPT_COMMAND_EVERY) && s >= SCRIPT_COMMANDS_FROM_S {
            let (v, w) = scenario.command_at(s);
            let twist = format!(r#"{{"linear":{{"x":{v}}},"angular":{{"z":{w}}}}}"#);
            self.command("cmd_vel", &twist, &mut ScriptSink(sink));
        }
        self.step_conditions(scenario, sink);
    }

    /// Advances one plant step under `scenario`'s gyro drift and GNSS condition, without
    /// its driving (an operator has taken over).
    pub fn step_conditions(&mut self, scenario: &Scenario, sink: &mut impl Sink) {
        let s = self.steps as f64 * PLANT_STEP.as_secs_f64();
        self.vehicle
            .add_gyro_bias(scenario.gyro_bias_ramp * PLANT_STEP.as_secs_f64());
        self.step(scenario.gnss_at(s), sink);
    }

    /// Advances one plant step under `gnss`.
    pub fn step(&mut self, gnss: GnssCondition, sink: &mut impl Sink) {
        self.t = self.t.saturating_add(PLANT_STEP);
        self.steps += 1;
        let mut produced = Vec::new();
        self.vehicle.step(self.t, gnss, &mut produced);
        if self.bus_down {
            produced.retain(|r| r.source != SIM_BUS);
        }
        self.queue.extend(produced);
        self.drain(sink);
        self.engine.advance_to(self.t, &mut self.outputs);
        self.dispatch(self.t, sink);
        self.drain(sink);
    }

    /// Takes the simulated CAN interface down or up, now, as an unplugged or restored
    /// adapter would: the engine hears of the link as from the live driver, and no frame
    /// crosses the bus while it is down (the drives' own master watchdogs see silence).
    pub fn set_bus_up(&mut self, up: bool, sink: &mut impl Sink) {
        if self.bus_down != up {
            return;
        }
        self.bus_down = !up;
        let state = if up { LinkState::Up } else { LinkState::Down };
        self.input(SIM_BUS, Payload::Link(state), sink);
    }

    /// Puts the drive at `node` into fault with the EMCY `code`, now.
    pub fn inject_drive_fault(&mut self, node: NodeId, code: u16, sink: &mut impl Sink) {
        let mut produced = Vec::new();
        self.vehicle
            .inject_drive_fault(self.t, node, code, &mut produced);
        self.queue.extend(produced);
        self.drain(sink);
    }

    /// Advances one plant step with chassisd gone (killed, hung): the vehicle's devices run
    /// on, and nothing reaches them from the engine.
    pub fn step_unattended(&mut self, gnss: GnssCondition) {
        self.t = self.t.saturating_add(PLANT_STEP);
        self.steps += 1;
        let mut produced = Vec::new();
        self.vehicle.step(self.t, gnss, &mut produced);
    }

    /// Feeds queued records to the engine, and the drives' replies to what it sends.
    fn drain(&mut self, sink: &mut impl Sink) {
        while let Some(mut record) = self.queue.pop_front() {
            record.t = self.engine.handle(&record, &mut self.outputs);
            sink.record(&record);
            self.dispatch(record.t, sink);
        }
    }

    /// Routes the engine's outputs: frames to the drives (and the sink), the rest to the sink.
    fn dispatch(&mut self, t: Timestamp, sink: &mut impl Sink) {
        for output in std::mem::take(&mut self.outputs) {
            match output {
                // A frame sent while the interface is down never reaches the bus.
                EngineOutput::CanTx { .. } if self.bus_down => {}
                EngineOutput::CanTx { bus, frame } => {
                    sink.record(&Record {
                        t,
                        source: bus,
                        payload: Payload::CanTx(frame.into()),
                    });
                    self.vehicle.on_can(t, &frame, &mut self.replies);
                    self.queue.extend(self.replies.drain(..));
                }
                // The receiver's port: the simulated receiver takes the corrections.
                EngineOutput::SerialTx { port, bytes } if port == GNSS_SOURCE => {
                    self.vehicle.on_corrections(t, &bytes);
                }
                other => sink.output(other),
            }
        }
    }
}
