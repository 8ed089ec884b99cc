//! BMS profiles (TOML in `devices/`): Daly polling settings, or a DBC file and a mapping of
//! its signals to the status fields.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::alarm;
pub use super::dbc::{DbcAlarm, DbcFields, DbcProfile};
use crate::devices::profile::ProfileError;

/// A BMS profile.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum BmsProfile {
    /// Daly CAN protocol.
    Daly(DalyProfile),
    /// Broadcast BMS described by a DBC file.
    Dbc(DbcProfile),
}

/// Which way a raw Daly current above its 30000 offset flows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CurrentAboveOffset {
    /// Above the offset is charging.
    Charge,
    /// Above the offset is discharging.
    Discharge,
}

/// `kind = "daly"`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DalyProfile {
    /// Human-readable name.
    pub name: String,
    /// The host's address in the identifiers (Daly's "upper computer", 0x40).
    #[serde(default = "default_host")]
    pub host_address: u8,
    /// Direction of a current above the offset; firmware differs, so check at bring-up
    /// that the current reads negative under load.
    #[serde(default = "default_current")]
    pub current_above_offset: CurrentAboveOffset,
}

fn default_host() -> u8 {
    0x40
}
fn default_current() -> CurrentAboveOffset {
    CurrentAboveOffset::Charge
}

impl BmsProfile {
    /// Parses a profile's text; `file` names it in errors. A DBC profile that names its DBC
    /// file (`dbc = "..."`) gets that file's text from `read_dbc`, called with the name as
    /// written: reading files is the configuration's job, not the profile's. The profile
    /// is checked once complete.
    pub fn from_toml<E: From<ProfileError>>(
        text: &str,
        file: &Path,
        read_dbc: impl FnOnce(&str) -> Result<String, E>,
    ) -> Result<Self, E> {
        let mut profile: Self = toml::from_str(text).map_err(|e| ProfileError::parse(file, &e))?;
        if let Self::Dbc(p) = &mut profile
            && let Some(name) = &p.dbc
        {
            p.dbc_text = read_dbc(name)?;
        }
        profile.validate(file)?;
        Ok(profile)
    }

    /// Checks names and the DBC mapping.
    pub fn validate(&self, file: &Path) -> Result<(), ProfileError> {
        let invalid =
            |key: &str, problem: String, fix: &str| ProfileError::invalid(file, key, problem, fix);
        let Self::Dbc(p) = self else {
            return Ok(());
        };
        if p.dbc_text.trim().is_empty() {
            return Err(invalid(
                "dbc",
                "no DBC given".into(),
                "name the DBC file, e.g. dbc = \"pack.dbc\"",
            ));
        }
        if p.current_sign != 1.0 && p.current_sign != -1.0 {
            return Err(invalid(
                "current_sign",
                format!("{}", p.current_sign),
                "use 1 or -1",
            ));
        }
        for (i, a) in p.alarm.iter().enumerate() {
            if alarm::by_name(&a.bit).is_none() {
                let names: Vec<&str> = alarm::NAMES.iter().map(|(name, _)| *name).collect();
                return Err(invalid(
                    &format!("alarm[{i}].bit"),
                    format!("{:?} is not an alarm bit", a.bit),
                    &format!("use one of: {}", names.join(", ")),
                ));
            }
        }
        super::dbc::DbcBms::new(p).map_err(|e| {
            invalid(
                "fields",
                e.to_string(),
                "check the message and signal names against the DBC",
            )
        })?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shipped profile, its DBC read from beside it.
    fn shipped(name: &str) -> BmsProfile {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices");
        let text = std::fs::read_to_string(dir.join(name)).unwrap();
        BmsProfile::from_toml::<ProfileError>(&text, Path::new(name), |dbc| {
            Ok(std::fs::read_to_string(dir.join(dbc)).unwrap())
        })
        .unwrap()
    }

    #[test]
    fn a_dbc_profile_without_its_dbc_is_refused_without_reading_files() {
        let text = "kind = \"dbc\"\nname = \"x\"\n[fields]\nvoltage = \"a.b\"\ncurrent = \"a.c\"\nsoc = \"a.d\"\n";
        let e =
            BmsProfile::from_toml::<ProfileError>(text, Path::new("x.toml"), |_| unreachable!())
                .unwrap_err();
        assert!(e.to_string().contains("no DBC given"), "{e}");
    }

    #[test]
    fn shipped_profiles_load() {
        assert!(matches!(shipped("daly-bms.toml"), BmsProfile::Daly(_)));
        let BmsProfile::Dbc(p) = shipped("pylontech-bms.toml") else {
            panic!("not a DBC profile")
        };
        assert!(p.dbc_text.contains("BO_ 854"));
    }

    #[test]
    fn a_bad_mapping_names_the_key() {
        let BmsProfile::Dbc(mut p) = shipped("pylontech-bms.toml") else {
            panic!()
        };
        p.fields.soc = "pylon_soc_soh.state_of_charge".into();
        let e = BmsProfile::Dbc(p.clone())
            .validate(Path::new("b.toml"))
            .unwrap_err();
        assert!(e.to_string().contains("`fields`") && e.to_string().contains("state_of_charge"));
        p.fields.soc = "pylon_soc_soh.soc".into();
        p.alarm[0].bit = "too_hot".into();
        let e = BmsProfile::Dbc(p)
            .validate(Path::new("b.toml"))
            .unwrap_err();
        assert!(e.to_string().contains("`alarm[0].bit`"), "{e}");
    }
}
