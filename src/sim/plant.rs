//! The simulated vehicle: a differential-drive plant turned by simulated CiA 402 drives, with
//! wheel slip, and the sensors it carries — an IMU (HiPNUC or WitMotion frames) with noise and
//! a drifting gyro bias, and an RTK receiver (NMEA) with noise per fix quality, outages, jumps
//! and latency. It emits the frames a real vehicle would; the truth is kept beside them.
//! Parameters come from a plant TOML file (`devices/plant.*.toml`). Its CAN devices (drives,
//! BMS, cutter switch) are the ones the vehicle's configuration names, built by the
//! simulated devices' table ([`super::can_devices::KINDS`]) as `can-sim` builds them; the
//! plant couples them to its physics through their trait.

use std::collections::VecDeque;
use std::f64::consts::TAU;
use std::path::Path;
use std::time::Duration;

use bytes::Bytes;
use chrono::NaiveDateTime;
use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

pub use super::gnss_error::PerQuality;
use super::gnss_error::quality_index;

use super::can_devices::{self, BusLoad, Hardware, Injection, SimCanDevice};
use super::cia402_drive::{MotorModel, SimDrive};
use super::gnss_error::{GnssErrorProcess, GnssFaults};
use super::nmea_out::{self, Epoch};
use crate::config::chassis::{Wheel, WheelRadius};
use crate::config::imu::ImuProtocol;
use crate::config::zones::Footprint;
use crate::config::{ConfigError, VehicleConfig};
use crate::devices::can::Frame;
use crate::devices::canopen::NodeId;
use crate::devices::gnss::FixQuality;
use crate::devices::imu::{G, hipnuc, witmotion};
use crate::fusion::planar::wrap;
use crate::geodesy::{Enu, Geodetic};
use crate::record::{Payload, Record};
use crate::time::Timestamp;

/// The CAN interface name of the simulated drives.
pub const SIM_BUS: &str = "sim0";

/// Names the configuration built for a plant in errors.
pub const SIM_CONFIG_NAME: &str = "<simulated vehicle>";

/// The node of the left wheel's drive.
pub const LEFT_NODE: NodeId = match NodeId::new(1) {
    Some(n) => n,
    None => panic!("node id 1 is in range"),
};
/// The node of the right wheel's drive.
pub const RIGHT_NODE: NodeId = match NodeId::new(2) {
    Some(n) => n,
    None => panic!("node id 2 is in range"),
};

/// A plant file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PlantConfig {
    /// Name of the vehicle.
    pub name: String,
    /// Where it drives: latitude, longitude (degrees), ellipsoidal height (m).
    pub datum: [f64; 3],
    /// Geometry.
    pub geometry: Geometry,
    /// Drive motors.
    pub motors: Motors,
    /// Wheel slip.
    pub slip: Slip,
    /// IMU.
    pub imu: ImuModel,
    /// GNSS receiver.
    pub gnss: GnssModel,
    /// The drive train's limits and the speed the benchmark's scenarios are driven at.
    #[serde(default, skip_serializing_if = "DriveLimits::is_default")]
    pub drive: DriveLimits,
    /// The charging dock, the battery and the cutter, when the vehicle has them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yard: Option<Yard>,
    /// What the vehicle's configuration believes where it differs from the truth above: a
    /// miscalibrated vehicle, for the calibration procedures.
    #[serde(default, skip_serializing_if = "Configured::is_empty")]
    pub configured: Configured,
    /// A calibration file the vehicle's configuration reads (as `[vehicle] calibration`
    /// does on a real one); given on the command line, not in the plant file.
    #[serde(skip)]
    pub calibration: Option<crate::config::calibration::CalibrationFile>,
}

/// `[configured]`: values the configuration built from the plant holds instead of the
/// plant's true ones. Each one left out is configured true (the gyro bias as zero).
#[derive(Debug, Clone, Copy, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Configured {
    /// Wheel radius, m: one number, or `[left, right]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_radius_m: Option<WheelRadius>,
    /// Track, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub track_m: Option<f64>,
    /// GNSS antenna (x forward, y left), m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub antenna: Option<[f64; 2]>,
    /// Gyro bias the configuration subtracts (sensor frame), rad/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro_bias_rps: Option<[f64; 3]>,
    /// The gyro bias's random walk the configuration states (`localization.gyro_bias_walk`),
    /// rad/s per √s; else the plant's own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro_bias_walk: Option<f64>,
}

impl Configured {
    fn is_empty(&self) -> bool {
        *self == Self::default()
    }
}

/// `[drive]`: the limits the vehicle's configuration gives its drive train (`[chassis]`), and
/// how fast the benchmark's scenarios drive it: their speeds times `scenario_speed` (a car
/// drives the mower's laps at ten times their speed, on ten times their radius). Each left
/// out is a mower's.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriveLimits {
    /// Fastest forward or backward speed, m/s.
    pub max_speed_mps: f64,
    /// Fastest turn, rad/s.
    pub max_yaw_rate_rps: f64,
    /// Acceleration, m/s².
    pub max_accel_mps2: f64,
    /// Braking, m/s².
    pub max_decel_mps2: f64,
    /// The scenarios' speeds are multiplied by this.
    pub scenario_speed: f64,
}

impl Default for DriveLimits {
    fn default() -> Self {
        Self {
            max_speed_mps: 1.5,
            max_yaw_rate_rps: 1.5,
            max_accel_mps2: 1.0,
            max_decel_mps2: 1.5,
            scenario_speed: 1.0,
        }
    }
}

impl DriveLimits {
    fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// `[yard]`: a Daly BMS on the drives' bus that charges while the vehicle rests on the dock,
/// and a blade: a CiA 402 drive on the drives' bus, or a motor switched by a CAN frame.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Yard {
    /// The dock: east, north (m from the datum) and the heading to dock with (degrees).
    pub dock: [f64; 3],
    /// The vehicle charges at rest within this of the dock, m.
    #[serde(default = "default_dock_radius")]
    pub dock_radius_m: f64,
    /// The Daly BMS's address.
    #[serde(default = "default_bms_address")]
    pub bms_address: u8,
    /// The blade's switch frame (standard id): data `[1]` on, `[0]` off. Give this or
    /// `blade_node`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cutter_can_id: Option<u32>,
    /// The blade's CiA 402 drive node on the drives' bus (the wheel drives' profile).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blade_node: Option<u8>,
    /// The blade motor's speed while the cutter is on, r/min.
    #[serde(default = "default_blade_rpm")]
    pub blade_rpm: f64,
    /// Charging current on the dock, A.
    #[serde(default = "default_charge_current")]
    pub charge_current_a: f64,
}

fn default_dock_radius() -> f64 {
    0.15
}
fn default_bms_address() -> u8 {
    1
}
fn default_charge_current() -> f64 {
    10.0
}
fn default_blade_rpm() -> f64 {
    3000.0
}

/// `[geometry]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Geometry {
    /// Wheel radius, m: one number, or `[left, right]`.
    pub wheel_radius_m: WheelRadius,
    /// Track, m.
    pub track_m: f64,
    /// Motor revolutions per wheel revolution.
    pub gear_ratio: f64,
    /// GNSS antenna in the vehicle frame (x forward, y left), m.
    pub antenna: [f64; 2],
    /// The vehicle's outline about the axle, for zones (default: a box round the wheels).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub footprint: Option<Footprint>,
}

impl Geometry {
    /// The outline: the one given, or a box 10 cm beyond the wheels on every side.
    pub fn footprint(&self) -> Footprint {
        let reach = self.wheel_radius_m.left.max(self.wheel_radius_m.right) + 0.1;
        self.footprint.unwrap_or(Footprint {
            front_m: reach,
            rear_m: reach,
            width_m: self.track_m + 0.2,
        })
    }
}

/// `[motors]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Motors {
    /// Acceleration limit, motor r/min per second.
    pub accel_rpm_per_s: f64,
    /// Speed-loop lag, s.
    pub time_constant_s: f64,
}

/// `[slip]`: the ground speed of each wheel is its surface speed times (1 + slip).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Slip {
    /// Random slip, 1σ fraction, redrawn every 100 ms.
    pub sigma: f64,
    /// Systematic slip of the left and right wheels, fraction (unequal tyres, soft ground).
    pub bias: [f64; 2],
    /// The wheels' scale walks by this, 1σ per √m driven (both wheels alike; 0: it stays).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub scale_walk: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// `[imu]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ImuModel {
    /// Wire protocol.
    pub protocol: ImuProtocol,
    /// Output rate, Hz.
    pub rate_hz: f64,
    /// Gyro white noise per sample, 1σ rad/s.
    pub gyro_noise_rps: f64,
    /// Gyro z bias at start, rad/s.
    pub gyro_bias_rps: f64,
    /// Gyro bias random walk, rad/s per √s.
    pub gyro_bias_walk: f64,
    /// Accelerometer noise per sample, 1σ m/s².
    pub accel_noise_mps2: f64,
}

/// `[gnss]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GnssModel {
    /// Epochs per second.
    pub rate_hz: f64,
    /// Delay from an epoch to its sentences, s.
    pub latency_s: f64,
    /// Whether the receiver has a second antenna for heading.
    pub dual_antenna: bool,
    /// Heading noise, 1σ degrees.
    pub heading_sigma_deg: f64,
    /// The dual-antenna baseline's true misalignment: the receiver's heading minus the
    /// vehicle's, degrees.
    #[serde(default)]
    pub heading_offset_deg: f64,
    /// Velocity noise per axis, 1σ m/s (speed and course over ground come from it).
    pub velocity_sigma_mps: f64,
    /// Horizontal position noise per axis, 1σ m: RTK fixed, float, DGPS, single.
    pub sigma_m: [f64; 4],
    /// Part of the position noise that is correlated in time (multipath, SBAS wander),
    /// fraction of σ: one number, or one per quality like `sigma_m`.
    pub correlated_fraction: PerQuality,
    /// Correlation time of that part, s.
    pub correlation_time_s: f64,
    /// The slow part of corrected fixes (DGPS, RTK float and fixed) also decorrelates over
    /// this distance of the antenna's travel, m (multipath, the corrections' residuals);
    /// none: by time alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correlation_distance_m: Option<f64>,
    /// Steps, RTK-float episodes, wild fixes and the receiver's smoothing.
    #[serde(default)]
    pub faults: GnssFaults,
}

/// The plant `chassisd sim` and `chassisd bench fusion` use without `--plant`.
pub const DEFAULT_PLANT: &str = include_str!("../../devices/plant.mower.toml");

impl PlantConfig {
    /// The built-in plant (`devices/plant.mower.toml`).
    pub fn builtin() -> Result<Self, ConfigError> {
        Self::from_toml(DEFAULT_PLANT, Path::new("plant.mower.toml (built in)"))
    }

    /// Reads and checks a plant file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = crate::config::read_text(path)?;
        Self::from_toml(&text, path)
    }

    /// Parses and checks plant TOML.
    pub fn from_toml(text: &str, file: &Path) -> Result<Self, ConfigError> {
        let p: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            file: file.to_owned(),
            message: e.to_string(),
        })?;
        use crate::config::check_range;
        let g = &p.geometry;
        for r in [g.wheel_radius_m.left, g.wheel_radius_m.right] {
            check_range(file, "geometry.wheel_radius_m", r, 0.01..=2.0, "m")?;
        }
        check_range(file, "geometry.track_m", g.track_m, 0.05..=5.0, "m")?;
        check_range(
            file,
            "gnss.heading_offset_deg",
            p.gnss.heading_offset_deg,
            -180.0..=180.0,
            "degrees",
        )?;
        let c = &p.configured;
        if let Some(r) = c.wheel_radius_m {
            for r in [r.left, r.right] {
                check_range(file, "configured.wheel_radius_m", r, 0.01..=2.0, "m")?;
            }
        }
        if let Some(t) = c.track_m {
            check_range(file, "configured.track_m", t, 0.05..=5.0, "m")?;
        }
        for a in c.antenna.into_iter().flatten() {
            check_range(file, "configured.antenna", a, -10.0..=10.0, "m")?;
        }
        for b in c.gyro_bias_rps.into_iter().flatten() {
            check_range(file, "configured.gyro_bias_rps", b, -0.5..=0.5, "rad/s")?;
        }
        check_range(file, "geometry.gear_ratio", g.gear_ratio, 0.1..=500.0, "")?;
        check_range(
            file,
            "motors.accel_rpm_per_s",
            p.motors.accel_rpm_per_s,
            1.0..=1e6,
            "r/min/s",
        )?;
        check_range(
            file,
            "motors.time_constant_s",
            p.motors.time_constant_s,
            0.0..=5.0,
            "s",
        )?;
        check_range(file, "slip.sigma", p.slip.sigma, 0.0..=0.5, "")?;
        check_range(
            file,
            "slip.scale_walk",
            p.slip.scale_walk,
            0.0..=0.01,
            "per √m",
        )?;
        check_range(file, "imu.rate_hz", p.imu.rate_hz, 1.0..=1000.0, "Hz")?;
        check_range(file, "gnss.rate_hz", p.gnss.rate_hz, 0.2..=50.0, "Hz")?;
        check_range(file, "gnss.latency_s", p.gnss.latency_s, 0.0..=1.0, "s")?;
        for f in p.gnss.correlated_fraction.values() {
            check_range(file, "gnss.correlated_fraction", f, 0.0..=1.0, "")?;
        }
        check_range(
            file,
            "gnss.correlation_time_s",
            p.gnss.correlation_time_s,
            0.1..=600.0,
            "s",
        )?;
        if let Some(d) = p.gnss.correlation_distance_m {
            check_range(file, "gnss.correlation_distance_m", d, 0.1..=100_000.0, "m")?;
        }
        let f = &p.gnss.faults;
        for (key, value, range, unit) in [
            ("gnss.faults.smoothing_s", f.smoothing_s, 0.0..=60.0, "s"),
            (
                "gnss.faults.steps_per_hour",
                f.steps_per_hour,
                0.0..=3600.0,
                "/h",
            ),
            ("gnss.faults.step_m", f.step_m, 0.0..=100.0, "m"),
            (
                "gnss.faults.float_per_hour",
                f.float_per_hour,
                0.0..=3600.0,
                "/h",
            ),
            ("gnss.faults.float_s", f.float_s, 0.0..=3600.0, "s"),
            (
                "gnss.faults.wild_per_hour",
                f.wild_per_hour,
                0.0..=3600.0,
                "/h",
            ),
            (
                "gnss.faults.wild_m",
                f.wild_m[0],
                0.0..=f.wild_m[1].max(0.0),
                "m",
            ),
            ("gnss.faults.wild_m", f.wild_m[1], 0.0..=100_000.0, "m"),
        ] {
            check_range(file, key, value, range, unit)?;
        }
        if let Some(y) = p.yard {
            match (y.cutter_can_id, y.blade_node) {
                (Some(id), None) if id <= 0x7FF => {}
                (None, Some(node)) if (3..=126).contains(&node) => {
                    check_range(file, "yard.blade_rpm", y.blade_rpm, 1.0..=30_000.0, "r/min")?;
                }
                _ => {
                    return Err(ConfigError::invalid(
                        file,
                        "yard",
                        "needs one blade: cutter_can_id (a standard id) or blade_node",
                        "give cutter_can_id up to 0x7FF, or blade_node 3 to 126 (1 and 2 are \
                         the wheels)",
                    ));
                }
            }
        }
        Ok(p)
    }

    /// The datum as a geodetic position.
    pub fn datum(&self) -> Geodetic {
        Geodetic {
            lat_deg: self.datum[0],
            lon_deg: self.datum[1],
            h_m: self.datum[2],
        }
    }

    /// The 1σ position noise of a fix quality, m.
    pub fn sigma(&self, q: FixQuality) -> f64 {
        self.gnss.sigma_m[quality_index(q)]
    }
}

/// What the GNSS receiver can do at a moment (the scenario decides).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssCondition {
    /// Fix quality, or `None` during an outage.
    pub quality: Option<FixQuality>,
    /// A position error added on top of the noise (a jump), east and north, m.
    pub offset: (f64, f64),
}

/// The vehicle's true state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Truth {
    /// East, m (local frame of the plant's datum).
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Yaw, rad.
    pub yaw: f64,
    /// Forward speed, m/s.
    pub v: f64,
    /// Yaw rate, rad/s.
    pub w: f64,
    /// Distance driven forward by the random part of the wheel slip alone, m: on top of the
    /// wheels' turning and the systematic slip, and seen by no wheel odometry.
    pub unseen_slip_m: f64,
}

/// The simulated vehicle.
pub struct SimVehicle {
    plant: PlantConfig,
    rng: ChaCha8Rng,
    /// The CAN devices on [`SIM_BUS`], in the table's order.
    devices: Vec<Box<dyn SimCanDevice>>,
    /// The left and right wheels' motors among them.
    wheels: [WheelMotor; 2],
    /// The blade's drive among them, when the cutter is one.
    blade: Option<usize>,
    truth: Truth,
    frame: Enu,
    utc_at_zero: NaiveDateTime,
    start: Timestamp,
    last: Option<Timestamp>,
    slip: (f64, f64),
    next_slip: Timestamp,
    /// The wheels' walked scale ([`Slip::scale_walk`]), and the distance driven since it
    /// last walked, m.
    scale: f64,
    scale_walked_m: f64,
    gyro_bias: f64,
    next_imu: Timestamp,
    next_gnss: Timestamp,
    gnss_error: GnssErrorProcess,
    pending_gnss: VecDeque<(Timestamp, Bytes)>,
    imu_count: u32,
    /// The IMU is stalled: it sends nothing (a hung sensor or a cut cable).
    imu_stalled: bool,
    /// A recorded motion played through the simulator, in place of the motors and the gyro.
    forced: Option<ForcedMotion>,
    /// RTK corrections, when the simulation has a caster (without, RTK is always possible).
    corrections: Option<super::receiver_corrections::ReceiverCorrections>,
    /// The antenna's velocity (east, north, m/s) as the receiver's velocity filter has it,
    /// and its recent history for a late report.
    velocity: ReceiverVelocity,
    /// Where the antenna was at the last epoch.
    last_epoch_antenna: Option<(f64, f64)>,
}

/// The receiver's view of the antenna's velocity: smoothed and late.
#[derive(Debug, Clone, Default)]
struct ReceiverVelocity {
    smoothed: Option<(f64, f64)>,
    history: VecDeque<(Timestamp, (f64, f64))>,
}

impl ReceiverVelocity {
    /// The true velocity at `t`, `dt` after the last.
    fn step(&mut self, t: Timestamp, dt: f64, truth: (f64, f64), faults: &GnssFaults) {
        let smoothed = match self.smoothed {
            Some((e, n)) if faults.velocity_smoothing_s > 0.0 => {
                let k = (dt / faults.velocity_smoothing_s).min(1.0);
                (e + (truth.0 - e) * k, n + (truth.1 - n) * k)
            }
            _ => truth,
        };
        self.smoothed = Some(smoothed);
        if faults.velocity_lag_s > 0.0 {
            self.history.push_back((t, smoothed));
            let keep = Duration::from_secs_f64(faults.velocity_lag_s + 0.1);
            while self
                .history
                .front()
                .is_some_and(|(at, _)| t.saturating_since(*at) > keep)
            {
                self.history.pop_front();
            }
        }
    }

    /// What the receiver reports at `t`.
    fn reported(&self, t: Timestamp, faults: &GnssFaults) -> (f64, f64) {
        let now = self.smoothed.unwrap_or_default();
        if faults.velocity_lag_s <= 0.0 {
            return now;
        }
        let then = Timestamp::from_nanos(
            t.as_nanos()
                .saturating_sub(Duration::from_secs_f64(faults.velocity_lag_s).as_nanos() as u64),
        );
        self.history
            .iter()
            .rev()
            .find(|(at, _)| *at <= then)
            .or(self.history.front())
            .map_or(now, |(_, v)| *v)
    }
}

/// The motor that turns a wheel: a drive among the plant's devices, its axis, and the
/// configured sense (+1 when a positive motor speed drives the wheel forward).
#[derive(Debug, Clone, Copy)]
struct WheelMotor {
    device: usize,
    axis: usize,
    direction: f64,
}

/// A motion imposed on the simulated vehicle (a real robot's recorded wheel odometry and
/// gyro), so its frames carry real data through the real decoders.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ForcedMotion {
    /// Forward speed, m/s.
    pub v: f64,
    /// Yaw rate the wheels show, rad/s (sets their speed difference).
    pub wheel_yaw_rate: f64,
    /// What the gyro reads (z), rad/s, bias and noise included.
    pub gyro_z: f64,
}

impl SimVehicle {
    /// A vehicle at rest at the datum facing east, started at `start`, with the CAN devices
    /// `config` puts on [`SIM_BUS`] (the configuration [`super::lockstep::vehicle_config`]
    /// builds from the plant, or one that keeps its wheels there).
    pub fn new(
        plant: PlantConfig,
        config: &VehicleConfig,
        seed: u64,
        start: Timestamp,
    ) -> Result<Self, ConfigError> {
        let hardware = Hardware {
            motor: MotorModel {
                accel_rpm_per_s: plant.motors.accel_rpm_per_s,
                time_constant_s: plant.motors.time_constant_s,
            },
        };
        let file = Path::new(SIM_CONFIG_NAME);
        let bus = config
            .can
            .iter()
            .find(|b| b.interface == SIM_BUS)
            .ok_or_else(|| {
                ConfigError::invalid(
                    file,
                    "can",
                    format!("has no interface {SIM_BUS}"),
                    "put the simulated vehicle's devices on [[can]] interface sim0",
                )
            })?;
        let devices = can_devices::build(config, bus, &hardware)
            .map_err(|e| ConfigError::invalid(file, "can", e, "check the devices' profiles"))?;
        let drive_index = |name: &str| {
            devices
                .iter()
                .position(|d| d.name() == name && d.drive().is_some())
        };
        let wheel = |wheel: Wheel| {
            let (side, sense) = match wheel {
                Wheel::Left => ("left", config.wheels.map_or(1, |w| w.left.direction)),
                Wheel::Right => ("right", config.wheels.map_or(1, |w| w.right.direction)),
            };
            config
                .drive
                .iter()
                .filter(|d| d.bus == SIM_BUS)
                .find_map(|d| {
                    let axis = d.wheels.iter().position(|w| *w == wheel)?;
                    Some(WheelMotor {
                        device: drive_index(&d.name)?,
                        axis,
                        direction: f64::from(sense),
                    })
                })
                .ok_or_else(|| {
                    ConfigError::invalid(
                        file,
                        "drive",
                        format!("no drive on {SIM_BUS} turns the {side} wheel"),
                        "give each wheel a [[drive]] on the simulated interface",
                    )
                })
        };
        let wheels = [wheel(Wheel::Left)?, wheel(Wheel::Right)?];
        let blade = config
            .cutter
            .as_ref()
            .and_then(|c| c.drive_name())
            .and_then(drive_index);
        let gnss_error = GnssErrorProcess::new(
            1.0 / plant.gnss.rate_hz,
            plant.gnss.correlated_fraction,
            (
                plant.gnss.correlation_time_s,
                plant.gnss.correlation_distance_m,
            ),
            plant.gnss.faults,
            seed,
        );
        let utc_at_zero = chrono::DateTime::from_timestamp_micros(start.as_micros() as i64)
            .map(|d| d.naive_utc())
            .unwrap_or_default();
        Ok(Self {
            frame: Enu::new(plant.datum()),
            devices,
            wheels,
            blade,
            gyro_bias: plant.imu.gyro_bias_rps,
            plant,
            rng: ChaCha8Rng::seed_from_u64(seed),
            truth: Truth::default(),
            utc_at_zero,
            start,
            last: None,
            slip: (0.0, 0.0),
            next_slip: start,
            scale: 0.0,
            scale_walked_m: 0.0,
            next_imu: start,
            next_gnss: start,
            gnss_error,
            pending_gnss: VecDeque::new(),
            imu_count: 0,
            imu_stalled: false,
            forced: None,
            corrections: None,
            velocity: ReceiverVelocity::default(),
            last_epoch_antenna: None,
        })
    }

    /// From now on the receiver holds RTK fixed only while corrections reach it (within
    /// `fixed_for` of the last valid frame), as a receiver fed by a caster does.
    pub fn expect_corrections(&mut self, fixed_for: Duration) {
        self.corrections = Some(super::receiver_corrections::ReceiverCorrections::new(
            fixed_for,
        ));
    }

    /// Bytes written to the receiver's port at `t` (corrections).
    pub fn on_corrections(&mut self, t: Timestamp, bytes: &[u8]) {
        if let Some(c) = &mut self.corrections {
            c.receive(t, bytes);
        }
    }

    /// Valid correction frames the receiver has taken.
    pub fn corrections_received(&self) -> u64 {
        self.corrections.as_ref().map_or(0, |c| c.frames())
    }

    /// Whether the blade runs: its switch's relay is closed, or its drive turns it at more
    /// than half its speed.
    pub fn cutter_on(&self) -> bool {
        match (self.blade_drive(), self.plant.yard) {
            (Some(_), Some(y)) => self.blade_rpm().abs() > 0.5 * y.blade_rpm.abs(),
            _ => self.devices.iter().find_map(|d| d.cutter_on()) == Some(true),
        }
    }

    /// Puts axis 0 of the drive at `node` (a wheel's or the blade's) into fault with the EMCY
    /// `code`, as an overcurrent or an encoder failure would; its frames go to `out`.
    pub fn inject_drive_fault(
        &mut self,
        t: Timestamp,
        node: NodeId,
        code: u16,
        out: &mut Vec<Record>,
    ) {
        let mut frames = Vec::new();
        let fault = Injection::Fault {
            axis: 0,
            code,
            refused: 0,
        };
        for d in &mut self.devices {
            if d.drive().is_some_and(|drive| drive.node() == node) {
                d.inject(fault, &mut frames);
            }
        }
        out.extend(frames.into_iter().map(|f| can_record(t, f)));
    }

    /// Stalls the IMU (it sends nothing) or lets it run again.
    pub fn set_imu_stalled(&mut self, stalled: bool) {
        self.imu_stalled = stalled;
    }

    /// Stops or restarts the wheel drives' heartbeats (a drive whose CANopen stack hangs
    /// while its motor still obeys).
    pub fn set_drive_heartbeats(&mut self, on: bool) {
        for w in self.wheels {
            if let Some(d) = self.devices.get_mut(w.device) {
                d.inject(Injection::Heartbeat(on), &mut Vec::new());
            }
        }
    }

    /// Whether both wheel drives are commanded to stop (see [`SimDrive::commanded_to_stop`]).
    pub fn wheels_commanded_to_stop(&self) -> bool {
        self.wheels
            .iter()
            .all(|w| self.wheel_drive(w).is_some_and(|d| d.commanded_to_stop()))
    }

    fn wheel_drive(&self, wheel: &WheelMotor) -> Option<&SimDrive> {
        self.devices.get(wheel.device).and_then(|d| d.drive())
    }

    /// The blade drive's motor speed, r/min (0 without one).
    pub fn blade_rpm(&self) -> f64 {
        self.blade_drive()
            .and_then(|b| b.motor_rpm().first().copied())
            .unwrap_or(0.0)
    }

    /// The blade's drive, when the cutter is one.
    pub fn blade_drive(&self) -> Option<&SimDrive> {
        self.blade
            .and_then(|i| self.devices.get(i))
            .and_then(|d| d.drive())
    }

    /// The battery, when the vehicle has a BMS.
    pub fn battery(&self) -> Option<super::bms::Battery> {
        self.devices.iter().find_map(|d| d.battery())
    }

    /// Whether the vehicle rests on the dock.
    pub fn docked(&self) -> bool {
        self.plant.yard.is_some_and(|y| {
            (self.truth.x - y.dock[0]).hypot(self.truth.y - y.dock[1]) <= y.dock_radius_m
                && self.truth.v.abs() < 0.01
        })
    }

    /// The true state.
    pub fn truth(&self) -> Truth {
        self.truth
    }

    /// The plant.
    pub fn plant(&self) -> &PlantConfig {
        &self.plant
    }

    /// Imposes a motion from now on (wheels back-driven, the gyro reading given), or gives
    /// the vehicle back to its motors (`None`).
    pub fn force_motion(&mut self, motion: Option<ForcedMotion>) {
        self.forced = motion;
        let g = self.plant.geometry;
        let rpm = |v: f64, radius: f64| v / radius * 60.0 / TAU * g.gear_ratio;
        let (l, r) = match motion {
            Some(m) => {
                let half = m.wheel_yaw_rate * g.track_m / 2.0;
                (
                    Some(rpm(m.v - half, g.wheel_radius_m.left)),
                    Some(rpm(m.v + half, g.wheel_radius_m.right)),
                )
            }
            None => (None, None),
        };
        for (w, wheel_rpm) in self.wheels.into_iter().zip([l, r]) {
            if let Some(d) = self.devices.get_mut(w.device).and_then(|d| d.drive_mut()) {
                d.back_drive(w.axis, wheel_rpm.map(|r| r * w.direction));
            }
        }
    }

    /// The gyro's z bias now, rad/s (it walks).
    pub fn gyro_bias(&self) -> f64 {
        self.gyro_bias
    }

    /// Adds to the gyro's z bias (a scenario's temperature drift), rad/s.
    pub fn add_gyro_bias(&mut self, rps: f64) {
        self.gyro_bias += rps;
    }

    /// The GNSS antenna's true position (east, north), m.
    pub fn true_antenna(&self) -> (f64, f64) {
        let [ax, ay] = self.plant.geometry.antenna;
        let (s, c) = self.truth.yaw.sin_cos();
        (
            self.truth.x + c * ax - s * ay,
            self.truth.y + s * ax + c * ay,
        )
    }

    /// The antenna's true velocity (east, north, m/s): the vehicle's, plus the turn about
    /// the antenna's offset.
    fn antenna_velocity(&self) -> (f64, f64) {
        let tr = self.truth;
        let [ax, ay] = self.plant.geometry.antenna;
        let (along, across) = (tr.v - tr.w * ay, tr.w * ax);
        let (s, c) = tr.yaw.sin_cos();
        (along * c - across * s, along * s + across * c)
    }

    /// The UTC time the receiver stamps on an epoch at `t`.
    pub fn utc_at(&self, t: Timestamp) -> NaiveDateTime {
        self.utc_at_zero
            + chrono::TimeDelta::microseconds(t.saturating_since(self.start).as_micros() as i64)
    }

    fn normal(&mut self, sigma: f64) -> f64 {
        super::gnss_error::normal(&mut self.rng, sigma)
    }

    /// Wheel surface speeds from the motors, before any slip, m/s.
    fn wheel_surface_speeds(&self) -> (f64, f64) {
        let g = &self.plant.geometry;
        let speed = |rpm: f64, radius: f64| rpm * TAU / 60.0 / g.gear_ratio * radius;
        let [l, r] = self.wheels.map(|w| {
            let rpm = self
                .wheel_drive(&w)
                .and_then(|d| d.motor_rpm().get(w.axis).copied());
            rpm.unwrap_or(0.0) * w.direction
        });
        (
            speed(l, g.wheel_radius_m.left),
            speed(r, g.wheel_radius_m.right),
        )
    }

    /// Advances to `t` and emits what is due, as records at `t`.
    pub fn step(&mut self, t: Timestamp, gnss: GnssCondition, out: &mut Vec<Record>) {
        let dt = self
            .last
            .map_or(0.0, |l| t.saturating_since(l).as_secs_f64());
        self.last = Some(t);
        let mut frames = Vec::new();
        let mut load = BusLoad::default();
        // The drives turn first: the motion, and the current it draws, follow their speeds.
        for d in self.devices.iter_mut().filter(|d| d.drive().is_some()) {
            d.step(t, &mut load, &mut frames);
        }
        if t >= self.next_slip {
            self.next_slip = t.saturating_add(Duration::from_millis(100));
            let s = self.plant.slip.sigma;
            self.slip = (self.normal(s), self.normal(s));
            let walk = self.plant.slip.scale_walk;
            if walk > 0.0 {
                let step = self.normal(walk * self.scale_walked_m.sqrt());
                self.scale = (self.scale + step).clamp(-0.2, 0.2);
                self.scale_walked_m = 0.0;
            }
        }
        if self.forced.is_some() {
            // The recorded wheels are the motion; there is no slip beyond what they show.
            self.slip = (
                -self.plant.slip.bias[0] - self.scale,
                -self.plant.slip.bias[1] - self.scale,
            );
        }
        let (sl, sr) = self.wheel_surface_speeds();
        let bias = self.plant.slip.bias;
        let (vl, vr) = (
            sl * (1.0 + self.slip.0 + bias[0] + self.scale),
            sr * (1.0 + self.slip.1 + bias[1] + self.scale),
        );
        let v = (vl + vr) / 2.0;
        self.scale_walked_m += v.abs() * dt;
        let w = (vr - vl) / self.plant.geometry.track_m;
        let tr = &mut self.truth;
        let mid_yaw = tr.yaw + w * dt / 2.0;
        tr.x += v * mid_yaw.cos() * dt;
        tr.y += v * mid_yaw.sin() * dt;
        tr.yaw = wrap(tr.yaw + w * dt);
        let accel = (v - tr.v) / dt.max(1e-6);
        tr.v = v;
        tr.w = w;
        if self.forced.is_none() {
            tr.unseen_slip_m += (sl * self.slip.0 + sr * self.slip.1) / 2.0 * dt;
        }
        let antenna_velocity = self.antenna_velocity();
        self.velocity
            .step(t, dt, antenna_velocity, &self.plant.gnss.faults);
        let docked = self.docked();
        let cutting = self.cutter_on();
        // On the dock the charger feeds the pack; elsewhere the drives and the blade draw.
        load.current_a = self.plant.yard.map(|y| {
            if docked {
                y.charge_current_a
            } else {
                -(2.0 + 4.0 * v.abs() + if cutting { 6.0 } else { 0.0 })
            }
        });
        for d in self.devices.iter_mut().filter(|d| d.drive().is_none()) {
            d.step(t, &mut load, &mut frames);
        }
        out.extend(frames.into_iter().map(|f| can_record(t, f)));
        self.gyro_bias += self.normal(self.plant.imu.gyro_bias_walk * dt.sqrt());
        if t >= self.next_imu {
            self.next_imu = t.saturating_add(Duration::from_secs_f64(1.0 / self.plant.imu.rate_hz));
            if !self.imu_stalled {
                out.push(self.imu_record(t, accel));
            }
        }
        if t >= self.next_gnss {
            self.next_gnss =
                t.saturating_add(Duration::from_secs_f64(1.0 / self.plant.gnss.rate_hz));
            if let Some(bytes) = self.gnss_epoch(t, gnss) {
                let due = t.saturating_add(Duration::from_secs_f64(self.plant.gnss.latency_s));
                self.pending_gnss.push_back((due, bytes));
            }
        }
        while self.pending_gnss.front().is_some_and(|(due, _)| *due <= t) {
            if let Some((_, bytes)) = self.pending_gnss.pop_front() {
                out.push(Record {
                    t,
                    source: "gnss".into(),
                    payload: Payload::Serial(bytes),
                });
            }
        }
    }

    /// A frame chassisd sent to the drives; their answers go to `out`.
    pub fn on_can(&mut self, t: Timestamp, frame: &Frame, out: &mut Vec<Record>) {
        let mut frames = Vec::new();
        for d in &mut self.devices {
            d.on_frame(t, frame, &mut frames);
        }
        out.extend(frames.into_iter().map(|f| can_record(t, f)));
    }

    fn imu_record(&mut self, t: Timestamp, forward_accel: f64) -> Record {
        let m = self.plant.imu;
        let gyro_z = match self.forced {
            Some(f) => f.gyro_z,
            None => self.truth.w + self.gyro_bias + self.normal(m.gyro_noise_rps),
        };
        let gyro = Vector3::new(
            self.normal(m.gyro_noise_rps),
            self.normal(m.gyro_noise_rps),
            gyro_z,
        );
        let accel = Vector3::new(
            forward_accel.clamp(-20.0, 20.0) + self.normal(m.accel_noise_mps2),
            self.truth.v * self.truth.w + self.normal(m.accel_noise_mps2),
            G + self.normal(m.accel_noise_mps2),
        );
        let q = nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, self.truth.yaw);
        self.imu_count = self.imu_count.wrapping_add(1);
        let bytes = match m.protocol {
            ImuProtocol::Hipnuc => hipnuc::frame(&hipnuc::packet_91(
                self.imu_count,
                (accel / G).map(|a| a as f32).into(),
                gyro.map(|g| g.to_degrees() as f32).into(),
                [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
            )),
            ImuProtocol::Witmotion => {
                let scale = |v: f64, full: f64| {
                    (v / full * 32768.0).round().clamp(-32768.0, 32767.0) as i16
                };
                let mut b = witmotion::frame(
                    witmotion::ACCEL,
                    [
                        scale(accel.x, 16.0 * G),
                        scale(accel.y, 16.0 * G),
                        scale(accel.z, 16.0 * G),
                        2500,
                    ],
                )
                .to_vec();
                let full_rate = 2000f64.to_radians();
                b.extend(witmotion::frame(
                    witmotion::GYRO,
                    [
                        scale(gyro.x, full_rate),
                        scale(gyro.y, full_rate),
                        scale(gyro.z, full_rate),
                        0,
                    ],
                ));
                b
            }
        };
        Record {
            t,
            source: "imu".into(),
            payload: Payload::Serial(Bytes::from(bytes)),
        }
    }

    fn gnss_epoch(&mut self, t: Timestamp, c: GnssCondition) -> Option<Bytes> {
        let possible = c.quality?;
        let antenna = self.true_antenna();
        let moved = self
            .last_epoch_antenna
            .replace(antenna)
            .map_or(0.0, |(e, n)| (antenna.0 - e).hypot(antenna.1 - n));
        let plant = &self.plant;
        let rng = &mut self.rng;
        let (possible, correction_age) = match &self.corrections {
            Some(rc) => (rc.quality(t, possible), rc.age(t)),
            None => (possible, None),
        };
        let error = self.gnss_error.epoch(
            possible,
            moved,
            |q| plant.sigma(q),
            |s| super::gnss_error::normal(rng, s),
        );
        let quality = error.quality;
        let g = self.plant.gnss;
        let sigma = self.plant.sigma(quality);
        let tr = self.truth;
        let (antenna_e, antenna_n) = self.true_antenna();
        let e = antenna_e + error.offset.0 + c.offset.0;
        let n = antenna_n + error.offset.1 + c.offset.1;
        let p = self.frame.to_geodetic(&Vector3::new(e, n, 0.0));
        let heading = 90.0 - tr.yaw.to_degrees() + g.heading_offset_deg;
        let heading_noise = self.normal(g.heading_sigma_deg);
        // The antenna's velocity as the receiver's filter has it, late and smoothed.
        let (ve, vn) = self.velocity.reported(t, &g.faults);
        let ve = ve + self.normal(g.velocity_sigma_mps);
        let vn = vn + self.normal(g.velocity_sigma_mps);
        let utc = self.utc_at(t);
        let epoch = Epoch {
            utc,
            quality,
            position: (p.lat_deg, p.lon_deg, p.h_m),
            speed_mps: ve.hypot(vn),
            course_deg: (90.0 - vn.atan2(ve).to_degrees()).rem_euclid(360.0),
            sigma_m: sigma,
            heading_deg: g
                .dual_antenna
                .then(|| (heading + heading_noise).rem_euclid(360.0)),
            correction_age_s: correction_age.map(|a| a.as_secs_f64()),
        };
        Some(Bytes::from(nmea_out::epoch(&epoch)))
    }
}

fn can_record(t: Timestamp, frame: Frame) -> Record {
    Record {
        t,
        source: SIM_BUS.into(),
        payload: Payload::Can(frame.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::chassis::ProfileRef;
    use crate::devices::cia402::DriveProfile;
    use crate::sim::lockstep::vehicle_config;

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_nanos(1_000_000_000 + ms * 1_000_000)
    }

    #[test]
    fn a_dual_axis_drive_mounted_reversed_turns_the_wheels_its_configuration_names() {
        let plant = PlantConfig::builtin().unwrap();
        let mut config = vehicle_config(&plant).unwrap();
        let text = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("devices/zlac8015d.toml"),
        )
        .unwrap();
        let profile = DriveProfile::from_toml(&text, Path::new("zlac8015d.toml")).unwrap();
        config.drive.truncate(1);
        config.drive[0].name = "both".into();
        config.drive[0].wheels = vec![Wheel::Left, Wheel::Right];
        config.drive[0].profile = ProfileRef::Inline(Box::new(profile));
        if let Some(w) = config.wheels.as_mut() {
            w.left.direction = -1;
        }
        let mut vehicle = SimVehicle::new(plant, &config, 7, at(0)).unwrap();
        vehicle.force_motion(Some(ForcedMotion {
            v: 0.5,
            wheel_yaw_rate: 0.0,
            gyro_z: 0.0,
        }));
        let mut out = Vec::new();
        for ms in (0..=2000).step_by(10) {
            let outage = GnssCondition {
                quality: None,
                offset: (0.0, 0.0),
            };
            vehicle.step(at(ms), outage, &mut out);
        }
        let truth = vehicle.truth();
        assert!((truth.x - 1.0).abs() < 0.05, "{truth:?}");
        assert!(truth.yaw.abs() < 0.01, "straight: {truth:?}");
        let rpm = vehicle.wheel_drive(&vehicle.wheels[0]).unwrap().motor_rpm();
        assert!(rpm[0] < 0.0 && rpm[1] > 0.0, "left axis reversed: {rpm:?}");
    }

    #[test]
    fn a_configuration_without_the_wheels_on_the_simulated_bus_is_refused() {
        let plant = PlantConfig::builtin().unwrap();
        let mut config = vehicle_config(&plant).unwrap();
        config.drive.retain(|d| d.name != "right");
        let Err(e) = SimVehicle::new(plant, &config, 7, at(0)) else {
            panic!("a plant without its right wheel's drive");
        };
        assert!(e.to_string().contains("right wheel"), "{e}");
    }
}
