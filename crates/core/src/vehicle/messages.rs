//! What goes into the core and what comes out: the inputs the runtime hands it (readings,
//! link states, commands, ticks) and the outputs it returns.

use super::chassis::{ChassisFeedback, CommandRejected, DriveMode, WheelCommand};
use super::event::Event;
use super::status::{HostUsage, VehicleStatus};
use super::zones;
use crate::control::goal::GoalPose;
use crate::control::mission::{MissionEvent, MissionStep};
use crate::control::{MotionResult, MotionTag, MoveKind};
use crate::devices::bms::BmsReading;
use crate::devices::gnss::GnssFix;
use crate::devices::imu::ImuSample;
use crate::geodesy::Geodetic;

/// A device whose link state the drivers report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Device {
    /// The GNSS receiver.
    Gnss,
    /// The IMU.
    Imu,
    /// The NTRIP caster's correction stream.
    Corrections,
}

/// Whether a device's port or bus is usable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkState {
    /// Open and readable.
    Up,
    /// Closed, missing or failing; the driver is reconnecting.
    Down,
}

/// The points of a path task.
#[derive(Debug, Clone, PartialEq)]
pub enum PathPoints {
    /// East and north in the map frame, m.
    Map(Vec<(f64, f64)>),
    /// Latitude and longitude, degrees: placed in the map frame of the datum in force when
    /// the task starts, so the path stays where it was recorded on the ground.
    Geodetic(Vec<(f64, f64)>),
}

/// A path to follow.
#[derive(Debug, Clone, PartialEq)]
pub struct PathRequest {
    /// Its points in driving order (the vehicle drives to the first one first).
    pub points: PathPoints,
    /// Speed, m/s (at most the motion speed limit; slower in curves).
    pub speed: f64,
}

/// A command from a protocol dialect.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Drive at forward speed `vx` (m/s) and yaw rate `wz` (rad/s) until the command
    /// times out.
    Velocity {
        /// Forward speed, m/s.
        vx: f64,
        /// Yaw rate, rad/s, counter-clockwise.
        wz: f64,
    },
    /// Re-zero the local frame at the vehicle's position (`init_rtk_data`).
    ZeroLocalFrame,
    /// Set the pose in the local frame (INIT_POSITION).
    SetPose {
        /// East, m.
        x: f64,
        /// North, m.
        y: f64,
        /// Yaw, rad, counter-clockwise from east.
        yaw: f64,
    },
    /// Move the datum of the local frame (SET_LNG_LAT).
    SetDatum(Geodetic),
    /// An operator's stop: latches until a zero velocity command or a reset.
    Stop,
    /// Re-arm a latched stop once its cause has cleared, resetting drive faults.
    Reset,
    /// Engage or release the software emergency stop (releasing does not re-arm).
    EmergencyStop {
        /// Engage (true) or release.
        engaged: bool,
    },
    /// A heartbeat from the controlling client (the control-link watchdog).
    ControlHeartbeat,
    /// Switch who may drive (SWITCH_MODE).
    SetMode(DriveMode),
    /// Add or remove a zone (ROS1 `/set_shape`, `/set_region`).
    EditZones(zones::ZoneEdit),
    /// A closed-loop distance or angle move (`set_navi_cmd` 1–4), replacing the one under
    /// way.
    Move(MoveKind),
    /// Go to a pose in the map frame (`device/{serial}/goal`, MOVE_TO_POSITION), replacing
    /// the motion under way; the result carries `tag`.
    Goal {
        /// Where.
        goal: GoalPose,
        /// Who asked.
        tag: Option<MotionTag>,
    },
    /// End the move under way and bring the vehicle to rest, without latching
    /// (`set_navi_cmd` 5).
    CancelMotion,
    /// Follow a path (`start_task`, COVERAGE), replacing the motion under way; the result
    /// carries `tag`.
    FollowPath {
        /// The path (shared: a recorded trajectory can hold many points).
        path: std::sync::Arc<PathRequest>,
        /// Who asked.
        tag: Option<MotionTag>,
    },
    /// Run a root MISSION's steps in order, replacing the mission and motion under way;
    /// progress goes out tagged `tag`.
    Mission {
        /// The steps.
        steps: std::sync::Arc<Vec<MissionStep>>,
        /// Who asked.
        tag: Option<MotionTag>,
    },
    /// The operator's PAUSE: a task under way is held where it is (other motion ends), and
    /// the stop latches.
    Pause,
    /// The operator's CONTINUE: the deliberate act that re-arms a PAUSE and goes on with the
    /// held task from where it stopped.
    Continue,
}

/// One input to the core.
#[derive(Debug, Clone, PartialEq)]
pub enum Input<'a> {
    /// The GNSS receiver's fix changed.
    Gnss(&'a GnssFix),
    /// A driver reports its link state.
    Link(Device, LinkState),
    /// The drives' feedback, every control period.
    Chassis(&'a ChassisFeedback),
    /// The BMS reading changed.
    Bms(&'a BmsReading),
    /// An IMU sample, in the vehicle frame.
    Imu(&'a ImuSample),
    /// The host computer's load.
    Host(HostUsage),
    /// Valid RTCM frames went to the receiver.
    Corrections {
        /// How many.
        frames: u64,
        /// Their bytes.
        bytes: u64,
    },
    /// A command.
    Command(Command),
    /// The control period elapsed: produce the wheel command.
    ControlTick,
    /// The status period elapsed.
    Tick,
}

/// One output of the core.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    /// A status snapshot, produced on every tick.
    Status(Box<VehicleStatus>),
    /// What the drives should do, every control tick.
    Wheels(WheelCommand),
    /// The answer to a command.
    CommandResult(Result<(), CommandRejected>),
    /// Something for the operator's log.
    Event(Event),
    /// A closed-loop motion ended.
    MotionEnded(MotionResult),
    /// Switch the cutter on (true) or off.
    Cutter(bool),
    /// The zones changed: all of them as GeoJSON, to be written back to the zones file.
    ZonesChanged(String),
    /// A mission's progress, for the requester.
    Mission {
        /// Who asked for the mission.
        tag: Option<MotionTag>,
        /// What happened.
        event: MissionEvent,
    },
}
