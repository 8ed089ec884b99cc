//! The drive train's arbiter: who may move the vehicle, velocity limits and ramps, wheel
//! odometry and the chassis status bits. Whether it may move at all is the safety
//! supervisor's decision ([`super::safety`]).
//!
//! Wheel-level only: the engine maps wheels to drive nodes and axes. Speeds here are SI:
//! m/s and rad/s for the vehicle, rad/s for wheels (positive rolls the vehicle forward).

use std::time::Duration;

pub use super::feedback::{ChassisFeedback, DriveSummary, WheelFeedback};
use super::safety::{Cause, Power, Refusal, Safety, SafetyConfig, State, StopKind};
use crate::config::chassis::ChassisConfig;
use crate::control::response::ResponseEstimator;
use crate::time::Timestamp;

/// The control period the engine runs the chassis at.
pub const CONTROL_PERIOD: Duration = Duration::from_millis(10);

/// A velocity command this share over a limit is taken as the limit (a sender's rounding);
/// further over, it is refused.
const LIMIT_ROUNDING: f64 = 1e-6;
/// A move's command leads the modelled drive speed by about the drives' response time, at
/// most this, s (times the acceleration limit).
pub const MAX_LEAD_S: f64 = 0.3;

/// Bits of `robot.robot_status`.
pub mod status_bits {
    /// Every drive axis is in "operation enabled".
    pub const ENABLED: u32 = 1 << 0;
    /// A drive fault is latched.
    pub const FAULT: u32 = 1 << 1;
    /// A drive's heartbeat was lost.
    pub const HEARTBEAT_LOST: u32 = 1 << 2;
    /// An emergency stop holds the vehicle: an e-stop input pressed or silent, or the
    /// software e-stop engaged.
    pub const ESTOP: u32 = 1 << 3;
    /// Motion allowed, but no fresh velocity command: holding zero.
    pub const COMMAND_TIMEOUT: u32 = 1 << 4;
    /// A CAN interface is down.
    pub const BUS_DOWN: u32 = 1 << 5;
    /// Stopped (latched): a zero velocity command or a reset re-arms, once the cause cleared.
    pub const AWAITING_COMMAND: u32 = 1 << 6;
    /// A drive is still booting, being set up, or unreachable.
    pub const NOT_READY: u32 = 1 << 7;
    /// The commanded velocity is not zero.
    pub const MOVING: u32 = 1 << 8;
    /// A drive fault reset is under way.
    pub const RESETTING: u32 = 1 << 9;
    /// The controlling client's heartbeat is lost.
    pub const CONTROL_LINK_LOST: u32 = 1 << 10;

    /// Each bit's name, in bit order.
    const NAMES: [(u32, &str); 11] = [
        (ENABLED, "enabled"),
        (FAULT, "drive fault"),
        (HEARTBEAT_LOST, "drive heartbeat lost"),
        (ESTOP, "emergency stop"),
        (COMMAND_TIMEOUT, "command timeout"),
        (BUS_DOWN, "CAN interface down"),
        (AWAITING_COMMAND, "awaiting a command"),
        (NOT_READY, "drive not ready"),
        (MOVING, "moving"),
        (RESETTING, "fault reset"),
        (CONTROL_LINK_LOST, "control link lost"),
    ];

    /// The names of the bits set in `bits`, joined by commas.
    pub fn describe(bits: u32) -> String {
        NAMES
            .iter()
            .filter(|(bit, _)| bits & bit != 0)
            .map(|(_, name)| *name)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// What the drives should do until the next tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelCommand {
    /// The power stage wanted.
    pub power: Power,
    /// Reset latched faults now (a deliberate act asked for it).
    pub reset_faults: bool,
    /// Left wheel speed, rad/s.
    pub left_rad_s: f64,
    /// Right wheel speed, rad/s.
    pub right_rad_s: f64,
}

/// Why a velocity command was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandRejected {
    /// The vehicle has no drives configured.
    #[error("no drives are configured")]
    NoDrives,
    /// A drive cannot take commands yet.
    #[error("drive {0} is not ready (booting, being set up, or unreachable)")]
    NotReady(String),
    /// The CAN interface of the drives is down.
    #[error(
        "the CAN interface of the drives is down: bring it up (`ip link set IFACE up`) or \
         reconnect the adapter"
    )]
    BusDown,
    /// The command's values are not finite numbers or out of range.
    #[error("a value is not a finite number in range")]
    NotFinite,
    /// The command needs a position, and there is none yet.
    #[error("no position yet")]
    NoPosition,
    /// A move needs the wheel odometry, and the drives have not reported yet.
    #[error("no wheel odometry yet (the drives have not reported)")]
    NoOdometry,
    /// A goal in the map frame needs the vehicle located.
    #[error("not located: a goal in the map frame needs a good position and heading (LOCATE_TRUE)")]
    NotLocated,
    /// The command would move the map frame under a motion that depends on it.
    #[error("a move or goal in the map frame is under way; stop it first")]
    MoveUnderWay,
    /// A task cannot start or go on: why.
    #[error("{0}")]
    Task(String),
    /// CONTINUE with no task paused.
    #[error("no task is paused")]
    NothingPaused,
    /// A velocity beyond the configured limit: refused rather than clamped, so the sender
    /// learns the vehicle cannot do what it asked.
    #[error("{what} {} {unit} is beyond the limit of {limit} {unit} ({key})", compact(*.value))]
    BeyondLimit {
        /// What: speed or yaw rate.
        what: &'static str,
        /// The value asked for.
        value: f64,
        /// The configured limit.
        limit: f64,
        /// Its unit.
        unit: &'static str,
        /// The configuration key that sets it.
        key: &'static str,
    },
    /// A value outside the range the world allows (a latitude, a height).
    #[error("{what} {} {unit} is outside {min}..={max} {unit}", compact(*.value))]
    OutOfRange {
        /// What: latitude, longitude, height.
        what: &'static str,
        /// The value given.
        value: f64,
        /// The least allowed.
        min: f64,
        /// The most allowed.
        max: f64,
        /// Its unit.
        unit: &'static str,
    },
    /// The motion's way meets a zone (map frame, m).
    #[error("the way meets the {kind} zone {name:?} at ({x:.2}, {y:.2}) m")]
    Zone {
        /// The zone's kind (`boundary`, `keep_out`, `wall`).
        kind: &'static str,
        /// Its name.
        name: String,
        /// Where the way first comes too close, x (m).
        x: f64,
        /// And y (m).
        y: f64,
    },
    /// Zones are configured, but the vehicle is not placed on them yet.
    #[error(
        "zones are configured and the vehicle is not located on them: a motion needs a \
         datum and a position (LOCATE_TRUE) to be checked against them"
    )]
    ZonesUnplaced,
    /// An edit of the zones cannot be made: why.
    #[error("the zones are not changed: {0}")]
    ZoneEdit(String),
    /// The GNSS gate is closed: autonomous work is refused (not queued) until it opens.
    #[error(
        "the GNSS gate is closed ({0}): autonomous work is refused until zones.resume_after_s \
         of good fixes open it; send the command again then"
    )]
    GnssGate(super::gate::GateReason),
    /// Manual velocity commands are refused in navigation mode.
    #[error("manual velocity commands are refused in navigation mode (switch to manual)")]
    NavigationMode,
    /// The safety supervisor holds the vehicle.
    #[error("{0}")]
    Safety(#[from] Refusal),
}

impl CommandRejected {
    /// Whether the command itself is wrong (a value out of range or not finite), as
    /// opposed to the vehicle's state refusing it: protocols answer the two differently.
    pub fn is_bad_value(&self) -> bool {
        matches!(
            self,
            Self::NotFinite
                | Self::BeyondLimit { .. }
                | Self::OutOfRange { .. }
                | Self::ZoneEdit(_)
        )
    }
}

/// A number as a person reads it: huge and tiny ones in exponent form (1e308, not 309 digits).
fn compact(v: f64) -> String {
    if v != 0.0 && !(1e-3..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// Who may drive: the operator by velocity commands (manual), or autonomous moves
/// (navigation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DriveMode {
    /// Velocity commands (DRIVE, cmd_vel) drive.
    #[default]
    Manual,
    /// Only autonomous moves drive; velocity commands are refused.
    Navigation,
}

/// Travelled distance and speed of each wheel.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WheelOdometry {
    /// Left wheel distance since start, m.
    pub left_m: f64,
    /// Right wheel distance since start, m.
    pub right_m: f64,
    /// Left wheel speed, m/s.
    pub left_mps: f64,
    /// Right wheel speed, m/s.
    pub right_mps: f64,
}

/// Chassis state for the status report.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ChassisStatus {
    /// Measured forward speed, m/s.
    pub vx: f64,
    /// Measured yaw rate, rad/s.
    pub wz: f64,
    /// [`status_bits`].
    pub status_bits: u32,
    /// Drives configured, all ready, no fault, bus up.
    pub ok: bool,
    /// Wheel odometry.
    pub odometry: WheelOdometry,
    /// Why motion is latched off, if it is.
    pub stop_reason: Option<String>,
}

/// The drive-train arbiter.
#[derive(Debug, Clone)]
pub struct Chassis {
    config: ChassisConfig,
    mode: DriveMode,
    safety: Safety,
    /// The speed the drives are taken to have (v, w), which changes at most at the
    /// acceleration limits: for manual commands the command ramped within them; for a move
    /// a first-order model of the drives (their learnt response time) fed with the setpoint.
    reference: (f64, f64),
    /// What the drives are sent (v, w): the reference, or for a move the move's command
    /// within its lead allowance of the reference.
    setpoint: (f64, f64),
    /// The command in force came from a closed-loop move.
    autonomous: bool,
    /// Why the wheels hold zero at the last tick.
    stop: Option<StopKind>,
    feedback: ChassisFeedback,
    last_angles: Option<(f64, f64)>,
    odometry: WheelOdometry,
    last_tick: Option<Timestamp>,
    /// How quickly the drives follow their speed command.
    response: ResponseEstimator,
}

impl Chassis {
    /// A chassis with `config`; `safety` adds what the configuration beyond the chassis
    /// says (the control link).
    pub fn new(config: ChassisConfig, safety: SafetyConfig) -> Self {
        Self {
            safety: Safety::new(safety),
            mode: DriveMode::default(),
            config,
            reference: (0.0, 0.0),
            setpoint: (0.0, 0.0),
            autonomous: false,
            stop: None,
            feedback: ChassisFeedback::default(),
            last_angles: None,
            odometry: WheelOdometry::default(),
            last_tick: None,
            response: ResponseEstimator::default(),
        }
    }

    /// Takes the drives' feedback; the supervisor judges it at the next tick.
    pub fn feedback(&mut self, feedback: ChassisFeedback) {
        if let Some(angles) = feedback.left.angle_rad.zip(feedback.right.angle_rad) {
            if let Some((l0, r0)) = self.last_angles {
                let r = self.config.wheel_radius_m;
                self.odometry.left_m += (angles.0 - l0) * r.left;
                self.odometry.right_m += (angles.1 - r0) * r.right;
            }
            self.last_angles = Some(angles);
        }
        let r = self.config.wheel_radius_m;
        self.odometry.left_mps = feedback.left.velocity_rad_s.unwrap_or(0.0) * r.left;
        self.odometry.right_mps = feedback.right.velocity_rad_s.unwrap_or(0.0) * r.right;
        self.feedback = feedback;
    }

    /// The safety supervisor.
    pub fn safety(&self) -> &Safety {
        &self.safety
    }

    /// An operator's stop: latches; a zero velocity command or a reset re-arms.
    pub fn operator_stop(&mut self, t: Timestamp) {
        self.safety.operator_stop(t);
    }

    /// Engages or releases the software e-stop.
    pub fn software_estop(&mut self, t: Timestamp, engaged: bool) {
        self.safety.set_software_estop(t, engaged);
    }

    /// An explicit reset: re-arms once every cause has cleared, resetting drive faults.
    pub fn reset(&mut self, t: Timestamp) -> Result<(), CommandRejected> {
        self.drives_reachable()?;
        Ok(self.safety.reset(t)?)
    }

    /// A heartbeat from the controlling client.
    pub fn control_heartbeat(&mut self, t: Timestamp) {
        self.safety.control_heartbeat(t);
    }

    /// Switches who may drive; switching stops any motion under way.
    pub fn set_mode(&mut self, mode: DriveMode) {
        if mode != self.mode {
            self.mode = mode;
            self.safety.clear_command();
        }
    }

    /// Who may drive.
    pub fn mode(&self) -> DriveMode {
        self.mode
    }

    fn drives_reachable(&self) -> Result<(), CommandRejected> {
        if self.feedback.drives.is_empty() {
            return Err(CommandRejected::NoDrives);
        }
        if self.feedback.bus_down {
            return Err(CommandRejected::BusDown);
        }
        if let Some(d) = self.feedback.drives.iter().find(|d| !d.running) {
            return Err(CommandRejected::NotReady(d.name.clone()));
        }
        Ok(())
    }

    /// A velocity command: forward speed (m/s) and yaw rate (rad/s). After a stop only a
    /// zero command is taken: the deliberate act that re-arms.
    pub fn command(&mut self, t: Timestamp, vx: f64, wz: f64) -> Result<(), CommandRejected> {
        if !vx.is_finite() || !wz.is_finite() {
            return Err(CommandRejected::NotFinite);
        }
        if self.mode == DriveMode::Navigation {
            return Err(CommandRejected::NavigationMode);
        }
        self.within_limits(vx, wz)?;
        self.drives_reachable()?;
        if self.autonomous {
            // The ramp goes on from what the drives were sent, the move's lead included.
            self.reference = self.setpoint;
            self.autonomous = false;
        }
        self.safety.velocity(
            t,
            vx.clamp(-self.config.max_speed_mps, self.config.max_speed_mps),
            wz.clamp(-self.config.max_yaw_rate_rps, self.config.max_yaw_rate_rps),
        )?;
        Ok(())
    }

    /// Refuses a velocity command beyond the configured limits (a rounding error's worth
    /// over them is taken, and clamped).
    fn within_limits(&self, vx: f64, wz: f64) -> Result<(), CommandRejected> {
        for (what, value, limit, unit, key) in [
            (
                "speed",
                vx,
                self.config.max_speed_mps,
                "m/s",
                "chassis.max_speed_mps",
            ),
            (
                "yaw rate",
                wz,
                self.config.max_yaw_rate_rps,
                "rad/s",
                "chassis.max_yaw_rate_rps",
            ),
        ] {
            if value.abs() > limit * (1.0 + LIMIT_ROUNDING) {
                return Err(CommandRejected::BeyondLimit {
                    what,
                    value,
                    limit,
                    unit,
                    key,
                });
            }
        }
        Ok(())
    }

    /// A velocity proposed by a closed-loop move: forward speed (m/s) and yaw rate (rad/s),
    /// clamped to the limits. Taken in either drive mode; refused while latched (a move never
    /// re-arms).
    pub fn autonomous(&mut self, t: Timestamp, vx: f64, wz: f64) -> Result<(), CommandRejected> {
        if !vx.is_finite() || !wz.is_finite() {
            return Err(CommandRejected::NotFinite);
        }
        self.drives_reachable()?;
        self.safety.autonomous(
            t,
            vx.clamp(-self.config.max_speed_mps, self.config.max_speed_mps),
            wz.clamp(-self.config.max_yaw_rate_rps, self.config.max_yaw_rate_rps),
        )?;
        self.autonomous = true;
        Ok(())
    }

    /// Holds zero velocity while armed (the end of a move, a stop request); nothing else
    /// changes: no arming, no re-arming.
    pub fn hold_zero(&mut self, t: Timestamp) {
        if *self.safety.state() == State::Armed {
            // Armed takes any command.
            let _ = self.safety.autonomous(t, 0.0, 0.0);
        }
    }

    /// Whether the command in force came from a closed-loop move (not an operator).
    pub fn is_autonomous(&self) -> bool {
        self.autonomous
    }

    /// The speeds (m/s, rad/s) the vehicle must be able to brake from at `t`: what the
    /// wheels measure, and what the drives will be sent next (a move's command, which may
    /// lead the drives; an operator's, a control period's acceleration beyond what they are
    /// sent now; zero without one).
    pub fn speeds_ahead(&self, t: Timestamp) -> [(f64, f64); 2] {
        let status = self.status(t);
        let (v, w) = self.setpoint;
        let dt = CONTROL_PERIOD.as_secs_f64();
        let next = match self.safety.command_in_force(t) {
            None => (0.0, 0.0),
            Some(command) if self.autonomous => command,
            Some((cv, cw)) => (
                approach(v, cv, self.config.max_accel_mps2 * dt),
                approach(w, cw, self.config.max_yaw_accel_rps2 * dt),
            ),
        };
        [(status.vx, status.wz), next]
    }

    /// The zone in the braking way for the next tick, as the core judged it: a cause of a
    /// latched stop while it lasts.
    pub fn zone_ahead(&mut self, zone: Option<(&'static str, String)>) {
        self.safety.zone_ahead(zone);
    }

    /// The deceleration the drives are taken to brake at, at least, m/s².
    pub fn braking_decel(&self) -> f64 {
        self.config.max_decel_mps2
    }

    /// Whether the drives are ready to take a move: configured, reachable, not latched.
    pub fn ready_to_move(&self) -> Result<(), CommandRejected> {
        self.drives_reachable()?;
        Ok(self.safety.may_move()?)
    }

    /// The speed the drives are taken to have (m/s, rad/s): the ramped command, or for a
    /// move the drive model its command leads (at most [`MAX_LEAD_S`] times the limits).
    pub fn reference(&self) -> (f64, f64) {
        self.reference
    }

    /// The drives' speed response time (a first-order lag), s, learnt from commands and
    /// feedback.
    pub fn response_time(&self) -> f64 {
        self.response.time_constant()
    }

    /// One control step at `t`: the wheel speeds to command. A stop (latched, or no fresh
    /// command) zeroes the targets at once and leaves the braking to the drives' own ramps;
    /// commanded changes are ramped within the configured limits.
    pub fn tick(&mut self, t: Timestamp) -> WheelCommand {
        let dt = self
            .last_tick
            .map_or(CONTROL_PERIOD, |last| t.saturating_since(last))
            .as_secs_f64();
        self.last_tick = Some(t);
        let verdict = self.safety.tick(t, &self.feedback);
        self.stop = verdict.stop.clone();
        (self.reference, self.setpoint) = match verdict.target {
            Some(target) if verdict.stop.is_none() && self.autonomous => self.lead(target, dt),
            Some((target_v, target_w)) if verdict.stop.is_none() => {
                let (v, w) = self.reference;
                let reference = (
                    self.ramp_speed(v, target_v, dt),
                    approach(w, target_w, self.config.max_yaw_accel_rps2 * dt),
                );
                (reference, reference)
            }
            _ => ((0.0, 0.0), (0.0, 0.0)),
        };
        let (v, w) = self.setpoint;
        let half_track = self.config.track_m / 2.0;
        let r = self.config.wheel_radius_m;
        let command = WheelCommand {
            power: verdict.power,
            reset_faults: verdict.reset_faults,
            left_rad_s: (v - w * half_track) / r.left,
            right_rad_s: (v + w * half_track) / r.right,
        };
        self.learn_response(t, &command);
        command
    }

    /// Feeds the response estimator: the wheel speeds reported now, and the command from now
    /// on, while the drives follow commands.
    fn learn_response(&mut self, t: Timestamp, command: &WheelCommand) {
        let r = self.config.wheel_radius_m;
        // A speed is paired with the commands up to when it arrived.
        let reading = |wheel: &WheelFeedback, r: f64| {
            wheel
                .velocity_rad_s
                .map(|v| (wheel.velocity_received.map_or(t, |at| at.min(t)), v * r))
        };
        let measured =
            reading(&self.feedback.left, r.left).zip(reading(&self.feedback.right, r.right));
        match measured {
            Some((left, right)) if command.power == Power::Enabled => {
                self.response.feedback(left, right);
                self.response.command(
                    t,
                    (command.left_rad_s * r.left, command.right_rad_s * r.right),
                );
            }
            _ => self.response.interrupt(),
        }
    }

    /// A move's step towards `target` over `dt` s: the new reference and the setpoint.
    ///
    /// A drive that lags by τ needs its command to lead the speed wanted by τ times the
    /// acceleration, or the vehicle falls behind every ramp. So a move's command may lead
    /// the speed the drives are taken to have (the reference) by τ (at most
    /// [`MAX_LEAD_S`]) times the limit in that direction, and the reference follows the
    /// setpoint as a first-order lag of τ. A drive following that model accelerates
    /// within the limits; the reference itself never changes faster than they allow
    /// (Δ ≤ lead·(1 − e^(−dt/τ)) ≤ limit·dt).
    fn lead(&self, target: (f64, f64), dt: f64) -> ((f64, f64), (f64, f64)) {
        let tau = self.response.time_constant();
        let follow = 1.0 - (-dt / tau).exp();
        // The lead that moves the modelled drive by exactly limit·dt in this step (τ plus
        // about half a step: the setpoint is held for the whole step).
        let lead_s = if follow > 0.0 {
            (dt / follow).min(MAX_LEAD_S)
        } else {
            0.0
        };
        let (v, w) = self.reference;
        // Away from zero is acceleration, towards it deceleration.
        let (accel, decel) = (self.config.max_accel_mps2, self.config.max_decel_mps2);
        let up = if v < 0.0 { decel } else { accel };
        let down = if v > 0.0 { decel } else { accel };
        let lead_w = lead_s * self.config.max_yaw_accel_rps2;
        let setpoint = (
            target
                .0
                .clamp(v - lead_s * down, v + lead_s * up)
                .clamp(-self.config.max_speed_mps, self.config.max_speed_mps),
            target
                .1
                .clamp(w - lead_w, w + lead_w)
                .clamp(-self.config.max_yaw_rate_rps, self.config.max_yaw_rate_rps),
        );
        let reference = (v + (setpoint.0 - v) * follow, w + (setpoint.1 - w) * follow);
        (reference, setpoint)
    }

    /// One ramp step of the speed from `v` towards `target`: slowing down (towards zero)
    /// may use the stronger deceleration limit, speeding up only the acceleration limit; a
    /// reversal brakes to zero first.
    fn ramp_speed(&self, v: f64, target: f64, dt: f64) -> f64 {
        let reversing = target * v < 0.0;
        if reversing || target.abs() < v.abs() {
            let towards = if reversing { 0.0 } else { target };
            approach(v, towards, self.config.max_decel_mps2 * dt)
        } else {
            approach(v, target, self.config.max_accel_mps2 * dt)
        }
    }

    /// The status at `t`.
    pub fn status(&self, t: Timestamp) -> ChassisStatus {
        use status_bits::*;
        let fb = &self.feedback;
        let r = self.config.wheel_radius_m;
        let (vl, vr) = (
            fb.left.velocity_rad_s.unwrap_or(0.0) * r.left,
            fb.right.velocity_rad_s.unwrap_or(0.0) * r.right,
        );
        let mut bits = 0;
        if !fb.drives.is_empty() && fb.drives.iter().all(|d| d.enabled) {
            bits |= ENABLED;
        }
        if fb.drives.iter().any(|d| d.fault.is_some()) {
            bits |= FAULT;
        }
        if fb.drives.iter().any(|d| d.heartbeat_lost) {
            bits |= HEARTBEAT_LOST;
        }
        if self.safety.estop_active() {
            bits |= ESTOP;
        }
        if *self.safety.state() == State::Armed && !self.safety.command_fresh(t) {
            bits |= COMMAND_TIMEOUT;
        }
        if fb.bus_down {
            bits |= BUS_DOWN;
        }
        match self.safety.state() {
            State::Latched { .. } => bits |= AWAITING_COMMAND,
            State::Resetting { .. } => bits |= AWAITING_COMMAND | RESETTING,
            State::Standby | State::Armed => {}
        }
        if fb.drives.iter().any(|d| !d.running) {
            bits |= NOT_READY;
        }
        if self.setpoint != (0.0, 0.0) {
            bits |= MOVING;
        }
        if self.safety.control_link_lost() {
            bits |= CONTROL_LINK_LOST;
        }
        ChassisStatus {
            vx: (vl + vr) / 2.0,
            wz: (vr - vl) / self.config.track_m,
            status_bits: bits,
            ok: !fb.drives.is_empty() && !fb.bus_down && fb.drives.iter().all(|d| d.ready),
            odometry: self.odometry,
            stop_reason: match &self.stop {
                Some(StopKind::Latched(cause)) => Some(cause.to_string()),
                Some(StopKind::CommandTimeout) | None => {
                    self.safety.latched().map(Cause::to_string)
                }
            },
        }
    }
}

fn approach(from: f64, to: f64, step: f64) -> f64 {
    from + (to - from).clamp(-step, step)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::safety::DEFAULT_QUICK_STOP;

    fn config() -> ChassisConfig {
        ChassisConfig {
            wheel_radius_m: crate::config::chassis::WheelRadius::both(0.1),
            track_m: 0.5,
            max_speed_mps: 1.0,
            max_yaw_rate_rps: 1.0,
            max_accel_mps2: 0.5,
            max_decel_mps2: 1.0,
            max_yaw_accel_rps2: 2.0,
            cmd_timeout_s: 0.5,
            enable_on_start: true,
            quick_stop_s: 1.0,
            reset_timeout_s: 3.0,
        }
    }

    fn chassis() -> Chassis {
        let c = config();
        Chassis::new(
            c,
            SafetyConfig {
                cmd_timeout: c.cmd_timeout(),
                quick_stop: DEFAULT_QUICK_STOP,
                reset_timeout: Duration::from_secs(3),
                control_link: None,
                enable_on_start: c.enable_on_start,
            },
        )
    }

    fn drive(fault: Option<&str>) -> DriveSummary {
        DriveSummary {
            name: "d".into(),
            ready: fault.is_none(),
            running: true,
            enabled: fault.is_none(),
            fault: fault.map(str::to_owned),
            heartbeat_lost: fault == Some("heartbeat lost"),
            resetting: false,
        }
    }

    fn ms(v: u64) -> Timestamp {
        Timestamp::from_micros(v * 1000)
    }

    fn ok_feedback() -> ChassisFeedback {
        ChassisFeedback {
            drives: vec![drive(None)],
            ..ChassisFeedback::default()
        }
    }

    #[test]
    fn ramps_within_limits() {
        let mut c = chassis();
        c.feedback(ok_feedback());
        c.command(ms(0), 1.0, 0.0).unwrap();
        let mut last = 0.0;
        for i in 1..=300 {
            let cmd = c.tick(ms(i * 10));
            let v = (cmd.left_rad_s + cmd.right_rad_s) / 2.0 * 0.1;
            assert!(v - last <= 0.5 * 0.01 + 1e-12, "accel limit");
            last = v;
            if i % 40 == 0 {
                c.command(ms(i * 10), 1.0, 0.0).unwrap();
            }
        }
        assert!((last - 1.0).abs() < 1e-9, "at max speed: {last}");
    }

    #[test]
    fn an_expired_command_zeroes_the_targets_at_once() {
        let mut c = chassis();
        c.feedback(ok_feedback());
        c.command(ms(0), 0.2, 0.0).unwrap();
        for i in 1..=50 {
            c.tick(ms(i * 10));
        }
        assert!(c.status(ms(500)).status_bits & status_bits::MOVING != 0);
        let cmd = c.tick(ms(510));
        assert_eq!((cmd.left_rad_s, cmd.right_rad_s), (0.0, 0.0));
        assert!(c.status(ms(510)).status_bits & status_bits::COMMAND_TIMEOUT != 0);
        assert_eq!(
            cmd.power,
            Power::Enabled,
            "an expired command is not a fault"
        );
    }

    #[test]
    fn a_fault_latches_until_a_deliberate_act() {
        let mut c = chassis();
        c.feedback(ok_feedback());
        c.command(ms(0), 0.3, 0.0).unwrap();
        c.tick(ms(10));
        c.feedback(ChassisFeedback {
            drives: vec![drive(Some("heartbeat lost"))],
            ..ChassisFeedback::default()
        });
        let cmd = c.tick(ms(20));
        assert_ne!(cmd.power, Power::Enabled);
        assert_eq!((cmd.left_rad_s, cmd.right_rad_s), (0.0, 0.0));
        let s = c.status(ms(20));
        assert!(s.status_bits & status_bits::AWAITING_COMMAND != 0);
        assert!(s.status_bits & status_bits::HEARTBEAT_LOST != 0);
        assert_eq!(s.stop_reason.as_deref(), Some("d: heartbeat lost"));
        // The drive recovers, but its fault stays latched until a reset.
        let mut recovered = ok_feedback();
        recovered.drives[0].fault = Some("heartbeat lost".into());
        c.feedback(recovered);
        assert_ne!(c.tick(ms(30)).power, Power::Enabled);
        // A non-zero command does not re-arm.
        assert!(matches!(
            c.command(ms(40), 0.1, 0.0),
            Err(CommandRejected::Safety(Refusal::Latched { .. }))
        ));
        assert!(!c.tick(ms(50)).reset_faults);
        // A zero command does: the fault is reset once, then the drive reports it cleared.
        c.command(ms(60), 0.0, 0.0).unwrap();
        let cmd = c.tick(ms(70));
        assert!(cmd.reset_faults);
        c.feedback(ok_feedback());
        assert_eq!(c.tick(ms(80)).power, Power::Enabled);
        assert!(!c.tick(ms(90)).reset_faults, "the reset is one-shot");
        c.command(ms(100), 0.1, 0.0).unwrap();
    }

    #[test]
    fn rejects_commands_it_cannot_carry_out() {
        let mut c = chassis();
        assert_eq!(c.command(ms(0), 0.1, 0.0), Err(CommandRejected::NoDrives));
        let mut fb = ok_feedback();
        fb.drives[0].running = false;
        c.feedback(fb);
        assert!(matches!(
            c.command(ms(0), 0.1, 0.0),
            Err(CommandRejected::NotReady(_))
        ));
        let mut fb = ok_feedback();
        fb.bus_down = true;
        c.feedback(fb);
        let refused = c.command(ms(0), 0.1, 0.0).unwrap_err();
        assert_eq!(refused, CommandRejected::BusDown);
        assert!(refused.to_string().contains("CAN interface"), "{refused}");
        c.feedback(ok_feedback());
        assert_eq!(
            c.command(ms(0), f64::NAN, 0.0),
            Err(CommandRejected::NotFinite)
        );
        // Beyond a limit is refused, naming it; a rounding error over it is taken.
        let refused = c.command(ms(0), 1e308, -1e308).unwrap_err();
        assert!(matches!(
            refused,
            CommandRejected::BeyondLimit { what: "speed", .. }
        ));
        assert_eq!(
            refused.to_string(),
            "speed 1e308 m/s is beyond the limit of 1 m/s (chassis.max_speed_mps)"
        );
        assert!(matches!(
            c.command(ms(0), 0.5, -1.01),
            Err(CommandRejected::BeyondLimit {
                key: "chassis.max_yaw_rate_rps",
                ..
            })
        ));
        c.command(ms(0), -1.0 - 1e-9, 1.0).unwrap();
    }

    #[test]
    fn turning_splits_wheel_speeds() {
        let mut c = chassis();
        c.feedback(ok_feedback());
        c.command(ms(0), 0.0, 1.0).unwrap();
        let mut cmd = c.tick(ms(10));
        for i in 2..=60 {
            cmd = c.tick(ms(i * 10));
            if i % 30 == 0 {
                c.command(ms(i * 10), 0.0, 1.0).unwrap();
            }
        }
        // 1 rad/s on a 0.5 m track: ±0.25 m/s at the wheels, ±2.5 rad/s for r = 0.1 m.
        assert!((cmd.right_rad_s - 2.5).abs() < 1e-9 && (cmd.left_rad_s + 2.5).abs() < 1e-9);
    }
}
