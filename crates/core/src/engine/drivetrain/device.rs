//! The one shape every CAN device takes on its interface: frames in, frames out, each with
//! the time; the interface's link state; timers; and what it reports to the core. A device
//! kind implements [`CanDevice`] in its own module and adds one line to
//! [`super::KINDS`], which builds each interface's devices from the configuration.

use crate::devices::bms::BmsReading;
use crate::devices::can::Frame;
use crate::devices::cia402::node::DriveNode;
use crate::devices::cia402::state::Goal;
use crate::time::Timestamp;
use crate::vehicle::chassis::ChassisFeedback;

/// What a device made of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Heard {
    /// Nothing the core needs now.
    Nothing,
    /// A reading the core takes at once changed (the BMS's).
    Changed,
    /// A frame of its own it could not read (counted on the interface).
    Malformed,
}

/// The core's command, as the drives take it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveCommand {
    /// The power stage's goal.
    pub goal: Goal,
    /// Left wheel, rad/s.
    pub left_rad_s: f64,
    /// Right wheel, rad/s.
    pub right_rad_s: f64,
    /// Reset drive faults.
    pub reset_faults: bool,
    /// The cutter is switched on (a blade drive runs).
    pub cutter_on: bool,
}

/// One device on a CAN interface. Only what a kind does is written; the rest does nothing.
pub trait CanDevice: Send + std::fmt::Debug {
    /// A data frame heard at `t`; frames to send go to `out`.
    fn on_frame(&mut self, t: Timestamp, frame: &Frame, out: &mut Vec<Frame>) -> Heard;
    /// The interface went up or down at `t`.
    fn on_link(&mut self, _t: Timestamp, _up: bool, _out: &mut Vec<Frame>) {}
    /// Timers due at `t` (the interface is not known to be down); commands wait for
    /// [`CanDevice::flush`].
    fn poll(&mut self, _t: Timestamp, _out: &mut Vec<Frame>) {}
    /// The core's command at `t`.
    fn command(&mut self, _t: Timestamp, _command: &DriveCommand) {}
    /// Sends the commands due at `t`: what [`CanDevice::command`] gave it in this tick, and
    /// the periodic refresh, so no refresh repeats the last tick's command after it changed.
    fn flush(&mut self, _t: Timestamp, _out: &mut Vec<Frame>) {}
    /// The cutter is switched at `t`; false when the device is not the cutter's switch.
    fn switch_cutter(&mut self, _t: Timestamp, _on: bool, _out: &mut Vec<Frame>) -> bool {
        false
    }
    /// The daemon exits: what stops the device now.
    fn shut_down(&mut self, _out: &mut Vec<Frame>) {}
    /// What stops the device with nothing else running (a panic hook's frames, computed
    /// ahead).
    fn stop_frames(&self) -> Vec<Frame> {
        Vec::new()
    }
    /// What it tells the core, added to `feedback`.
    fn report(&mut self, _feedback: &mut ChassisFeedback) {}
    /// Whether it turns the wheels (a wheel or blade drive): a bus that carries one and is
    /// down fails the drive train.
    fn is_drive(&self) -> bool {
        false
    }
    /// Its BMS reading, when it is the battery's.
    fn bms(&self) -> Option<&BmsReading> {
        None
    }
    /// Its name and CiA 402 node, when it is a drive (diagnostics).
    fn node(&self) -> Option<(&str, &DriveNode)> {
        None
    }
}
