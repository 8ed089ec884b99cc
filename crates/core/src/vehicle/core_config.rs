//! The core's settings, taken from the vehicle configuration once at start.

use std::time::Duration;

use super::safety::ControlLinkConfig;
use crate::config::VehicleConfig;
use crate::config::chassis::ChassisConfig;
use crate::config::localization::{LocalizationConfig, localizer_config};
use crate::config::mission::{MissionConfig, MissionSettings};
use crate::config::motion::MotionSettings;
use crate::fusion::localizer::LocalizerConfig;

/// Core settings, taken from the vehicle configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoreConfig {
    /// A fix (or heading, or velocity) older than this is stale.
    pub gnss_fix_timeout: Duration,
    /// Course over ground stands in for heading only above this speed, m/s.
    pub cog_min_speed_mps: f64,
    /// The dual-antenna heading minus the vehicle's, degrees: taken off every heading.
    pub heading_offset_deg: f64,
    /// The drive train, when the vehicle has drives.
    pub chassis: Option<ChassisConfig>,
    /// The controlling client's heartbeat watchdog, when a dialect has one.
    pub control_link: Option<ControlLinkConfig>,
    /// A BMS reading older than this is stale; `None` without a BMS.
    pub bms_stale_after: Option<Duration>,
    /// No plausible IMU sample for this long: the IMU is not ok; `None` without an IMU.
    pub imu_timeout: Option<Duration>,
    /// The fusion filter.
    pub localizer: LocalizerConfig,
    /// Closed-loop moves, when the vehicle has drives.
    pub motion: Option<MotionSettings>,
    /// Missions.
    pub mission: MissionSettings,
    /// Whether a cutter is configured.
    pub has_cutter: bool,
    /// A position set by hand may lie at most this far from the datum, m.
    pub max_position_radius_m: f64,
    /// RTK corrections older than this are stale; `None` without a correction source.
    pub corrections_stale_after: Option<Duration>,
}

impl Default for CoreConfig {
    fn default() -> Self {
        Self {
            gnss_fix_timeout: Duration::from_secs(2),
            cog_min_speed_mps: 0.3,
            heading_offset_deg: 0.0,
            chassis: None,
            control_link: None,
            bms_stale_after: None,
            imu_timeout: None,
            localizer: LocalizerConfig::default(),
            motion: None,
            mission: MissionConfig::default().settings(),
            has_cutter: false,
            corrections_stale_after: None,
            max_position_radius_m: LocalizationConfig::default().max_position_radius_m,
        }
    }
}

impl CoreConfig {
    /// The core settings of a vehicle configuration.
    pub fn from_vehicle(config: &VehicleConfig) -> Self {
        let mut core = match &config.gnss {
            Some(g) => Self {
                gnss_fix_timeout: g.fix_timeout(),
                cog_min_speed_mps: g.cog_min_speed_mps,
                heading_offset_deg: g.heading_offset_deg,
                ..Self::default()
            },
            None => Self::default(),
        };
        if !config.drive.is_empty() {
            core.chassis = config.chassis;
            core.motion = config
                .chassis
                .map(|c| config.motion.unwrap_or_default().settings(&c));
        }
        core.control_link =
            config
                .mqtt
                .as_ref()
                .and_then(|m| m.root.as_ref())
                .map(|r| ControlLinkConfig {
                    timeout: r.heartbeat_timeout(),
                    required_from_start: r.require_heartbeat,
                });
        core.bms_stale_after = config
            .bms
            .as_ref()
            .map(|b| Duration::from_secs_f64(b.stale_s));
        core.imu_timeout = config.imu.as_ref().map(|i| i.timeout());
        core.localizer = localizer_config(config);
        core.mission = config.mission.unwrap_or_default().settings();
        core.has_cutter = config.cutter.is_some();
        core.corrections_stale_after = config.ntrip.as_ref().map(|n| n.timeout());
        core.max_position_radius_m = config
            .localization
            .unwrap_or_default()
            .max_position_radius_m;
        core
    }
}
