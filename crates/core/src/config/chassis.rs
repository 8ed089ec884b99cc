//! Configuration of the drive train and the CAN devices: geometry, limits, wheels, CAN
//! interfaces, drives and the BMS.

use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::{ConfigError, VehicleConfig, check_range, check_ranges};
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

impl Wheel {
    /// Its name as the configuration writes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Left => "left",
            Self::Right => "right",
        }
    }
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

/// Checks the drive train and CAN sections of `config`, in the order their errors are
/// reported: interfaces, chassis, wheels, drives, e-stops, then the BMS.
pub fn validate(config: &VehicleConfig, file: &Path) -> Result<(), ConfigError> {
    for (i, bus) in config.can.iter().enumerate() {
        check_can_interface(&config.can[..i], i, bus, file)?;
    }
    if !config.drive.is_empty() {
        check_chassis(config, file)?;
    }
    if let Some(wheels) = &config.wheels {
        check_wheels(wheels, file)?;
    }
    check_drives(config, file)?;
    for (i, estop) in config.estop.iter().enumerate() {
        check_estop(config, i, estop, file)?;
    }
    if let Some(bms) = &config.bms {
        check_bms(config, bms, file)?;
    }
    Ok(())
}

/// `can[i]`: its name, its timings, and chassisd's own node id.
fn check_can_interface(
    earlier: &[CanBusConfig],
    i: usize,
    bus: &CanBusConfig,
    file: &Path,
) -> Result<(), ConfigError> {
    check_can_name(earlier, i, bus, file)?;
    check_ranges(
        file,
        &format!("can[{i}]."),
        [
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
        ],
    )?;
    if !(1..=127).contains(&bus.master_node) {
        return Err(ConfigError::invalid(
            file,
            &format!("can[{i}].master_node"),
            format!("{}", bus.master_node),
            "use a CANopen node id 1 to 127 that no device on the bus has (default 127)",
        ));
    }
    Ok(())
}

/// `can[i].interface`: a kernel interface name, not among the `earlier` ones.
fn check_can_name(
    earlier: &[CanBusConfig],
    i: usize,
    bus: &CanBusConfig,
    file: &Path,
) -> Result<(), ConfigError> {
    let key = format!("can[{i}].interface");
    if bus.interface.is_empty()
        || bus.interface.len() > 15
        || bus.interface.contains(char::is_whitespace)
    {
        return Err(ConfigError::invalid(
            file,
            &key,
            format!("{:?}", bus.interface),
            "use a kernel interface name such as can0",
        ));
    }
    if earlier.iter().any(|b| b.interface == bus.interface) {
        return Err(ConfigError::invalid(
            file,
            &key,
            format!("{:?} is listed twice", bus.interface),
            "list each interface once",
        ));
    }
    Ok(())
}

/// With `[[drive]]` set: `[chassis]` and `[wheels]` are there, and the chassis' values are in
/// range.
fn check_chassis(config: &VehicleConfig, file: &Path) -> Result<(), ConfigError> {
    let Some(chassis) = &config.chassis else {
        return Err(ConfigError::invalid(
            file,
            "chassis",
            "missing while [[drive]] is set",
            "add [chassis] with wheel_radius_m and track_m",
        ));
    };
    if config.wheels.is_none() {
        return Err(ConfigError::invalid(
            file,
            "wheels",
            "missing while [[drive]] is set",
            "add [wheels.left] and [wheels.right]",
        ));
    }
    check_chassis_ranges(chassis, file)
}

/// The geometry, the limits and the timeouts of `[chassis]`.
fn check_chassis_ranges(c: &ChassisConfig, file: &Path) -> Result<(), ConfigError> {
    check_ranges(
        file,
        "chassis.",
        [
            ("wheel_radius_m", c.wheel_radius_m.left, 0.01..=2.0, "m"),
            ("wheel_radius_m", c.wheel_radius_m.right, 0.01..=2.0, "m"),
            ("track_m", c.track_m, 0.05..=5.0, "m"),
            ("max_speed_mps", c.max_speed_mps, 0.01..=20.0, "m/s"),
            ("max_yaw_rate_rps", c.max_yaw_rate_rps, 0.01..=20.0, "rad/s"),
            ("max_accel_mps2", c.max_accel_mps2, 0.01..=20.0, "m/s²"),
            ("max_decel_mps2", c.max_decel_mps2, 0.01..=50.0, "m/s²"),
            (
                "max_yaw_accel_rps2",
                c.max_yaw_accel_rps2,
                0.01..=50.0,
                "rad/s²",
            ),
            ("cmd_timeout_s", c.cmd_timeout_s, 0.05..=10.0, "s"),
            ("quick_stop_s", c.quick_stop_s, 0.0..=10.0, "s"),
            ("reset_timeout_s", c.reset_timeout_s, 0.1..=60.0, "s"),
        ],
    )
}

/// `[wheels]`: each wheel's direction and gear ratio.
fn check_wheels(wheels: &WheelsConfig, file: &Path) -> Result<(), ConfigError> {
    for (name, w) in [("left", wheels.left), ("right", wheels.right)] {
        if w.direction != 1 && w.direction != -1 {
            return Err(ConfigError::invalid(
                file,
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
    Ok(())
}

/// Every `[[drive]]` in turn, then that together they turn both wheels.
fn check_drives(config: &VehicleConfig, file: &Path) -> Result<(), ConfigError> {
    let mut wheels_seen: Vec<Wheel> = Vec::new();
    for (i, drive) in config.drive.iter().enumerate() {
        check_drive(config, i, drive, &mut wheels_seen, file)?;
    }
    if !config.drive.is_empty() && wheels_seen.len() != 2 {
        return Err(ConfigError::invalid(
            file,
            "drive",
            "not both wheels are driven",
            "assign left and right to drive axes",
        ));
    }
    Ok(())
}

/// `drive[i]`; `wheels_seen` holds the wheels the drives before it turn, and gains its own.
fn check_drive(
    config: &VehicleConfig,
    i: usize,
    d: &DriveConfig,
    wheels_seen: &mut Vec<Wheel>,
    file: &Path,
) -> Result<(), ConfigError> {
    check_drive_address(config, i, d, file)?;
    let Some(profile) = d.profile.get() else {
        return Err(ConfigError::invalid(
            file,
            &drive_key(i, "profile"),
            "not loaded",
            "name a profile file",
        ));
    };
    if is_blade(config, d) {
        check_blade_drive(i, d, profile, file)?;
    } else {
        check_wheel_drive(i, d, profile, file)?;
    }
    check_wheels_driven_once(i, d, wheels_seen, file)?;
    check_drive_timeouts(i, d, file)?;
    if let Some(bus) = config.can.iter().find(|b| b.interface == d.bus) {
        check_drive_on_bus(i, d, profile, bus, file)?;
    }
    check_feedback_timeout(i, d, profile, file)?;
    if let Some(chassis) = &config.chassis {
        check_reset_budget(chassis, d, file)?;
    }
    Ok(())
}

/// `drive[i].<key>`.
fn drive_key(i: usize, key: &str) -> String {
    format!("drive[{i}].{key}")
}

/// That `bus`, named at `key`, is a `[[can]]` interface.
fn check_bus_known(
    config: &VehicleConfig,
    key: &str,
    bus: &str,
    file: &Path,
) -> Result<(), ConfigError> {
    if config.can.iter().any(|b| b.interface == bus) {
        return Ok(());
    }
    Err(ConfigError::invalid(
        file,
        key,
        format!("{bus:?} is not a [[can]] interface"),
        "add it under [[can]], or fix the name",
    ))
}

/// `drive[i]`'s interface and node id, which no drive before it on that interface has.
fn check_drive_address(
    config: &VehicleConfig,
    i: usize,
    d: &DriveConfig,
    file: &Path,
) -> Result<(), ConfigError> {
    check_bus_known(config, &drive_key(i, "bus"), &d.bus, file)?;
    if !(1..=127).contains(&d.node) {
        return Err(ConfigError::invalid(
            file,
            &drive_key(i, "node"),
            format!("{}", d.node),
            "use a CANopen node id 1 to 127",
        ));
    }
    if config.drive[..i]
        .iter()
        .any(|o| o.bus == d.bus && o.node == d.node)
    {
        return Err(ConfigError::invalid(
            file,
            &drive_key(i, "node"),
            format!("node {} is used twice on {}", d.node, d.bus),
            "give each drive its own node id",
        ));
    }
    Ok(())
}

/// Whether `[cutter]` names `d` as the blade's drive.
fn is_blade(config: &VehicleConfig, d: &DriveConfig) -> bool {
    config
        .cutter
        .as_ref()
        .and_then(|c| c.drive_name())
        .is_some_and(|name| name == d.name)
}

/// The blade's drive: one axis, and no wheels.
fn check_blade_drive(
    i: usize,
    d: &DriveConfig,
    profile: &DriveProfile,
    file: &Path,
) -> Result<(), ConfigError> {
    if !d.wheels.is_empty() {
        return Err(ConfigError::invalid(
            file,
            "cutter.drive",
            format!("names {:?}, which turns wheels", d.name),
            "give the blade its own [[drive]] with wheels = []",
        ));
    }
    if profile.axes != 1 {
        return Err(ConfigError::invalid(
            file,
            &drive_key(i, "profile"),
            format!("the blade drive has {} axes", profile.axes),
            "give the blade a one-axis drive profile",
        ));
    }
    Ok(())
}

/// A drive that is not the blade's: a wheel for each of its axes.
fn check_wheel_drive(
    i: usize,
    d: &DriveConfig,
    profile: &DriveProfile,
    file: &Path,
) -> Result<(), ConfigError> {
    if d.wheels.is_empty() {
        return Err(ConfigError::invalid(
            file,
            &drive_key(i, "wheels"),
            "is empty, and [cutter] does not name this drive",
            "list the wheel of each axis, or set cutter.drive to this drive's name",
        ));
    }
    if d.wheels.len() != usize::from(profile.axes) {
        return Err(ConfigError::invalid(
            file,
            &drive_key(i, "wheels"),
            format!(
                "{} wheels for a {}-axis drive",
                d.wheels.len(),
                profile.axes
            ),
            "list the wheel of each axis, in axis order",
        ));
    }
    Ok(())
}

/// No wheel of `drive[i]` is turned by an axis before it; adds its wheels to `wheels_seen`.
fn check_wheels_driven_once(
    i: usize,
    d: &DriveConfig,
    wheels_seen: &mut Vec<Wheel>,
    file: &Path,
) -> Result<(), ConfigError> {
    for w in &d.wheels {
        if wheels_seen.contains(w) {
            return Err(ConfigError::invalid(
                file,
                &drive_key(i, "wheels"),
                format!("the {} wheel is driven twice", w.name()),
                "each wheel belongs to one axis",
            ));
        }
        wheels_seen.push(*w);
    }
    Ok(())
}

/// `drive[i]`'s heartbeat, SDO, boot, enable and fault-reset timings.
fn check_drive_timeouts(i: usize, d: &DriveConfig, file: &Path) -> Result<(), ConfigError> {
    if d.heartbeat_ms == 0 || u64::from(d.heartbeat_ms) * 2 > d.heartbeat_timeout_ms {
        return Err(ConfigError::invalid(
            file,
            &drive_key(i, "heartbeat_timeout_ms"),
            format!(
                "{} ms with a {} ms heartbeat",
                d.heartbeat_timeout_ms, d.heartbeat_ms
            ),
            "allow at least two heartbeat periods",
        ));
    }
    for (key, ms) in [
        ("sdo_timeout_ms", d.sdo_timeout_ms),
        ("boot_timeout_ms", d.boot_timeout_ms),
        ("enable_timeout_ms", d.enable_timeout_ms),
        ("reset_wait_ms", d.reset_wait_ms),
    ] {
        check_range(file, &drive_key(i, key), ms as f64, 1.0..=60_000.0, "ms")?;
    }
    check_range(
        file,
        &drive_key(i, "reset_attempts"),
        f64::from(d.reset_attempts),
        1.0..=10.0,
        "",
    )
}

/// `drive[i]` against its interface: not chassisd's own node id, and a loss-of-master
/// timeout that what feeds it can keep.
fn check_drive_on_bus(
    i: usize,
    d: &DriveConfig,
    profile: &DriveProfile,
    bus: &CanBusConfig,
    file: &Path,
) -> Result<(), ConfigError> {
    if bus.master_node == d.node {
        return Err(ConfigError::invalid(
            file,
            &drive_key(i, "node"),
            format!("{} is chassisd's own node id on {}", d.node, d.bus),
            "give the drive another id, or set can[].master_node",
        ));
    }
    check_master_timeout(d, profile, bus).map_err(|(problem, fix)| {
        ConfigError::invalid(file, &drive_key(i, "master_timeout_ms"), problem, &fix)
    })
}

/// A `drive[i].feedback_timeout_ms` that is set spans two feedback periods, and at most a
/// minute.
fn check_feedback_timeout(
    i: usize,
    d: &DriveConfig,
    profile: &DriveProfile,
    file: &Path,
) -> Result<(), ConfigError> {
    let period = feedback_period_ms(profile);
    if let Some(timeout) = d.feedback_timeout_ms
        && (timeout < 2 * period || timeout > 60_000)
    {
        return Err(ConfigError::invalid(
            file,
            &drive_key(i, "feedback_timeout_ms"),
            format!("{timeout} ms with feedback every {period} ms"),
            "allow at least two feedback periods (and at most 60000 ms)",
        ));
    }
    Ok(())
}

/// `chassis.reset_timeout_s` leaves time for all of drive `d`'s fault reset attempts.
fn check_reset_budget(
    chassis: &ChassisConfig,
    d: &DriveConfig,
    file: &Path,
) -> Result<(), ConfigError> {
    let needed = u64::from(d.reset_attempts) * (d.reset_wait_ms + 100);
    if (chassis.reset_timeout_s * 1000.0) < needed as f64 {
        return Err(ConfigError::invalid(
            file,
            "chassis.reset_timeout_s",
            format!(
                "{} s is shorter than drive {}'s {} reset attempts of {} ms",
                chassis.reset_timeout_s, d.name, d.reset_attempts, d.reset_wait_ms
            ),
            "raise it, or lower drive[].reset_attempts or reset_wait_ms",
        ));
    }
    Ok(())
}

/// `estop[i]`: a name of its own, a known interface, and its profile.
fn check_estop(
    config: &VehicleConfig,
    i: usize,
    e: &EStopConfig,
    file: &Path,
) -> Result<(), ConfigError> {
    if e.name.trim().is_empty() || config.estop[..i].iter().any(|o| o.name == e.name) {
        return Err(ConfigError::invalid(
            file,
            &format!("estop[{i}].name"),
            format!("{:?} is empty or used twice", e.name),
            "give each e-stop input its own name",
        ));
    }
    check_bus_known(config, &format!("estop[{i}].bus"), &e.bus, file)?;
    if e.profile.get().is_none() {
        return Err(ConfigError::invalid(
            file,
            &format!("estop[{i}].profile"),
            "not loaded",
            "name a profile file",
        ));
    }
    Ok(())
}

/// `[bms]`: a known interface, its polling rate and staleness.
fn check_bms(config: &VehicleConfig, bms: &BmsConfig, file: &Path) -> Result<(), ConfigError> {
    check_bus_known(config, "bms.bus", &bms.bus, file)?;
    check_range(file, "bms.poll_hz", bms.poll_hz, 0.1..=50.0, "Hz")?;
    check_range(file, "bms.stale_s", bms.stale_s, 0.1..=600.0, "s")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> (std::path::PathBuf, String) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices/vehicle.example.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        (path, text)
    }

    /// The error of the example with `text` in place of its own.
    fn error_of(path: &Path, text: &str) -> String {
        VehicleConfig::from_toml(text, path)
            .unwrap_err()
            .to_string()
    }

    /// The example without the table headed `header` (up to the next blank line).
    fn without_table(text: &str, header: &str) -> String {
        let start = text.find(header).expect("table in the example");
        let end = text[start..]
            .find("\n\n")
            .map_or(text.len(), |n| start + n + 1);
        format!("{}{}", &text[..start], &text[end..])
    }

    #[test]
    fn each_check_names_its_key_and_the_problem() {
        let (path, text) = example();
        let can0 = "interface = \"can0\"\n";
        let can1 = "interface = \"can1\"\n";
        let drive0 = "bus = \"can0\"\nnode = 1\n";
        let drive1 = "bus = \"can0\"\nnode = 3\n";
        for (from, to, expected) in [
            (
                can1,
                "interface = \"can 1\"\n",
                "`can[1].interface`: \"can 1\"",
            ),
            (
                can1,
                "interface = \"can1\"\ntx_queue = 4\n",
                "`can[1].tx_queue`: 4 is outside 8..=65536 frames",
            ),
            (
                can0,
                "interface = \"can0\"\nmaster_node = 0\n",
                "`can[0].master_node`: 0; fix: use a CANopen node id 1 to 127",
            ),
            (
                "wheel_radius_m = 0.0825",
                "wheel_radius_m = [0.0825, 3.0]",
                "`chassis.wheel_radius_m`: 3 is outside 0.01..=2 m",
            ),
            (
                "max_decel_mps2 = 1.0",
                "max_decel_mps2 = 60",
                "`chassis.max_decel_mps2`: 60 is outside 0.01..=50 m/s²",
            ),
            (
                "direction = -1\ngear_ratio = 1.0",
                "direction = -1\ngear_ratio = 0",
                "`wheels.right.gear_ratio`: 0 is outside 0.01..=1000",
            ),
            (
                drive1,
                "bus = \"can0\"\nnode = 1\n",
                "`drive[1].node`: node 1 is used twice on can0",
            ),
            (
                "profile = \"blade-cia402.toml\"",
                "profile = \"zlac8015d.toml\"",
                "`drive[1].profile`: the blade drive has 2 axes",
            ),
            (
                drive0,
                "bus = \"can0\"\nnode = 1\nsdo_timeout_ms = 0\n",
                "`drive[0].sdo_timeout_ms`: 0 is outside 1..=60000 ms",
            ),
            (
                drive1,
                "bus = \"can0\"\nnode = 3\nreset_attempts = 11\n",
                "`drive[1].reset_attempts`: 11 is outside 1..=10",
            ),
            (
                can0,
                "interface = \"can0\"\nmaster_node = 1\n",
                "`drive[0].node`: 1 is chassisd's own node id on can0",
            ),
            (
                drive0,
                "bus = \"can0\"\nnode = 1\nmaster_timeout_ms = 10\n",
                "`drive[0].master_timeout_ms`: 10 ms; fix: use 20 to 65535 ms",
            ),
            (
                drive0,
                "bus = \"can0\"\nnode = 1\nmaster_timeout_ms = 80\n",
                "`drive[0].master_timeout_ms`: 80 ms with the command stream every 50 ms",
            ),
            (
                drive1,
                "bus = \"can0\"\nnode = 3\nmaster_timeout_ms = 90\n",
                "`drive[1].master_timeout_ms`: 90 ms with chassisd's heartbeat every 50 ms",
            ),
            (
                drive0,
                "bus = \"can0\"\nnode = 1\nfeedback_timeout_ms = 60\n",
                "`drive[0].feedback_timeout_ms`: 60 ms with feedback every 50 ms",
            ),
            (
                "[chassis]\n",
                "[chassis]\nreset_timeout_s = 0.5\n",
                "`chassis.reset_timeout_s`: 0.5 s is shorter than drive wheels's 3 reset \
                 attempts of 200 ms",
            ),
            (
                "name = \"body\"",
                "name = \" \"",
                "`estop[0].name`: \" \" is empty or used twice",
            ),
            (
                "poll_hz = 2.0",
                "poll_hz = 0",
                "`bms.poll_hz`: 0 is outside 0.1..=50 Hz",
            ),
            (
                "stale_s = 3.0",
                "stale_s = 1000",
                "`bms.stale_s`: 1000 is outside 0.1..=600 s",
            ),
        ] {
            let bad = text.replacen(from, to, 1);
            assert_ne!(bad, text, "{from:?} not in the example");
            let e = error_of(&path, &bad);
            assert!(e.contains(expected), "{expected}: {e}");
        }
    }

    #[test]
    fn drives_need_the_chassis_the_wheels_and_both_wheels_driven() {
        let (path, text) = example();
        let e = error_of(&path, &without_table(&text, "[chassis]\n"));
        assert!(
            e.contains("`chassis`: missing while [[drive]] is set"),
            "{e}"
        );
        let no_wheels = without_table(&text, "[wheels.left]\n");
        let e = error_of(&path, &without_table(&no_wheels, "[wheels.right]\n"));
        assert!(
            e.contains("`wheels`: missing while [[drive]] is set"),
            "{e}"
        );
        let one_wheel = text
            .replacen(
                "profile = \"zlac8015d.toml\"",
                "profile = \"blade-cia402.toml\"",
                1,
            )
            .replacen("wheels = [\"left\", \"right\"]", "wheels = [\"left\"]", 1);
        let e = error_of(&path, &one_wheel);
        assert!(e.contains("`drive`: not both wheels are driven"), "{e}");
    }

    #[test]
    fn the_first_section_in_error_is_reported() {
        let (path, text) = example();
        // The interfaces come before the chassis, the chassis before the wheels, a drive
        // before the drives after it, and the e-stops before the BMS.
        for (edits, expected) in [
            (
                [
                    ("track_m = 0.42", "track_m = 0"),
                    (
                        "interface = \"can0\"\nreconnect_max_s = 5.0",
                        "interface = \"can0\"\nreconnect_max_s = 0",
                    ),
                ],
                "`can[0].reconnect_max_s`",
            ),
            (
                [
                    ("direction = -1", "direction = 0"),
                    ("track_m = 0.42", "track_m = 0"),
                ],
                "`chassis.track_m`",
            ),
            (
                [
                    ("bus = \"can0\"\nnode = 3", "bus = \"can0\"\nnode = 0"),
                    ("heartbeat_ms = 100", "heartbeat_ms = 0"),
                ],
                "`drive[0].heartbeat_timeout_ms`",
            ),
            (
                [
                    ("poll_hz = 2.0", "poll_hz = 0"),
                    ("name = \"body\"", "name = \"\""),
                ],
                "`estop[0].name`",
            ),
        ] {
            let bad = edits
                .iter()
                .fold(text.clone(), |t, (from, to)| t.replacen(from, to, 1));
            let e = error_of(&path, &bad);
            assert!(e.contains(expected), "{expected}: {e}");
        }
    }
}
