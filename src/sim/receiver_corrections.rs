//! The simulated receiver's use of RTK corrections, when the simulation has a caster: it
//! frames what reaches its port as a real receiver does, and holds RTK fixed only while valid
//! frames keep coming. Without them it falls back to float, then to DGPS (SBAS), by the age
//! of the last frame: the same age the core reports.

use std::time::Duration;

use crate::devices::gnss::FixQuality;
use crate::devices::gnss::rtcm::RtcmFramer;
use crate::time::Timestamp;

/// How long RTK float holds once the corrections are stale, before DGPS.
pub const FLOAT_HOLD: Duration = Duration::from_secs(20);

/// What the receiver knows of its corrections.
#[derive(Debug, Clone)]
pub struct ReceiverCorrections {
    framer: RtcmFramer,
    last: Option<Timestamp>,
    /// Corrections older than this no longer hold RTK fixed.
    fixed_for: Duration,
}

impl ReceiverCorrections {
    /// A receiver that holds RTK fixed for `fixed_for` after the last valid frame.
    pub fn new(fixed_for: Duration) -> Self {
        Self {
            framer: RtcmFramer::new(),
            last: None,
            fixed_for,
        }
    }

    /// Bytes arrived on the port at `t`; only valid frames count.
    pub fn receive(&mut self, t: Timestamp, bytes: &[u8]) {
        let mut valid = false;
        self.framer.push(bytes, |_, _| valid = true);
        if valid {
            self.last = Some(t);
        }
    }

    /// The age of the last valid frame at `t`.
    pub fn age(&self, t: Timestamp) -> Option<Duration> {
        self.last.map(|l| t.saturating_since(l))
    }

    /// The quality the receiver reaches at `t` where the sky allows `possible`: RTK only
    /// with fresh corrections.
    pub fn quality(&self, t: Timestamp, possible: FixQuality) -> FixQuality {
        if !matches!(possible, FixQuality::RtkFixed | FixQuality::RtkFloat) {
            return possible;
        }
        match self.age(t) {
            Some(age) if age <= self.fixed_for => possible,
            Some(age) if age <= self.fixed_for + FLOAT_HOLD => FixQuality::RtkFloat,
            _ => FixQuality::Dgps,
        }
    }

    /// Valid frames received.
    pub fn frames(&self) -> u64 {
        self.framer.stats().frames
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::gnss::rtcm::encode;

    fn at(s: f64) -> Timestamp {
        Timestamp::from_nanos((s * 1e9) as u64)
    }

    #[test]
    fn rtk_holds_only_while_valid_frames_come() {
        let mut r = ReceiverCorrections::new(Duration::from_secs(10));
        assert_eq!(r.quality(at(0.0), FixQuality::RtkFixed), FixQuality::Dgps);
        r.receive(at(1.0), b"\xD3\x00\x01garbage");
        assert_eq!(r.quality(at(1.0), FixQuality::RtkFixed), FixQuality::Dgps);
        r.receive(at(2.0), &encode(&[0x3E, 0xD0, 0x00]));
        assert_eq!(r.frames(), 1);
        assert_eq!(
            r.quality(at(12.0), FixQuality::RtkFixed),
            FixQuality::RtkFixed
        );
        assert_eq!(
            r.quality(at(12.5), FixQuality::RtkFixed),
            FixQuality::RtkFloat
        );
        assert_eq!(
            r.quality(at(32.0), FixQuality::RtkFixed),
            FixQuality::RtkFloat
        );
        assert_eq!(r.quality(at(32.5), FixQuality::RtkFixed), FixQuality::Dgps);
        assert_eq!(r.quality(at(32.5), FixQuality::Single), FixQuality::Single);
    }
}
