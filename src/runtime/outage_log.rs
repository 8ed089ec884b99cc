//! When to say again that a device is still unreachable: at the first failure, then 1 s and
//! 10 s into the outage, then every minute. A person reading the log sees a port that stays
//! absent without a line per retry, and never waits minutes for the first reminder.

use std::time::Duration;

/// The reminders' times into the outage before they settle at [`EVERY`].
const FIRST: [Duration; 2] = [Duration::from_secs(1), Duration::from_secs(10)];
/// The reminder period once the outage is long.
const EVERY: Duration = Duration::from_secs(60);

/// Tracks one outage.
#[derive(Debug, Clone, Default)]
pub struct OutageLog {
    /// Failed attempts in this outage.
    attempts: u64,
    /// When the next reminder is due, into the outage (none before the first failure).
    next: Option<Duration>,
}

/// What to log for a failed attempt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Say {
    /// The first failure: a warning.
    First,
    /// A reminder: still failing after this many attempts.
    Still(u64),
    /// Nothing above debug level.
    Quiet,
}

impl OutageLog {
    /// A failed attempt `into` the outage (since its first failure).
    pub fn failed(&mut self, into: Duration) -> Say {
        self.attempts += 1;
        let Some(next) = self.next else {
            self.next = Some(FIRST[0]);
            return Say::First;
        };
        if into < next {
            return Say::Quiet;
        }
        // The first of the early reminders still ahead, else a minute from this one.
        self.next = Some(
            FIRST
                .iter()
                .copied()
                .find(|&t| t > into)
                .unwrap_or(into + EVERY),
        );
        Say::Still(self.attempts)
    }

    /// The device is back: the next failure starts a new outage.
    pub fn recovered(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reminders_come_at_one_and_ten_seconds_then_every_minute() {
        let mut log = OutageLog::default();
        let mut said = Vec::new();
        // An attempt every 100 ms for ten minutes.
        for ms in (0..600_000u64).step_by(100) {
            if let Say::First | Say::Still(_) = log.failed(Duration::from_millis(ms)) {
                said.push(ms / 1000);
            }
        }
        assert_eq!(said, [0, 1, 10, 70, 130, 190, 250, 310, 370, 430, 490, 550]);
        // Slow attempts (every 25 s): the early reminders fall on the first attempt after
        // them, and then at least a minute passes between two.
        let mut log = OutageLog::default();
        let said: Vec<u64> = (0..10u64)
            .filter(|k| log.failed(Duration::from_secs(k * 25)) != Say::Quiet)
            .map(|k| k * 25)
            .collect();
        assert_eq!(said, [0, 25, 100, 175]);
        log.recovered();
        assert_eq!(log.failed(Duration::from_secs(300)), Say::First);
    }
}
