//! The drive train's decisions: who may move the vehicle, velocity limits and ramps, the
//! command watchdog, the safety latch, wheel odometry and the chassis status bits.
//!
//! Wheel-level only: the engine maps wheels to drive nodes and axes. Speeds here are SI:
//! m/s and rad/s for the vehicle, rad/s for wheels (positive rolls the vehicle forward).

use std::fmt;
use std::time::Duration;

use crate::config::chassis::ChassisConfig;
use crate::time::Timestamp;

/// The control period the engine runs the chassis at.
pub const CONTROL_PERIOD: Duration = Duration::from_millis(10);

/// Bits of `robot.robot_status`.
pub mod status_bits {
    /// Every drive axis is in "operation enabled".
    pub const ENABLED: u32 = 1 << 0;
    /// A drive fault is latched.
    pub const FAULT: u32 = 1 << 1;
    /// A drive's heartbeat was lost.
    pub const HEARTBEAT_LOST: u32 = 1 << 2;
    /// Emergency stop (reserved: no e-stop input is wired yet).
    pub const ESTOP: u32 = 1 << 3;
    /// Motion allowed, but no fresh velocity command: holding zero.
    pub const COMMAND_TIMEOUT: u32 = 1 << 4;
    /// A CAN interface is down.
    pub const BUS_DOWN: u32 = 1 << 5;
    /// Stopped by a fault; a fresh command is needed to move again.
    pub const AWAITING_COMMAND: u32 = 1 << 6;
    /// A drive is still booting, being set up, or unreachable.
    pub const NOT_READY: u32 = 1 << 7;
    /// The commanded velocity is not zero.
    pub const MOVING: u32 = 1 << 8;
}

/// What the engine reports about one drive node.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveSummary {
    /// The drive's name from the configuration.
    pub name: String,
    /// Set up and running, no fault latched.
    pub ready: bool,
    /// Running (fault or not): faults can be reset.
    pub running: bool,
    /// Every axis in operation enabled.
    pub enabled: bool,
    /// The latched fault, described.
    pub fault: Option<String>,
    /// The fault is a lost heartbeat.
    pub heartbeat_lost: bool,
}

/// One wheel's feedback.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WheelFeedback {
    /// Wheel speed, rad/s, positive forward.
    pub velocity_rad_s: Option<f64>,
    /// Wheel angle, rad, positive forward (from the encoder, unwrapped by the engine).
    pub angle_rad: Option<f64>,
}

/// The drive train's feedback at a control tick.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ChassisFeedback {
    /// Left wheel.
    pub left: WheelFeedback,
    /// Right wheel.
    pub right: WheelFeedback,
    /// Every drive.
    pub drives: Vec<DriveSummary>,
    /// A CAN interface carrying drives is down.
    pub bus_down: bool,
}

/// What the drives should do until the next tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelCommand {
    /// Power stages enabled.
    pub enable: bool,
    /// Reset latched faults now (a fresh command arrived).
    pub reset_faults: bool,
    /// Left wheel speed, rad/s.
    pub left_rad_s: f64,
    /// Right wheel speed, rad/s.
    pub right_rad_s: f64,
}

/// Why motion stopped and waits for a fresh command.
#[derive(Debug, Clone, PartialEq)]
pub enum StopReason {
    /// A drive reported a fault.
    Drive(String),
    /// A CAN interface with drives went down.
    BusDown,
    /// The controlling client's heartbeat stopped.
    ControlLinkLost,
    /// An operator asked for a stop (PAUSE).
    Operator,
}

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Drive(d) => write!(f, "{d}"),
            Self::BusDown => write!(f, "CAN interface down"),
            Self::ControlLinkLost => write!(f, "control link heartbeat lost"),
            Self::Operator => write!(f, "stopped by the operator"),
        }
    }
}

/// Why a velocity command was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandRejected {
    /// The vehicle has no drives configured.
    #[error("no drives are configured")]
    NoDrives,
    /// A drive cannot take commands yet.
    #[error("drive {0} is not ready")]
    NotReady(String),
    /// The command's values are not finite numbers or out of range.
    #[error("a value is not a finite number in range")]
    NotFinite,
    /// The command needs a position, and there is none yet.
    #[error("no position yet")]
    NoPosition,
    /// Manual velocity commands are refused in navigation mode.
    #[error("manual velocity commands are refused in navigation mode (switch to manual)")]
    NavigationMode,
}

/// A stop asked for by a command (rather than by a fault).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopRequest {
    /// The controlling client's heartbeat stopped.
    ControlLinkLost,
    /// An operator asked for a stop (PAUSE).
    Operator,
}

impl From<StopRequest> for StopReason {
    fn from(r: StopRequest) -> Self {
        match r {
            StopRequest::ControlLinkLost => Self::ControlLinkLost,
            StopRequest::Operator => Self::Operator,
        }
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

/// The drive-train decision maker.
#[derive(Debug, Clone)]
pub struct Chassis {
    config: ChassisConfig,
    mode: DriveMode,
    armed: bool,
    latch: Option<StopReason>,
    reset_pending: bool,
    command: Option<(Timestamp, f64, f64)>,
    /// Ramped setpoint (v, w).
    setpoint: (f64, f64),
    feedback: ChassisFeedback,
    last_angles: Option<(f64, f64)>,
    odometry: WheelOdometry,
    last_tick: Option<Timestamp>,
}

impl Chassis {
    /// A chassis with `config`, not armed unless it enables on start.
    pub fn new(config: ChassisConfig) -> Self {
        Self {
            armed: config.enable_on_start,
            mode: DriveMode::default(),
            config,
            latch: None,
            reset_pending: false,
            command: None,
            setpoint: (0.0, 0.0),
            feedback: ChassisFeedback::default(),
            last_angles: None,
            odometry: WheelOdometry::default(),
            last_tick: None,
        }
    }

    /// Takes the drives' feedback; faults latch a stop.
    pub fn feedback(&mut self, feedback: ChassisFeedback) {
        if let Some(angles) = feedback.left.angle_rad.zip(feedback.right.angle_rad) {
            if let Some((l0, r0)) = self.last_angles {
                let r = self.config.wheel_radius_m;
                self.odometry.left_m += (angles.0 - l0) * r;
                self.odometry.right_m += (angles.1 - r0) * r;
            }
            self.last_angles = Some(angles);
        }
        let r = self.config.wheel_radius_m;
        self.odometry.left_mps = feedback.left.velocity_rad_s.unwrap_or(0.0) * r;
        self.odometry.right_mps = feedback.right.velocity_rad_s.unwrap_or(0.0) * r;
        // A fault already being reset by a fresh command does not latch again.
        if self.armed && !self.reset_pending {
            let reason = if feedback.bus_down {
                Some(StopReason::BusDown)
            } else {
                feedback.drives.iter().find_map(|d| {
                    d.fault
                        .as_ref()
                        .map(|f| StopReason::Drive(format!("{}: {f}", d.name)))
                })
            };
            if let Some(reason) = reason {
                self.latch = Some(reason);
                self.armed = false;
                self.command = None;
            }
        }
        self.feedback = feedback;
    }

    /// Stops now for `reason`: the wheels decelerate to zero and stay there until a fresh
    /// command.
    pub fn stop(&mut self, reason: StopReason) {
        self.latch = Some(reason);
        self.armed = false;
        self.command = None;
    }

    /// Switches who may drive; switching stops any motion under way.
    pub fn set_mode(&mut self, mode: DriveMode) {
        if mode != self.mode {
            self.mode = mode;
            self.command = None;
        }
    }

    /// Who may drive.
    pub fn mode(&self) -> DriveMode {
        self.mode
    }

    /// A velocity command: forward speed (m/s) and yaw rate (rad/s). A command after a
    /// safety stop is the "fresh command" that resets faults and re-arms.
    pub fn command(&mut self, t: Timestamp, vx: f64, wz: f64) -> Result<(), CommandRejected> {
        if !vx.is_finite() || !wz.is_finite() {
            return Err(CommandRejected::NotFinite);
        }
        if self.mode == DriveMode::Navigation {
            return Err(CommandRejected::NavigationMode);
        }
        if self.feedback.drives.is_empty() {
            return Err(CommandRejected::NoDrives);
        }
        if self.feedback.bus_down {
            return Err(CommandRejected::NotReady("bus".into()));
        }
        if let Some(d) = self.feedback.drives.iter().find(|d| !d.running) {
            return Err(CommandRejected::NotReady(d.name.clone()));
        }
        if self.latch.take().is_some() || self.feedback.drives.iter().any(|d| d.fault.is_some()) {
            self.reset_pending = true;
        }
        self.armed = true;
        self.command = Some((
            t,
            vx.clamp(-self.config.max_speed_mps, self.config.max_speed_mps),
            wz.clamp(-self.config.max_yaw_rate_rps, self.config.max_yaw_rate_rps),
        ));
        Ok(())
    }

    /// One control step at `t`: the wheel speeds to command.
    pub fn tick(&mut self, t: Timestamp) -> WheelCommand {
        let dt = self
            .last_tick
            .map_or(CONTROL_PERIOD, |last| t.saturating_since(last))
            .as_secs_f64();
        self.last_tick = Some(t);
        let (target_v, target_w) = match self.command {
            Some((at, v, w))
                if self.armed && t.saturating_since(at) <= self.config.cmd_timeout() =>
            {
                (v, w)
            }
            _ => (0.0, 0.0),
        };
        let (v, w) = self.setpoint;
        // Slowing down (towards zero) may use the stronger deceleration limit.
        let accel = if target_v.abs() < v.abs() || target_v * v < 0.0 {
            self.config.max_decel_mps2
        } else {
            self.config.max_accel_mps2
        };
        let v = approach(v, target_v, accel * dt);
        let w = approach(w, target_w, self.config.max_yaw_accel_rps2 * dt);
        let v = if self.armed {
            v
        } else {
            approach(self.setpoint.0, 0.0, self.config.max_decel_mps2 * dt)
        };
        let w = if self.armed {
            w
        } else {
            approach(self.setpoint.1, 0.0, self.config.max_yaw_accel_rps2 * dt)
        };
        self.setpoint = (v, w);
        let half_track = self.config.track_m / 2.0;
        let r = self.config.wheel_radius_m;
        let reset_faults = std::mem::take(&mut self.reset_pending);
        WheelCommand {
            enable: self.armed,
            reset_faults,
            left_rad_s: (v - w * half_track) / r,
            right_rad_s: (v + w * half_track) / r,
        }
    }

    /// The status at `t`.
    pub fn status(&self, t: Timestamp) -> ChassisStatus {
        use status_bits::*;
        let fb = &self.feedback;
        let r = self.config.wheel_radius_m;
        let (vl, vr) = (
            fb.left.velocity_rad_s.unwrap_or(0.0) * r,
            fb.right.velocity_rad_s.unwrap_or(0.0) * r,
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
        let fresh = self
            .command
            .is_some_and(|(at, _, _)| t.saturating_since(at) <= self.config.cmd_timeout());
        if self.armed && !fresh {
            bits |= COMMAND_TIMEOUT;
        }
        if fb.bus_down {
            bits |= BUS_DOWN;
        }
        if self.latch.is_some() {
            bits |= AWAITING_COMMAND;
        }
        if fb.drives.iter().any(|d| !d.running) {
            bits |= NOT_READY;
        }
        if self.setpoint != (0.0, 0.0) {
            bits |= MOVING;
        }
        ChassisStatus {
            vx: (vl + vr) / 2.0,
            wz: (vr - vl) / self.config.track_m,
            status_bits: bits,
            ok: !fb.drives.is_empty() && !fb.bus_down && fb.drives.iter().all(|d| d.ready),
            odometry: self.odometry,
            stop_reason: self.latch.as_ref().map(ToString::to_string),
        }
    }
}

fn approach(from: f64, to: f64, step: f64) -> f64 {
    from + (to - from).clamp(-step, step)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> ChassisConfig {
        ChassisConfig {
            wheel_radius_m: 0.1,
            track_m: 0.5,
            max_speed_mps: 1.0,
            max_yaw_rate_rps: 1.0,
            max_accel_mps2: 0.5,
            max_decel_mps2: 1.0,
            max_yaw_accel_rps2: 2.0,
            cmd_timeout_s: 0.5,
            enable_on_start: true,
        }
    }

    fn drive(fault: Option<&str>) -> DriveSummary {
        DriveSummary {
            name: "d".into(),
            ready: fault.is_none(),
            running: true,
            enabled: fault.is_none(),
            fault: fault.map(str::to_owned),
            heartbeat_lost: fault == Some("heartbeat lost"),
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
    fn ramps_within_limits_and_clamps() {
        let mut c = Chassis::new(config());
        c.feedback(ok_feedback());
        c.command(ms(0), 5.0, 0.0).unwrap();
        let mut last = 0.0;
        for i in 1..=300 {
            let cmd = c.tick(ms(i * 10));
            let v = (cmd.left_rad_s + cmd.right_rad_s) / 2.0 * 0.1;
            assert!(v - last <= 0.5 * 0.01 + 1e-12, "accel limit");
            last = v;
            if i % 40 == 0 {
                c.command(ms(i * 10), 5.0, 0.0).unwrap();
            }
        }
        assert!((last - 1.0).abs() < 1e-9, "clamped to max speed: {last}");
    }

    #[test]
    fn command_expires_and_decelerates() {
        let mut c = Chassis::new(config());
        c.feedback(ok_feedback());
        c.command(ms(0), 0.2, 0.0).unwrap();
        for i in 1..=50 {
            c.tick(ms(i * 10));
        }
        assert!(c.status(ms(500)).status_bits & status_bits::MOVING != 0);
        let mut cmd = c.tick(ms(510));
        for i in 52..=100 {
            cmd = c.tick(ms(i * 10));
        }
        assert_eq!((cmd.left_rad_s, cmd.right_rad_s), (0.0, 0.0));
        assert!(c.status(ms(1000)).status_bits & status_bits::COMMAND_TIMEOUT != 0);
        assert!(cmd.enable, "an expired command is not a fault");
    }

    #[test]
    fn a_fault_latches_until_a_fresh_command() {
        let mut c = Chassis::new(config());
        c.feedback(ok_feedback());
        c.command(ms(0), 0.3, 0.0).unwrap();
        c.tick(ms(10));
        c.feedback(ChassisFeedback {
            drives: vec![drive(Some("heartbeat lost"))],
            ..ChassisFeedback::default()
        });
        let cmd = c.tick(ms(20));
        assert!(!cmd.enable);
        let s = c.status(ms(20));
        assert!(s.status_bits & status_bits::AWAITING_COMMAND != 0);
        assert!(s.status_bits & status_bits::HEARTBEAT_LOST != 0);
        assert_eq!(s.stop_reason.as_deref(), Some("d: heartbeat lost"));
        // The drive recovers; nothing moves until a command arrives.
        c.feedback(ok_feedback());
        assert!(!c.tick(ms(30)).enable);
        c.command(ms(40), 0.1, 0.0).unwrap();
        let cmd = c.tick(ms(50));
        assert!(cmd.enable && cmd.reset_faults);
        assert!(!c.tick(ms(60)).reset_faults, "the reset is one-shot");
    }

    #[test]
    fn rejects_commands_it_cannot_carry_out() {
        let mut c = Chassis::new(config());
        assert_eq!(c.command(ms(0), 0.1, 0.0), Err(CommandRejected::NoDrives));
        let mut fb = ok_feedback();
        fb.drives[0].running = false;
        c.feedback(fb);
        assert!(matches!(
            c.command(ms(0), 0.1, 0.0),
            Err(CommandRejected::NotReady(_))
        ));
        c.feedback(ok_feedback());
        assert_eq!(
            c.command(ms(0), f64::NAN, 0.0),
            Err(CommandRejected::NotFinite)
        );
    }

    #[test]
    fn turning_splits_wheel_speeds() {
        let mut c = Chassis::new(config());
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
