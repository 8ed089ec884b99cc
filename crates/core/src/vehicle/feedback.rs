//! What the drive train reports at a control tick: the inputs of both the arbiter
//! ([`super::chassis`]) and the safety supervisor ([`super::safety`]).

use crate::devices::estop::EStopInput;
use crate::time::Timestamp;

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
    /// A fault reset handshake is under way.
    pub resetting: bool,
}

/// One wheel's feedback.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WheelFeedback {
    /// Wheel speed, rad/s, positive forward.
    pub velocity_rad_s: Option<f64>,
    /// Wheel angle, rad, positive forward (from the encoder, unwrapped by the engine).
    pub angle_rad: Option<f64>,
    /// When these values arrived from the drive (it reports less often than the control
    /// loop runs, so they may be a feedback period old).
    pub received: Option<Timestamp>,
    /// When the wheel speed arrived (the response estimate pairs it with the commands
    /// before it).
    pub velocity_received: Option<Timestamp>,
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
    /// The e-stop inputs.
    pub estops: Vec<EStopInput>,
}
