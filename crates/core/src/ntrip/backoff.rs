//! When to connect to the caster again: a schedule a caster's operator would accept.
//! rtk2go bans clients that reconnect in a storm; this one never does:
//! - after a failed attempt (refused, an error status, a connection that delivered no valid
//!   frame), wait 10 s, doubling up to 300 s;
//! - never more than 12 connects in any 60 s, whatever happens;
//! - the delay resets only after a connection has delivered valid frames;
//! - it never gives up.
//!
//! Times are offsets from any fixed instant, so the schedule is a pure function of its
//! history (and property-tested as one).

use std::collections::VecDeque;
use std::time::Duration;

/// The first delay.
pub const FIRST: Duration = Duration::from_secs(10);
/// The longest delay.
pub const LONGEST: Duration = Duration::from_secs(300);
/// At most this many connects ...
pub const MAX_CONNECTS: usize = 12;
/// ... in any window this long.
pub const WINDOW: Duration = Duration::from_secs(60);

/// The schedule's state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Backoff {
    /// The delay after the next failure.
    delay: Duration,
    /// When the next connect may start (`None`: at once).
    next: Option<Duration>,
    /// The last connects' start times, at most [`MAX_CONNECTS`].
    recent: VecDeque<Duration>,
    /// Failures in a row (for the log's falling rate).
    failures: u32,
}

impl Default for Backoff {
    fn default() -> Self {
        Self {
            delay: FIRST,
            next: None,
            recent: VecDeque::with_capacity(MAX_CONNECTS),
            failures: 0,
        }
    }
}

impl Backoff {
    /// A schedule that may connect at once.
    pub fn new() -> Self {
        Self::default()
    }

    /// When the next connect may start, at or after `now`.
    pub fn next_connect(&self, now: Duration) -> Duration {
        let mut at = self.next.unwrap_or(now).max(now);
        // The window: the connect MAX_CONNECTS back must be a window ago.
        if self.recent.len() >= MAX_CONNECTS
            && let Some(&oldest) = self.recent.front()
        {
            at = at.max(oldest + WINDOW);
        }
        at
    }

    /// A connect starts at `now` (call only at or after [`Backoff::next_connect`]).
    pub fn connecting(&mut self, now: Duration) {
        if self.recent.len() >= MAX_CONNECTS {
            self.recent.pop_front();
        }
        self.recent.push_back(now);
    }

    /// The connection that started last ended at `now`; `delivered` says whether it
    /// delivered valid frames. Returns the wait before the next connect.
    pub fn ended(&mut self, now: Duration, delivered: bool) -> Duration {
        if delivered {
            self.delay = FIRST;
            self.failures = 0;
        } else {
            self.failures = self.failures.saturating_add(1);
        }
        let wait = self.delay;
        self.next = Some(now + wait);
        if !delivered {
            self.delay = (self.delay * 2).min(LONGEST);
        }
        wait
    }

    /// Failures in a row.
    pub fn failures(&self) -> u32 {
        self.failures
    }

    /// Whether the attempt after `failures` failures in a row is worth a log line: the
    /// first few, then at a falling rate (powers of two).
    pub fn worth_logging(failures: u32) -> bool {
        failures <= 3 || failures.is_power_of_two()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(secs: u64) -> Duration {
        Duration::from_secs(secs)
    }

    #[test]
    fn failures_double_to_five_minutes_and_success_resets() {
        let mut b = Backoff::new();
        let mut now = s(0);
        let mut waits = Vec::new();
        for _ in 0..8 {
            now = b.next_connect(now);
            b.connecting(now);
            waits.push(b.ended(now, false).as_secs());
        }
        assert_eq!(waits, [10, 20, 40, 80, 160, 300, 300, 300]);
        now = b.next_connect(now);
        b.connecting(now);
        assert_eq!(b.ended(now, true), FIRST);
        now = b.next_connect(now);
        b.connecting(now);
        assert_eq!(b.ended(now, false), FIRST);
        assert_eq!(b.ended(now, false), s(20));
    }

    /// A caster that accepts, delivers a frame and closes at once, forever: the delay stays
    /// at its first value, and the window still holds.
    #[test]
    fn the_window_bounds_connects_whatever_the_outcome() {
        let mut b = Backoff::new();
        let mut now = s(0);
        let mut starts = Vec::new();
        for i in 0..1000u64 {
            now = b.next_connect(now);
            b.connecting(now);
            starts.push(now);
            // Alternate good and bad endings, some instantly, some after a while.
            b.ended(now + Duration::from_millis(i % 7 * 100), i % 3 == 0);
        }
        for (i, &t) in starts.iter().enumerate() {
            let in_window = starts[i..].iter().take_while(|&&u| u < t + WINDOW).count();
            assert!(in_window <= MAX_CONNECTS, "{in_window} connects from {t:?}");
        }
    }

    #[test]
    fn logs_fall_off() {
        let logged: Vec<u32> = (1..=100).filter(|&f| Backoff::worth_logging(f)).collect();
        assert_eq!(logged, [1, 2, 3, 4, 8, 16, 32, 64]);
    }
}
