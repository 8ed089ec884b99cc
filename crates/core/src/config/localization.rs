//! `[localization]`: the datum and the fusion filter's settings.

use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::{ConfigError, VehicleConfig, check_range, check_ranges};
use crate::fusion::localizer::LocalizerConfig;
use crate::geodesy::Geodetic;

/// `[localization]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LocalizationConfig {
    /// Datum of the local frame: latitude, longitude (degrees), ellipsoidal height (m).
    /// Without it, the first RTK-fixed position is the datum.
    #[serde(default)]
    pub datum: Option<[f64; 3]>,
    /// `nav.locate` is `LOCATE_TRUE` while the 1σ position uncertainty is within this, m.
    #[serde(default = "default_bound")]
    pub locate_bound_m: f64,
    /// How long a GNSS fix takes to arrive after its epoch, s.
    #[serde(default)]
    pub gnss_latency_s: f64,
    /// Dual-antenna heading noise, 1σ degrees.
    #[serde(default = "default_heading_sigma")]
    pub heading_sigma_deg: f64,
    /// GNSS positions rejected without a break for this long make the filter take GNSS's
    /// position (the vehicle really is elsewhere), s.
    #[serde(default = "default_relocate_after_s")]
    pub relocate_after_s: f64,
    /// The slowly wandering part of a fix's error (multipath, atmosphere, SBAS corrections),
    /// as a fraction of its 1σ: what averaging fixes cannot remove. For RTK float, DGPS, SBAS
    /// and single fixes.
    #[serde(default = "default_correlated_fraction")]
    pub gnss_correlated_fraction: f64,
    /// The same for RTK-fixed fixes (multipath): RTK errors are centimetres and mostly white.
    #[serde(default = "default_rtk_correlated_fraction")]
    pub rtk_correlated_fraction: f64,
    /// That part's correlation time while the antenna stands, s.
    #[serde(default = "default_correlation_time_s")]
    pub gnss_correlation_time_s: f64,
    /// That part's correlation distance, m: it decorrelates as the antenna moves
    /// (multipath, and the corrections' errors with the satellites' geometry).
    #[serde(default = "default_correlation_distance_m")]
    pub gnss_correlation_distance_m: f64,
    /// The receiver's velocity accuracy, 1σ per axis, m/s (its datasheet's figure). NMEA
    /// carries none; without it a typical figure per fix quality is used.
    #[serde(default)]
    pub gnss_velocity_sigma_mps: Option<f64>,
    /// The gyro's white noise per sample, 1σ rad/s (its datasheet's figure at the output
    /// rate).
    #[serde(default = "default_gyro_noise")]
    pub gyro_noise_rps: f64,
    /// The odom frame's heading error while moving, a random walk, rad per √s: the gyro's
    /// angle random walk, and what else turns the odom frame with time.
    #[serde(default = "default_heading_walk")]
    pub heading_walk: f64,
    /// The gyro bias's random walk, rad/s per √s: how fast the bias leaves what the last
    /// standstill taught it (temperature), so the odom heading's drift grows with the time
    /// since.
    #[serde(default = "default_gyro_bias_walk")]
    pub gyro_bias_walk: f64,
    /// The odom frame's distance error, a variance per metre driven along the heading, m²/m
    /// (the wheels' random and systematic slip): 1e-2 is 0.1 m after 1 m, 0.55 m after 30 m.
    #[serde(default = "default_odom_along")]
    pub odom_along_m2_per_m: f64,
    /// The wheels' random slip alone, a variance per metre driven, m²/m: what scatters the
    /// wheels' distance about their scale (the scale itself is learnt from RTK). It decides
    /// how many metres of RTK prove the scale.
    #[serde(default = "default_wheel_slip")]
    pub wheel_slip_m2_per_m: f64,
    /// How fast the wheels' scale (true distance per odom distance) may change, 1σ per √m
    /// driven: the ground changes under a mower's tyres; a car's on asphalt change with
    /// temperature and wear only (1e-4).
    #[serde(default = "default_wheel_scale_walk")]
    pub wheel_scale_walk: f64,
    /// The same across the heading (sideways slip), m²/m.
    #[serde(default = "default_odom_across")]
    pub odom_across_m2_per_m: f64,
    /// The odom frame's heading error per radian turned, a variance, rad²/rad (the gyro's
    /// scale error).
    #[serde(default = "default_odom_yaw")]
    pub odom_yaw_rad2_per_rad: f64,
    /// A position set by hand (INIT_POSITION) may lie at most this far from the datum, m.
    #[serde(default = "default_max_position_radius_m")]
    pub max_position_radius_m: f64,
}

fn default_bound() -> f64 {
    0.5
}
fn default_heading_sigma() -> f64 {
    0.5
}
fn default_relocate_after_s() -> f64 {
    3.0
}
fn default_correlated_fraction() -> f64 {
    0.95
}
fn default_rtk_correlated_fraction() -> f64 {
    0.3
}
fn default_correlation_time_s() -> f64 {
    60.0
}
fn default_correlation_distance_m() -> f64 {
    20.0
}
fn default_gyro_noise() -> f64 {
    0.003
}
fn default_gyro_bias_walk() -> f64 {
    2e-5
}
fn default_heading_walk() -> f64 {
    // Fitted with the GNSS error's settings on a real robot's data (docs/fusion.md).
    0.0045
}
// The odom error's defaults: fitted with the heading walk on a real robot's data (docs/fusion.md),
// a skid-steered Husky on grass, so loose for most wheels.
fn default_odom_along() -> f64 {
    1e-2
}
fn default_wheel_slip() -> f64 {
    // 1 cm per metre: a tyre on grass or gravel.
    1e-4
}
fn default_wheel_scale_walk() -> f64 {
    // 1 % over 100 m: grass, then gravel, then wet grass.
    1e-3
}
fn default_odom_across() -> f64 {
    4e-3
}
fn default_odom_yaw() -> f64 {
    4e-4
}
fn default_max_position_radius_m() -> f64 {
    10_000.0
}

impl Default for LocalizationConfig {
    fn default() -> Self {
        Self {
            datum: None,
            locate_bound_m: default_bound(),
            gnss_latency_s: 0.0,
            heading_sigma_deg: default_heading_sigma(),
            relocate_after_s: default_relocate_after_s(),
            gnss_correlated_fraction: default_correlated_fraction(),
            rtk_correlated_fraction: default_rtk_correlated_fraction(),
            gnss_correlation_time_s: default_correlation_time_s(),
            gnss_correlation_distance_m: default_correlation_distance_m(),
            gnss_velocity_sigma_mps: None,
            gyro_noise_rps: default_gyro_noise(),
            heading_walk: default_heading_walk(),
            gyro_bias_walk: default_gyro_bias_walk(),
            odom_along_m2_per_m: default_odom_along(),
            wheel_slip_m2_per_m: default_wheel_slip(),
            wheel_scale_walk: default_wheel_scale_walk(),
            odom_across_m2_per_m: default_odom_across(),
            odom_yaw_rad2_per_rad: default_odom_yaw(),
            max_position_radius_m: default_max_position_radius_m(),
        }
    }
}

impl LocalizationConfig {
    /// Checks ranges: the datum, how GNSS fixes are weighed, then how dead reckoning's
    /// error grows.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if let Some(datum) = self.datum {
            check_datum(datum, file)?;
        }
        self.check_gnss_weighting(file)?;
        self.check_gnss_error_model(file)?;
        self.check_gyro_model(file)?;
        self.check_odometry_model(file)?;
        check_range(
            file,
            "localization.max_position_radius_m",
            self.max_position_radius_m,
            1.0..=1_000_000.0,
            "m",
        )
    }

    /// The locate bound, the fixes' latency, the heading's noise and when to relocate.
    fn check_gnss_weighting(&self, file: &Path) -> Result<(), ConfigError> {
        check_ranges(
            file,
            "localization.",
            [
                ("locate_bound_m", self.locate_bound_m, 0.01..=100.0, "m"),
                ("gnss_latency_s", self.gnss_latency_s, 0.0..=1.0, "s"),
                (
                    "heading_sigma_deg",
                    self.heading_sigma_deg,
                    0.01..=30.0,
                    "degrees",
                ),
                ("relocate_after_s", self.relocate_after_s, 0.2..=60.0, "s"),
            ],
        )
    }

    /// The wandering part of a fix's error, and the receiver's velocity accuracy.
    fn check_gnss_error_model(&self, file: &Path) -> Result<(), ConfigError> {
        check_ranges(
            file,
            "localization.",
            [
                (
                    "gnss_correlated_fraction",
                    self.gnss_correlated_fraction,
                    0.0..=0.95,
                    "",
                ),
                (
                    "rtk_correlated_fraction",
                    self.rtk_correlated_fraction,
                    0.0..=0.95,
                    "",
                ),
                (
                    "gnss_correlation_time_s",
                    self.gnss_correlation_time_s,
                    1.0..=3600.0,
                    "s",
                ),
                (
                    "gnss_correlation_distance_m",
                    self.gnss_correlation_distance_m,
                    0.1..=100_000.0,
                    "m",
                ),
            ],
        )?;
        if let Some(v) = self.gnss_velocity_sigma_mps {
            check_range(
                file,
                "localization.gnss_velocity_sigma_mps",
                v,
                0.001..=1.0,
                "m/s",
            )?;
        }
        Ok(())
    }

    /// The gyro's noise, the odom heading's walk and the gyro bias's walk.
    fn check_gyro_model(&self, file: &Path) -> Result<(), ConfigError> {
        check_ranges(
            file,
            "localization.",
            [
                ("gyro_noise_rps", self.gyro_noise_rps, 1e-5..=0.5, "rad/s"),
                ("heading_walk", self.heading_walk, 1e-5..=0.1, "rad per √s"),
                (
                    "gyro_bias_walk",
                    self.gyro_bias_walk,
                    0.0..=1e-2,
                    "rad/s per √s",
                ),
            ],
        )
    }

    /// The odometry's error variances (which share one range) and the wheels' scale walk.
    fn check_odometry_model(&self, file: &Path) -> Result<(), ConfigError> {
        for (key, value, unit) in [
            ("odom_along_m2_per_m", self.odom_along_m2_per_m, "m²/m"),
            ("wheel_slip_m2_per_m", self.wheel_slip_m2_per_m, "m²/m"),
            ("odom_across_m2_per_m", self.odom_across_m2_per_m, "m²/m"),
            (
                "odom_yaw_rad2_per_rad",
                self.odom_yaw_rad2_per_rad,
                "rad²/rad",
            ),
        ] {
            let key = format!("localization.{key}");
            check_range(file, &key, value, 1e-7..=1.0, unit)?;
        }
        check_range(
            file,
            "localization.wheel_scale_walk",
            self.wheel_scale_walk,
            0.0..=0.1,
            "per √m",
        )
    }
}

/// `localization.datum`: latitude, longitude and a plausible height.
fn check_datum([lat, lon, h]: [f64; 3], file: &Path) -> Result<(), ConfigError> {
    check_ranges(
        file,
        "localization.",
        [
            ("datum[0]", lat, -90.0..=90.0, "degrees"),
            ("datum[1]", lon, -180.0..=180.0, "degrees"),
            ("datum[2]", h, crate::geodesy::PLAUSIBLE_HEIGHT_M, "m"),
        ],
    )
}

/// The localiser settings of a vehicle configuration.
pub fn localizer_config(config: &VehicleConfig) -> LocalizerConfig {
    let l = config.localization.unwrap_or_default();
    let mut c = LocalizerConfig {
        datum: l.datum.map(|[lat_deg, lon_deg, h_m]| Geodetic {
            lat_deg,
            lon_deg,
            h_m,
        }),
        gnss_latency: Duration::from_secs_f64(l.gnss_latency_s),
        locate_bound_m: l.locate_bound_m,
        heading_sigma_rad: l.heading_sigma_deg.to_radians(),
        relocate_after: Duration::from_secs_f64(l.relocate_after_s),
        gnss_correlated_fraction: l.gnss_correlated_fraction,
        rtk_correlated_fraction: l.rtk_correlated_fraction,
        gnss_velocity_sigma_mps: l.gnss_velocity_sigma_mps,
        gyro_sigma: l.gyro_noise_rps,
        ..LocalizerConfig::default()
    };
    c.gnss_correlation = Duration::from_secs_f64(l.gnss_correlation_time_s);
    c.gnss_correlation_m = l.gnss_correlation_distance_m;
    c.heading_walk = l.heading_walk;
    c.gyro_bias_walk = l.gyro_bias_walk;
    c.wheel_slip = l.wheel_slip_m2_per_m;
    c.wheel_scale_walk = l.wheel_scale_walk;
    c.odom_error = (
        l.odom_along_m2_per_m,
        l.odom_across_m2_per_m,
        l.odom_yaw_rad2_per_rad,
    );
    if let Some(g) = &config.gnss {
        c.antenna = (g.antenna.x, g.antenna.y);
        c.cog_min_speed_mps = g.cog_min_speed_mps;
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The error of the default settings changed by `edit`.
    fn error_with(edit: impl FnOnce(&mut LocalizationConfig)) -> String {
        let mut l = LocalizationConfig::default();
        edit(&mut l);
        l.validate(Path::new("v.toml")).unwrap_err().to_string()
    }

    #[test]
    fn each_range_names_its_key() {
        assert!(
            LocalizationConfig::default()
                .validate(Path::new("v.toml"))
                .is_ok()
        );
        for (e, expected) in [
            (
                error_with(|l| l.datum = Some([91.0, 8.0, 400.0])),
                "`localization.datum[0]`: 91 is outside -90..=90 degrees",
            ),
            (
                error_with(|l| l.datum = Some([47.0, 8.0, 20_000.0])),
                "`localization.datum[2]`: 20000 is outside -500..=10000 m",
            ),
            (
                error_with(|l| l.relocate_after_s = 0.1),
                "`localization.relocate_after_s`: 0.1 is outside 0.2..=60 s",
            ),
            (
                error_with(|l| l.gnss_velocity_sigma_mps = Some(2.0)),
                "`localization.gnss_velocity_sigma_mps`: 2 is outside 0.001..=1 m/s",
            ),
            (
                error_with(|l| l.gyro_bias_walk = 1.0),
                "`localization.gyro_bias_walk`: 1 is outside 0..=0.01 rad/s per √s",
            ),
            (
                error_with(|l| l.odom_yaw_rad2_per_rad = 0.0),
                "`localization.odom_yaw_rad2_per_rad`: 0 is outside 0.0000001..=1 rad²/rad",
            ),
            (
                error_with(|l| l.wheel_scale_walk = 1.0),
                "`localization.wheel_scale_walk`: 1 is outside 0..=0.1 per √m",
            ),
            (
                error_with(|l| l.max_position_radius_m = 0.0),
                "`localization.max_position_radius_m`: 0 is outside 1..=1000000 m",
            ),
        ] {
            assert!(e.contains(expected), "{expected}: {e}");
        }
    }

    #[test]
    fn the_first_value_out_of_range_is_reported() {
        let e = error_with(|l| {
            l.datum = Some([47.0, 181.0, 400.0]);
            l.locate_bound_m = 0.0;
        });
        assert!(e.contains("`localization.datum[1]`"), "{e}");
        let e = error_with(|l| {
            l.gnss_velocity_sigma_mps = Some(2.0);
            l.gyro_noise_rps = 1.0;
        });
        assert!(e.contains("`localization.gnss_velocity_sigma_mps`"), "{e}");
        let e = error_with(|l| {
            l.wheel_scale_walk = 1.0;
            l.max_position_radius_m = 0.0;
        });
        assert!(e.contains("`localization.wheel_scale_walk`"), "{e}");
    }
}
