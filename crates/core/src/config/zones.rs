//! `[zones]`: the zones file the vehicle keeps to (GeoJSON: boundaries, keep-out zones,
//! walls), read and checked on load, and the GNSS gate's thresholds for autonomous motion
//! and the cutter.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{ConfigError, check_range};
use crate::devices::gnss::FixQuality;
use crate::zones::ZoneSet;

/// `[zones]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ZonesConfig {
    /// The zones file (GeoJSON, RFC 7946), relative to the configuration; edits are
    /// written back to it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<PathBuf>,
    /// The zones as GeoJSON text, in place of `file` (what recordings hold, so that a
    /// replay needs no file beside them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geojson: Option<String>,
    /// The vehicle's outline about `base_link`, as the zones see it.
    pub footprint: Footprint,
    /// In manual mode, a zone ahead stops the vehicle (`stop`) or is only reported (`warn`).
    #[serde(default)]
    pub manual: ManualPolicy,
    /// At plan time, room kept beyond the footprint: what the position's σ and the braking
    /// way take at run time, m.
    #[serde(default = "default_margin_m")]
    pub margin_m: f64,
    /// The least fix quality for autonomous motion and the cutter.
    #[serde(default)]
    pub min_quality: GateQuality,
    /// The largest horizontal σ for autonomous motion and the cutter, m.
    #[serde(default = "default_max_sigma_m")]
    pub max_sigma_m: f64,
    /// The oldest fix autonomous motion and the cutter go on, s.
    #[serde(default = "default_max_fix_age_s")]
    pub max_fix_age_s: f64,
    /// With `[ntrip]`: the oldest corrections autonomous motion and the cutter go on, s.
    #[serde(default = "default_max_correction_age_s")]
    pub max_correction_age_s: f64,
    /// After the gate closes again, the fix must stay good this long before work resumes, s.
    #[serde(default = "default_resume_after_s")]
    pub resume_after_s: f64,
    /// The zones, read on load.
    #[serde(skip)]
    pub set: ZoneSet,
}

/// `[zones] footprint`: the vehicle's outline, a rectangle about `base_link` (the wheels'
/// axle centre), blade and bumpers included.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Footprint {
    /// From `base_link` forward to the front edge, m.
    pub front_m: f64,
    /// From `base_link` back to the rear edge, m.
    pub rear_m: f64,
    /// Full width, m.
    pub width_m: f64,
}

impl Footprint {
    /// The radius of the smallest disc about `base_link` that holds the outline, m.
    pub fn radius_m(&self) -> f64 {
        self.front_m.max(self.rear_m).hypot(self.width_m / 2.0)
    }

    /// The outline with `base_link` at (x, y) heading `yaw` (rad), as a closed polygon.
    pub fn outline_at(&self, x: f64, y: f64, yaw: f64) -> geo::Polygon<f64> {
        let (s, c) = yaw.sin_cos();
        let at = |fx: f64, fy: f64| geo::Coord {
            x: x + c * fx - s * fy,
            y: y + s * fx + c * fy,
        };
        let half = self.width_m / 2.0;
        geo::Polygon::new(
            geo::LineString::new(vec![
                at(self.front_m, half),
                at(-self.rear_m, half),
                at(-self.rear_m, -half),
                at(self.front_m, -half),
                at(self.front_m, half),
            ]),
            Vec::new(),
        )
    }
}

/// What a zone ahead does in manual mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ManualPolicy {
    /// The vehicle stops, as in autonomous modes.
    #[default]
    Stop,
    /// The operator is warned and keeps control.
    Warn,
}

/// The least fix quality of the GNSS gate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GateQuality {
    /// RTK fixed only.
    #[default]
    RtkFixed,
    /// RTK float or fixed.
    RtkFloat,
    /// DGPS (SBAS) or better.
    Dgps,
    /// Any fix.
    Single,
}

/// As the configuration writes it (`rtk_fixed`).
impl std::fmt::Display for GateQuality {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::RtkFixed => "rtk_fixed",
            Self::RtkFloat => "rtk_float",
            Self::Dgps => "dgps",
            Self::Single => "single",
        })
    }
}

impl GateQuality {
    /// Whether a fix of `quality` passes.
    pub fn admits(self, quality: FixQuality) -> bool {
        let rank = |q: FixQuality| match q {
            FixQuality::RtkFixed => 4,
            FixQuality::RtkFloat => 3,
            FixQuality::Dgps => 2,
            FixQuality::Single => 1,
            _ => 0,
        };
        let least = match self {
            Self::RtkFixed => 4,
            Self::RtkFloat => 3,
            Self::Dgps => 2,
            Self::Single => 1,
        };
        rank(quality) >= least
    }
}

fn default_margin_m() -> f64 {
    0.1
}
fn default_max_sigma_m() -> f64 {
    0.10
}
fn default_max_fix_age_s() -> f64 {
    1.0
}
fn default_max_correction_age_s() -> f64 {
    10.0
}
fn default_resume_after_s() -> f64 {
    10.0
}

impl ZonesConfig {
    /// The section for the zones in `file`, with `footprint` and the defaults, read.
    pub fn from_file(file: &Path, footprint: Footprint) -> Result<Self, ConfigError> {
        let mut zones = Self {
            file: Some(file.to_owned()),
            geojson: None,
            ..Self::of_set(ZoneSet::default(), footprint)
        };
        zones.load(Path::new("."), file)?;
        zones.validate(file)?;
        Ok(zones)
    }

    /// The section for `set`, inline, with `footprint` and the defaults (what a simulated
    /// session builds its zones into).
    pub fn of_set(set: ZoneSet, footprint: Footprint) -> Self {
        Self {
            file: None,
            geojson: Some(set.to_geojson()),
            footprint,
            manual: ManualPolicy::default(),
            margin_m: default_margin_m(),
            min_quality: GateQuality::default(),
            max_sigma_m: default_max_sigma_m(),
            max_fix_age_s: default_max_fix_age_s(),
            max_correction_age_s: default_max_correction_age_s(),
            resume_after_s: default_resume_after_s(),
            set,
        }
    }

    /// Reads and checks the zones: `file`, relative to `base` (the configuration's
    /// folder), or the inline `geojson`.
    pub fn load(&mut self, base: &Path, config_file: &Path) -> Result<(), ConfigError> {
        let (text, source) = match (&mut self.file, &self.geojson) {
            (Some(file), None) => {
                if file.is_relative() {
                    *file = base.join(&*file);
                }
                let text =
                    super::read_text(file).map_err(|e| e.named_by(config_file, "zones.file"))?;
                (text, file.clone())
            }
            (None, Some(text)) => (text.clone(), config_file.to_owned()),
            _ => {
                return Err(ConfigError::invalid(
                    config_file,
                    "zones",
                    "needs one of file and geojson",
                    "name the zones file: [zones] file = \"zones.geojson\"",
                ));
            }
        };
        self.set = ZoneSet::from_geojson(&text).map_err(|e| {
            let (problem, fix) = e.problem_and_fix();
            ConfigError::invalid(&source, "zones", problem, fix)
        })?;
        Ok(())
    }

    /// This section as a recording stores it: the zones inline, no file named.
    pub fn recorded(&self) -> Self {
        Self {
            file: None,
            geojson: Some(self.set.to_geojson()),
            ..self.clone()
        }
    }

    /// Checks the outline and the thresholds.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        let f = &self.footprint;
        check_range(file, "zones.footprint.front_m", f.front_m, 0.0..=10.0, "m")?;
        check_range(file, "zones.footprint.rear_m", f.rear_m, 0.0..=10.0, "m")?;
        check_range(file, "zones.footprint.width_m", f.width_m, 0.05..=10.0, "m")?;
        if f.front_m + f.rear_m < 0.05 {
            return Err(ConfigError::invalid(
                file,
                "zones.footprint",
                format!("is {} m long", f.front_m + f.rear_m),
                "give the outline's reach ahead of and behind the axle (front_m, rear_m)",
            ));
        }
        check_range(file, "zones.margin_m", self.margin_m, 0.0..=5.0, "m")?;
        check_range(
            file,
            "zones.max_sigma_m",
            self.max_sigma_m,
            0.005..=10.0,
            "m",
        )?;
        check_range(
            file,
            "zones.max_fix_age_s",
            self.max_fix_age_s,
            0.05..=10.0,
            "s",
        )?;
        check_range(
            file,
            "zones.max_correction_age_s",
            self.max_correction_age_s,
            1.0..=120.0,
            "s",
        )?;
        check_range(
            file,
            "zones.resume_after_s",
            self.resume_after_s,
            0.0..=600.0,
            "s",
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::VehicleConfig;

    const SQUARE: &str = r#"{"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"kind": "keep_out", "name": "pond"},
         "geometry": {"type": "Polygon", "coordinates":
            [[[8.5455, 47.3975], [8.5458, 47.3975], [8.5458, 47.3977], [8.5455, 47.3977],
              [8.5455, 47.3975]]]}}]}"#;

    const SECTION: &str = "[zones]\nfile = \"zones.geojson\"\n\
                           footprint = { front_m = 0.5, rear_m = 0.3, width_m = 0.6 }\n";

    fn folder(name: &str, zones: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("chassisd-zones-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("zones.geojson"), zones).unwrap();
        dir
    }

    #[test]
    fn the_zones_file_is_read_beside_the_configuration_and_recorded_inline() {
        let dir = folder("read", SQUARE);
        let config = VehicleConfig::from_toml(SECTION, &dir.join("vehicle.toml")).unwrap();
        let zones = config.zones.as_ref().unwrap();
        assert_eq!(
            zones.file.as_deref(),
            Some(dir.join("zones.geojson").as_path())
        );
        assert_eq!(zones.set.zones()[0].name, "pond");
        assert_eq!(zones.manual, ManualPolicy::Stop);
        assert!(zones.min_quality.admits(FixQuality::RtkFixed));
        assert!(!zones.min_quality.admits(FixQuality::RtkFloat));
        assert!((zones.footprint.radius_m() - 0.5831).abs() < 1e-4);
        // A recording holds the zones themselves, and reads them back without the file.
        let recorded = config.to_effective_toml();
        assert!(!recorded.contains("zones.geojson"), "{recorded}");
        std::fs::remove_dir_all(&dir).unwrap();
        let again = VehicleConfig::from_toml(&recorded, &dir.join("vehicle.toml")).unwrap();
        assert_eq!(again.zones.unwrap().set, zones.set);
    }

    #[test]
    fn a_bad_zones_file_is_refused_naming_it_the_feature_and_the_fix() {
        let dir = folder(
            "bad",
            &SQUARE.replace("[8.5455, 47.3975]]]", "[8.5455, 47.3976]]]"),
        );
        let err = VehicleConfig::from_toml(SECTION, &dir.join("vehicle.toml")).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("zones.geojson")
                && text.contains("feature 0 (\"pond\")")
                && text.contains("not closed"),
            "{text}"
        );
        let missing = SECTION.replace("zones.geojson", "nowhere.geojson");
        let err = VehicleConfig::from_toml(&missing, &dir.join("vehicle.toml")).unwrap_err();
        assert!(err.to_string().contains("zones.file"), "{err}");
        std::fs::write(dir.join("zones.geojson"), SQUARE).unwrap();
        let no_outline = "[zones]\nfile = \"zones.geojson\"\n";
        assert!(VehicleConfig::from_toml(no_outline, &dir.join("vehicle.toml")).is_err());
        let flat = SECTION.replace("width_m = 0.6", "width_m = 0.0");
        let err = VehicleConfig::from_toml(&flat, &dir.join("vehicle.toml")).unwrap_err();
        assert!(err.to_string().contains("zones.footprint.width_m"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
