//! A hardware e-stop input on its interface, only listened to.

use super::device::{CanDevice, Heard};
use crate::config::VehicleConfig;
use crate::config::chassis::CanBusConfig;
use crate::devices::can::Frame;
use crate::devices::estop::EStopSignal;
use crate::time::Timestamp;
use crate::vehicle::chassis::ChassisFeedback;

/// The `[[estop]]`s of `bus`, in the configuration's order.
pub fn build(config: &VehicleConfig, bus: &CanBusConfig) -> Vec<Box<dyn CanDevice>> {
    config
        .estop
        .iter()
        .filter(|e| e.bus == bus.interface)
        .filter_map(|e| {
            let signal = EStopSignal::new(e.name.clone(), e.profile.get()?.clone());
            Some(Box::new(signal) as Box<dyn CanDevice>)
        })
        .collect()
}

impl CanDevice for EStopSignal {
    fn on_frame(&mut self, t: Timestamp, frame: &Frame, _out: &mut Vec<Frame>) -> Heard {
        match EStopSignal::on_frame(self, t, frame) {
            Ok(()) => Heard::Nothing,
            Err(_) => Heard::Malformed,
        }
    }

    fn report(&mut self, feedback: &mut ChassisFeedback) {
        // A bus that is down delivers nothing: the input falls silent and counts as pressed.
        feedback.estops.push(self.input());
    }
}
