//! Vehicle configuration: loaded from TOML, validated on load, errors that name the key.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

pub use crate::devices::gnss::ubx::config::Port as UbloxPort;
use crate::devices::profile::{ProfileError, toml_fix};

pub mod calibration;
pub mod chassis;
pub mod imu;
pub mod localization;
pub mod mission;
pub mod motion;
pub mod mqtt;
pub mod ntrip;
pub mod ros1;
pub mod ros2;
pub mod websocket;
pub mod zones;

/// A configuration that failed to load or validate.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{}: cannot read: {reason}{}", .file.display(), describe_named_by(.named_by))]
    Read {
        /// The file, as a full path.
        file: PathBuf,
        /// Why (the operating system's word, once).
        reason: String,
        /// The configuration file and key that named it, when one did.
        named_by: Option<(PathBuf, String)>,
    },
    /// The file is not valid TOML or does not match the schema.
    #[error("{file}: {message}\nfix: {}", toml_fix(.message))]
    Parse {
        /// The file.
        file: PathBuf,
        /// The TOML parser's message, which names the key and line.
        message: String,
    },
    /// A value is out of range or inconsistent.
    #[error("{file}: key `{key}`: {problem}; fix: {fix}")]
    Invalid {
        /// The file.
        file: PathBuf,
        /// Dotted key path.
        key: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
    /// A device profile it names does not parse or hold together.
    #[error(transparent)]
    Profile(#[from] ProfileError),
}

/// Reads a configuration-type file (vehicle, profile, plant, calibration, DBC) as text.
pub fn read_text(path: &Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(path).map_err(|e| ConfigError::Read {
        file: std::path::absolute(path).unwrap_or_else(|_| path.to_owned()),
        reason: e.to_string(),
        named_by: None,
    })
}

/// Whether `path` lies inside the folder `root`: by their real paths (links followed) where
/// they exist, else by their names with `.` and `..` worked out.
pub fn lies_within(path: &Path, root: &Path) -> bool {
    let real = |p: &Path| {
        std::fs::canonicalize(p).unwrap_or_else(|_| {
            let absolute = std::path::absolute(p).unwrap_or_else(|_| p.to_owned());
            let mut clean = PathBuf::new();
            for part in absolute.components() {
                match part {
                    std::path::Component::ParentDir => {
                        clean.pop();
                    }
                    std::path::Component::CurDir => {}
                    other => clean.push(other),
                }
            }
            clean
        })
    };
    real(path).starts_with(real(root))
}

/// " (named by `key` in FILE)" for a file a configuration named.
fn describe_named_by(by: &Option<(PathBuf, String)>) -> String {
    by.as_ref().map_or(String::new(), |(config, key)| {
        format!(" (named by `{key}` in {})", config.display())
    })
}

impl ConfigError {
    /// Says which key of which configuration named a file that could not be read.
    pub fn named_by(self, config: &Path, key: &str) -> Self {
        match self {
            Self::Read {
                file,
                reason,
                named_by: None,
            } => Self::Read {
                file,
                reason,
                named_by: Some((config.to_owned(), key.to_owned())),
            },
            other => other,
        }
    }

    /// An invalid value in `file` at `key`, with what is wrong and how to fix it.
    pub fn invalid(file: &Path, key: &str, problem: impl Into<String>, fix: &str) -> Self {
        Self::Invalid {
            file: file.to_owned(),
            key: key.to_owned(),
            problem: problem.into(),
            fix: fix.to_owned(),
        }
    }
}

/// The whole vehicle configuration.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct VehicleConfig {
    /// Identity of the vehicle.
    #[serde(default)]
    pub vehicle: VehicleSection,
    /// The GNSS receiver; absent on vehicles without one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gnss: Option<GnssConfig>,
    /// The datum and the fusion filter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub localization: Option<localization::LocalizationConfig>,
    /// The IMU; absent on vehicles without one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imu: Option<imu::ImuConfig>,
    /// Geometry, limits and safety of the drive train; required with `[[drive]]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chassis: Option<chassis::ChassisConfig>,
    /// Limits and tolerances of closed-loop moves (default: the chassis limits).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<motion::MotionConfig>,
    /// How root MISSION steps run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mission: Option<mission::MissionConfig>,
    /// The blade actuator of OPEN_CUTTER and CLOSE_CUTTER.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cutter: Option<mission::CutterConfig>,
    /// Per-wheel direction and gear ratio.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheels: Option<chassis::WheelsConfig>,
    /// CAN interfaces.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub can: Vec<chassis::CanBusConfig>,
    /// Motor drives on CAN.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub drive: Vec<chassis::DriveConfig>,
    /// Hardware e-stop inputs on CAN.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub estop: Vec<chassis::EStopConfig>,
    /// The battery management system.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bms: Option<chassis::BmsConfig>,
    /// The MQTT broker and the protocol dialects.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mqtt: Option<mqtt::MqttConfig>,
    /// RTK corrections from an NTRIP caster.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ntrip: Option<ntrip::NtripConfig>,
    /// The native ROS1 node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros1: Option<ros1::Ros1Config>,
    /// The native ROS 2 node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<ros2::Ros2Config>,
    /// The rosbridge WebSocket server.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub websocket: Option<websocket::WebsocketConfig>,
    /// The zones the vehicle keeps to, and the GNSS gate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zones: Option<zones::ZonesConfig>,
    /// The calibration file read on load and the values it put in force, for the log.
    #[serde(skip)]
    pub calibration_in_force: Option<(PathBuf, Vec<String>)>,
}

/// What a secret reads in a recorded configuration.
pub const REDACTED: &str = "***redacted***";

/// `[vehicle]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSection {
    /// A name for logs and recordings.
    #[serde(default = "default_vehicle_name")]
    pub name: String,
    /// The calibration file, relative to this configuration (default
    /// `calib/<name>.toml` beside it, when that exists). Read on load; its values replace
    /// the configuration's.
    #[serde(default, skip_serializing)]
    pub calibration: Option<String>,
}

impl Default for VehicleSection {
    fn default() -> Self {
        Self {
            name: default_vehicle_name(),
            calibration: None,
        }
    }
}

fn default_vehicle_name() -> String {
    "chassisd".to_owned()
}

/// Wire protocol of a GNSS receiver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum GnssProtocol {
    /// NMEA 0183 sentences.
    #[default]
    Nmea0183,
}

/// The receiver family, which sets what `check` asks of it and may configure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ReceiverKind {
    /// Any receiver sending NMEA 0183 (and its vendors' sentences).
    #[default]
    Nmea,
    /// u-blox (UBX and NMEA): `check` asks MON-VER; `check --configure` sets its messages.
    Ublox,
    /// Unicore UM98x (NMEA, its `H` forms, HPR, KSXT, `#UNIHEADINGA`).
    Unicore,
}

/// `[gnss]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GnssConfig {
    /// Serial device path, e.g. `/dev/ttyUSB0` or a udev symlink.
    pub port: String,
    /// Baud rate.
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// Wire protocol. Kept for older files: the framer tells NMEA, UBX and Unicore's logs
    /// apart by themselves.
    #[serde(default)]
    pub protocol: GnssProtocol,
    /// The receiver family.
    #[serde(default)]
    pub receiver: ReceiverKind,
    /// The u-blox port this cable reaches (its message-rate keys differ by port); by default
    /// USB for `/dev/ttyACM*`, else UART1.
    #[serde(default)]
    pub ublox_port: Option<UbloxPort>,
    /// A fix older than this is stale, seconds.
    #[serde(default = "default_fix_timeout_s")]
    pub fix_timeout_s: f64,
    /// Course over ground stands in for heading only above this speed, m/s.
    #[serde(default = "default_cog_min_speed_mps")]
    pub cog_min_speed_mps: f64,
    /// Longest wait between reconnect attempts, seconds.
    #[serde(default = "default_reconnect_max_s")]
    pub reconnect_max_s: f64,
    /// Antenna phase centre in the vehicle frame (x forward, y left, z up), metres.
    #[serde(default)]
    pub antenna: Vector3,
    /// The dual-antenna receiver's heading minus the vehicle's heading, degrees (the
    /// baseline's misalignment with the vehicle's axis); subtracted from every heading.
    #[serde(default)]
    pub heading_offset_deg: f64,
}

/// A position in the vehicle frame, metres.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Vector3 {
    /// Forward, metres.
    #[serde(default)]
    pub x: f64,
    /// Left, metres.
    #[serde(default)]
    pub y: f64,
    /// Up, metres.
    #[serde(default)]
    pub z: f64,
}

fn default_baud() -> u32 {
    115_200
}
fn default_fix_timeout_s() -> f64 {
    2.0
}
fn default_cog_min_speed_mps() -> f64 {
    0.3
}
fn default_reconnect_max_s() -> f64 {
    5.0
}

/// Baud rates a serial GNSS receiver can use.
pub(crate) const STANDARD_BAUDS: [u32; 10] = [
    4_800, 9_600, 19_200, 38_400, 57_600, 115_200, 230_400, 460_800, 921_600, 1_000_000,
];

impl GnssConfig {
    /// The stale-fix timeout.
    pub fn fix_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.fix_timeout_s)
    }

    /// The longest reconnect back-off.
    pub fn reconnect_max(&self) -> Duration {
        Duration::from_secs_f64(self.reconnect_max_s)
    }

    /// The u-blox port: as configured, else USB for a CDC-ACM device, else UART1.
    pub fn ublox_port(&self) -> UbloxPort {
        self.ublox_port.unwrap_or_else(|| {
            let device = std::fs::canonicalize(&self.port)
                .map(|p| p.to_string_lossy().into_owned())
                .unwrap_or_else(|_| self.port.clone());
            if device.contains("ttyACM") {
                UbloxPort::Usb
            } else {
                UbloxPort::Uart1
            }
        })
    }
}

impl VehicleConfig {
    /// Whether it names a device to read or drive: a receiver, an IMU or a CAN interface.
    pub fn has_devices(&self) -> bool {
        self.gnss.is_some() || self.imu.is_some() || !self.can.is_empty()
    }

    /// Refuses a configuration with no device for `chassisd run` (a configuration error:
    /// systemd must not restart it in a loop).
    pub fn require_devices(&self, file: &Path) -> Result<(), ConfigError> {
        if self.has_devices() {
            return Ok(());
        }
        Err(ConfigError::invalid(
            file,
            "gnss",
            "the configuration names no device ([gnss], [imu] or a [[can]] interface), so \
             there is nothing to run",
            "name at least a receiver, e.g. [gnss] port = \"/dev/ttyUSB0\"; \
             devices/vehicle.example.toml is a complete configuration, and `chassisd sim` \
             runs a simulated vehicle without hardware",
        ))
    }

    /// Reads and validates a TOML file. Device profiles it names are read relative to it.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = read_text(path)?;
        Self::from_toml(&text, path)
    }

    /// Reads and validates a configuration stored in a recording: every file it names
    /// must lie inside the recording's folder `root` (a recording's own configuration has
    /// its profiles inline). A name outside is refused before anything is read from it:
    /// a recording is data, and must not make chassisd read, or print, other files.
    pub fn load_within(path: &Path, root: &Path) -> Result<Self, ConfigError> {
        let text = read_text(path)?;
        Self::parse_and_resolve(&text, path, Some(root))
    }

    /// Parses and validates TOML text; `file` names it in errors, and profile files are
    /// found relative to its folder.
    pub fn from_toml(text: &str, file: &Path) -> Result<Self, ConfigError> {
        Self::parse_and_resolve(text, file, None)
    }

    fn parse_and_resolve(
        text: &str,
        file: &Path,
        root: Option<&Path>,
    ) -> Result<Self, ConfigError> {
        let mut config: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            file: file.to_owned(),
            message: e.to_string(),
        })?;
        let base = file.parent().unwrap_or(Path::new("."));
        if let Some(root) = root {
            config.confine(base, file, root)?;
        }
        for (i, drive) in config.drive.iter_mut().enumerate() {
            drive
                .profile
                .resolve(base, file, &format!("drive[{i}].profile"))?;
        }
        for (i, estop) in config.estop.iter_mut().enumerate() {
            estop
                .profile
                .resolve(base, file, &format!("estop[{i}].profile"))?;
        }
        if let Some(bms) = &mut config.bms {
            bms.profile.resolve(base, file, "bms.profile")?;
        }
        config.load_calibration(base, file)?;
        if let Some(zones) = &mut config.zones {
            zones.load(base, file)?;
        }
        if let Some(ntrip) = &mut config.ntrip {
            ntrip.resolve(base);
        }
        if let Some(mqtt) = &mut config.mqtt {
            mqtt.resolve(base);
            // Found now, not after the devices are opened and the broker is dialled.
            for (i, link) in mqtt.links.iter().enumerate() {
                let Some(tls) = &link.tls else { continue };
                for (key, path) in tls.files().into_iter().take(3) {
                    if let Some(path) = path {
                        read_text(Path::new(path)).map_err(|e| {
                            e.named_by(file, &format!("{}{key}", mqtt.key_prefix(i)))
                        })?;
                    }
                }
            }
        }
        config.validate(file)?;
        Ok(config)
    }

    /// Refuses every file this configuration names (relative to `base`) that lies outside
    /// `root`, before any is read.
    fn confine(&self, base: &Path, file: &Path, root: &Path) -> Result<(), ConfigError> {
        let mut named: Vec<(String, String)> = Vec::new();
        for (i, d) in self.drive.iter().enumerate() {
            if let Some(name) = d.profile.file_name() {
                named.push((format!("drive[{i}].profile"), name.to_owned()));
            }
        }
        for (i, e) in self.estop.iter().enumerate() {
            if let Some(name) = e.profile.file_name() {
                named.push((format!("estop[{i}].profile"), name.to_owned()));
            }
        }
        if let Some(name) = self.bms.as_ref().and_then(|b| b.profile.file_name()) {
            named.push(("bms.profile".into(), name.to_owned()));
        }
        named.push((
            "vehicle.calibration".into(),
            self.vehicle.calibration.clone().unwrap_or_else(|| {
                calibration::default_path(&self.vehicle.name)
                    .to_string_lossy()
                    .into_owned()
            }),
        ));
        if let Some(m) = &self.mqtt {
            for (i, link) in m.links.iter().enumerate() {
                let Some(tls) = &link.tls else { continue };
                for (key, path) in tls.files() {
                    if let Some(path) = path {
                        named.push((format!("{}{key}", m.key_prefix(i)), path.clone()));
                    }
                }
            }
        }
        if let Some(n) = &self.ntrip {
            for (key, path) in [
                ("ntrip.password_file", &n.password_file),
                ("ntrip.ca_file", &n.ca_file),
            ] {
                if let Some(path) = path {
                    named.push((key.into(), path.to_string_lossy().into_owned()));
                }
            }
        }
        if let Some(file) = self.zones.as_ref().and_then(|z| z.file.as_ref()) {
            named.push(("zones.file".into(), file.to_string_lossy().into_owned()));
        }
        for (key, name) in named {
            if !lies_within(&base.join(&name), root) {
                return Err(ConfigError::invalid(
                    file,
                    &key,
                    format!("{name:?} lies outside the recording's folder"),
                    "a recording's configuration names only files inside its folder (its \
                     profiles are inline); replay it with --config FILE to use files elsewhere",
                ));
            }
        }
        Ok(())
    }

    /// Reads the calibration file `[vehicle] calibration` names, or `calib/<name>.toml`
    /// beside the configuration when that exists, into the values it calibrates.
    fn load_calibration(&mut self, base: &Path, file: &Path) -> Result<(), ConfigError> {
        let (path, named) = match &self.vehicle.calibration {
            Some(name) => (base.join(name), true),
            None => (
                base.join(calibration::default_path(&self.vehicle.name)),
                false,
            ),
        };
        if !named && !path.exists() {
            return Ok(());
        }
        let calib = calibration::CalibrationFile::load(&path)
            .map_err(|e| e.named_by(file, "vehicle.calibration"))?;
        let lines = calib.apply(self);
        self.calibration_in_force = Some((path, lines));
        Ok(())
    }

    /// This configuration as self-contained TOML, with every device profile written inline,
    /// as recordings store it.
    /// Secrets are left out: the MQTT password and the WebSocket token read [`REDACTED`], the
    /// NTRIP URL keeps its user without the password, and no password file is named (a
    /// replay connects to nothing that needs them).
    pub fn to_effective_toml(&self) -> String {
        let mut recorded = self.clone();
        if let Some(m) = &mut recorded.mqtt {
            for link in &mut m.links {
                if link.password.is_some() {
                    link.password = Some(REDACTED.into());
                }
            }
        }
        if let Some(w) = &mut recorded.websocket
            && w.token.is_some()
        {
            w.token = Some(REDACTED.into());
        }
        if let Some(n) = &mut recorded.ntrip {
            *n = n.redacted();
        }
        if let Some(z) = &mut recorded.zones {
            *z = z.recorded();
        }
        // Plain data structures always serialise.
        toml::to_string(&recorded).unwrap_or_default()
    }

    /// Checks ranges and consistency.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        let invalid =
            |key: &str, problem: String, fix: &str| ConfigError::invalid(file, key, problem, fix);
        if self.vehicle.name.trim().is_empty() {
            return Err(invalid(
                "vehicle.name",
                "is empty".into(),
                "give the vehicle a name",
            ));
        }
        chassis::validate(self, file)?;
        if let Some(imu) = &self.imu {
            imu.validate(file)?;
        }
        if let Some(l) = &self.localization {
            l.validate(file)?;
        }
        if let Some(m) = &self.motion {
            m.validate(self.chassis.as_ref(), file)?;
        }
        if let Some(m) = &self.mission {
            m.validate(file)?;
        }
        if let Some(c) = &self.cutter {
            c.validate(self, file)?;
        }
        if let Some(m) = &self.mqtt {
            m.validate(file)?;
        }
        if let Some(r) = &self.ros1 {
            r.validate(file)?;
        }
        if let Some(r) = &self.ros2 {
            r.validate(file)?;
        }
        if let Some(w) = &self.websocket {
            w.validate(file)?;
        }
        if let Some(z) = &self.zones {
            z.validate(file)?;
        }
        if let Some(n) = &self.ntrip {
            n.validate(file)?;
            if n.port.is_none() && self.gnss.is_none() {
                return Err(invalid(
                    "ntrip",
                    "the corrections have nowhere to go: no [gnss] receiver and no ntrip.port"
                        .into(),
                    "configure the receiver ([gnss] port), or name its correction port as \
                     ntrip.port",
                ));
            }
        }
        let Some(gnss) = &self.gnss else {
            return Ok(());
        };
        if gnss.port.trim().is_empty() {
            return Err(invalid(
                "gnss.port",
                "is empty".into(),
                "set the serial device, e.g. \"/dev/ttyUSB0\"",
            ));
        }
        if !STANDARD_BAUDS.contains(&gnss.baud) {
            return Err(invalid(
                "gnss.baud",
                format!("{} is not a standard rate", gnss.baud),
                "use one of 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600",
            ));
        }
        check_range(
            file,
            "gnss.fix_timeout_s",
            gnss.fix_timeout_s,
            0.1..=60.0,
            "seconds",
        )?;
        check_range(
            file,
            "gnss.cog_min_speed_mps",
            gnss.cog_min_speed_mps,
            0.0..=10.0,
            "m/s",
        )?;
        check_range(
            file,
            "gnss.reconnect_max_s",
            gnss.reconnect_max_s,
            0.05..=300.0,
            "seconds",
        )?;
        for (key, v) in [
            ("gnss.antenna.x", gnss.antenna.x),
            ("gnss.antenna.y", gnss.antenna.y),
            ("gnss.antenna.z", gnss.antenna.z),
        ] {
            check_range(file, key, v, -10.0..=10.0, "metres")?;
        }
        check_range(
            file,
            "gnss.heading_offset_deg",
            gnss.heading_offset_deg,
            -180.0..=180.0,
            "degrees",
        )?;
        Ok(())
    }
}

pub fn check_range(
    file: &Path,
    key: &str,
    value: f64,
    range: std::ops::RangeInclusive<f64>,
    unit: &str,
) -> Result<(), ConfigError> {
    if range.contains(&value) {
        return Ok(());
    }
    let unit = if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    };
    let (low, high) = (range.start(), range.end());
    // A range open above says so, rather than print the largest float's 309 digits.
    let (problem, fix) = if *high == f64::MAX {
        (
            format!("{value}{unit} is below {low}{unit}"),
            format!("set a value of at least {low}{unit}"),
        )
    } else {
        (
            format!("{value} is outside {low}..={high}{unit}"),
            format!("set a value between {low} and {high}{unit}"),
        )
    };
    Err(ConfigError::Invalid {
        file: file.to_owned(),
        key: key.to_owned(),
        problem,
        fix,
    })
}

/// [`check_range`] on each `(key, value, range, unit)` in turn, its key written under
/// `prefix` (e.g. `chassis.`): the first value out of its range is the error.
pub fn check_ranges<'a>(
    file: &Path,
    prefix: &str,
    checks: impl IntoIterator<Item = (&'a str, f64, std::ops::RangeInclusive<f64>, &'a str)>,
) -> Result<(), ConfigError> {
    for (key, value, range, unit) in checks {
        check_range(file, &format!("{prefix}{key}"), value, range, unit)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> Result<VehicleConfig, ConfigError> {
        VehicleConfig::from_toml(text, Path::new("test.toml"))
    }

    #[test]
    fn a_range_is_said_as_a_person_writes_it() {
        let said = |value, range, unit| {
            check_range(Path::new("v.toml"), "k", value, range, unit)
                .unwrap_err()
                .to_string()
        };
        let plain = said(11.0, 1.0..=10.0, "");
        assert!(
            plain.contains("11 is outside 1..=10; fix: set a value between 1 and 10"),
            "{plain}"
        );
        assert!(!plain.ends_with(' '), "{plain:?}");
        let open = said(0.0, 0.001..=f64::MAX, "m/s");
        assert!(
            open.contains("0 m/s is below 0.001 m/s; fix: set a value of at least 0.001 m/s"),
            "{open}"
        );
        assert!(said(3.0, 0.01..=2.0, "m").contains("3 is outside 0.01..=2 m; fix"));
    }

    #[test]
    fn defaults_fill_optional_keys() {
        let c = load("[gnss]\nport = \"/dev/ttyUSB0\"\n").unwrap();
        let g = c.gnss.unwrap();
        assert_eq!(g.baud, 115_200);
        assert_eq!(g.fix_timeout(), Duration::from_secs(2));
        assert_eq!(g.protocol, GnssProtocol::Nmea0183);
    }

    #[test]
    fn shipped_example_is_valid() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices/vehicle.example.toml");
        let c = VehicleConfig::load(&path).unwrap();
        assert!(c.gnss.is_some());
        let mqtt = c.mqtt.expect("[mqtt]");
        assert!(mqtt.rtk.is_some() && mqtt.root.is_some() && mqtt.device.is_some());
        assert_eq!(
            c.cutter.expect("[cutter]").cutter().map_err(|e| e.0),
            Ok(mission::Cutter::Drive {
                name: "blade".into(),
                rpm: 3000.0
            })
        );
        let estop = c.estop[0].profile.get().expect("e-stop profile loaded");
        assert_eq!((estop.id, estop.timeout_ms), (0x18A, 300));
    }

    #[test]
    fn a_missing_file_is_named_once_with_its_full_path_and_the_key_that_named_it() {
        let devices = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices");
        let example = std::fs::read_to_string(devices.join("vehicle.example.toml")).unwrap();
        let text = example.replace("profile = \"zlac8015d.toml\"", "profile = \"nope.toml\"");
        let config = devices.join("vehicle.example.toml");
        let msg = VehicleConfig::from_toml(&text, &config)
            .unwrap_err()
            .to_string();
        let full = devices.join("nope.toml");
        assert_eq!(
            msg,
            format!(
                "{}: cannot read: No such file or directory (os error 2) (named by \
                 `drive[0].profile` in {})",
                full.display(),
                config.display()
            )
        );
        // Not a source either: a caller's error chain would print it a second time.
        let e = VehicleConfig::load(Path::new("nope.toml")).unwrap_err();
        assert!(std::error::Error::source(&e).is_none());
        let cwd = std::env::current_dir().unwrap();
        assert!(
            e.to_string()
                .starts_with(&format!("{}: ", cwd.join("nope.toml").display())),
            "{e}"
        );
    }

    #[test]
    fn a_missing_broker_certificate_is_found_when_the_configuration_loads() {
        let text = "[mqtt]\nhost = \"broker\"\nport = 8883\n[mqtt.tls]\nca_file = \"ca.pem\"\n";
        let msg = load(text).unwrap_err().to_string();
        assert!(
            msg.contains("ca.pem: cannot read: No such file")
                && msg.ends_with("(named by `mqtt.tls.ca_file` in test.toml)"),
            "{msg}"
        );
    }

    #[test]
    fn parse_errors_say_how_to_fix_them() {
        for (text, key, fix) in [
            (
                "[gnss]\nprot = \"/dev/x\"\n",
                "prot",
                "correct its spelling",
            ),
            ("[gnss]\nbaud = 9600\n", "port", "add the key"),
            ("[gnss]\nport = 5\n", "port", "text in quotes"),
            ("[gnss\nport = \"/dev/x\"\n", "gnss", "correct the TOML"),
        ] {
            let msg = load(text).unwrap_err().to_string();
            assert!(
                msg.starts_with("test.toml: ") && msg.contains(key) && msg.contains(fix),
                "{msg}"
            );
        }
    }

    #[test]
    fn errors_name_the_key() {
        let e = load("[gnss]\nport = \"/dev/x\"\nbaud = 12345\n").unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("test.toml") && msg.contains("`gnss.baud`"),
            "{msg}"
        );
        let e = load("[gnss]\nport = \"/dev/x\"\nfix_timeout_s = -1\n").unwrap_err();
        assert!(e.to_string().contains("`gnss.fix_timeout_s`"));
        let e = load("[gnss]\nport = \"/dev/x\"\n[gnss.antenna]\nz = 40.0\n").unwrap_err();
        assert!(e.to_string().contains("`gnss.antenna.z`"));
    }

    #[test]
    fn drive_train_errors_name_the_key() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices/vehicle.example.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let check = |from: &str, to: &str, key: &str| {
            let bad = text.replace(from, to);
            assert_ne!(bad, text, "{from:?} not in the example");
            let e = VehicleConfig::from_toml(&bad, &path)
                .unwrap_err()
                .to_string();
            assert!(e.contains(&format!("`{key}`")), "{key}: {e}");
        };
        check(
            "bus = \"can0\"\nnode = 1",
            "bus = \"can9\"\nnode = 1",
            "drive[0].bus",
        );
        check("node = 1\n", "node = 200\n", "drive[0].node");
        check(
            "wheels = [\"left\", \"right\"]",
            "wheels = [\"left\"]",
            "drive[0].wheels",
        );
        check(
            "wheels = [\"left\", \"right\"]",
            "wheels = [\"left\", \"left\"]",
            "drive[0].wheels",
        );
        check(
            "heartbeat_timeout_ms = 350",
            "heartbeat_timeout_ms = 150",
            "drive[0].heartbeat_timeout_ms",
        );
        check(
            "drive = \"blade\"\nrpm",
            "drive = \"wheels\"\nrpm",
            "cutter.drive",
        );
        check("name = \"blade\"", "name = \"blades\"", "drive[1].wheels");
        // A drive with no wheels is the cutter's, or a mistake.
        check(
            "drive = \"blade\"\nrpm = 3000",
            "bus = \"can0\"",
            "drive[1].wheels",
        );
        check("rpm = 3000", "rpm = 0", "cutter.rpm");
        check("track_m = 0.42", "track_m = 0.0", "chassis.track_m");
        check("direction = -1", "direction = 0", "wheels.right.direction");
        check(
            "bus = \"can1\"\naddress",
            "bus = \"can7\"\naddress",
            "bms.bus",
        );
        check(
            "interface = \"can1\"",
            "interface = \"can0\"",
            "can[1].interface",
        );
        check(
            "name = \"body\"\nprofile = \"estop-canopen-di.toml\"\nbus = \"can0\"",
            "name = \"body\"\nprofile = \"estop-canopen-di.toml\"\nbus = \"can5\"",
            "estop[0].bus",
        );
        let e = VehicleConfig::from_toml(
            &text.replace("estop-canopen-di.toml", "../Cargo.toml"),
            &path,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("Cargo.toml"), "{e}");
        let e = VehicleConfig::from_toml(
            &format!("{text}\n[[estop]]\nname = \"body\"\nprofile = \"estop-canopen-di.toml\"\nbus = \"can1\"\n"),
            &path,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("`estop[1].name`"), "{e}");
        let e = VehicleConfig::from_toml(
            &text.replace("profile = \"zlac8015d.toml\"", "profile = \"missing.toml\""),
            &path,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("missing.toml"), "{e}");
    }

    #[test]
    fn effective_configuration_is_self_contained() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices/vehicle.example.toml");
        let config = VehicleConfig::load(&path).unwrap();
        let effective = config.to_effective_toml();
        // Loaded from anywhere: the profiles are inline.
        let again =
            VehicleConfig::from_toml(&effective, Path::new("/nonexistent/vehicle.toml")).unwrap();
        assert_eq!(again, config);
    }

    #[test]
    fn unknown_keys_and_wrong_types_are_rejected_with_the_key() {
        let e = load("[gnss]\nport = \"/dev/x\"\nbaudrate = 9600\n").unwrap_err();
        assert!(e.to_string().contains("baudrate"), "{e}");
        let e = load("[gnss]\nport = \"/dev/x\"\nbaud = \"fast\"\n").unwrap_err();
        assert!(e.to_string().contains("baud"), "{e}");
        let e = load("[gnss]\nport = \"/dev/x\"\nprotocol = \"ubx\"\n").unwrap_err();
        assert!(e.to_string().contains("protocol"), "{e}");
    }
}
