//! How many lines a kind of per-message log (a refused command, an ignored message) may
//! write: the first few of every 5 s, the rest counted and told with the next line that is
//! written. A client sending bad commands as fast as the rate limit lets it costs the log a
//! few lines per period, never one per message. Times are the records' (the core reads no
//! clock).

use std::time::Duration;

use crate::time::Timestamp;

/// The period over which lines are counted.
pub const PERIOD: Duration = Duration::from_secs(5);
/// Lines written per period.
pub const LINES_PER_PERIOD: u32 = 5;

/// One kind of log line's budget.
#[derive(Debug, Default)]
pub struct LogBudget {
    period_start: Option<Timestamp>,
    written: u32,
    suppressed: u64,
}

/// A log site's budget, shared by every instance that writes that line.
pub type SharedBudget = std::sync::Mutex<LogBudget>;

/// [`LogBudget::allow`] at `now`, on a shared budget.
pub fn allow(budget: &SharedBudget, now: Timestamp) -> Option<u64> {
    budget
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .allow(now)
}

impl LogBudget {
    /// A budget with nothing written yet (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            period_start: None,
            written: 0,
            suppressed: 0,
        }
    }

    /// Whether a line may be written at `now`: `Some(n)` with the lines left unwritten
    /// since the last one written (to be told in it), `None` to stay quiet (counted).
    pub fn allow(&mut self, now: Timestamp) -> Option<u64> {
        if self
            .period_start
            .is_none_or(|start| now.saturating_since(start) >= PERIOD)
        {
            self.period_start = Some(now);
            self.written = 0;
        }
        if self.written >= LINES_PER_PERIOD {
            self.suppressed += 1;
            return None;
        }
        self.written += 1;
        Some(std::mem::take(&mut self.suppressed))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_writes_a_few_lines_per_period_and_tells_what_it_left_out() {
        let mut b = LogBudget::default();
        let t0 = Timestamp::from_micros(1_000_000);
        let at = |d: Duration| t0.saturating_add(d);
        let verdicts: Vec<Option<u64>> = (0..1000)
            .map(|i| b.allow(at(Duration::from_millis(i))))
            .collect();
        assert_eq!(verdicts.iter().filter(|v| v.is_some()).count(), 5);
        assert!(verdicts[..5].iter().all(|v| *v == Some(0)));
        // The next period's first line tells the 995 left out.
        assert_eq!(b.allow(at(PERIOD + Duration::from_secs(1))), Some(995));
        assert_eq!(b.allow(at(PERIOD + Duration::from_secs(2))), Some(0));
    }
}
