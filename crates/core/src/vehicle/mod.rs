//! The sans-IO vehicle core: owns the vehicle state and is driven only by
//! [`Vehicle::handle`], which takes the time as an argument and never reads a clock.

pub mod chassis;
pub mod corrections;
pub mod envelope;
pub mod feedback;
pub mod gate;
pub mod safety;
pub mod status;
pub mod zones;

use std::time::Duration;

use crate::config::VehicleConfig;
use crate::config::chassis::ChassisConfig;
use crate::config::localization::{LocalizationConfig, localizer_config};
use crate::config::mission::{MissionConfig, MissionSettings};
use crate::config::motion::{MinGnss, MotionSettings, Reach};
use crate::control::MotionId;
use crate::control::goal::GoalPose;
use crate::control::mission::{Mission, MissionEvent, MissionStep, Request};
use crate::control::outcome::{AbortReason, CancelReason, Replacement};
use crate::control::path::StartRefusal;
use crate::control::{Motion, MotionResult, MotionTag, MoveKind, Outcome, PoseView};
use crate::devices::bms::ChargeState;
use crate::devices::bms::{BmsReading, is_stale};
use crate::devices::gnss::{FixQuality, GnssFix};
use crate::devices::imu::ImuSample;
use crate::fusion::epoch_clock::EpochClock;
use crate::fusion::localizer::{
    Localizer, LocalizerConfig, LocateState, Measurement, yaw_of_heading_deg,
};
use crate::fusion::map_filter::Trust;
use crate::fusion::odometry::{OdomPose, Odometry, WheelReading};
use crate::geodesy::Geodetic;
use crate::time::Timestamp;
pub use chassis::DriveMode;
use chassis::{Chassis, ChassisFeedback, CommandRejected, WheelCommand};
use safety::{Cause, ControlLinkConfig, SafetyConfig};
pub use status::{
    BatteryStatus, FrameTree, GnssStatus, HostUsage, Localization, Navigation, Pose2D,
    PoseCovariance, PoseReport, VehicleStatus,
};

/// How far an epoch of `quality` is trusted: RTK fixed is believed over the wheels (and only
/// it may teach the dead reckoning); a lesser fix's step is its own error.
fn trust_of(quality: FixQuality) -> Trust {
    if quality == FixQuality::RtkFixed {
        Trust::OverWheels
    } else {
        Trust::UnderWheels
    }
}

/// A receiver's typical speed accuracy (1σ, m/s) at a fix quality, when the configuration
/// gives none: NMEA carries none. Speed comes from Doppler, which RTK does not sharpen;
/// differential and single fixes carry more multipath and fewer satellites.
fn typical_speed_sigma(quality: FixQuality) -> f64 {
    match quality {
        FixQuality::RtkFixed | FixQuality::RtkFloat => 0.04,
        FixQuality::Dgps | FixQuality::Pps => 0.06,
        _ => 0.1,
    }
}

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

/// What a motion's way is, from where the vehicle stands.
enum Way {
    /// Straight to each point in turn (map frame), at a speed (m/s).
    Through(Vec<(f64, f64)>, f64),
    /// A straight move along the heading, or a turn on the spot.
    Move(MoveKind),
}

/// The key of the goal reach, named in refusals.
const GOAL_KEY: &str = "motion.max_goal_distance_m";
/// The key of the path reach.
const PATH_KEY: &str = "motion.max_path_radius_m";

/// Refuses `points` when one lies farther than `limit` from the vehicle (when it is
/// located; a motion that needs the map refuses an unlocated vehicle by itself).
fn within_reach(
    view: &PoseView,
    points: &[(f64, f64)],
    limit: Option<f64>,
    key: &'static str,
) -> Result<(), CommandRejected> {
    let (Some(limit), Some((x, y))) = (limit, view.map_xy) else {
        return Ok(());
    };
    let farthest = points
        .iter()
        .map(|(px, py)| (px - x).hypot(py - y))
        .fold(0.0, f64::max);
    if farthest > limit {
        return Err(CommandRejected::BeyondLimit {
            what: "distance from the vehicle",
            value: farthest,
            limit,
            unit: "m",
            key,
        });
    }
    Ok(())
}

/// A pose set by hand: finite, and within `radius_m` of the datum.
fn plausible_pose(x: f64, y: f64, yaw: f64, radius_m: f64) -> Result<(), CommandRejected> {
    if ![x, y, yaw].iter().all(|v| v.is_finite()) {
        return Err(CommandRejected::NotFinite);
    }
    let distance = x.hypot(y);
    if distance > radius_m {
        return Err(CommandRejected::BeyondLimit {
            what: "distance from the datum",
            value: distance,
            limit: radius_m,
            unit: "m",
            key: "localization.max_position_radius_m",
        });
    }
    Ok(())
}

/// A place on the Earth: latitude ±90°, longitude ±180°, a height a ground vehicle can have.
fn plausible_place(p: &Geodetic) -> Result<(), CommandRejected> {
    let height = crate::geodesy::PLAUSIBLE_HEIGHT_M;
    for (what, value, min, max, unit) in [
        ("latitude", p.lat_deg, -90.0, 90.0, "degrees"),
        ("longitude", p.lon_deg, -180.0, 180.0, "degrees"),
        ("height", p.h_m, *height.start(), *height.end(), "m"),
    ] {
        if !value.is_finite() {
            return Err(CommandRejected::NotFinite);
        }
        if !(min..=max).contains(&value) {
            return Err(CommandRejected::OutOfRange {
                what,
                value,
                min,
                max,
                unit,
            });
        }
    }
    Ok(())
}

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
    Event(String),
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

/// The vehicle core.
#[derive(Debug, Clone)]
pub struct Vehicle {
    config: CoreConfig,
    gnss_fix: Option<GnssFix>,
    gnss_link_down: bool,
    /// The heading last published, held while no fresh source exists.
    held_heading_deg: f64,
    chassis: Option<Chassis>,
    bms: Option<BmsReading>,
    /// The last plausible IMU sample.
    imu: Option<ImuSample>,
    imu_link_down: bool,
    localizer: Localizer,
    /// The `odom` frame: wheels and gyro, with or without GNSS.
    odometry: Option<Odometry>,
    /// Receive times of the GNSS data already given to the localiser.
    fed_gnss: (Option<Timestamp>, Option<Timestamp>, Option<Timestamp>),
    /// The GNSS epochs' arrivals against their UTC stamps.
    epoch_clock: EpochClock,
    /// The host's load, when sampled.
    host: Option<HostUsage>,
    /// Closed-loop moves; `None` without drives.
    motion: Option<Motion>,
    /// The root MISSION under way.
    mission: Option<Mission>,
    /// Whether a mission switched the cutter on (and nothing has switched it off since).
    cutter_on: bool,
    /// Whether the blade was last told to run: only while the cutter is on and nothing is
    /// latched, so a stop or a pause stops the blade and only a deliberate act restarts it.
    blade_running: bool,
    /// RTK corrections, when a correction source is configured.
    corrections: Option<corrections::Corrections>,
    /// The zones and the GNSS gate, when zones are configured.
    envelope: Option<envelope::Envelope>,
}

impl Vehicle {
    /// A core with nothing known yet.
    pub fn new(config: CoreConfig) -> Self {
        Self {
            chassis: config.chassis.map(|c| {
                Chassis::new(
                    c,
                    SafetyConfig {
                        cmd_timeout: c.cmd_timeout(),
                        quick_stop: c.quick_stop(),
                        reset_timeout: c.reset_timeout(),
                        control_link: config.control_link,
                        enable_on_start: c.enable_on_start,
                    },
                )
            }),
            config,
            gnss_fix: None,
            gnss_link_down: false,
            held_heading_deg: 0.0,
            bms: None,
            imu: None,
            imu_link_down: false,
            localizer: Localizer::new(config.localizer),
            odometry: config
                .chassis
                .map(|c| Odometry::new(c.track_m, config.localizer.gyro_bias_walk)),
            fed_gnss: (None, None, None),
            epoch_clock: EpochClock::default(),
            host: None,
            motion: config.motion.map(Motion::new),
            mission: None,
            cutter_on: false,
            blade_running: false,
            corrections: config
                .corrections_stale_after
                .map(corrections::Corrections::new),
            envelope: None,
        }
    }

    /// The core, keeping to the zones and the GNSS gate of `envelope`: every motion's way is
    /// checked before it starts, the braking way every control tick.
    pub fn with_envelope(mut self, envelope: envelope::Envelope) -> Self {
        self.envelope = Some(envelope);
        self
    }

    /// The `odom` frame's pose (wheels and gyro), once the drives have reported.
    pub fn odom_pose(&self) -> Option<OdomPose> {
        self.odometry.as_ref().and_then(Odometry::pose)
    }

    /// The drives' speed response time learnt so far, s; `None` without drives.
    pub fn response_time(&self) -> Option<f64> {
        self.chassis.as_ref().map(Chassis::response_time)
    }

    /// Handles one input at time `t` and returns what it produced.
    pub fn handle(&mut self, t: Timestamp, input: Input<'_>) -> Vec<Output> {
        match input {
            Input::Gnss(fix) => {
                self.gnss_fix = Some(*fix);
                self.feed_gnss(fix);
                // A drift of the odom heading proven against GNSS corrects the gyro's bias.
                if let Some(drift) = self.localizer.take_bias_correction()
                    && let Some(odometry) = self.odometry.as_mut()
                {
                    odometry.correct_bias(t, drift.rate, drift.sigma);
                }
                self.localizer
                    .take_events()
                    .into_iter()
                    .map(Output::Event)
                    .collect()
            }
            Input::Link(Device::Gnss, state) => {
                self.gnss_link_down = state == LinkState::Down;
                Vec::new()
            }
            Input::Link(Device::Imu, state) => {
                self.imu_link_down = state == LinkState::Down;
                Vec::new()
            }
            Input::Link(Device::Corrections, state) => {
                if let Some(c) = &mut self.corrections {
                    c.link(t, state == LinkState::Up);
                }
                Vec::new()
            }
            Input::Corrections { frames, bytes } => self
                .corrections
                .as_mut()
                .and_then(|c| c.frames(t, frames, bytes))
                .map(Output::Event)
                .into_iter()
                .collect(),
            Input::Imu(sample) => {
                if sample.is_plausible() {
                    self.imu = Some(*sample);
                    if let Some(o) = &mut self.odometry {
                        o.gyro(sample.rx, sample.gyro.z);
                    }
                }
                Vec::new()
            }
            Input::Chassis(feedback) => {
                if let (Some(c), Some(cfg)) = (&mut self.chassis, self.config.chassis) {
                    c.feedback(feedback.clone());
                    if let (Some(l), Some(r)) =
                        (feedback.left.velocity_rad_s, feedback.right.velocity_rad_s)
                    {
                        let radius = cfg.wheel_radius_m;
                        let (vl, vr) = (l * radius.left, r * radius.right);
                        // A reading counts once, at the time it arrived: the drives report
                        // less often than the control loop polls them.
                        let measured = feedback
                            .left
                            .received
                            .max(feedback.right.received)
                            .map_or(t, |r| r.min(t));
                        if let Some(o) = self
                            .odometry
                            .as_mut()
                            .filter(|o| o.updated_at().is_none_or(|u| measured > u))
                        {
                            let travel = feedback
                                .left
                                .angle_rad
                                .zip(feedback.right.angle_rad)
                                .map(|(a, b)| (a * radius.left, b * radius.right));
                            o.wheels(
                                measured,
                                WheelReading {
                                    speeds: (vl, vr),
                                    travel,
                                },
                            );
                            // The map pose stands on the odom frame: it moves by its
                            // increments (REP-105).
                            if let Some(pose) = o.pose() {
                                self.localizer
                                    .set_gyro_bias_sigma(o.gyro_bias_sigma(measured));
                                self.localizer.add(measured, Measurement::Odom(pose));
                            }
                        }
                    }
                }
                Vec::new()
            }
            Input::Bms(reading) => {
                self.bms = Some(*reading);
                Vec::new()
            }
            Input::Command(Command::Velocity { vx, wz }) => {
                // Taken (manual mode), the operator's velocity takes over from a move;
                // refused (navigation mode, a bad value), the move goes on.
                let result = self.with_chassis(|c| c.command(t, vx, wz));
                if result.is_ok() {
                    self.end_motion(t, Outcome::Cancelled(CancelReason::VelocityCommand));
                    self.cancel_mission(CancelReason::VelocityCommand);
                }
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::Move(kind)) => {
                let result = self.start_move(t, kind);
                if result.is_ok() {
                    self.cancel_mission(CancelReason::Replaced(Replacement::Move));
                }
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::Goal { goal, tag }) => {
                let result = self.start_goal(t, goal, tag).map(|_| ());
                if result.is_ok() {
                    self.cancel_mission(CancelReason::Replaced(Replacement::Goal));
                }
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::FollowPath { path, tag }) => {
                let result = self.start_path(t, &path, tag).map(|_| ());
                if result.is_ok() {
                    self.cancel_mission(CancelReason::Replaced(Replacement::Task));
                }
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::Mission { steps, tag }) => {
                let result = self.start_mission(t, &steps, tag);
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::Pause) => {
                if let Some(m) = &mut self.mission {
                    m.pause();
                }
                let mission = self.mission.is_some();
                let held = self.motion.as_mut().is_some_and(|m| m.pause(t));
                if mission && !held {
                    // A step's goal cannot hold: it ends, and CONTINUE starts the step again.
                    if let Some(m) = &mut self.mission {
                        m.restart_step();
                    }
                }
                if !held {
                    self.end_motion(t, Outcome::Cancelled(CancelReason::PausedByOperator));
                }
                let result = self.with_chassis(|c| {
                    c.operator_stop(t);
                    Ok(())
                });
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::Continue) => {
                let result = self.continue_task(t);
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::CancelMotion) => {
                self.cancel_mission(CancelReason::StopRequested);
                self.end_motion(t, Outcome::Cancelled(CancelReason::StopRequested));
                let result = self.with_chassis(|c| {
                    c.hold_zero(t);
                    Ok(())
                });
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::Stop) => {
                self.cancel_mission(CancelReason::StoppedByOperator);
                self.end_motion(t, Outcome::Cancelled(CancelReason::StoppedByOperator));
                let result = self.with_chassis(|c| {
                    c.operator_stop(t);
                    Ok(())
                });
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::EditZones(edit)) => self.edit_zones(&edit),
            Input::Command(Command::Reset) => {
                let result = self.with_chassis(|c| c.reset(t));
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::EmergencyStop { engaged }) => {
                let result = self.with_chassis(|c| {
                    c.software_estop(t, engaged);
                    Ok(())
                });
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::ControlHeartbeat) => {
                if let Some(c) = &mut self.chassis {
                    c.control_heartbeat(t);
                }
                vec![Output::CommandResult(Ok(()))]
            }
            Input::Command(Command::SetMode(mode)) => {
                if self.chassis.as_ref().is_some_and(|c| c.mode() != mode) {
                    self.cancel_mission(CancelReason::ModeSwitched);
                    self.end_motion(t, Outcome::Cancelled(CancelReason::ModeSwitched));
                }
                let result = self.with_chassis(|c| {
                    c.set_mode(mode);
                    Ok(())
                });
                vec![Output::CommandResult(result)]
            }
            Input::Command(
                Command::ZeroLocalFrame | Command::SetPose { .. } | Command::SetDatum(_),
            ) if self.motion.as_ref().is_some_and(Motion::uses_map_frame) => {
                // The motion's goal or heading is in the map: moving it would move the goal.
                vec![Output::CommandResult(Err(CommandRejected::MoveUnderWay))]
            }
            Input::Command(Command::ZeroLocalFrame) => {
                let result = if self.localizer.zero_here(t) {
                    Ok(())
                } else {
                    Err(CommandRejected::NoPosition)
                };
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::SetPose { x, y, yaw }) => {
                let result = plausible_pose(x, y, yaw, self.config.max_position_radius_m);
                if result.is_ok() {
                    self.localizer.set_pose(t, x, y, yaw);
                }
                vec![Output::CommandResult(result)]
            }
            Input::Command(Command::SetDatum(datum)) => {
                let result = plausible_place(&datum);
                if result.is_ok() {
                    self.localizer.set_datum(datum);
                }
                vec![Output::CommandResult(result)]
            }
            Input::ControlTick => self.control_tick(t),
            Input::Host(usage) => {
                self.host = Some(usage);
                Vec::new()
            }
            Input::Tick => {
                let mut outputs = Vec::with_capacity(1);
                let corrections = self.corrections.as_mut().map(|c| c.tick(t));
                let event = corrections.as_ref().and_then(|(_, e)| e.clone());
                let mut status = self.status(t);
                status.corrections = corrections.map(|(s, _)| s);
                outputs.push(Output::Status(Box::new(status)));
                outputs.extend(event.map(Output::Event));
                outputs
            }
        }
    }

    /// One control step: a latched stop ends the move under way, the move proposes a
    /// velocity, and the drive train decides what reaches the wheels. A stop that latches
    /// during this tick ends the move at the next.
    fn control_tick(&mut self, t: Timestamp) -> Vec<Output> {
        if self.chassis.is_none() {
            return Vec::new();
        }
        let mut out = Vec::new();
        self.gate_tick(t, &mut out);
        // Only a move needs the pose (two filter predictions).
        let moving = self.motion.as_ref().is_some_and(Motion::is_active);
        let view = if moving { self.pose_view(t) } else { None };
        let Some(chassis) = &mut self.chassis else {
            return out;
        };
        let mut results = Vec::new();
        if let Some(motion) = &mut self.motion {
            // A task the operator paused waits under the operator's stop; any other stop
            // ends the motion.
            let held = motion.is_paused() || self.mission.as_ref().is_some_and(Mission::is_paused);
            match chassis.safety().latched() {
                Some(Cause::Operator) if held => {}
                Some(cause) => {
                    motion.end(
                        t,
                        Outcome::Aborted(AbortReason::SafetyStop(cause.to_string())),
                        None,
                    );
                    if let Some(m) = &mut self.mission {
                        m.end(Outcome::Aborted(AbortReason::SafetyStop(cause.to_string())));
                    }
                }
                None => {}
            }
            if motion.is_active() {
                match motion.step(t, view.as_ref(), chassis.response_time()) {
                    Some((v, w)) => {
                        if let Err(e) = chassis.autonomous(t, v, w) {
                            motion.end(
                                t,
                                Outcome::Aborted(AbortReason::DrivesRefused(e.to_string())),
                                None,
                            );
                        }
                    }
                    // Just ended: hold zero rather than let the last speed run to the timeout.
                    None => chassis.hold_zero(t),
                }
            }
            out.extend(motion.take_events().into_iter().map(Output::Event));
            results = motion.take_results();
        }
        if let Some(envelope) = &mut self.envelope {
            envelope::zone_tick(envelope, &self.localizer, chassis, t, &mut out);
        }
        out.insert(0, Output::Wheels(chassis.tick(t)));
        self.mission_tick(t, &results, &mut out);
        self.cutter_tick(&mut out);
        for result in results {
            out.push(Output::Event(result.to_string()));
            out.push(Output::MotionEnded(result));
        }
        out
    }

    /// What a move sees: the `odom` pose, and the map pose while located.
    fn pose_view(&self, t: Timestamp) -> Option<PoseView> {
        let odometry = self.odometry.as_ref()?;
        let (odom, odom_at) = (odometry.pose()?, odometry.updated_at()?);
        let yaw_rate_at = odometry.yaw_rate_at().unwrap_or(odom_at);
        let located = self
            .localizer
            .published(t)
            .filter(|p| p.locate == LocateState::Good);
        let map = located.map(|p| p.map_pose);
        let wheel_scale = located.map(|p| p.wheel_scale);
        Some(PoseView {
            odom,
            odom_at,
            yaw_rate_at,
            map_xy: map.map(|(x, y, _)| (x, y)),
            map_yaw: map.map(|(_, _, yaw)| yaw),
            wheel_scale,
            gnss: MinGnss::of(self.fresh_fix_quality(t)),
        })
    }

    /// Starts a move, once the drives can take it and the odometry runs.
    fn start_move(&mut self, t: Timestamp, kind: MoveKind) -> Result<(), CommandRejected> {
        let finite = match kind {
            MoveKind::Straight { distance_m } => distance_m.is_finite(),
            MoveKind::Turn { angle_rad } => angle_rad.is_finite(),
        };
        if finite {
            self.check_way(t, Way::Move(kind))?;
        }
        self.start_motion(t, finite, |motion, view| Ok(motion.start(t, kind, view)))
            .map(|_| ())
    }

    /// Starts a goal, once the drives can take it and the vehicle is located.
    fn start_goal(
        &mut self,
        t: Timestamp,
        goal: GoalPose,
        tag: Option<MotionTag>,
    ) -> Result<MotionId, CommandRejected> {
        let finite = goal.x.is_finite() && goal.y.is_finite() && goal.yaw.is_finite();
        if finite {
            self.check_way(t, Way::Through(vec![(goal.x, goal.y)], self.cruise_mps()))?;
        }
        let reach = self.reach();
        self.start_motion(t, finite, |motion, view| {
            within_reach(view, &[(goal.x, goal.y)], reach.map(|r| r.goal_m), GOAL_KEY)?;
            motion
                .start_goal(t, goal, view, tag)
                .ok_or(CommandRejected::NotLocated)
        })
    }

    /// Starts a path task, once the drives can take it, the vehicle is located and the fix
    /// is good enough. Geodetic points are placed with the datum in force now.
    fn start_path(
        &mut self,
        t: Timestamp,
        path: &PathRequest,
        tag: Option<MotionTag>,
    ) -> Result<MotionId, CommandRejected> {
        let points: Vec<(f64, f64)> = match &path.points {
            PathPoints::Map(points) => points.clone(),
            PathPoints::Geodetic(points) => {
                let Some(frame) = self.localizer.frame() else {
                    return Err(CommandRejected::NotLocated);
                };
                points
                    .iter()
                    .map(|&(lat_deg, lon_deg)| {
                        let enu = frame.to_enu(&Geodetic {
                            lat_deg,
                            lon_deg,
                            h_m: frame.datum().h_m,
                        });
                        (enu.x, enu.y)
                    })
                    .collect()
            }
        };
        let finite = path.speed.is_finite()
            && path.speed > 0.0
            && !points.is_empty()
            && points.iter().all(|(x, y)| x.is_finite() && y.is_finite());
        let speed = path.speed;
        if finite {
            self.check_way(t, Way::Through(points.clone(), speed))?;
        }
        let reach = self.reach();
        self.start_motion(t, finite, |motion, view| {
            within_reach(view, &points, reach.map(|r| r.path_m), PATH_KEY)?;
            motion
                .start_path(t, &points, speed, view, tag)
                .map_err(|refusal| match refusal {
                    StartRefusal::NotLocated => CommandRejected::NotLocated,
                    other => CommandRejected::Task(other.to_string()),
                })
        })
    }

    /// CONTINUE: re-arms the operator's stop and goes on with the paused task.
    fn continue_task(&mut self, t: Timestamp) -> Result<(), CommandRejected> {
        let task = self.motion.as_ref().is_some_and(Motion::is_paused);
        let mission = self.mission.as_ref().is_some_and(Mission::is_paused);
        if !task && !mission {
            return Err(CommandRejected::NothingPaused);
        }
        self.gate_may_start()?;
        self.with_chassis(|c| c.reset(t))?;
        if task {
            let view = self.pose_view(t).ok_or(CommandRejected::NoOdometry)?;
            if let Some(m) = &mut self.motion {
                m.resume(t, &view);
            }
        }
        if let Some(m) = &mut self.mission {
            m.resume();
        }
        Ok(())
    }

    /// Starts a mission, replacing the one (and the motion) under way.
    fn start_mission(
        &mut self,
        t: Timestamp,
        steps: &[MissionStep],
        tag: Option<MotionTag>,
    ) -> Result<(), CommandRejected> {
        let (Some(chassis), Some(_)) = (&self.chassis, &self.motion) else {
            return Err(CommandRejected::NoDrives);
        };
        chassis.ready_to_move()?;
        if steps.is_empty() {
            return Err(CommandRejected::Task(
                "a mission needs at least one step".into(),
            ));
        }
        // Where the vehicle is now: MOVE_TO_POSITION points within the goal reach, COVERAGE
        // within the path reach (each step checks again when it starts).
        let view = self.pose_view(t);
        let reach = self.reach();
        for step in steps {
            let (points, limit, key) = match step {
                MissionStep::MoveTo(p) => (p, reach.map(|r| r.goal_m), GOAL_KEY),
                MissionStep::Coverage(p) => (p, reach.map(|r| r.path_m), PATH_KEY),
                _ => continue,
            };
            if points.iter().any(|(x, y)| !x.is_finite() || !y.is_finite()) {
                return Err(CommandRejected::NotFinite);
            }
            if let Some(view) = &view {
                within_reach(view, points, limit, key)?;
            }
        }
        // The paths one after the other, from where the vehicle stands (the dock is left
        // out: it often lies on a boundary).
        let way: Vec<(f64, f64)> = steps
            .iter()
            .flat_map(|step| match step {
                MissionStep::MoveTo(p) | MissionStep::Coverage(p) => p.as_slice(),
                _ => &[],
            })
            .copied()
            .collect();
        if !way.is_empty() {
            self.check_way(t, Way::Through(way, self.config.mission.speed_mps))?;
        }
        for (i, step) in steps.iter().enumerate() {
            let problem = match step {
                MissionStep::Cutter(_) if !self.config.has_cutter => {
                    Some("needs a [cutter] in the configuration")
                }
                MissionStep::Charge(_) if self.config.mission.dock.is_none() => {
                    Some("needs a dock pose (mission.dock)")
                }
                MissionStep::Charge(_) if self.config.bms_stale_after.is_none() => {
                    Some("needs a BMS to report charging ([bms])")
                }
                _ => None,
            };
            if let Some(problem) = problem {
                return Err(CommandRejected::Task(format!(
                    "step {i} ({}) {problem}",
                    step.action()
                )));
            }
        }
        self.cancel_mission(CancelReason::NewMission);
        self.end_motion(
            t,
            Outcome::Cancelled(CancelReason::Replaced(Replacement::Mission)),
        );
        self.mission = Some(Mission::new(steps.to_vec(), self.config.mission, tag));
        if let Some(m) = &mut self.motion {
            m.set_navigation(Navigation::Running);
        }
        Ok(())
    }

    /// Cancels the mission under way, if any: `why`.
    fn cancel_mission(&mut self, why: CancelReason) {
        if let Some(m) = &mut self.mission {
            m.end(Outcome::Cancelled(why));
        }
    }

    /// Runs the blade while the cutter is on and the supervisor is armed. A stop other than the
    /// operator's pause of a task switches the cutter off for good; the pause only holds it.
    fn cutter_tick(&mut self, out: &mut Vec<Output>) {
        let Some(safety) = self.chassis.as_ref().map(|c| c.safety()) else {
            return;
        };
        let latched = safety.latched().cloned();
        // Armed: the drives are enabled (not in standby before the first arm, nor latched).
        let armed = matches!(safety.state(), safety::State::Armed);
        let paused = self.motion.as_ref().is_some_and(Motion::is_paused)
            || self.mission.as_ref().is_some_and(Mission::is_paused);
        match latched {
            Some(Cause::Operator) if paused => {}
            Some(_) => self.cutter_on = false,
            None => {}
        }
        let run = self.cutter_on && armed && self.gate_lets_blade_run();
        if run != self.blade_running {
            self.blade_running = run;
            out.push(Output::Cutter(run));
        }
    }

    /// The mission's part of a control tick: the ends of its motions, its timers, what it
    /// asks for next, and its progress out.
    fn mission_tick(&mut self, t: Timestamp, results: &[MotionResult], out: &mut Vec<Output>) {
        let Some(mission) = &mut self.mission else {
            return;
        };
        for r in results {
            mission.motion_ended(r.id, &r.outcome);
        }
        let charging = self.bms.is_some_and(|b| {
            b.charge_state == Some(ChargeState::Charging)
                && self
                    .config
                    .bms_stale_after
                    .is_some_and(|stale| !is_stale(&b, t, stale))
        });
        // Instant steps (the cutter) run in the same tick as the next one starts.
        while let Some(request) = self.mission.as_mut().and_then(|m| m.tick(t, charging)) {
            let started = match request {
                Request::Path(points, speed) => {
                    let path = PathRequest {
                        points: PathPoints::Map(points),
                        speed,
                    };
                    self.start_path(t, &path, None)
                }
                Request::Goal(goal) => self.start_goal(t, goal, None),
                Request::Cutter(on) => {
                    self.cutter_on = on;
                    self.cutter_tick(out);
                    continue;
                }
            };
            if let Some(m) = &mut self.mission {
                match started {
                    Ok(id) => m.started(id),
                    Err(e) => m.end(Outcome::Aborted(AbortReason::StepNotStarted(e.to_string()))),
                }
            }
        }
        let Some(mission) = &mut self.mission else {
            return;
        };
        let tag = mission.tag();
        for event in mission.take_events() {
            out.push(Output::Event(event.to_string()));
            out.push(Output::Mission { tag, event });
        }
        let ended = mission.ended().cloned();
        let Some(motion) = &mut self.motion else {
            return;
        };
        match ended {
            None => motion.set_navigation(Navigation::Running),
            Some(outcome) => {
                if outcome != Outcome::Succeeded {
                    motion.end(t, Outcome::Cancelled(CancelReason::MissionEnded), None);
                    // The blade stops with a mission that did not finish.
                    self.cutter_on = false;
                }
                motion.set_navigation(outcome.navigation());
                self.mission = None;
            }
        }
    }

    /// The quality of the GNSS fix at `t`: `Invalid` once stale or with the link down.
    fn fresh_fix_quality(&self, t: Timestamp) -> FixQuality {
        let Some(fix) = &self.gnss_fix else {
            return FixQuality::Invalid;
        };
        let fresh = fix
            .position
            .is_some_and(|p| t.saturating_since(p.rx) <= self.config.gnss_fix_timeout);
        if !self.gnss_link_down && fix.quality.is_valid() && fresh {
            fix.quality
        } else {
            FixQuality::Invalid
        }
    }

    /// Starts a motion with `start` once its values are `finite`, the drives can take it
    /// and the odometry runs.
    fn start_motion(
        &mut self,
        t: Timestamp,
        finite: bool,
        start: impl FnOnce(&mut Motion, &PoseView) -> Result<MotionId, CommandRejected>,
    ) -> Result<MotionId, CommandRejected> {
        if !finite {
            return Err(CommandRejected::NotFinite);
        }
        let view = self.pose_view(t);
        let (Some(chassis), Some(motion)) = (&mut self.chassis, &mut self.motion) else {
            return Err(CommandRejected::NoDrives);
        };
        chassis.ready_to_move()?;
        let Some(view) = view else {
            return Err(CommandRejected::NoOdometry);
        };
        start(motion, &view)
    }

    /// Refuses a motion whose way meets a zone, or any while the GNSS gate is closed (when
    /// zones are configured): the way from where the vehicle stands in the map frame.
    fn check_way(&mut self, t: Timestamp, way: Way) -> Result<(), CommandRejected> {
        if self.envelope.is_none() {
            return Ok(());
        }
        let here = self
            .pose_view(t)
            .and_then(|v| Some((v.map_xy?, v.map_yaw?)));
        let placement = self.localizer.map_placement();
        let speed = match &way {
            Way::Through(_, speed) => *speed,
            Way::Move(MoveKind::Straight { .. }) => self.cruise_mps(),
            Way::Move(MoveKind::Turn { .. }) => 0.0,
        };
        // What the run-time check will take at that speed: σ and the braking way.
        let run_time = match (&self.chassis, envelope::map_sigma(&self.localizer, t)) {
            (Some(chassis), Some(sigma)) => sigma + envelope::braking(chassis).distance(speed),
            _ => 0.0,
        };
        let Some(envelope) = &mut self.envelope else {
            return Ok(());
        };
        let Some(((x, y), yaw)) = here else {
            return Err(CommandRejected::ZonesUnplaced);
        };
        let points = match way {
            Way::Through(points, _) => std::iter::once((x, y)).chain(points).collect(),
            Way::Move(MoveKind::Straight { distance_m }) => vec![
                (x, y),
                (x + distance_m * yaw.cos(), y + distance_m * yaw.sin()),
            ],
            // On the spot: the footprint's disc where it stands.
            Way::Move(MoveKind::Turn { .. }) => vec![(x, y)],
        };
        // The way first: it is the request's own fault, the gate only the moment's.
        envelope.guard().check_way(placement, &points, run_time)?;
        envelope.may_start()
    }

    /// Adds or removes a zone; the zones written back when they changed.
    fn edit_zones(&mut self, edit: &zones::ZoneEdit) -> Vec<Output> {
        let placement = self.localizer.map_placement();
        let result = match &mut self.envelope {
            None => Err(CommandRejected::ZoneEdit(
                "no zones are configured ([zones] in the configuration, or --zones FILE)".into(),
            )),
            Some(envelope) => envelope.guard().edit(placement, edit),
        };
        let mut out = Vec::new();
        if let (Ok(id), Some(envelope)) = (&result, &mut self.envelope) {
            let what = match edit {
                zones::ZoneEdit::Add { name, kind, .. } => {
                    format!("{} zone {name:?} added", kind.name())
                }
                zones::ZoneEdit::Remove(_) => "zone removed".to_owned(),
            };
            out.push(Output::Event(format!("zones: {what} (id {id})")));
            out.push(Output::ZonesChanged(envelope.guard().set().to_geojson()));
        }
        out.push(Output::CommandResult(result.map(|_| ())));
        out
    }

    /// The speed goals and straight moves cruise at, m/s (0 without drives).
    fn cruise_mps(&self) -> f64 {
        self.config.motion.map_or(0.0, |m| m.linear.speed)
    }

    /// How far a motion may lead, when the vehicle has drives.
    fn reach(&self) -> Option<Reach> {
        self.config.motion.map(|m| m.reach)
    }

    /// Ends the motion under way, if any.
    fn end_motion(&mut self, t: Timestamp, outcome: Outcome) {
        if let Some(m) = &mut self.motion {
            m.end(t, outcome, None);
        }
    }

    /// Runs `f` on the drive train; refused without one.
    fn with_chassis(
        &mut self,
        f: impl FnOnce(&mut Chassis) -> Result<(), CommandRejected>,
    ) -> Result<(), CommandRejected> {
        match &mut self.chassis {
            Some(c) => f(c),
            None => Err(CommandRejected::NoDrives),
        }
    }

    fn status(&mut self, t: Timestamp) -> VehicleStatus {
        let battery = self.config.bms_stale_after.map(|stale_after| {
            let reading = self.bms.unwrap_or_default();
            BatteryStatus {
                stale: is_stale(&reading, t, stale_after),
                reading,
            }
        });
        let imu_ok = self.config.imu_timeout.is_some_and(|timeout| {
            !self.imu_link_down
                && self
                    .imu
                    .is_some_and(|s| t.saturating_since(s.rx) <= timeout)
        });
        let PoseReport {
            odom,
            map,
            frames,
            localization,
        } = self.pose_report(t);
        // The map pose once GNSS (or INIT_POSITION) has placed the vehicle; before that the
        // odom frame's, which LOCATE_UNINIT marks.
        let pose = match (map, odom) {
            (Some((pose, _)), _) => pose,
            (None, Some(o)) => Pose2D {
                x: o.x,
                y: o.y,
                yaw: o.yaw,
            },
            (None, None) => Pose2D::default(),
        };
        VehicleStatus {
            time: t,
            imu_ok,
            chassis: self.chassis.as_ref().map(|c| c.status(t)),
            battery,
            gnss: self.gnss_status(t),
            pose,
            pose_covariance: map.map(|(_, covariance)| covariance),
            odom,
            frames,
            localization,
            navigation: self
                .motion
                .as_ref()
                .map_or(Navigation::Idle, Motion::navigation),
            plan: self.motion.as_ref().and_then(Motion::plan).cloned(),
            obstacle_stop: false,
            host: self.host,
            mode: self.chassis.as_ref().map(Chassis::mode),
            corrections: None,
            envelope: self
                .envelope
                .as_mut()
                .map(|e| e.status(&self.localizer, self.chassis.as_ref(), t)),
        }
    }

    /// The receiver's latest fix, as the core holds it.
    pub fn gnss_fix(&self) -> Option<&GnssFix> {
        self.gnss_fix.as_ref()
    }

    /// The age of the last valid correction frame at `t`, when a source is configured and
    /// one has arrived.
    pub fn correction_age(&self, t: Timestamp) -> Option<Duration> {
        self.corrections.as_ref().and_then(|c| c.age(t))
    }

    /// The `odom` pose and the map pose at `t`, without the rest of a status.
    pub fn pose_report(&self, t: Timestamp) -> PoseReport {
        let published = self.localizer.published(t);
        let odom = self.odometry.as_ref().and_then(Odometry::pose);
        PoseReport {
            odom,
            frames: published.and_then(|p| {
                let (x, y, yaw) = p.map_to_odom;
                let (ox, oy, oyaw) = p.odom_pose?;
                Some(FrameTree {
                    map_to_odom: Pose2D { x, y, yaw },
                    odom_to_base: Pose2D {
                        x: ox,
                        y: oy,
                        yaw: oyaw,
                    },
                })
            }),
            map: published.map(|p| {
                let (x, y, yaw) = p.map_pose;
                let [xx, xy, yy, yaw_var] = p.map_covariance;
                (
                    Pose2D { x, y, yaw },
                    PoseCovariance {
                        xx,
                        xy,
                        yy,
                        yaw: yaw_var,
                    },
                )
            }),
            localization: match published.map_or(LocateState::Uninitialized, |p| p.locate) {
                LocateState::Uninitialized => Localization::Uninitialized,
                LocateState::Good => Localization::Good,
                LocateState::Lost => Localization::Lost,
            },
        }
    }

    /// Gives the localiser what is new in the fix: heading, course, position.
    fn feed_gnss(&mut self, fix: &GnssFix) {
        let latency = self.localizer.config().gnss_latency;
        if let Some(p) = fix.position
            && self.fed_gnss.2 != Some(p.rx)
        {
            self.epoch_clock.observe(p.rx, fix.utc);
        }
        // The epoch's time: its arrival without the link's jitter, less the latency.
        let clock = self.epoch_clock;
        let at = |rx: Timestamp| {
            let rx = clock.steady(rx, fix.utc);
            Timestamp::from_nanos(rx.as_nanos().saturating_sub(latency.as_nanos() as u64))
        };
        if let Some(h) = fix.heading_deg
            && self.fed_gnss.0 != Some(h.rx)
        {
            self.fed_gnss.0 = Some(h.rx);
            // The configured σ is the least the heading is trusted to; a receiver that
            // states a larger one (a float baseline) is taken at its word.
            let sigma = fix
                .heading_sigma_deg
                .map(f64::to_radians)
                .unwrap_or(0.0)
                .max(self.localizer.config().heading_sigma_rad);
            self.localizer.add(
                at(h.rx),
                Measurement::Heading {
                    yaw: yaw_of_heading_deg(h.value - self.config.heading_offset_deg),
                    sigma,
                    trust: trust_of(fix.quality),
                },
            );
        }
        if let Some(v) = fix.velocity
            && self.fed_gnss.1 != Some(v.rx)
        {
            self.fed_gnss.1 = Some(v.rx);
            let speed = v.value.speed_mps;
            // The course's 1σ follows from the receiver's speed accuracy at this fix
            // quality, or its scatter when larger; the localiser models the antenna's motion
            // (turning, reversing) and drops a course too uncertain to help.
            let speed_sigma = self
                .localizer
                .config()
                .gnss_velocity_sigma_mps
                .unwrap_or_else(|| typical_speed_sigma(fix.quality));
            if let Some(course) = v.value.course_deg
                && speed >= self.localizer.config().cog_min_speed_mps
            {
                self.localizer.add(
                    at(v.rx),
                    Measurement::Course {
                        yaw: yaw_of_heading_deg(course),
                        speed,
                        speed_sigma,
                        trust: trust_of(fix.quality),
                    },
                );
            }
        }
        let Some(p) = fix.position.filter(|_| fix.quality.is_valid()) else {
            return;
        };
        if self.fed_gnss.2 == Some(p.rx) {
            return;
        }
        self.fed_gnss.2 = Some(p.rx);
        let here = Geodetic {
            lat_deg: p.value.latitude_deg,
            lon_deg: p.value.longitude_deg,
            h_m: p.value.height_above_ellipsoid_m(),
        };
        // Without a configured datum the first valid fix of any quality is the origin.
        if self.localizer.offer_datum(here) {
            self.localizer.add_event(format!(
                "datum: the first fix ({}) at {:.8}, {:.8}, {:.2} m is the local frame's origin \
                 (no localization.datum configured)",
                fix.quality, here.lat_deg, here.lon_deg, here.h_m
            ));
        }
        let Some(frame) = self.localizer.frame() else {
            return;
        };
        let enu = frame.to_enu(&here);
        let by_quality = match fix.quality {
            FixQuality::RtkFixed => 0.02,
            FixQuality::RtkFloat => 0.3,
            FixQuality::Dgps => 0.8,
            _ => 2.5,
        };
        // The receiver's own error estimate for this epoch, when it sends GST.
        let sigma = fix
            .accuracy
            .filter(|a| {
                a.rx.saturating_since(p.rx) < Duration::from_secs(1)
                    && p.rx.saturating_since(a.rx) < Duration::from_secs(1)
            })
            .and_then(|a| a.value.latitude_sd_m.zip(a.value.longitude_sd_m))
            .map_or((by_quality, by_quality), |(lat, lon)| {
                (lon.max(0.005), lat.max(0.005))
            });
        self.localizer.add(
            at(p.rx),
            Measurement::Position {
                en: (enu.x, enu.y),
                sigma,
                trust: trust_of(fix.quality),
                corrected: fix.quality.is_corrected(),
            },
        );
    }

    fn gnss_status(&mut self, t: Timestamp) -> GnssStatus {
        let Some(fix) = &self.gnss_fix else {
            return GnssStatus::default();
        };
        let timeout = self.config.gnss_fix_timeout;
        let fresh = |rx: Timestamp| t.saturating_since(rx) <= timeout;
        let quality = self.fresh_fix_quality(t);
        let ok = quality.is_valid();

        let dual_antenna = fix
            .heading_deg
            .filter(|h| !self.gnss_link_down && fresh(h.rx))
            .map(|h| (h.value - self.config.heading_offset_deg).rem_euclid(360.0));
        let course = fix
            .velocity
            .filter(|v| !self.gnss_link_down && fresh(v.rx))
            .filter(|v| v.value.speed_mps >= self.config.cog_min_speed_mps)
            .and_then(|v| v.value.course_deg);
        if let Some(heading) = dual_antenna.or(course) {
            self.held_heading_deg = heading;
        }

        let (latitude_deg, longitude_deg) = fix
            .position
            .map(|p| (p.value.latitude_deg, p.value.longitude_deg))
            .unwrap_or((0.0, 0.0));
        GnssStatus {
            ok,
            quality,
            latitude_deg,
            longitude_deg,
            heading_deg: self.held_heading_deg,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::gnss::decode::GroundVelocity;
    use crate::devices::gnss::{GeoPosition, Timed};

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_micros(ms * 1_000)
    }

    fn fixed_at(ms: u64) -> GnssFix {
        GnssFix {
            quality: FixQuality::RtkFixed,
            position: Some(Timed {
                value: GeoPosition {
                    latitude_deg: 23.1,
                    longitude_deg: 113.0,
                    altitude_msl_m: None,
                    geoid_separation_m: None,
                    ellipsoid_height_m: None,
                },
                rx: at(ms),
            }),
            ..GnssFix::default()
        }
    }

    fn tick(v: &mut Vehicle, ms: u64) -> VehicleStatus {
        match v.handle(at(ms), Input::Tick).pop() {
            Some(Output::Status(s)) => *s,
            other => panic!("a tick must produce a status, not {other:?}"),
        }
    }

    #[test]
    fn fix_goes_stale_after_the_timeout() {
        let mut v = Vehicle::new(CoreConfig::default());
        assert!(!tick(&mut v, 0).gnss.ok);
        v.handle(at(1_000), Input::Gnss(&fixed_at(1_000)));
        let s = tick(&mut v, 3_000);
        assert!(s.gnss.ok);
        assert_eq!(s.gnss.quality, FixQuality::RtkFixed);
        let s = tick(&mut v, 3_001);
        assert!(!s.gnss.ok);
        assert_eq!(s.gnss.quality, FixQuality::Invalid);
        assert_eq!(s.gnss.latitude_deg, 23.1);
    }

    #[test]
    fn link_down_is_immediately_not_ok() {
        let mut v = Vehicle::new(CoreConfig::default());
        v.handle(at(0), Input::Gnss(&fixed_at(0)));
        v.handle(at(10), Input::Link(Device::Gnss, LinkState::Down));
        assert!(!tick(&mut v, 100).gnss.ok);
        v.handle(at(150), Input::Link(Device::Gnss, LinkState::Up));
        v.handle(at(200), Input::Gnss(&fixed_at(200)));
        assert!(tick(&mut v, 300).gnss.ok);
    }

    #[test]
    fn heading_prefers_dual_antenna_then_course_while_moving() {
        let mut v = Vehicle::new(CoreConfig::default());
        let mut fix = fixed_at(0);
        fix.velocity = Some(Timed {
            value: GroundVelocity {
                speed_mps: 1.0,
                course_deg: Some(90.0),
            },
            rx: at(0),
        });
        fix.heading_deg = Some(Timed {
            value: 45.0,
            rx: at(0),
        });
        v.handle(at(0), Input::Gnss(&fix));
        assert_eq!(tick(&mut v, 100).gnss.heading_deg, 45.0);
        fix.heading_deg = None;
        v.handle(at(200), Input::Gnss(&fix));
        assert_eq!(tick(&mut v, 300).gnss.heading_deg, 90.0);
        // Slow: the course is noise, the last heading is held.
        fix.velocity = Some(Timed {
            value: GroundVelocity {
                speed_mps: 0.1,
                course_deg: Some(270.0),
            },
            rx: at(400),
        });
        v.handle(at(400), Input::Gnss(&fix));
        assert_eq!(tick(&mut v, 500).gnss.heading_deg, 90.0);
    }

    /// docs/configuration.md: the configured heading σ is the least a heading is trusted
    /// to; a receiver that states a larger one is weighed by that, a smaller one is not.
    #[test]
    fn a_stated_heading_sigma_weighs_the_heading_when_larger_than_the_configured() {
        let yaw_variance = |stated: Option<f64>| {
            let mut v = Vehicle::new(CoreConfig::default());
            let mut status = None;
            for i in 0..20 {
                let mut fix = fixed_at(i * 100);
                fix.heading_deg = Some(Timed {
                    value: 45.0,
                    rx: at(i * 100),
                });
                fix.heading_sigma_deg = stated;
                v.handle(at(i * 100), Input::Gnss(&fix));
                status = Some(tick(&mut v, i * 100 + 50));
            }
            status.and_then(|s| s.pose_covariance).expect("located").yaw
        };
        let configured = yaw_variance(None);
        assert!(yaw_variance(Some(20.0)) > 10.0 * configured);
        assert_eq!(yaw_variance(Some(0.01)), configured);
    }
}
