//! A cutter switched by a frame on its interface (`[cutter]` with `bus`, `can_id`, `on`,
//! `off`): the on frame is repeated while on when the module wants it, and the off frame
//! stops the blade at exit and from a panic hook. (A blade drive is a `[[drive]]`.)

use std::time::Duration;

use super::device::{CanDevice, Heard};
use crate::config::VehicleConfig;
use crate::config::chassis::CanBusConfig;
use crate::config::mission::Cutter;
use crate::devices::can::Frame;
use crate::time::Timestamp;

/// The switch frames of a cutter.
#[derive(Debug, Clone)]
pub struct CutterSwitch {
    on_frame: Frame,
    off_frame: Frame,
    repeat: Option<Duration>,
    on: bool,
    next_repeat: Option<Timestamp>,
}

/// The cutter's switch, when `[cutter]` names a frame on `bus`.
pub fn build(config: &VehicleConfig, bus: &CanBusConfig) -> Vec<Box<dyn CanDevice>> {
    match config.cutter.as_ref().and_then(|c| c.cutter().ok()) {
        Some(Cutter::Frame {
            bus: name,
            on,
            off,
            repeat,
        }) if name == bus.interface => vec![Box::new(CutterSwitch {
            on_frame: on,
            off_frame: off,
            repeat,
            on: false,
            next_repeat: None,
        })],
        _ => Vec::new(),
    }
}

impl CanDevice for CutterSwitch {
    fn on_frame(&mut self, _t: Timestamp, _frame: &Frame, _out: &mut Vec<Frame>) -> Heard {
        Heard::Nothing
    }

    fn poll(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        let Some(repeat) = self.repeat else {
            return;
        };
        if !self.on || self.next_repeat.is_some_and(|next| t < next) {
            return;
        }
        self.next_repeat = Some(t.saturating_add(repeat));
        out.push(self.on_frame);
    }

    fn switch_cutter(&mut self, t: Timestamp, on: bool, out: &mut Vec<Frame>) -> bool {
        self.on = on;
        self.next_repeat = self.repeat.filter(|_| on).map(|r| t.saturating_add(r));
        out.push(if on { self.on_frame } else { self.off_frame });
        true
    }

    fn stop_frames(&self) -> Vec<Frame> {
        vec![self.off_frame]
    }
}
