//! The settings motions and missions run with: plain values the configuration resolves
//! from its files and the chassis limits, so the controllers never read a file.

use serde::{Deserialize, Serialize};

use crate::control::profile::Limits;
use crate::devices::gnss::FixQuality;

/// The least GNSS fix quality a trajectory task drives on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MinGnss {
    /// Any localisation the fusion calls good (INIT_POSITION and odometry alone, too).
    None,
    /// A satellite fix of any kind.
    Single,
    /// Differential (SBAS, DGPS) or better.
    Dgps,
    /// RTK float or fixed.
    RtkFloat,
    /// RTK fixed.
    RtkFixed,
}

impl MinGnss {
    /// The level `quality` reaches.
    pub fn of(quality: FixQuality) -> Self {
        match quality {
            FixQuality::RtkFixed => Self::RtkFixed,
            FixQuality::RtkFloat => Self::RtkFloat,
            FixQuality::Dgps => Self::Dgps,
            FixQuality::Single | FixQuality::Pps => Self::Single,
            FixQuality::Invalid
            | FixQuality::DeadReckoning
            | FixQuality::Manual
            | FixQuality::Simulation => Self::None,
        }
    }
}

impl std::fmt::Display for MinGnss {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::None => "none",
            Self::Single => "single",
            Self::Dgps => "dgps",
            Self::RtkFloat => "rtk_float",
            Self::RtkFixed => "rtk_fixed",
        })
    }
}

/// How trajectory tasks run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskSettings {
    /// Sideways acceleration in curves, m/s².
    pub max_lateral_accel_mps2: f64,
    /// The least GNSS quality to drive on.
    pub min_gnss: MinGnss,
    /// How long a task waits for it, s.
    pub gnss_wait_s: f64,
    /// How far its first point may be, m.
    pub max_approach_m: f64,
    /// Further from the path than this ends the task, m.
    pub max_cross_track_m: f64,
}

/// How far from the vehicle a motion may lead.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    /// A goal, or a MOVE_TO_POSITION point, m.
    pub goal_m: f64,
    /// A point of a task or COVERAGE path, m.
    pub path_m: f64,
}

/// The settings a move runs with, resolved against the chassis limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionSettings {
    /// Distance moves, m.
    pub linear: Limits,
    /// Turns, rad.
    pub angular: Limits,
    /// Arrival tolerance of a distance move, m.
    pub position_tolerance_m: f64,
    /// Arrival tolerance of a turn, rad.
    pub angle_tolerance_rad: f64,
    /// Arrival tolerance of a goal's position, m.
    pub goal_position_tolerance_m: f64,
    /// Arrival tolerance of a goal's heading, rad.
    pub goal_angle_tolerance_rad: f64,
    /// Time allowance: the profile's duration times this ...
    pub time_allowance_factor: f64,
    /// ... plus this, s.
    pub time_allowance_s: f64,
    /// Trajectory tasks.
    pub task: TaskSettings,
    /// How far a motion may lead.
    pub reach: Reach,
    /// The slowest speed and yaw rate a move settling on its goal commands (m/s, rad/s):
    /// twice what the odometry and the localiser take for standing still, so a move never
    /// creeps unseen (its measured progress frozen) while off its goal.
    pub creep: (f64, f64),
}

/// The creep speeds of a vehicle of track `track_m`: each wheel at twice the standstill
/// speed, and a turn on the spot above the standstill yaw rate too.
pub fn creep(track_m: f64) -> (f64, f64) {
    use crate::fusion::{localizer::STILL_RPS, odometry::STILL_MPS};
    (
        2.0 * STILL_MPS,
        (2.0 * 2.0 * STILL_MPS / track_m).max(2.0 * STILL_RPS),
    )
}
