//! `[motion]`: the limits and tolerances of closed-loop moves (distance and angle moves,
//! goals, trajectory tasks). Every limit defaults to the drive train's (`[chassis]`) and may
//! only be lower: the chassis limits stay the last word on what reaches the wheels.

use std::ops::RangeInclusive;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::chassis::ChassisConfig;
use super::{ConfigError, check_range, check_ranges};
use crate::control::profile::Limits;
pub use crate::control::settings::{MinGnss, MotionSettings, Reach, TaskSettings, creep};

/// `[motion]`
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct MotionConfig {
    /// Peak speed of a move, m/s (default: `chassis.max_speed_mps`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_speed_mps: Option<f64>,
    /// Acceleration of a move, m/s² (default: `chassis.max_accel_mps2`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_accel_mps2: Option<f64>,
    /// Deceleration of a move, m/s² (default: `chassis.max_decel_mps2`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_decel_mps2: Option<f64>,
    /// Jerk limit of a move, m/s³; without one the profile is a trapezoid.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_jerk_mps3: Option<f64>,
    /// Peak yaw rate of a turn, rad/s (default: `chassis.max_yaw_rate_rps`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_yaw_rate_rps: Option<f64>,
    /// Yaw acceleration (and deceleration) of a turn, rad/s² (default:
    /// `chassis.max_yaw_accel_rps2`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_yaw_accel_rps2: Option<f64>,
    /// Yaw jerk limit of a turn, rad/s³; without one the profile is a trapezoid.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_yaw_jerk_rps3: Option<f64>,
    /// A distance move has arrived within this, m (default 0.001).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_tolerance_m: Option<f64>,
    /// A turn has arrived within this, degrees (default 0.15).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angle_tolerance_deg: Option<f64>,
    /// A goal has arrived within this distance of it, m (default 0.02).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_position_tolerance_m: Option<f64>,
    /// ... and this far from its heading, degrees (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_angle_tolerance_deg: Option<f64>,
    /// A move times out after its profile's duration times this ... (default 1.5)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_allowance_factor: Option<f64>,
    /// ... plus this, s (default 3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_allowance_s: Option<f64>,
    /// A trajectory task slows in curves to keep the sideways acceleration within this,
    /// m/s² (default 0.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_lateral_accel_mps2: Option<f64>,
    /// The least GNSS fix quality a trajectory task drives on (default `rtk_fixed`): below
    /// it the task waits at rest, and goes on when the quality is back.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task_min_gnss: Option<MinGnss>,
    /// A task waiting for GNSS quality fails after this, s (default 120).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task_gnss_wait_s: Option<f64>,
    /// A task starts only this close to its first point, m (default 5): the way there is
    /// driven straight, unplanned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task_max_approach_m: Option<f64>,
    /// A trajectory task or COVERAGE path that strays further than this from its path
    /// stops with the reason, m (default 0.3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_cross_track_m: Option<f64>,
    /// A goal (and each point of a MOVE_TO_POSITION) may lie at most this far from the
    /// vehicle, m (default 100, as a `set_navi_cmd` move).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_goal_distance_m: Option<f64>,
    /// Every point of a trajectory task or a COVERAGE path may lie at most this far from
    /// the vehicle, m (default 2000).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_path_radius_m: Option<f64>,
}

impl MotionConfig {
    /// The settings under `chassis`'s limits.
    pub fn settings(&self, chassis: &ChassisConfig) -> MotionSettings {
        MotionSettings {
            linear: Limits {
                speed: self.max_speed_mps.unwrap_or(chassis.max_speed_mps),
                accel: self.max_accel_mps2.unwrap_or(chassis.max_accel_mps2),
                decel: self.max_decel_mps2.unwrap_or(chassis.max_decel_mps2),
                jerk: self.max_jerk_mps3.unwrap_or(f64::INFINITY),
            },
            angular: Limits {
                speed: self.max_yaw_rate_rps.unwrap_or(chassis.max_yaw_rate_rps),
                accel: self
                    .max_yaw_accel_rps2
                    .unwrap_or(chassis.max_yaw_accel_rps2),
                decel: self
                    .max_yaw_accel_rps2
                    .unwrap_or(chassis.max_yaw_accel_rps2),
                jerk: self.max_yaw_jerk_rps3.unwrap_or(f64::INFINITY),
            },
            position_tolerance_m: self.position_tolerance_m.unwrap_or(0.001),
            angle_tolerance_rad: self.angle_tolerance_deg.unwrap_or(0.15).to_radians(),
            goal_position_tolerance_m: self.goal_position_tolerance_m.unwrap_or(0.02),
            goal_angle_tolerance_rad: self.goal_angle_tolerance_deg.unwrap_or(1.0).to_radians(),
            time_allowance_factor: self.time_allowance_factor.unwrap_or(1.5),
            time_allowance_s: self.time_allowance_s.unwrap_or(3.0),
            task: TaskSettings {
                max_lateral_accel_mps2: self.max_lateral_accel_mps2.unwrap_or(0.5),
                min_gnss: self.task_min_gnss.unwrap_or(MinGnss::RtkFixed),
                gnss_wait_s: self.task_gnss_wait_s.unwrap_or(120.0),
                max_approach_m: self.task_max_approach_m.unwrap_or(5.0),
                max_cross_track_m: self.max_cross_track_m.unwrap_or(0.3),
            },
            reach: Reach {
                goal_m: self.max_goal_distance_m.unwrap_or(100.0),
                path_m: self.max_path_radius_m.unwrap_or(2000.0),
            },
            creep: creep(chassis.track_m),
        }
    }

    /// Checks every value against its range and the chassis limits.
    pub fn validate(
        &self,
        chassis: Option<&ChassisConfig>,
        file: &Path,
    ) -> Result<(), ConfigError> {
        let Some(chassis) = chassis else {
            return Err(ConfigError::invalid(
                file,
                "motion",
                "is set without a [chassis]".to_owned(),
                "add the [chassis] table of the drive train, or remove [motion]",
            ));
        };
        self.check_chassis_caps(chassis, file)?;
        self.check_move_ranges(file)?;
        self.check_task_ranges(file)
    }

    /// The limits a move shares with the drive train: positive, and within the chassis'.
    fn check_chassis_caps(&self, c: &ChassisConfig, file: &Path) -> Result<(), ConfigError> {
        for (key, value, cap, unit) in [
            ("max_speed_mps", self.max_speed_mps, c.max_speed_mps, "m/s"),
            (
                "max_accel_mps2",
                self.max_accel_mps2,
                c.max_accel_mps2,
                "m/s²",
            ),
            (
                "max_decel_mps2",
                self.max_decel_mps2,
                c.max_decel_mps2,
                "m/s²",
            ),
            (
                "max_yaw_rate_rps",
                self.max_yaw_rate_rps,
                c.max_yaw_rate_rps,
                "rad/s",
            ),
            (
                "max_yaw_accel_rps2",
                self.max_yaw_accel_rps2,
                c.max_yaw_accel_rps2,
                "rad/s²",
            ),
        ] {
            let Some(v) = value else { continue };
            check_range(file, &format!("motion.{key}"), v, 0.001..=f64::MAX, unit)?;
            // A move may be gentler than the drive train, never harsher.
            if v > cap {
                return Err(ConfigError::invalid(
                    file,
                    &format!("motion.{key}"),
                    format!("{v} {unit} is above chassis.{key} = {cap} {unit}"),
                    &format!(
                        "a move may be gentler than the drive train, never harsher: lower it, \
                         or raise chassis.{key}"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// A move's own jerk limits, arrival tolerances and time allowance.
    fn check_move_ranges(&self, file: &Path) -> Result<(), ConfigError> {
        check_set_ranges(
            file,
            [
                ("max_jerk_mps3", self.max_jerk_mps3, 0.01..=1000.0, "m/s³"),
                (
                    "max_yaw_jerk_rps3",
                    self.max_yaw_jerk_rps3,
                    0.01..=1000.0,
                    "rad/s³",
                ),
                (
                    "position_tolerance_m",
                    self.position_tolerance_m,
                    0.0001..=0.5,
                    "m",
                ),
                (
                    "angle_tolerance_deg",
                    self.angle_tolerance_deg,
                    0.01..=20.0,
                    "degrees",
                ),
                (
                    "goal_position_tolerance_m",
                    self.goal_position_tolerance_m,
                    0.001..=5.0,
                    "m",
                ),
                (
                    "goal_angle_tolerance_deg",
                    self.goal_angle_tolerance_deg,
                    0.05..=180.0,
                    "degrees",
                ),
                (
                    "time_allowance_factor",
                    self.time_allowance_factor,
                    1.0..=100.0,
                    "times",
                ),
                ("time_allowance_s", self.time_allowance_s, 0.0..=3600.0, "s"),
            ],
        )
    }

    /// Trajectory tasks' curves, GNSS wait and approach, and how far goals and paths reach.
    fn check_task_ranges(&self, file: &Path) -> Result<(), ConfigError> {
        check_set_ranges(
            file,
            [
                (
                    "max_lateral_accel_mps2",
                    self.max_lateral_accel_mps2,
                    0.01..=10.0,
                    "m/s²",
                ),
                (
                    "task_gnss_wait_s",
                    self.task_gnss_wait_s,
                    0.0..=86_400.0,
                    "s",
                ),
                (
                    "task_max_approach_m",
                    self.task_max_approach_m,
                    0.0..=1000.0,
                    "m",
                ),
                (
                    "max_cross_track_m",
                    self.max_cross_track_m,
                    0.05..=10.0,
                    "m",
                ),
                (
                    "max_goal_distance_m",
                    self.max_goal_distance_m,
                    0.1..=10_000.0,
                    "m",
                ),
                (
                    "max_path_radius_m",
                    self.max_path_radius_m,
                    1.0..=100_000.0,
                    "m",
                ),
            ],
        )
    }
}

/// [`check_ranges`] under `motion.` on the values that are set.
fn check_set_ranges<'a>(
    file: &Path,
    checks: impl IntoIterator<Item = (&'a str, Option<f64>, RangeInclusive<f64>, &'a str)>,
) -> Result<(), ConfigError> {
    let set = checks
        .into_iter()
        .filter_map(|(key, value, range, unit)| Some((key, value?, range, unit)));
    check_ranges(file, "motion.", set)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chassis() -> ChassisConfig {
        toml::from_str("wheel_radius_m = 0.1\ntrack_m = 0.5\nmax_speed_mps = 1.0").expect("chassis")
    }

    #[test]
    fn limits_default_to_the_chassis_and_may_only_be_lower() {
        let m = MotionConfig::default();
        let s = m.settings(&chassis());
        assert_eq!(s.linear.speed, 1.0);
        assert!(s.linear.jerk.is_infinite());
        let file = Path::new("v.toml");
        assert!(m.validate(Some(&chassis()), file).is_ok());
        let faster = MotionConfig {
            max_speed_mps: Some(1.2),
            ..m
        };
        let e = faster
            .validate(Some(&chassis()), file)
            .unwrap_err()
            .to_string();
        assert!(e.contains("motion.max_speed_mps"), "{e}");
        // The bound is named by its own key, and the fix says which way to go.
        assert!(e.contains("above chassis.max_speed_mps = 1 m/s"), "{e}");
        assert!(e.contains("raise chassis.max_speed_mps"), "{e}");
        assert!(m.validate(None, file).is_err());
    }

    #[test]
    fn each_range_names_its_key() {
        let file = Path::new("v.toml");
        for (m, expected) in [
            (
                MotionConfig {
                    max_yaw_accel_rps2: Some(0.0),
                    ..MotionConfig::default()
                },
                "`motion.max_yaw_accel_rps2`: 0 rad/s² is below 0.001 rad/s²; fix: set a value of at least 0.001 rad/s²",
            ),
            (
                MotionConfig {
                    time_allowance_factor: Some(0.5),
                    ..MotionConfig::default()
                },
                "`motion.time_allowance_factor`: 0.5 is outside 1..=100 times",
            ),
            (
                MotionConfig {
                    max_cross_track_m: Some(0.01),
                    ..MotionConfig::default()
                },
                "`motion.max_cross_track_m`: 0.01 is outside 0.05..=10 m",
            ),
            // The chassis' caps come first, then a move's ranges, then a task's.
            (
                MotionConfig {
                    max_path_radius_m: Some(0.0),
                    max_jerk_mps3: Some(0.0),
                    max_yaw_rate_rps: Some(2.0),
                    ..MotionConfig::default()
                },
                "`motion.max_yaw_rate_rps`: 2 rad/s is above chassis.max_yaw_rate_rps",
            ),
            (
                MotionConfig {
                    max_path_radius_m: Some(0.0),
                    max_jerk_mps3: Some(0.0),
                    ..MotionConfig::default()
                },
                "`motion.max_jerk_mps3`",
            ),
        ] {
            let e = m.validate(Some(&chassis()), file).unwrap_err().to_string();
            assert!(e.contains(expected), "{expected}: {e}");
        }
    }
}
