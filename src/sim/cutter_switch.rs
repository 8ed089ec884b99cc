//! A simulated cutter switch module: a relay that turns the blade on at its on frame and off
//! at its off frame. A module whose on frame is repeated (`[cutter] repeat_ms`) has a
//! keep-alive: it opens the relay when the repeats stop, as the module that setting is for
//! does when chassisd is gone.

use std::time::Duration;

use crate::devices::can::Frame;
use crate::time::Timestamp;

/// Repeat periods a module waits, without an on frame, before it opens the relay: one lost
/// repeat is tolerated, two are not.
const KEEP_ALIVE_PERIODS: u32 = 3;

/// One simulated cutter switch module.
#[derive(Debug, Clone)]
pub struct SimCutterSwitch {
    on_frame: Frame,
    off_frame: Frame,
    keep_alive: Option<Duration>,
    on_since: Option<Timestamp>,
}

impl SimCutterSwitch {
    /// A module, relay open, that obeys `on_frame` and `off_frame`; with `repeat`, the on
    /// frame must come again within a few repeats.
    pub fn new(on_frame: Frame, off_frame: Frame, repeat: Option<Duration>) -> Self {
        Self {
            on_frame,
            off_frame,
            keep_alive: repeat.map(|r| r * KEEP_ALIVE_PERIODS),
            on_since: None,
        }
    }

    /// A frame heard at `t`: only the module's own two frames switch it.
    pub fn on_frame(&mut self, t: Timestamp, frame: &Frame) {
        if *frame == self.on_frame {
            self.on_since = Some(t);
        } else if *frame == self.off_frame {
            self.on_since = None;
        }
    }

    /// Runs on to `t`: the keep-alive opens the relay when the on frame stopped coming.
    pub fn step(&mut self, t: Timestamp) {
        if let (Some(since), Some(keep_alive)) = (self.on_since, self.keep_alive)
            && t.saturating_since(since) > keep_alive
        {
            self.on_since = None;
        }
    }

    /// Whether the relay is closed (the blade turns).
    pub fn on(&self) -> bool {
        self.on_since.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames() -> (Frame, Frame) {
        (
            Frame::standard(0x300, &[1]).unwrap(),
            Frame::standard(0x300, &[0]).unwrap(),
        )
    }

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_nanos(ms * 1_000_000)
    }

    #[test]
    fn the_on_and_off_frames_switch_it_and_nothing_else_does() {
        let (on, off) = frames();
        let mut switch = SimCutterSwitch::new(on, off, None);
        switch.on_frame(at(0), &Frame::standard(0x301, &[1]).unwrap());
        assert!(!switch.on(), "another id");
        switch.on_frame(at(0), &Frame::standard(0x300, &[2]).unwrap());
        assert!(!switch.on(), "other data");
        switch.on_frame(at(0), &on);
        switch.step(at(3_600_000));
        assert!(switch.on(), "without a keep-alive it stays on");
        switch.on_frame(at(3_600_001), &off);
        assert!(!switch.on());
    }

    #[test]
    fn a_repeated_switch_opens_when_the_repeats_stop() {
        let (on, off) = frames();
        let mut switch = SimCutterSwitch::new(on, off, Some(Duration::from_millis(100)));
        for ms in (0..=1000).step_by(100) {
            switch.on_frame(at(ms), &on);
            switch.step(at(ms + 50));
            assert!(switch.on(), "repeated at {ms} ms");
        }
        switch.step(at(1250));
        assert!(switch.on(), "one repeat lost is tolerated");
        switch.step(at(1301));
        assert!(!switch.on(), "three periods without the on frame");
    }
}
