//! The vehicle status snapshot the core hands to the dialects, in SI units.

use super::chassis::{ChassisStatus, DriveMode};
pub use crate::control::Navigation;
use crate::devices::bms::BmsReading;
use crate::devices::gnss::FixQuality;
use crate::time::Timestamp;

/// Everything a status report needs, taken at one tick.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VehicleStatus {
    /// Tick time.
    pub time: Timestamp,
    /// An IMU is configured, its link is up, and a plausible sample is fresh.
    pub imu_ok: bool,
    /// The drive train; `None` without drives.
    pub chassis: Option<ChassisStatus>,
    /// The battery; `None` without a BMS.
    pub battery: Option<BatteryStatus>,
    /// GNSS receiver state.
    pub gnss: GnssStatus,
    /// The published pose: in the map frame (the datum's ENU frame, or INIT_POSITION's)
    /// once GNSS or INIT_POSITION has placed the vehicle; until then the `odom` frame's, and
    /// `localization` is `Uninitialized`. Zero without either.
    pub pose: Pose2D,
    /// The map pose's covariance; `None` while the pose is the odom frame's.
    pub pose_covariance: Option<PoseCovariance>,
    /// Where the map frame lies on the globe, once there is a datum: what turns the map pose
    /// into latitude and longitude.
    pub placement: Option<crate::fusion::localizer::MapPlacement>,
    /// The `odom` frame's pose (wheels and gyro only, continuous), once the drives report.
    pub odom: Option<crate::fusion::odometry::OdomPose>,
    /// The frame tree at `time`, once both the map and the odom frame exist.
    pub frames: Option<FrameTree>,
    /// Localisation state.
    pub localization: Localization,
    /// Navigation task state.
    pub navigation: Navigation,
    /// The path of the motion under way, in the map frame (when it has one).
    pub plan: Option<crate::control::Plan>,
    /// Whether an obstacle has stopped the vehicle.
    pub obstacle_stop: bool,
    /// The host computer's load, once sampled.
    pub host: Option<HostUsage>,
    /// Who may drive; `None` without drives.
    pub mode: Option<DriveMode>,
    /// RTK corrections; `None` without a correction source.
    pub corrections: Option<super::corrections::CorrectionsStatus>,
    /// The zones and the GNSS gate; `None` without zones.
    pub envelope: Option<super::envelope::EnvelopeStatus>,
    /// Each MQTT link, in the configuration's order; empty without `[mqtt]`.
    pub mqtt_links: Vec<MqttLinkStatus>,
}

/// One MQTT link as its recorded states say.
#[derive(Debug, Clone, PartialEq)]
pub struct MqttLinkStatus {
    /// The link's name (`mqtt` in the one-link form).
    pub name: String,
    /// Whether its session with the broker is up.
    pub up: bool,
    /// When it last went up or down; `None` before its first state.
    pub since: Option<Timestamp>,
}

/// The frame tree of REP-105 at one time: the map pose is `map_to_odom` composed with
/// `odom_to_base`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameTree {
    /// Where the `odom` frame's origin lies in the map frame and how it is turned: the
    /// correction GNSS estimates.
    pub map_to_odom: Pose2D,
    /// The odom pose carried to that time as the map pose is (by the last speeds).
    pub odom_to_base: Pose2D,
}

/// The vehicle's poses at one control tick: what a 100 Hz odometry topic needs, without
/// the rest of a status.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseReport {
    /// The `odom` frame's pose and speeds, once the drives report.
    pub odom: Option<crate::fusion::odometry::OdomPose>,
    /// The map pose and its covariance, once GNSS or INIT_POSITION has placed the vehicle.
    pub map: Option<(Pose2D, PoseCovariance)>,
    /// The frame tree, once both frames exist.
    pub frames: Option<FrameTree>,
    /// Localisation state.
    pub localization: Localization,
}

/// The host computer's load.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct HostUsage {
    /// CPU busy over the last sample period, % of all cores.
    pub cpu: f64,
    /// Memory in use, % of the total.
    pub memory: f64,
}

/// The battery at a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatteryStatus {
    /// The last reading (all `None` before the first).
    pub reading: BmsReading,
    /// No reading within the stale timeout.
    pub stale: bool,
}

/// GNSS state at a tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GnssStatus {
    /// Link up and a valid fix younger than the fix timeout.
    pub ok: bool,
    /// Fix quality; `Invalid` whenever `ok` is false.
    pub quality: FixQuality,
    /// Last valid latitude, degrees north (0 before the first fix).
    pub latitude_deg: f64,
    /// Last valid longitude, degrees east (0 before the first fix).
    pub longitude_deg: f64,
    /// Heading, degrees true (0 = north, clockwise): dual-antenna heading when fresh, else
    /// course over ground while moving, else the last value.
    pub heading_deg: f64,
}

/// Planar pose in the local ENU frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose2D {
    /// East, metres.
    pub x: f64,
    /// North, metres.
    pub y: f64,
    /// Yaw, radians counter-clockwise from east.
    pub yaw: f64,
}

/// The covariance of a planar pose: m², m² and rad².
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseCovariance {
    /// Var(x).
    pub xx: f64,
    /// Cov(x, y).
    pub xy: f64,
    /// Var(y).
    pub yy: f64,
    /// Var(yaw).
    pub yaw: f64,
}

/// Localisation state (`nav.locate`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Localization {
    /// No map pose yet: the pose is the `odom` frame's (`LOCATE_UNINIT`).
    #[default]
    Uninitialized,
    /// Map pose with position and heading within their bounds (`LOCATE_TRUE`).
    Good,
    /// Map pose beyond a bound, or with its heading not yet known (`LOCATE_FALSE`).
    Lost,
}
