//! RTK corrections as the core knows them: when the last valid RTCM frame went to the
//! receiver, and whether that is recent enough. The age is one signal, read by the status
//! (and so by every report), the log and the simulated receiver alike.

use std::time::Duration;

use crate::time::Timestamp;

/// The corrections' state at a status tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CorrectionsStatus {
    /// The caster's stream is connected.
    pub connected: bool,
    /// Seconds since the last valid frame; `None` before the first.
    pub age_s: Option<f64>,
    /// A frame arrived within the stale limit.
    pub fresh: bool,
    /// Valid frames so far.
    pub frames: u64,
    /// Their bytes.
    pub bytes: u64,
    /// The age beyond which corrections are stale, s.
    pub stale_after_s: f64,
}

/// Tracks the corrections; reports when they stop and when they come back.
#[derive(Debug, Clone)]
pub struct Corrections {
    stale_after: Duration,
    connected: bool,
    last_frame: Option<Timestamp>,
    frames: u64,
    bytes: u64,
    /// Whether the log has been told they stopped (so it hears when they are back).
    stopped_reported: bool,
    /// When they were last seen to stop, for the length of the gap.
    stopped_since: Option<Timestamp>,
    /// When tracking began: the first frame is overdue `stale_after` after it.
    started: Option<Timestamp>,
}

impl Corrections {
    /// Corrections that go stale after `stale_after` without a frame.
    pub fn new(stale_after: Duration) -> Self {
        Self {
            stale_after,
            connected: false,
            last_frame: None,
            frames: 0,
            bytes: 0,
            stopped_reported: false,
            stopped_since: None,
            started: None,
        }
    }

    /// Valid frames went to the receiver at `t`. Returns an event when they come back after
    /// a reported stop.
    pub fn frames(&mut self, t: Timestamp, count: u64, bytes: u64) -> Option<String> {
        self.started.get_or_insert(t);
        self.frames += count;
        self.bytes += bytes;
        self.last_frame = Some(t);
        if !self.stopped_reported {
            return None;
        }
        self.stopped_reported = false;
        let gap = self
            .stopped_since
            .map_or(0.0, |s| t.saturating_since(s).as_secs_f64());
        Some(format!(
            "RTK corrections arriving again (after {gap:.0} s without)"
        ))
    }

    /// The caster's stream connected or ended.
    pub fn link(&mut self, t: Timestamp, connected: bool) {
        self.started.get_or_insert(t);
        self.connected = connected;
    }

    /// The age of the last frame at `t`.
    pub fn age(&self, t: Timestamp) -> Option<Duration> {
        self.last_frame.map(|f| t.saturating_since(f))
    }

    /// Whether a frame arrived within the stale limit.
    pub fn is_fresh(&self, t: Timestamp) -> bool {
        self.age(t).is_some_and(|a| a <= self.stale_after)
    }

    /// The state at `t`, and an event when corrections have just gone stale (or never
    /// came within the limit of the start).
    pub fn tick(&mut self, t: Timestamp) -> (CorrectionsStatus, Option<String>) {
        let started = *self.started.get_or_insert(t);
        let fresh = self.is_fresh(t);
        let mut event = None;
        if !fresh && !self.stopped_reported {
            let since = self.last_frame.unwrap_or(started);
            if t.saturating_since(since) > self.stale_after {
                self.stopped_reported = true;
                self.stopped_since = Some(since);
                event = Some(match self.last_frame {
                    Some(_) => format!(
                        "RTK corrections stopped: no valid frame for {:.0} s (the receiver \
                         falls back from RTK; check the caster's link)",
                        self.stale_after.as_secs_f64()
                    ),
                    None => format!(
                        "RTK corrections not arriving: no valid frame within {:.0} s of \
                         the start (check the caster, the mountpoint and the credentials)",
                        self.stale_after.as_secs_f64()
                    ),
                });
            }
        }
        let status = CorrectionsStatus {
            connected: self.connected,
            age_s: self.age(t).map(|a| a.as_secs_f64()),
            fresh,
            frames: self.frames,
            bytes: self.bytes,
            stale_after_s: self.stale_after.as_secs_f64(),
        };
        (status, event)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(s: f64) -> Timestamp {
        Timestamp::from_nanos((s * 1e9) as u64)
    }

    #[test]
    fn a_gap_longer_than_the_limit_is_told_once_and_its_end_once() {
        let mut c = Corrections::new(Duration::from_secs(10));
        c.link(at(0.0), true);
        assert_eq!(c.frames(at(1.0), 2, 300), None);
        let (s, e) = c.tick(at(5.0));
        assert!(s.fresh && e.is_none());
        assert_eq!(s.age_s, Some(4.0));
        assert!(c.tick(at(11.0)).1.is_none(), "10 s is still fresh");
        let (s, e) = c.tick(at(11.5));
        assert!(!s.fresh);
        assert!(e.unwrap().contains("stopped"));
        assert!(c.tick(at(20.0)).1.is_none(), "told once");
        let back = c.frames(at(31.0), 1, 100).unwrap();
        assert!(back.contains("after 30 s"), "{back}");
        assert_eq!(c.frames(at(32.0), 1, 100), None);
        let (s, _) = c.tick(at(32.0));
        assert_eq!((s.frames, s.bytes), (4, 500));
    }

    #[test]
    fn corrections_that_never_come_are_reported_after_the_limit() {
        let mut c = Corrections::new(Duration::from_secs(10));
        assert!(c.tick(at(100.0)).1.is_none());
        let (s, e) = c.tick(at(110.5));
        assert_eq!(s.age_s, None);
        assert!(e.unwrap().contains("not arriving"));
        assert!(c.frames(at(120.0), 1, 50).unwrap().contains("again"));
    }
}
