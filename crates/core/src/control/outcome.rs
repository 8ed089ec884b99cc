//! Why a motion or a mission ended without arriving. The reasons are typed so that each
//! protocol picks its code by matching on them; `Display` gives the words the logs and the
//! clients' messages carry, which recordings hold, so they stay as they were written.

use std::fmt;

use super::settings::MinGnss;

/// How a motion or a mission ended.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Arrived within its tolerance.
    Succeeded,
    /// Ended on request (a new move, a velocity command, a stop, a mode switch).
    Cancelled(CancelReason),
    /// Did not arrive within its time allowance.
    TimedOut,
    /// Ended by a fault or a lost precondition.
    Aborted(AbortReason),
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Succeeded => write!(f, "succeeded"),
            Self::Cancelled(why) => write!(f, "cancelled: {why}"),
            Self::TimedOut => write!(f, "timed out"),
            Self::Aborted(why) => write!(f, "aborted: {why}"),
        }
    }
}

/// A mission step a reason arose in: its index and its action's name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepAt {
    /// 0-based.
    pub index: usize,
    /// The step's action as the mission names it (`MOVE_TO_POSITION`, `CHARGING`, ...).
    pub action: &'static str,
}

impl fmt::Display for StepAt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "step {} ({})", self.index, self.action)
    }
}

/// What took a motion or mission's place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replacement {
    /// A distance or angle move.
    Move,
    /// A goal.
    Goal,
    /// A trajectory task.
    Task,
    /// A mission.
    Mission,
}

/// Why a motion or mission was ended on request.
#[derive(Debug, Clone, PartialEq)]
pub enum CancelReason {
    /// `set_navi_cmd` 5 or `/navi_stop`: brought to rest, not latched.
    StopRequested,
    /// An operator's stop (latched).
    StoppedByOperator,
    /// A velocity command took the wheels.
    VelocityCommand,
    /// The operator paused a move (a move does not resume).
    PausedByOperator,
    /// The drive mode was switched.
    ModeSwitched,
    /// A new motion started in its place.
    NewMotion,
    /// Another motion took a mission's place.
    Replaced(Replacement),
    /// A new mission took the mission's place.
    NewMission,
    /// The mission the motion belonged to ended first.
    MissionEnded,
    /// A mission's step was cancelled, which cancels the mission.
    Step(StepAt, Box<CancelReason>),
}

impl fmt::Display for CancelReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::StopRequested => f.write_str("stop requested"),
            Self::StoppedByOperator => f.write_str("stopped by the operator"),
            Self::VelocityCommand => f.write_str("a velocity command took over"),
            Self::PausedByOperator => f.write_str("paused by the operator"),
            Self::ModeSwitched => f.write_str("the drive mode was switched"),
            Self::NewMotion => f.write_str("replaced by a new move"),
            Self::Replaced(by) => write!(
                f,
                "a {} replaced it",
                match by {
                    Replacement::Move => "move",
                    Replacement::Goal => "goal",
                    Replacement::Task => "task",
                    Replacement::Mission => "mission",
                }
            ),
            Self::NewMission => f.write_str("replaced by a new mission"),
            Self::MissionEnded => f.write_str("the mission ended"),
            Self::Step(step, why) => write!(f, "{step}: {why}"),
        }
    }
}

/// The motion whose localisation was lost.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LostDuring {
    /// A move that steered on the map's heading.
    MapHeadingMove,
    /// A trajectory task or path.
    Task,
    /// A goal.
    Goal,
}

/// Why a motion or mission was ended by a fault or a lost precondition.
#[derive(Debug, Clone, PartialEq)]
pub enum AbortReason {
    /// The map pose it steered on is gone.
    LocalisationLost(LostDuring),
    /// The GNSS quality stayed below the task's least for longer than it waits.
    GnssBelow {
        /// The quality the receiver gives.
        quality: MinGnss,
        /// The least the task drives on.
        min: MinGnss,
        /// How long it waited, s.
        waited_s: f64,
    },
    /// The vehicle left its path by more than the limit.
    OffPath {
        /// How far, m.
        off_m: f64,
        /// The limit, m.
        limit_m: f64,
    },
    /// A goal came to rest outside its tolerance after its last approach.
    GoalMissed {
        /// Where it rests from the goal, m.
        distance_m: f64,
        /// Approaches made.
        approaches: u32,
        /// The tolerance, m.
        tolerance_m: f64,
    },
    /// No odometry to close the motion on.
    NoOdometry,
    /// The safety supervisor latched a stop: its cause, described.
    SafetyStop(String),
    /// The drive train refused the motion's command: its refusal, described.
    DrivesRefused(String),
    /// The GNSS gate closed under a goal or a move, which cannot hold: why, described.
    GnssGate(String),
    /// A mission's step could not start: the refusal, described.
    StepNotStarted(String),
    /// A mission's charging step found no dock in the configuration.
    NoDock,
    /// At the dock, the BMS did not report charging within the timeout.
    NotCharging {
        /// The timeout, s.
        timeout_s: f64,
    },
    /// A mission's step ran out of time, which aborts the mission.
    StepTimedOut(StepAt),
    /// A mission's step was aborted, which aborts the mission.
    Step(StepAt, Box<AbortReason>),
}

impl AbortReason {
    /// The reason at the bottom of a mission's steps: what actually went wrong.
    pub fn root(&self) -> &AbortReason {
        match self {
            Self::Step(_, why) => why.root(),
            other => other,
        }
    }
}

impl fmt::Display for AbortReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::LocalisationLost(during) => write!(
                f,
                "localisation lost during {}",
                match during {
                    LostDuring::MapHeadingMove => "the move (its heading was the map's)",
                    LostDuring::Task => "the task",
                    LostDuring::Goal => "the goal",
                }
            ),
            Self::GnssBelow {
                quality,
                min,
                waited_s,
            } => write!(
                f,
                "GNSS quality {quality} below motion.task_min_gnss = {min} for {waited_s:.0} s \
                 (motion.task_gnss_wait_s)"
            ),
            Self::OffPath { off_m, limit_m } => {
                write!(
                    f,
                    "left the path by {off_m:.2} m (motion.max_cross_track_m = {limit_m} m)"
                )
            }
            Self::GoalMissed {
                distance_m,
                approaches,
                tolerance_m,
            } => write!(
                f,
                "ended {:.0} mm from the goal after {approaches} approaches \
                 (motion.goal_position_tolerance_m = {:.0} mm)",
                distance_m * 1000.0,
                tolerance_m * 1000.0
            ),
            Self::NoOdometry => f.write_str("no odometry"),
            Self::SafetyStop(cause) => write!(f, "safety stop: {cause}"),
            Self::DrivesRefused(why) => f.write_str(why),
            Self::GnssGate(why) => write!(f, "the GNSS gate closed: {why}"),
            Self::StepNotStarted(why) => write!(f, "a step could not start: {why}"),
            Self::NoDock => f.write_str("no dock is configured (mission.dock)"),
            Self::NotCharging { timeout_s } => write!(
                f,
                "the BMS has not reported charging for {timeout_s} s at the dock \
                 (mission.charge_timeout_s)"
            ),
            Self::StepTimedOut(step) => write!(f, "{step} timed out"),
            Self::Step(step, why) => write!(f, "{step}: {why}"),
        }
    }
}
