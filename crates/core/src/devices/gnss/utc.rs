//! Resolves NMEA time-of-day fields into full UTC date-times.
//!
//! Most sentences carry only `hhmmss.ss`; the date comes from RMC or ZDA, possibly later.
//! The tracker remembers the last date and rolls it over at midnight, when the time of day
//! falls back by more than half a day without a new date.

use chrono::{NaiveDate, NaiveDateTime, NaiveTime, TimeDelta};

/// How far the time of day must fall back to count as a day roll-over rather than a glitch.
const ROLLOVER_THRESHOLD: TimeDelta = TimeDelta::hours(12);

/// Tracks the current UTC date across time-only sentences.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UtcTracker {
    date: Option<NaiveDate>,
    last_time: Option<NaiveTime>,
}

impl UtcTracker {
    /// A tracker that starts on `date` (used by the log importer, which knows the first date
    /// before it sees the first sentence).
    pub fn starting_on(date: NaiveDate) -> Self {
        Self {
            date: Some(date),
            last_time: None,
        }
    }

    /// Records a time of day with an optional date and returns the full date-time when the
    /// date is known. A date, when given, wins over the tracked one.
    pub fn observe(&mut self, time: NaiveTime, date: Option<NaiveDate>) -> Option<NaiveDateTime> {
        match date {
            Some(d) => self.date = Some(d),
            None => {
                if let (Some(d), Some(last)) = (self.date, self.last_time)
                    && last.signed_duration_since(time) > ROLLOVER_THRESHOLD
                {
                    self.date = d.succ_opt();
                }
            }
        }
        self.last_time = Some(time);
        self.date.map(|d| d.and_time(time))
    }

    /// The date-time of `time` on the tracked date, without recording it.
    pub fn resolve(&self, time: NaiveTime) -> Option<NaiveDateTime> {
        self.date.map(|d| d.and_time(time))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(h: u32, m: u32, s: u32) -> NaiveTime {
        NaiveTime::from_hms_opt(h, m, s).unwrap()
    }

    #[test]
    fn unknown_until_a_date_arrives() {
        let mut u = UtcTracker::default();
        assert_eq!(u.observe(t(0, 38, 32), None), None);
        let d = NaiveDate::from_ymd_opt(2022, 3, 29).unwrap();
        assert_eq!(
            u.observe(t(0, 38, 32), Some(d)),
            Some(d.and_time(t(0, 38, 32)))
        );
        assert_eq!(
            u.observe(t(0, 38, 33), None),
            Some(d.and_time(t(0, 38, 33)))
        );
    }

    #[test]
    fn rolls_over_at_midnight_but_not_on_small_steps_back() {
        let d = NaiveDate::from_ymd_opt(2024, 12, 31).unwrap();
        let mut u = UtcTracker::starting_on(d);
        u.observe(t(23, 59, 59), None);
        let next = u.observe(t(0, 0, 0), None).unwrap();
        assert_eq!(next.date(), NaiveDate::from_ymd_opt(2025, 1, 1).unwrap());
        let back = u.observe(t(0, 0, 0), None).unwrap();
        assert_eq!(back.date(), next.date());
        u.observe(t(0, 0, 5), None);
        assert_eq!(u.observe(t(0, 0, 3), None).unwrap().date(), next.date());
    }
}
