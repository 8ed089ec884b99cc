//! A simulated e-stop module: it broadcasts its status frame as its profile describes, a
//! quarter of the silence timeout apart, with the button pressed, released, or the module
//! silent (a cut cable or a dead module).

use std::time::Duration;

use crate::devices::can::Frame;
use crate::devices::estop::{ActiveLevel, EStopProfile};
use crate::time::Timestamp;

/// What the module sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Button {
    /// The button is pressed.
    Pressed,
    /// The button is released.
    Released,
    /// The module sends nothing.
    Silent,
}

/// One simulated e-stop module.
#[derive(Debug, Clone)]
pub struct SimEStop {
    profile: EStopProfile,
    button: Button,
    next: Option<Timestamp>,
}

impl SimEStop {
    /// A module with its button released.
    pub fn new(profile: EStopProfile) -> Self {
        Self {
            profile,
            button: Button::Released,
            next: None,
        }
    }

    /// Presses or releases the button, or silences the module. A change is sent at once.
    pub fn set(&mut self, button: Button) {
        self.button = button;
        self.next = None;
    }

    /// The status frame for the button's state (`None` only for an unchecked profile whose
    /// id, byte or bit does not fit).
    pub fn frame(&self, pressed: bool) -> Option<Frame> {
        let mut data = [0u8; 8];
        if pressed == (self.profile.active == ActiveLevel::High) {
            let byte = data.get_mut(usize::from(self.profile.byte))?;
            *byte |= 1u8.checked_shl(u32::from(self.profile.bit))?;
        }
        if self.profile.extended {
            Frame::extended(self.profile.id, &data)
        } else {
            Frame::standard(self.profile.id, &data)
        }
    }

    /// Sends the status frame when due.
    pub fn step(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        let pressed = match self.button {
            Button::Silent => return,
            Button::Pressed => true,
            Button::Released => false,
        };
        if self.next.is_none_or(|n| t >= n) {
            out.extend(self.frame(pressed));
            let period = Duration::from_millis((self.profile.timeout_ms / 4).max(5));
            self.next = Some(t.saturating_add(period));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::estop::EStopSignal;

    #[test]
    fn the_driver_decodes_what_the_module_sends() {
        for active in [ActiveLevel::High, ActiveLevel::Low] {
            let profile = EStopProfile {
                name: "t".into(),
                id: 0x1ABC_DEF0,
                extended: true,
                byte: 6,
                bit: 5,
                active,
                timeout_ms: 200,
            };
            let mut sim = SimEStop::new(profile.clone());
            let mut signal = EStopSignal::new("t".into(), profile);
            for (button, expect) in [
                (Button::Pressed, Some(true)),
                (Button::Released, Some(false)),
            ] {
                sim.set(button);
                let mut out = Vec::new();
                sim.step(Timestamp::from_nanos(1), &mut out);
                signal.on_frame(Timestamp::from_nanos(1), &out[0]).unwrap();
                assert_eq!(signal.input().pressed, expect, "{active:?} {button:?}");
            }
            sim.set(Button::Silent);
            let mut out = Vec::new();
            sim.step(Timestamp::from_nanos(2), &mut out);
            assert!(out.is_empty());
        }
    }
}
