//! Drive profiles: which objects a CiA 402 drive uses, their units, whether feedback and
//! commands travel by PDO or SDO, and how the drive stops by itself when chassisd is gone.
//! Profiles are TOML files in `devices/`, checked on load; one without a loss-of-master
//! reaction is refused.

use serde::{Deserialize, Serialize};

use crate::devices::canopen::ObjectAddress;
use crate::devices::canopen::pdo::{PdoEntry, PdoMapping};
use crate::devices::canopen::sdo::SdoData;
use crate::devices::profile::ProfileError;

/// A CiA 402 drive profile.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DriveProfile {
    /// Always `cia402`.
    pub kind: DriveKind,
    /// Human-readable name.
    pub name: String,
    /// Motor axes per node (1, or 2 for dual-channel drives).
    pub axes: u8,
    /// Object addresses.
    pub objects: DriveObjects,
    /// Unit conversions.
    pub units: DriveUnits,
    /// How feedback is read.
    #[serde(default)]
    pub feedback: FeedbackSpec,
    /// How commands are written.
    #[serde(default)]
    pub command: CommandSpec,
    /// TPDOs to configure (node → chassisd).
    #[serde(default)]
    pub tpdo: Vec<PdoSpec>,
    /// RPDOs to configure (chassisd → node).
    #[serde(default)]
    pub rpdo: Vec<PdoSpec>,
    /// Vendor-specific SDO writes made after the standard set-up, in order.
    #[serde(default)]
    pub setup: Vec<SetupWrite>,
    /// How the drive notices that chassisd is gone, and what it does then. Required.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub master_loss: Option<MasterLoss>,
}

/// How a drive notices that its master (chassisd) is gone: a dead process, a hung loop or a
/// cut cable. Every way ends in the drive stopping its motors by itself.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(tag = "watch", rename_all = "snake_case", deny_unknown_fields)]
pub enum MasterLoss {
    /// The drive consumes chassisd's heartbeat (0x1016:1, node id and time) and reacts as
    /// 0x6007 (abort connection option code) says.
    Heartbeat {
        /// The reaction written to 0x6007.
        reaction: LossReaction,
    },
    /// The drive watches chassisd's SYNC (0x1006, communication cycle period) and reacts as
    /// 0x6007 says.
    Sync {
        /// The reaction written to 0x6007.
        reaction: LossReaction,
    },
    /// A vendor object holds a communication timeout in ms: with no frame addressed to the
    /// drive for that long, the drive stops its motors itself.
    VendorTimeout {
        /// The object.
        object: ObjectAddress,
        /// Its type (unsigned).
        #[serde(rename = "type")]
        value_type: ValueType,
    },
}

/// What a CiA 402 drive does when its master is lost (0x6007 abort connection option code).
/// "No action" (0) is not offered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LossReaction {
    /// 1: a fault (the motor stops as the fault reaction says).
    Fault,
    /// 2: disable voltage (the motor coasts).
    DisableVoltage,
    /// 3: quick stop (the motor brakes on the quick-stop ramp).
    QuickStop,
}

impl LossReaction {
    /// The option code written to 0x6007.
    pub fn code(self) -> i16 {
        match self {
            Self::Fault => 1,
            Self::DisableVoltage => 2,
            Self::QuickStop => 3,
        }
    }

    /// The reaction of an option code, if it is one of these.
    pub fn from_code(code: i16) -> Option<Self> {
        match code {
            1 => Some(Self::Fault),
            2 => Some(Self::DisableVoltage),
            3 => Some(Self::QuickStop),
            _ => None,
        }
    }
}

/// CiA 402 abort connection option code.
pub const ABORT_CONNECTION_OPTION: ObjectAddress = ObjectAddress::new(0x6007, 0);
/// CiA 301 consumer heartbeat time, first entry.
pub const CONSUMER_HEARTBEAT: ObjectAddress = ObjectAddress::new(0x1016, 1);
/// CiA 301 communication cycle period (SYNC), µs.
pub const COMMUNICATION_CYCLE: ObjectAddress = ObjectAddress::new(0x1006, 0);

/// The profile family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DriveKind {
    /// CiA 402 drive in profile velocity mode.
    Cia402,
}

/// Object addresses of a drive. Per-axis lists hold one address per axis, in axis order.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DriveObjects {
    /// Controlword (u16), shared by all axes.
    #[serde(default = "default_controlword")]
    pub controlword: ObjectAddress,
    /// Statusword.
    #[serde(default = "default_statusword")]
    pub statusword: ObjectAddress,
    /// Statusword width: 16, or 32 for dual-channel drives that pack axis 1 in the low and
    /// axis 2 in the high 16 bits.
    #[serde(default = "default_statusword_bits")]
    pub statusword_bits: u8,
    /// Modes of operation (i8); profile velocity mode (3) is written at set-up.
    #[serde(default = "default_mode_of_operation")]
    pub mode_of_operation: ObjectAddress,
    /// Target velocity (i32) per axis.
    pub target_velocity: Vec<ObjectAddress>,
    /// One object setting both axes at once: low 16 bits axis 1, high 16 bits axis 2 (i16
    /// each). Used for commands when present.
    #[serde(default)]
    pub combined_target_velocity: Option<ObjectAddress>,
    /// Actual velocity (i32) per axis.
    pub actual_velocity: Vec<ObjectAddress>,
    /// Actual position (i32 encoder counts) per axis.
    pub actual_position: Vec<ObjectAddress>,
    /// Producer heartbeat time (u16, ms).
    #[serde(default = "default_heartbeat_producer")]
    pub heartbeat_producer: ObjectAddress,
}

fn default_controlword() -> ObjectAddress {
    ObjectAddress::new(0x6040, 0)
}
fn default_statusword() -> ObjectAddress {
    ObjectAddress::new(0x6041, 0)
}
fn default_statusword_bits() -> u8 {
    16
}
fn default_mode_of_operation() -> ObjectAddress {
    ObjectAddress::new(0x6060, 0)
}
fn default_heartbeat_producer() -> ObjectAddress {
    ObjectAddress::new(0x1017, 0)
}

/// Unit conversions between the drive's numbers and motor revolutions.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DriveUnits {
    /// Target velocity units per motor rev/min (1 when the drive takes r/min).
    pub target_velocity_per_rpm: f64,
    /// Actual velocity units per motor rev/min (10 when the drive reports 0.1 r/min).
    pub actual_velocity_per_rpm: f64,
    /// Position counts per motor revolution.
    pub counts_per_rev: f64,
}

/// Whether data moves by PDO or by SDO.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Transport {
    /// SDO reads and writes.
    #[default]
    Sdo,
    /// PDOs configured at set-up.
    Pdo,
}

/// `[feedback]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FeedbackSpec {
    /// PDO or SDO.
    #[serde(default)]
    pub mode: Transport,
    /// SDO polling rate, Hz.
    #[serde(default = "default_rate_hz")]
    pub poll_hz: f64,
}

impl Default for FeedbackSpec {
    fn default() -> Self {
        Self {
            mode: Transport::Sdo,
            poll_hz: default_rate_hz(),
        }
    }
}

/// `[command]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CommandSpec {
    /// PDO or SDO.
    #[serde(default)]
    pub mode: Transport,
    /// How often the target is sent even when unchanged, Hz (drives watch for silence).
    #[serde(default = "default_rate_hz")]
    pub rate_hz: f64,
}

impl Default for CommandSpec {
    fn default() -> Self {
        Self {
            mode: Transport::Sdo,
            rate_hz: default_rate_hz(),
        }
    }
}

fn default_rate_hz() -> f64 {
    20.0
}

/// A PDO to configure.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PdoSpec {
    /// PDO number, 1–4.
    pub number: u8,
    /// Mapped objects, `"index:sub:bits"`.
    pub objects: Vec<PdoEntry>,
    /// TPDO event timer, ms.
    #[serde(default)]
    pub event_timer_ms: u16,
    /// TPDO transmission type (0xFF: event-driven).
    #[serde(default = "default_transmission_type")]
    pub transmission_type: u8,
}

fn default_transmission_type() -> u8 {
    0xFF
}

/// Type of a set-up value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ValueType {
    /// Unsigned 8 bits.
    U8,
    /// Signed 8 bits.
    I8,
    /// Unsigned 16 bits.
    U16,
    /// Signed 16 bits.
    I16,
    /// Unsigned 32 bits.
    U32,
    /// Signed 32 bits.
    I32,
}

/// As the profile writes it (`u16`), with its range.
impl std::fmt::Display for ValueType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::U8 => "u8 (0 to 255)",
            Self::I8 => "i8 (-128 to 127)",
            Self::U16 => "u16 (0 to 65535)",
            Self::I16 => "i16 (-32768 to 32767)",
            Self::U32 => "u32 (0 to 4294967295)",
            Self::I32 => "i32 (-2147483648 to 2147483647)",
        })
    }
}

/// One vendor set-up write.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SetupWrite {
    /// The object.
    pub object: ObjectAddress,
    /// Its type.
    #[serde(rename = "type")]
    pub value_type: ValueType,
    /// The value.
    pub value: i64,
}

impl SetupWrite {
    /// The bytes to write, if the value fits the type.
    pub fn data(&self) -> Option<SdoData> {
        let v = self.value;
        Some(match self.value_type {
            ValueType::U8 => SdoData::u8(u8::try_from(v).ok()?),
            ValueType::I8 => SdoData::i8(i8::try_from(v).ok()?),
            ValueType::U16 => SdoData::u16(u16::try_from(v).ok()?),
            ValueType::I16 => SdoData::u16(i16::try_from(v).ok()? as u16),
            ValueType::U32 => SdoData::u32(u32::try_from(v).ok()?),
            ValueType::I32 => SdoData::i32(i32::try_from(v).ok()?),
        })
    }
}

impl DriveProfile {
    /// Parses and checks a profile; `file` names it in errors.
    pub fn from_toml(text: &str, file: &std::path::Path) -> Result<Self, ProfileError> {
        let profile: Self = toml::from_str(text).map_err(|e| ProfileError::parse(file, &e))?;
        profile
            .validate()
            .map_err(|(key, problem, fix)| ProfileError::invalid(file, &key, problem, &fix))?;
        Ok(profile)
    }

    /// The TPDO mappings, checked.
    pub fn tpdo_mappings(&self) -> Vec<(u8, PdoMapping, &PdoSpec)> {
        self.tpdo
            .iter()
            .filter_map(|s| {
                PdoMapping::new(s.objects.clone())
                    .ok()
                    .map(|m| (s.number, m, s))
            })
            .collect()
    }

    /// The RPDO mappings, checked.
    pub fn rpdo_mappings(&self) -> Vec<(u8, PdoMapping)> {
        self.rpdo
            .iter()
            .filter_map(|s| {
                PdoMapping::new(s.objects.clone())
                    .ok()
                    .map(|m| (s.number, m))
            })
            .collect()
    }

    /// Checks consistency; an error is (key, problem, fix).
    pub fn validate(&self) -> Result<(), (String, String, String)> {
        self.check_master_loss()?;
        self.check_axes()?;
        self.check_units()?;
        self.check_rates()?;
        check_pdo_list("tpdo", &self.tpdo)?;
        check_pdo_list("rpdo", &self.rpdo)?;
        if self.feedback.mode == Transport::Pdo {
            self.check_feedback_mapped()?;
        }
        if self.command.mode == Transport::Pdo {
            self.check_command_mapped()?;
        }
        self.check_setup()
    }

    /// A loss-of-master reaction is set, and a vendor timeout's object holds milliseconds.
    fn check_master_loss(&self) -> Check {
        match self.master_loss {
            None => problem(
                "master_loss",
                "not set: nothing would stop this drive if chassisd died, hung or lost its \
                 cable"
                    .into(),
                "add [master_loss] with watch = \"heartbeat\" (or \"sync\") and reaction = \
                 \"quick_stop\", or watch = \"vendor_timeout\" with the drive's own \
                 timeout object",
            ),
            Some(MasterLoss::VendorTimeout { value_type, .. })
                if !matches!(value_type, ValueType::U16 | ValueType::U32) =>
            {
                problem(
                    "master_loss.type",
                    format!("{value_type} is not a timeout's type"),
                    "a timeout in ms is u16 or u32",
                )
            }
            Some(_) => Ok(()),
        }
    }

    /// One or two axes, with an object per axis and a statusword (and combined target) that
    /// fit their number.
    fn check_axes(&self) -> Check {
        if !(1..=2).contains(&self.axes) {
            return problem(
                "axes",
                format!("{} axes", self.axes),
                "use 1, or 2 for a dual-channel drive",
            );
        }
        let axes = usize::from(self.axes);
        for (key, list) in [
            ("objects.target_velocity", &self.objects.target_velocity),
            ("objects.actual_velocity", &self.objects.actual_velocity),
            ("objects.actual_position", &self.objects.actual_position),
        ] {
            if list.len() != axes {
                return problem(
                    key,
                    format!("{} entries for {axes} axes", list.len()),
                    "give one object per axis, in axis order",
                );
            }
        }
        if !matches!(self.objects.statusword_bits, 16 | 32)
            || (self.objects.statusword_bits == 32 && axes != 2)
        {
            return problem(
                "objects.statusword_bits",
                format!("{} bits with {axes} axes", self.objects.statusword_bits),
                "use 16, or 32 for a dual-channel drive that packs both statuswords",
            );
        }
        if self.objects.combined_target_velocity.is_some() && axes != 2 {
            return problem(
                "objects.combined_target_velocity",
                "set on a single-axis drive".into(),
                "remove it, or set axes = 2",
            );
        }
        Ok(())
    }

    /// The unit conversions are positive numbers.
    fn check_units(&self) -> Check {
        let u = &self.units;
        for (key, v) in [
            ("units.target_velocity_per_rpm", u.target_velocity_per_rpm),
            ("units.actual_velocity_per_rpm", u.actual_velocity_per_rpm),
            ("units.counts_per_rev", u.counts_per_rev),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return problem(
                    key,
                    format!("{v} is not a positive number"),
                    "set the drive's scale",
                );
            }
        }
        Ok(())
    }

    /// The feedback polling and command rates.
    fn check_rates(&self) -> Check {
        for (key, hz) in [
            ("feedback.poll_hz", self.feedback.poll_hz),
            ("command.rate_hz", self.command.rate_hz),
        ] {
            if !(1.0..=1000.0).contains(&hz) {
                return problem(key, format!("{hz} Hz"), "use 1 to 1000 Hz");
            }
        }
        Ok(())
    }

    /// With PDO feedback, the TPDOs carry the statusword and each axis' velocity and
    /// position.
    fn check_feedback_mapped(&self) -> Check {
        let needed = std::iter::once(self.objects.statusword)
            .chain(self.objects.actual_velocity.iter().copied())
            .chain(self.objects.actual_position.iter().copied());
        for object in needed {
            if !is_mapped(&self.tpdo, object) {
                return problem(
                    "tpdo",
                    format!("feedback.mode is pdo but {object} is in no TPDO"),
                    "map it in a [[tpdo]], or use feedback.mode = \"sdo\"",
                );
            }
        }
        Ok(())
    }

    /// With PDO commands, the RPDOs carry the controlword and the targets (the combined
    /// one, when there is one).
    fn check_command_mapped(&self) -> Check {
        let targets: Vec<ObjectAddress> = match self.objects.combined_target_velocity {
            Some(c) => vec![c],
            None => self.objects.target_velocity.clone(),
        };
        for object in std::iter::once(self.objects.controlword).chain(targets) {
            if !is_mapped(&self.rpdo, object) {
                return problem(
                    "rpdo",
                    format!("command.mode is pdo but {object} is in no RPDO"),
                    "map it in a [[rpdo]], or use command.mode = \"sdo\"",
                );
            }
        }
        Ok(())
    }

    /// Each set-up value fits its type.
    fn check_setup(&self) -> Check {
        for (i, w) in self.setup.iter().enumerate() {
            if w.data().is_none() {
                return problem(
                    &format!("setup[{i}].value"),
                    format!("{} does not fit {}", w.value, w.value_type),
                    "use a value within the type's range",
                );
            }
        }
        Ok(())
    }
}

/// The outcome of one of a profile's checks: an error is (key, problem, fix).
type Check = Result<(), (String, String, String)>;

/// The error of a check: `problem` at `key`, and how to fix it.
fn problem(key: &str, problem: String, fix: &str) -> Check {
    Err((key.to_owned(), problem, fix.to_owned()))
}

/// The PDOs of `list` (`tpdo` or `rpdo`, its `key`): distinct numbers 1 to 4, each mapping
/// at most 8 bytes.
fn check_pdo_list(key: &str, list: &[PdoSpec]) -> Check {
    let mut seen = Vec::new();
    for (i, spec) in list.iter().enumerate() {
        if !(1..=4).contains(&spec.number) || seen.contains(&spec.number) {
            return problem(
                &format!("{key}[{i}].number"),
                format!("PDO number {}", spec.number),
                "use distinct numbers 1 to 4",
            );
        }
        seen.push(spec.number);
        if let Err(e) = PdoMapping::new(spec.objects.clone()) {
            return problem(
                &format!("{key}[{i}].objects"),
                e.to_string(),
                "map at most 8 bytes",
            );
        }
    }
    Ok(())
}

/// Whether a PDO of `list` maps `object`.
fn is_mapped(list: &[PdoSpec], object: ObjectAddress) -> bool {
    list.iter()
        .any(|s| s.objects.iter().any(|e| e.object == object))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn shipped(name: &str) -> DriveProfile {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../devices")
            .join(name);
        let text = std::fs::read_to_string(&path).unwrap();
        DriveProfile::from_toml(&text, &path).unwrap()
    }

    #[test]
    fn shipped_profiles_load() {
        let generic = shipped("cia402-generic.toml");
        assert_eq!(generic.axes, 1);
        assert_eq!(generic.feedback.mode, Transport::Pdo);
        assert_eq!(
            generic.master_loss,
            Some(MasterLoss::Heartbeat {
                reaction: LossReaction::QuickStop
            })
        );
        let zlac = shipped("zlac8015d.toml");
        assert_eq!(zlac.axes, 2);
        assert!(matches!(
            zlac.master_loss,
            Some(MasterLoss::VendorTimeout { object, .. }) if object == ObjectAddress::new(0x2000, 0)
        ));
        assert_eq!(
            zlac.objects.combined_target_velocity,
            Some(ObjectAddress::new(0x60FF, 3))
        );
    }

    #[test]
    fn errors_name_the_key() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices/cia402-generic.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let bad = text.replace("axes = 1", "axes = 2");
        let e = DriveProfile::from_toml(&bad, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`objects.target_velocity`"), "{e}");
        let bad = text.replace("\"0x606C:0:32\"", "\"0x6077:0:16\"");
        let e = DriveProfile::from_toml(&bad, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`tpdo`") && e.contains("0x606C:0"), "{e}");
        let bad = text.replace("counts_per_rev = 4096", "counts_per_rev = 0");
        let e = DriveProfile::from_toml(&bad, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`units.counts_per_rev`"), "{e}");
        let start = text
            .find("[master_loss]")
            .expect("generic profile has [master_loss]");
        let bad = &text[..start];
        let e = DriveProfile::from_toml(bad, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`master_loss`") && e.contains("nothing would stop"),
            "{e}"
        );
        let bad = text.replace("\"0x6041:0:16\"", "\"0x6041:0:12\"");
        let e = DriveProfile::from_toml(&bad, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("bits must be 8, 16 or 32"), "{e}");
    }

    #[test]
    fn each_inconsistency_names_its_key_and_the_problem() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices/cia402-generic.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        for (from, to, expected) in [
            (
                "watch = \"heartbeat\"\nreaction = \"quick_stop\"",
                "watch = \"vendor_timeout\"\nobject = \"0x2000:0\"\ntype = \"i16\"",
                "`master_loss.type`: i16 (-32768 to 32767) is not a timeout's type",
            ),
            ("axes = 1", "axes = 3", "`axes`: 3 axes"),
            (
                "statusword = \"0x6041:0\"\n",
                "statusword = \"0x6041:0\"\nstatusword_bits = 32\n",
                "`objects.statusword_bits`: 32 bits with 1 axes",
            ),
            (
                "heartbeat_producer = ",
                "combined_target_velocity = \"0x60FF:3\"\nheartbeat_producer = ",
                "`objects.combined_target_velocity`: set on a single-axis drive",
            ),
            (
                "rate_hz = 50",
                "rate_hz = 2000",
                "`command.rate_hz`: 2000 Hz",
            ),
            ("number = 2", "number = 1", "`tpdo[1].number`: PDO number 1"),
            (
                "objects = [\"0x6040:0:16\", \"0x60FF:0:32\"]",
                "objects = [\"0x6040:0:16\", \"0x60FF:0:32\", \"0x6064:0:32\"]",
                "`rpdo[0].objects`",
            ),
            (
                "objects = [\"0x6040:0:16\", \"0x60FF:0:32\"]",
                "objects = [\"0x6040:0:16\"]",
                "`rpdo`: command.mode is pdo but 0x60FF:0 is in no RPDO",
            ),
            (
                "value = 3000",
                "value = -1",
                "`setup[0].value`: -1 does not fit u32 (0 to 4294967295)",
            ),
        ] {
            let bad = text.replacen(from, to, 1);
            assert_ne!(bad, text, "{from:?} not in the profile");
            let e = DriveProfile::from_toml(&bad, Path::new("p.toml"))
                .unwrap_err()
                .to_string();
            assert!(e.contains(expected), "{expected}: {e}");
        }
    }
}
