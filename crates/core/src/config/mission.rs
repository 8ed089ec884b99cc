//! `[mission]`: how root MISSION steps run (path speed, the dock for CHARGING), and
//! `[cutter]`: the blade actuator OPEN_CUTTER and CLOSE_CUTTER switch, as a CAN frame with
//! its on and off data.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{ConfigError, VehicleConfig, check_range};
use crate::control::goal::GoalPose;
pub use crate::control::mission::MissionSettings;

/// `[mission]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct MissionConfig {
    /// Speed of MOVE_TO_POSITION and COVERAGE paths, m/s (default 0.5; the motion speed
    /// limit caps it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_mps: Option<f64>,
    /// The charging dock: x, y (m, map frame) and the heading to dock with (degrees,
    /// counter-clockwise from east). Without one CHARGING fails with the reason.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dock: Option<[f64; 3]>,
    /// CHARGING fails when the BMS has not reported charging for this long (after docking, or
    /// since it last did), s (default 60).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub charge_timeout_s: Option<f64>,
}

impl MissionConfig {
    /// The settings.
    pub fn settings(&self) -> MissionSettings {
        MissionSettings {
            speed_mps: self.speed_mps.unwrap_or(0.5),
            dock: self.dock.map(|[x, y, heading]| GoalPose {
                x,
                y,
                yaw: crate::fusion::planar::wrap(heading.to_radians()),
            }),
            charge_timeout_s: self.charge_timeout_s.unwrap_or(60.0),
        }
    }

    /// Checks the values.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if let Some(v) = self.speed_mps {
            check_range(file, "mission.speed_mps", v, 0.01..=10.0, "m/s")?;
        }
        if let Some(v) = self.charge_timeout_s {
            check_range(file, "mission.charge_timeout_s", v, 1.0..=86_400.0, "s")?;
        }
        if let Some(dock) = self.dock
            && !dock.iter().all(|v| v.is_finite())
        {
            return Err(ConfigError::invalid(
                file,
                "mission.dock",
                "holds a value that is not a finite number".to_owned(),
                "give [x, y, heading]: metres east and north, degrees",
            ));
        }
        Ok(())
    }
}

/// `[cutter]`: the blade. Either a CiA 402 drive (`drive`, one of `[[drive]]` with no wheels,
/// run at `rpm`), or a frame that switches it on and another off (`bus`, `can_id`, `on`, `off`).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct CutterConfig {
    /// The blade drive: the name of a `[[drive]]` with `wheels = []`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drive: Option<String>,
    /// The blade drive's motor speed while the cutter is on, r/min (the sign sets the turning
    /// direction).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpm: Option<f64>,
    /// The switch frame's CAN interface (one of `[[can]]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bus: Option<String>,
    /// The switch frame's identifier.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub can_id: Option<u32>,
    /// A 29-bit identifier.
    #[serde(default)]
    pub extended: bool,
    /// The data that switches it on (at most 8 bytes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub on: Option<Vec<u8>>,
    /// The data that switches it off (at most 8 bytes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub off: Option<Vec<u8>>,
    /// While on, the on frame is sent again this often, ms, so that a switch module with a
    /// keep-alive timeout stops the blade when chassisd is gone (default: sent once).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeat_ms: Option<u64>,
}

/// What the cutter is, once checked.
#[derive(Debug, Clone, PartialEq)]
pub enum Cutter {
    /// A CiA 402 blade drive: its `[[drive]]` name and the motor speed when on, r/min.
    Drive { name: String, rpm: f64 },
    /// A switch frame on `bus`.
    Frame {
        bus: String,
        on: crate::devices::can::Frame,
        off: crate::devices::can::Frame,
        repeat: Option<std::time::Duration>,
    },
}

impl CutterConfig {
    /// The blade drive's name, when the cutter is one.
    pub fn drive_name(&self) -> Option<&str> {
        self.drive.as_deref()
    }

    /// The cutter, or the key at fault, the problem and the fix.
    pub fn cutter(&self) -> Result<Cutter, (&'static str, String, &'static str)> {
        let frame_keys = self.bus.is_some()
            || self.can_id.is_some()
            || self.on.is_some()
            || self.off.is_some()
            || self.repeat_ms.is_some();
        if let Some(name) = &self.drive {
            if frame_keys {
                return Err((
                    "cutter",
                    "names a drive and a switch frame".into(),
                    "keep either drive and rpm, or bus, can_id, on and off",
                ));
            }
            let rpm = self.rpm.ok_or((
                "cutter.rpm",
                "missing".into(),
                "give the blade motor's speed in r/min",
            ))?;
            if !rpm.is_finite() || rpm == 0.0 || rpm.abs() > 100_000.0 {
                return Err((
                    "cutter.rpm",
                    format!("{rpm}"),
                    "use a non-zero speed up to 100000 r/min",
                ));
            }
            return Ok(Cutter::Drive {
                name: name.clone(),
                rpm,
            });
        }
        if self.rpm.is_some() {
            return Err((
                "cutter.rpm",
                "set without a drive".into(),
                "name the blade's [[drive]] in cutter.drive",
            ));
        }
        let (Some(bus), Some(can_id), Some(on), Some(off)) =
            (&self.bus, self.can_id, &self.on, &self.off)
        else {
            return Err((
                "cutter",
                "is neither a drive nor a complete switch frame".into(),
                "give drive and rpm, or bus, can_id, on and off",
            ));
        };
        let frame = |data: &[u8]| {
            if self.extended {
                crate::devices::can::Frame::extended(can_id, data)
            } else {
                crate::devices::can::Frame::standard(can_id, data)
            }
        };
        let (Some(on), Some(off)) = (frame(on), frame(off)) else {
            return Err((
                "cutter",
                format!("can_id {can_id:#x} or its data does not make a CAN frame"),
                "use an identifier up to 0x7FF (0x1FFFFFFF with extended = true) and at most 8 \
                 bytes of on and off data",
            ));
        };
        let repeat = match self.repeat_ms {
            Some(ms) if !(10..=10_000).contains(&ms) => {
                return Err((
                    "cutter.repeat_ms",
                    format!("{ms} ms"),
                    "use 10 to 10000 ms, or leave it out to send the frame once",
                ));
            }
            Some(ms) => Some(std::time::Duration::from_millis(ms)),
            None => None,
        };
        Ok(Cutter::Frame {
            bus: bus.clone(),
            on,
            off,
            repeat,
        })
    }

    /// Checks it against the vehicle's buses and drives.
    pub fn validate(&self, vehicle: &VehicleConfig, file: &Path) -> Result<(), ConfigError> {
        let invalid =
            |key: &str, problem: String, fix: &str| ConfigError::invalid(file, key, problem, fix);
        match self
            .cutter()
            .map_err(|(key, problem, fix)| invalid(key, problem, fix))?
        {
            Cutter::Drive { name, .. } => {
                // That it turns no wheel is checked with the drives.
                if !vehicle.drive.iter().any(|d| d.name == name) {
                    return Err(invalid(
                        "cutter.drive",
                        format!("{name:?} is not a configured [[drive]]"),
                        "name the [[drive]] that turns the blade",
                    ));
                }
            }
            Cutter::Frame { bus, .. } => {
                if !vehicle.can.iter().any(|c| c.interface == bus) {
                    return Err(invalid(
                        "cutter.bus",
                        format!("{bus:?} is not a configured [[can]] interface"),
                        "name one of the [[can]] interfaces",
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_a_cutter_frame() {
        let s = MissionConfig::default().settings();
        assert_eq!(s.speed_mps, 0.5);
        assert_eq!(s.charge_timeout_s, 60.0);
        assert!(s.dock.is_none());
        let docked = MissionConfig {
            dock: Some([1.0, 2.0, 90.0]),
            ..MissionConfig::default()
        }
        .settings();
        let dock = docked.dock.expect("a dock");
        assert!((dock.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let cutter: CutterConfig =
            toml::from_str("bus = \"can0\"\ncan_id = 0x300\non = [1, 0xFF]\noff = [0]")
                .expect("cutter");
        let Ok(Cutter::Frame { on, repeat, .. }) = cutter.cutter() else {
            panic!("a frame cutter: {:?}", cutter.cutter());
        };
        assert_eq!((on.id(), on.data()), (0x300, &[1u8, 0xFF][..]));
        assert_eq!(repeat, None);
        let problem = |c: &CutterConfig| c.cutter().expect_err("refused").0;
        let too_long = CutterConfig {
            on: Some(vec![0; 9]),
            ..cutter.clone()
        };
        assert_eq!(problem(&too_long), "cutter");
        let too_fast = CutterConfig {
            repeat_ms: Some(1),
            ..cutter.clone()
        };
        assert_eq!(problem(&too_fast), "cutter.repeat_ms");
        let both = CutterConfig {
            drive: Some("blade".into()),
            rpm: Some(3000.0),
            ..cutter.clone()
        };
        assert_eq!(problem(&both), "cutter");
        let half = CutterConfig {
            off: None,
            ..cutter
        };
        assert_eq!(problem(&half), "cutter");

        let blade: CutterConfig = toml::from_str("drive = \"blade\"\nrpm = -2800").expect("blade");
        assert_eq!(
            blade.cutter(),
            Ok(Cutter::Drive {
                name: "blade".into(),
                rpm: -2800.0
            })
        );
        for rpm in [None, Some(0.0), Some(f64::NAN), Some(1e6)] {
            let bad = CutterConfig {
                rpm,
                ..blade.clone()
            };
            assert_eq!(problem(&bad), "cutter.rpm", "{rpm:?}");
        }
        let orphan_rpm = CutterConfig {
            rpm: Some(100.0),
            ..CutterConfig::default()
        };
        assert_eq!(problem(&orphan_rpm), "cutter.rpm");
    }
}
