//! Configuration of the drive train and the CAN devices: geometry, limits, wheels, CAN
//! interfaces, drives and the BMS.

use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::{ConfigError, VehicleConfig, check_range};
use crate::devices::bms::BmsProfile;
use crate::devices::cia402::DriveProfile;
use crate::devices::estop::EStopProfile;

/// `[chassis]`: differential-drive geometry, motion limits and the command watchdog.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ChassisConfig {
    /// Wheel radius, m: one number for both wheels, or `[left, right]` (a calibration
    /// finds them apart).
    pub wheel_radius_m: WheelRadius,
    /// Distance between the wheel contact points, m.
    pub track_m: f64,
    /// Forward and reverse speed limit, m/s.
    #[serde(default = "default_max_speed")]
    pub max_speed_mps: f64,
    /// Yaw rate limit, rad/s.
    #[serde(default = "default_max_yaw_rate")]
    pub max_yaw_rate_rps: f64,
    /// Linear acceleration limit, m/s².
    #[serde(default = "default_max_accel")]
    pub max_accel_mps2: f64,
    /// Linear deceleration limit (also for stops), m/s².
    #[serde(default = "default_max_decel")]
    pub max_decel_mps2: f64,
    /// Yaw acceleration limit, rad/s².
    #[serde(default = "default_max_yaw_accel")]
    pub max_yaw_accel_rps2: f64,
    /// A velocity command older than this is void: the vehicle decelerates to zero, s.
    #[serde(default = "default_cmd_timeout")]
    pub cmd_timeout_s: f64,
    /// Enable the drives (holding zero) as soon as they are ready, without a command.
    #[serde(default = "default_true")]
    pub enable_on_start: bool,
    /// After a latched stop the drives brake on their quick-stop ramp this long (while the
    /// wheels still turn), then are disabled, s.
    #[serde(default = "default_quick_stop")]
    pub quick_stop_s: f64,
    /// A fault reset that has not cleared every drive fault by then has failed, s.
    #[serde(default = "default_reset_timeout")]
    pub reset_timeout_s: f64,
}

/// The rolling radius of each wheel, m. TOML gives one number for both, or `[left, right]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(from = "RadiusText", into = "RadiusText")]
pub struct WheelRadius {
    /// Left wheel, m.
    pub left: f64,
    /// Right wheel, m.
    pub right: f64,
}

impl WheelRadius {
    /// The same radius on both wheels.
    pub fn both(r: f64) -> Self {
        Self { left: r, right: r }
    }

    /// The mean of the two, m.
    pub fn mean(&self) -> f64 {
        (self.left + self.right) / 2.0
    }
}

/// How `wheel_radius_m` is written: one number, or one per wheel.
#[derive(Debug, Clone, Copy, Deserialize, Serialize)]
#[serde(untagged)]
enum RadiusText {
    Both(f64),
    Each([f64; 2]),
}

impl From<RadiusText> for WheelRadius {
    fn from(text: RadiusText) -> Self {
        match text {
            RadiusText::Both(r) => Self::both(r),
            RadiusText::Each([left, right]) => Self { left, right },
        }
    }
}

impl From<WheelRadius> for RadiusText {
    fn from(r: WheelRadius) -> Self {
        if r.left == r.right {
            Self::Both(r.left)
        } else {
            Self::Each([r.left, r.right])
        }
    }
}

fn default_max_speed() -> f64 {
    1.0
}
fn default_max_yaw_rate() -> f64 {
    1.5
}
fn default_max_accel() -> f64 {
    0.5
}
fn default_max_decel() -> f64 {
    1.0
}
fn default_max_yaw_accel() -> f64 {
    2.0
}
fn default_cmd_timeout() -> f64 {
    0.5
}
fn default_true() -> bool {
    true
}
fn default_quick_stop() -> f64 {
    1.0
}
fn default_reset_timeout() -> f64 {
    3.0
}

impl ChassisConfig {
    /// The command watchdog period.
    pub fn cmd_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.cmd_timeout_s)
    }

    /// How long a latched stop quick-stops before disabling the drives.
    pub fn quick_stop(&self) -> Duration {
        Duration::from_secs_f64(self.quick_stop_s)
    }

    /// How long a fault reset may take.
    pub fn reset_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.reset_timeout_s)
    }
}

/// `[wheels.left]`, `[wheels.right]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WheelsConfig {
    /// The left wheel.
    pub left: WheelConfig,
    /// The right wheel.
    pub right: WheelConfig,
}

/// One wheel.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WheelConfig {
    /// +1 when positive motor velocity drives the wheel forward, -1 when backward.
    pub direction: i8,
    /// Motor revolutions per wheel revolution.
    #[serde(default = "default_gear")]
    pub gear_ratio: f64,
}

fn default_gear() -> f64 {
    1.0
}

/// Which wheel a drive axis turns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Wheel {
    /// Left wheel.
    Left,
    /// Right wheel.
    Right,
}

/// `[[can]]`: a CAN interface. Its bit rate is set outside the daemon (`ip link`).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CanBusConfig {
    /// Interface name, e.g. `can0`.
    pub interface: String,
    /// Decode only; never transmit (bus monitoring, or replaying another master's session).
    #[serde(default)]
    pub listen_only: bool,
    /// Longest wait between reconnect attempts, s.
    #[serde(default = "default_reconnect_max")]
    pub reconnect_max_s: f64,
    /// Frames waiting to be written before new ones are dropped (and counted).
    #[serde(default = "default_tx_queue")]
    pub tx_queue: usize,
    /// chassisd's own CANopen node id on this interface: it produces a heartbeat with it,
    /// which the drives consume.
    #[serde(default = "default_master_node")]
    pub master_node: u8,
    /// chassisd's heartbeat period, ms.
    #[serde(default = "default_master_heartbeat_ms")]
    pub master_heartbeat_ms: u64,
    /// The SYNC period, ms, produced when a drive's profile watches SYNC.
    #[serde(default = "default_sync_ms")]
    pub sync_ms: u64,
}

fn default_reconnect_max() -> f64 {
    5.0
}
fn default_tx_queue() -> usize {
    256
}
fn default_master_node() -> u8 {
    0x7F
}
fn default_master_heartbeat_ms() -> u64 {
    50
}
fn default_sync_ms() -> u64 {
    20
}

/// A device profile: a file name (relative to the configuration) or, in effective
/// configurations, the profile itself.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum ProfileRef<T> {
    /// Read from this file.
    File(String),
    /// Already read.
    Inline(Box<T>),
}

/// A profile type that can be read from a file.
pub trait LoadProfile: Sized {
    /// Reads and checks the file.
    fn load_file(path: &Path) -> Result<Self, ConfigError>;
    /// Checks a profile given inline; `file` names the configuration in errors.
    fn check(&self, file: &Path) -> Result<(), ConfigError>;
}

impl LoadProfile for DriveProfile {
    fn load_file(path: &Path) -> Result<Self, ConfigError> {
        let text = super::read_text(path)?;
        Ok(DriveProfile::from_toml(&text, path)?)
    }

    fn check(&self, file: &Path) -> Result<(), ConfigError> {
        self.validate().map_err(|(key, problem, fix)| {
            ConfigError::invalid(file, &format!("drive.profile.{key}"), problem, &fix)
        })
    }
}

impl LoadProfile for BmsProfile {
    /// A DBC file the profile names is read relative to the profile.
    fn load_file(path: &Path) -> Result<Self, ConfigError> {
        let text = super::read_text(path)?;
        let dir = path.parent().unwrap_or(Path::new("."));
        BmsProfile::from_toml(&text, path, |dbc| {
            super::read_text(&dir.join(dbc)).map_err(|e| e.named_by(path, "dbc"))
        })
    }

    fn check(&self, file: &Path) -> Result<(), ConfigError> {
        Ok(self.validate(file)?)
    }
}

impl LoadProfile for EStopProfile {
    fn load_file(path: &Path) -> Result<Self, ConfigError> {
        Ok(EStopProfile::from_toml(&super::read_text(path)?, path)?)
    }

    fn check(&self, file: &Path) -> Result<(), ConfigError> {
        Ok(self.validate(file, "estop.profile.")?)
    }
}

impl<T: LoadProfile> ProfileRef<T> {
    /// Reads a file reference, relative to `base`; checks an inline profile. `file` is the
    /// configuration and `key` the reference's key, for errors.
    pub fn resolve(&mut self, base: &Path, file: &Path, key: &str) -> Result<(), ConfigError> {
        match self {
            Self::File(name) => {
                let profile =
                    T::load_file(&base.join(name.as_str())).map_err(|e| e.named_by(file, key))?;
                *self = Self::Inline(Box::new(profile));
                Ok(())
            }
            Self::Inline(profile) => profile.check(file),
        }
    }

    /// The file it names, before it is read.
    pub fn file_name(&self) -> Option<&str> {
        match self {
            Self::File(name) => Some(name),
            Self::Inline(_) => None,
        }
    }

    /// The profile, once resolved.
    pub fn get(&self) -> Option<&T> {
        match self {
            Self::Inline(p) => Some(p),
            Self::File(_) => None,
        }
    }
}

/// `[[drive]]`: a CiA 402 drive node.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DriveConfig {
    /// Name for logs and status.
    pub name: String,
    /// Drive profile.
    pub profile: ProfileRef<DriveProfile>,
    /// CAN interface.
    pub bus: String,
    /// CANopen node id.
    pub node: u8,
    /// The wheel each axis turns, in axis order.
    pub wheels: Vec<Wheel>,
    /// Heartbeat producer time written to the node, ms.
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_ms: u16,
    /// Silence after which the node is lost, ms.
    #[serde(default = "default_heartbeat_timeout_ms")]
    pub heartbeat_timeout_ms: u64,
    /// SDO answer timeout, ms.
    #[serde(default = "default_sdo_timeout_ms")]
    pub sdo_timeout_ms: u64,
    /// SDO retries.
    #[serde(default = "default_sdo_retries")]
    pub sdo_retries: u8,
    /// Wait for the boot-up message before resetting the node again, ms.
    #[serde(default = "default_boot_timeout_ms")]
    pub boot_timeout_ms: u64,
    /// Time the enable sequence may take, ms.
    #[serde(default = "default_enable_timeout_ms")]
    pub enable_timeout_ms: u64,
    /// No feedback from an axis for this long is a fault, ms (default: three feedback
    /// periods of the profile, at least 250 ms).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub feedback_timeout_ms: Option<u64>,
    /// Fault reset attempts (rising edges of controlword bit 7) before giving up.
    #[serde(default = "default_reset_attempts")]
    pub reset_attempts: u8,
    /// How long each attempt waits for the drive to leave Fault, ms.
    #[serde(default = "default_reset_wait_ms")]
    pub reset_wait_ms: u64,
    /// Silence from chassisd after which the drive stops its motors by itself, ms (written
    /// to the drive's consumer heartbeat or vendor timeout).
    #[serde(default = "default_master_timeout_ms")]
    pub master_timeout_ms: u64,
}

impl DriveConfig {
    /// The feedback staleness timeout with `profile`.
    pub fn feedback_timeout(&self, profile: &DriveProfile) -> Duration {
        Duration::from_millis(
            self.feedback_timeout_ms
                .unwrap_or_else(|| (3 * feedback_period_ms(profile)).max(250)),
        )
    }
}

/// The longest gap between two feedback messages of a drive with `profile`, ms: the poll
/// period, or the slowest TPDO event timer.
pub fn feedback_period_ms(profile: &DriveProfile) -> u64 {
    use crate::devices::cia402::profile::Transport;
    match profile.feedback.mode {
        Transport::Sdo => (1000.0 / profile.feedback.poll_hz).ceil() as u64,
        Transport::Pdo => profile
            .tpdo
            .iter()
            .map(|t| u64::from(t.event_timer_ms))
            .max()
            .unwrap_or(0),
    }
}

fn default_heartbeat_ms() -> u16 {
    100
}
fn default_heartbeat_timeout_ms() -> u64 {
    350
}
fn default_sdo_timeout_ms() -> u64 {
    50
}
fn default_sdo_retries() -> u8 {
    2
}
fn default_boot_timeout_ms() -> u64 {
    1000
}
fn default_enable_timeout_ms() -> u64 {
    1000
}
fn default_reset_attempts() -> u8 {
    3
}
fn default_reset_wait_ms() -> u64 {
    200
}
fn default_master_timeout_ms() -> u64 {
    250
}

/// `[bms]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BmsConfig {
    /// BMS profile.
    pub profile: ProfileRef<BmsProfile>,
    /// CAN interface.
    pub bus: String,
    /// Daly: the pack's address.
    #[serde(default = "default_bms_address")]
    pub address: u8,
    /// Daly: full polling rounds per second.
    #[serde(default = "default_poll_hz")]
    pub poll_hz: f64,
    /// A reading older than this is stale, s.
    #[serde(default = "default_stale_s")]
    pub stale_s: f64,
}

fn default_bms_address() -> u8 {
    1
}
fn default_poll_hz() -> f64 {
    2.0
}
fn default_stale_s() -> f64 {
    3.0
}

/// `[[estop]]`: a hardware e-stop input read from a CAN status frame.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct EStopConfig {
    /// Name for logs and status.
    pub name: String,
    /// E-stop profile: the frame, bit, active level and silence timeout.
    pub profile: ProfileRef<EStopProfile>,
    /// CAN interface.
    pub bus: String,
}

/// Checks that a drive's loss-of-master timeout leaves room for what feeds it.
fn check_master_timeout(
    d: &DriveConfig,
    profile: &DriveProfile,
    bus: &CanBusConfig,
) -> Result<(), (String, String)> {
    use crate::devices::cia402::profile::MasterLoss;
    let timeout = d.master_timeout_ms;
    if !(20..=u64::from(u16::MAX)).contains(&timeout) {
        return Err((format!("{timeout} ms"), "use 20 to 65535 ms".into()));
    }
    // What keeps the drive's watchdog fed, and how often.
    let (fed_by, period) = match profile.master_loss {
        Some(MasterLoss::Heartbeat { .. }) => ("chassisd's heartbeat", bus.master_heartbeat_ms),
        Some(MasterLoss::Sync { .. }) => return Ok(()),
        Some(MasterLoss::VendorTimeout { .. }) => (
            "the command stream",
            (1000.0 / profile.command.rate_hz).ceil() as u64,
        ),
        None => return Ok(()),
    };
    if timeout < 2 * period {
        return Err((
            format!("{timeout} ms with {fed_by} every {period} ms"),
            "allow at least two periods".into(),
        ));
    }
    Ok(())
}

/// Checks the drive train and CAN sections of `config`.
pub fn validate(config: &VehicleConfig, file: &Path) -> Result<(), ConfigError> {
    let invalid =
        |key: &str, problem: String, fix: &str| ConfigError::invalid(file, key, problem, fix);
    for (i, bus) in config.can.iter().enumerate() {
        let key = format!("can[{i}].interface");
        if bus.interface.is_empty()
            || bus.interface.len() > 15
            || bus.interface.contains(char::is_whitespace)
        {
            return Err(invalid(
                &key,
                format!("{:?}", bus.interface),
                "use a kernel interface name such as can0",
            ));
        }
        if config.can[..i].iter().any(|b| b.interface == bus.interface) {
            return Err(invalid(
                &key,
                format!("{:?} is listed twice", bus.interface),
                "list each interface once",
            ));
        }
        for (key, value, range, unit) in [
            (
                "reconnect_max_s",
                bus.reconnect_max_s,
                0.05..=300.0,
                "seconds",
            ),
            ("tx_queue", bus.tx_queue as f64, 8.0..=65536.0, "frames"),
            (
                "master_heartbeat_ms",
                bus.master_heartbeat_ms as f64,
                10.0..=1000.0,
                "ms",
            ),
            ("sync_ms", bus.sync_ms as f64, 1.0..=1000.0, "ms"),
        ] {
            check_range(file, &format!("can[{i}].{key}"), value, range, unit)?;
        }
        if !(1..=127).contains(&bus.master_node) {
            return Err(invalid(
                &format!("can[{i}].master_node"),
                format!("{}", bus.master_node),
                "use a CANopen node id 1 to 127 that no device on the bus has (default 127)",
            ));
        }
    }
    let bus_known = |name: &str| config.can.iter().any(|b| b.interface == name);
    if !config.drive.is_empty() {
        let Some(chassis) = &config.chassis else {
            return Err(invalid(
                "chassis",
                "missing while [[drive]] is set".into(),
                "add [chassis] with wheel_radius_m and track_m",
            ));
        };
        if config.wheels.is_none() {
            return Err(invalid(
                "wheels",
                "missing while [[drive]] is set".into(),
                "add [wheels.left] and [wheels.right]",
            ));
        }
        for (key, value, range, unit) in [
            (
                "chassis.wheel_radius_m",
                chassis.wheel_radius_m.left,
                0.01..=2.0,
                "m",
            ),
            (
                "chassis.wheel_radius_m",
                chassis.wheel_radius_m.right,
                0.01..=2.0,
                "m",
            ),
            ("chassis.track_m", chassis.track_m, 0.05..=5.0, "m"),
            (
                "chassis.max_speed_mps",
                chassis.max_speed_mps,
                0.01..=20.0,
                "m/s",
            ),
            (
                "chassis.max_yaw_rate_rps",
                chassis.max_yaw_rate_rps,
                0.01..=20.0,
                "rad/s",
            ),
            (
                "chassis.max_accel_mps2",
                chassis.max_accel_mps2,
                0.01..=20.0,
                "m/s²",
            ),
            (
                "chassis.max_decel_mps2",
                chassis.max_decel_mps2,
                0.01..=50.0,
                "m/s²",
            ),
            (
                "chassis.max_yaw_accel_rps2",
                chassis.max_yaw_accel_rps2,
                0.01..=50.0,
                "rad/s²",
            ),
            (
                "chassis.cmd_timeout_s",
                chassis.cmd_timeout_s,
                0.05..=10.0,
                "s",
            ),
            (
                "chassis.quick_stop_s",
                chassis.quick_stop_s,
                0.0..=10.0,
                "s",
            ),
            (
                "chassis.reset_timeout_s",
                chassis.reset_timeout_s,
                0.1..=60.0,
                "s",
            ),
        ] {
            check_range(file, key, value, range, unit)?;
        }
    }
    if let Some(wheels) = &config.wheels {
        for (name, w) in [("left", wheels.left), ("right", wheels.right)] {
            if w.direction != 1 && w.direction != -1 {
                return Err(invalid(
                    &format!("wheels.{name}.direction"),
                    format!("{}", w.direction),
                    "use 1 or -1",
                ));
            }
            check_range(
                file,
                &format!("wheels.{name}.gear_ratio"),
                w.gear_ratio,
                0.01..=1000.0,
                "",
            )?;
        }
    }
    let mut wheels_seen: Vec<Wheel> = Vec::new();
    for (i, d) in config.drive.iter().enumerate() {
        let key = |k: &str| format!("drive[{i}].{k}");
        if !bus_known(&d.bus) {
            return Err(invalid(
                &key("bus"),
                format!("{:?} is not a [[can]] interface", d.bus),
                "add it under [[can]], or fix the name",
            ));
        }
        if !(1..=127).contains(&d.node) {
            return Err(invalid(
                &key("node"),
                format!("{}", d.node),
                "use a CANopen node id 1 to 127",
            ));
        }
        if config.drive[..i]
            .iter()
            .any(|o| o.bus == d.bus && o.node == d.node)
        {
            return Err(invalid(
                &key("node"),
                format!("node {} is used twice on {}", d.node, d.bus),
                "give each drive its own node id",
            ));
        }
        let Some(profile) = d.profile.get() else {
            return Err(invalid(
                &key("profile"),
                "not loaded".into(),
                "name a profile file",
            ));
        };
        let blade = config
            .cutter
            .as_ref()
            .and_then(|c| c.drive_name())
            .is_some_and(|name| name == d.name);
        if blade {
            if !d.wheels.is_empty() {
                return Err(invalid(
                    "cutter.drive",
                    format!("names {:?}, which turns wheels", d.name),
                    "give the blade its own [[drive]] with wheels = []",
                ));
            }
            if profile.axes != 1 {
                return Err(invalid(
                    &key("profile"),
                    format!("the blade drive has {} axes", profile.axes),
                    "give the blade a one-axis drive profile",
                ));
            }
        } else if d.wheels.is_empty() {
            return Err(invalid(
                &key("wheels"),
                "is empty, and [cutter] does not name this drive".into(),
                "list the wheel of each axis, or set cutter.drive to this drive's name",
            ));
        } else if d.wheels.len() != usize::from(profile.axes) {
            return Err(invalid(
                &key("wheels"),
                format!(
                    "{} wheels for a {}-axis drive",
                    d.wheels.len(),
                    profile.axes
                ),
                "list the wheel of each axis, in axis order",
            ));
        }
        for w in &d.wheels {
            if wheels_seen.contains(w) {
                return Err(invalid(
                    &key("wheels"),
                    format!("{w:?} is driven twice"),
                    "each wheel belongs to one axis",
                ));
            }
            wheels_seen.push(*w);
        }
        if d.heartbeat_ms == 0 || u64::from(d.heartbeat_ms) * 2 > d.heartbeat_timeout_ms {
            return Err(invalid(
                &key("heartbeat_timeout_ms"),
                format!(
                    "{} ms with a {} ms heartbeat",
                    d.heartbeat_timeout_ms, d.heartbeat_ms
                ),
                "allow at least two heartbeat periods",
            ));
        }
        for (k, v) in [
            ("sdo_timeout_ms", d.sdo_timeout_ms),
            ("boot_timeout_ms", d.boot_timeout_ms),
            ("enable_timeout_ms", d.enable_timeout_ms),
            ("reset_wait_ms", d.reset_wait_ms),
        ] {
            check_range(file, &key(k), v as f64, 1.0..=60_000.0, "ms")?;
        }
        check_range(
            file,
            &key("reset_attempts"),
            f64::from(d.reset_attempts),
            1.0..=10.0,
            "",
        )?;
        if let Some(bus) = config.can.iter().find(|b| b.interface == d.bus) {
            if bus.master_node == d.node {
                return Err(invalid(
                    &key("node"),
                    format!("{} is chassisd's own node id on {}", d.node, d.bus),
                    "give the drive another id, or set can[].master_node",
                ));
            }
            check_master_timeout(d, profile, bus)
                .map_err(|(problem, fix)| invalid(&key("master_timeout_ms"), problem, &fix))?;
        }
        let period = feedback_period_ms(profile);
        if let Some(timeout) = d.feedback_timeout_ms
            && (timeout < 2 * period || timeout > 60_000)
        {
            return Err(invalid(
                &key("feedback_timeout_ms"),
                format!("{timeout} ms with feedback every {period} ms"),
                "allow at least two feedback periods (and at most 60000 ms)",
            ));
        }
        if let Some(chassis) = &config.chassis {
            let needed = u64::from(d.reset_attempts) * (d.reset_wait_ms + 100);
            if (chassis.reset_timeout_s * 1000.0) < needed as f64 {
                return Err(invalid(
                    "chassis.reset_timeout_s",
                    format!(
                        "{} s is shorter than drive {}'s {} reset attempts of {} ms",
                        chassis.reset_timeout_s, d.name, d.reset_attempts, d.reset_wait_ms
                    ),
                    "raise it, or lower drive[].reset_attempts or reset_wait_ms",
                ));
            }
        }
    }
    if !config.drive.is_empty() && wheels_seen.len() != 2 {
        return Err(invalid(
            "drive",
            "not both wheels are driven".into(),
            "assign left and right to drive axes",
        ));
    }
    for (i, e) in config.estop.iter().enumerate() {
        if e.name.trim().is_empty() || config.estop[..i].iter().any(|o| o.name == e.name) {
            return Err(invalid(
                &format!("estop[{i}].name"),
                format!("{:?} is empty or used twice", e.name),
                "give each e-stop input its own name",
            ));
        }
        if !bus_known(&e.bus) {
            return Err(invalid(
                &format!("estop[{i}].bus"),
                format!("{:?} is not a [[can]] interface", e.bus),
                "add it under [[can]], or fix the name",
            ));
        }
        if e.profile.get().is_none() {
            return Err(invalid(
                &format!("estop[{i}].profile"),
                "not loaded".into(),
                "name a profile file",
            ));
        }
    }
    if let Some(bms) = &config.bms {
        if !bus_known(&bms.bus) {
            return Err(invalid(
                "bms.bus",
                format!("{:?} is not a [[can]] interface", bms.bus),
                "add it under [[can]], or fix the name",
            ));
        }
        check_range(file, "bms.poll_hz", bms.poll_hz, 0.1..=50.0, "Hz")?;
        check_range(file, "bms.stale_s", bms.stale_s, 0.1..=600.0, "s")?;
    }
    Ok(())
}
