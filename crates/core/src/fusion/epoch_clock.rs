//! When a GNSS epoch happened, on the host's clock. A fix describes its epoch, which its
//! sentences stamp in UTC to the millisecond; the host sees it only when its bytes arrive,
//! late by the receiver's processing and the serial link, and unevenly (a USB-serial
//! adapter holds bytes for up to 16 ms, a loaded host for longer). At 20 m/s a 15 ms
//! jitter is 0.3 m along the track. The host's clock and UTC need not agree, so the epoch
//! is placed at its UTC stamp plus the mean difference between arrivals and stamps: the
//! arrival with its jitter taken out. The configured latency then says how long before
//! that mean arrival the epoch truly was.

use chrono::NaiveDateTime;

use crate::time::Timestamp;

/// An arrival further than this from its stamp's place is not that stamp's epoch (a part
/// of another epoch, a receiver reset, the host's clock stepped): taken as it came, µs.
const MAX_JITTER_US: f64 = 250_000.0;
/// The mean follows the arrivals over about this long, µs.
const AVERAGE_US: f64 = 10_000_000.0;

/// The mean difference between the host's arrival times and the epochs' UTC stamps.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EpochClock {
    /// Arrival less stamp, µs, and the last stamp it saw (µs since 1970).
    mean: Option<(f64, i64)>,
}

impl EpochClock {
    /// A new epoch's arrival `rx` and its UTC stamp: the mean moves towards their
    /// difference (or restarts there, when it is far off: the clock stepped).
    pub fn observe(&mut self, rx: Timestamp, utc: Option<NaiveDateTime>) {
        let Some(utc) = utc else {
            return;
        };
        let stamp = utc.and_utc().timestamp_micros();
        let offset = rx.as_micros() as f64 - stamp as f64;
        self.mean = Some(match self.mean {
            // Weighted by the stamps' spacing, not the arrivals' (a late arrival would
            // otherwise weigh more).
            Some((mean, last)) if (offset - mean).abs() <= MAX_JITTER_US && stamp > last => {
                let k = ((stamp - last) as f64 / AVERAGE_US).clamp(1e-3, 1.0);
                (mean + (offset - mean) * k, stamp)
            }
            Some((mean, last)) if (offset - mean).abs() <= MAX_JITTER_US => (mean, last),
            _ => (offset, stamp),
        });
    }

    /// Where a part of the epoch stamped `utc` that arrived at `rx` arrives on average: its
    /// stamp plus the mean difference; `rx` itself without a stamp or a mean, or when it
    /// lies too far from its stamp's place.
    pub fn steady(&self, rx: Timestamp, utc: Option<NaiveDateTime>) -> Timestamp {
        let (Some(utc), Some((mean, _))) = (utc, self.mean) else {
            return rx;
        };
        let placed = utc.and_utc().timestamp_micros() as f64 + mean;
        if !placed.is_finite()
            || placed < 0.0
            || (placed - rx.as_micros() as f64).abs() > MAX_JITTER_US
        {
            return rx;
        }
        Timestamp::from_micros(placed.round() as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn utc(ms: i64) -> Option<NaiveDateTime> {
        chrono::DateTime::from_timestamp_millis(1_700_000_000_000 + ms).map(|d| d.naive_utc())
    }

    #[test]
    fn arrivals_lose_their_jitter_and_keep_their_mean_delay() {
        let mut clock = EpochClock::default();
        // A host clock 5 s ahead of UTC; epochs at 10 Hz arrive 200 ms late ± 20 ms.
        let host = |ms: i64| Timestamp::from_micros(((1_700_000_005_000 + ms) * 1000) as u64);
        let jitter = [0, 20, -20, 10, -10];
        for k in 0..200 {
            let ms = k * 100;
            let rx = host(ms + 200 + jitter[k as usize % 5]);
            clock.observe(rx, utc(ms));
        }
        // The next epoch arrives 20 ms late: it is placed 200 ms after its stamp.
        let rx = host(20_000 + 220);
        let placed = clock.steady(rx, utc(20_000));
        let expected = host(20_000 + 200).as_micros() as i64;
        assert!(
            (placed.as_micros() as i64 - expected).abs() < 2_000,
            "{placed:?}"
        );
        // Without a stamp, or a stamp of another epoch, the arrival stands.
        assert_eq!(clock.steady(rx, None), rx);
        assert_eq!(clock.steady(rx, utc(25_000)), rx);
    }

    #[test]
    fn a_stepped_clock_restarts_the_mean() {
        let mut clock = EpochClock::default();
        for k in 0..50 {
            let rx = Timestamp::from_micros(1_700_000_000_000_000 + k * 100_000);
            clock.observe(rx, utc(k as i64 * 100));
        }
        // The host's clock steps 3 s: the next arrivals define the mean afresh.
        for k in 50..55 {
            let rx = Timestamp::from_micros(1_700_000_003_000_000 + k * 100_000);
            clock.observe(rx, utc(k as i64 * 100));
        }
        let rx = Timestamp::from_micros(1_700_000_003_000_000 + 55 * 100_000);
        let placed = clock.steady(rx, utc(5_500)).as_micros() as i64;
        assert!((placed - rx.as_micros() as i64).abs() < 10, "{placed}");
    }
}
