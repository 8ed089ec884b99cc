//! Timestamps: the one notion of time that flows into the sans-IO core.
//!
//! A [`Timestamp`] counts nanoseconds since the Unix epoch on a clock that never steps
//! backwards. Live mode derives it from a monotonic clock anchored to wall time once at
//! start (see `runtime::clock`); replay takes it from the recording. Recordings store
//! microseconds, so live timestamps are truncated to microseconds before they reach the core,
//! which keeps a live run and the replay of its recording bit-identical.

use std::fmt;
use std::time::Duration;

/// Nanoseconds since the Unix epoch (1970-01-01T00:00:00Z), monotonic within a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Timestamp(u64);

impl Timestamp {
    /// The timestamp `nanos` nanoseconds after the epoch.
    pub const fn from_nanos(nanos: u64) -> Self {
        Self(nanos)
    }

    /// The timestamp `micros` microseconds after the epoch (saturating).
    pub const fn from_micros(micros: u64) -> Self {
        Self(micros.saturating_mul(1_000))
    }

    /// Nanoseconds since the epoch.
    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    /// Microseconds since the epoch (truncated).
    pub const fn as_micros(self) -> u64 {
        self.0 / 1_000
    }

    /// This timestamp truncated to whole microseconds, the resolution recordings keep.
    pub const fn truncate_to_micros(self) -> Self {
        Self(self.0 - self.0 % 1_000)
    }

    /// Time elapsed from `earlier` to `self`, or zero if `earlier` is later.
    pub fn saturating_since(self, earlier: Timestamp) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0))
    }

    /// `self + d`, saturating at the end of representable time.
    pub fn saturating_add(self, d: Duration) -> Self {
        let nanos = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        Self(self.0.saturating_add(nanos))
    }

    /// The first multiple of `period` at or after `self`. A zero period returns `self`.
    pub fn ceil_to(self, period: Duration) -> Self {
        let p = u64::try_from(period.as_nanos()).unwrap_or(u64::MAX);
        if p == 0 {
            return self;
        }
        match self.0 % p {
            0 => self,
            r => Self(self.0.saturating_add(p - r)),
        }
    }
}

/// Formats as `seconds.microseconds`, the candump `-L` spelling.
impl fmt::Display for Timestamp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let micros = self.as_micros();
        write!(f, "{}.{:06}", micros / 1_000_000, micros % 1_000_000)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn displays_like_candump() {
        let t = Timestamp::from_nanos(1_700_000_000_123_456_789);
        assert_eq!(t.to_string(), "1700000000.123456");
        assert_eq!(Timestamp::from_micros(5).to_string(), "0.000005");
    }

    #[test]
    fn ceil_to_period() {
        let p = Duration::from_millis(100);
        assert_eq!(
            Timestamp::from_nanos(0).ceil_to(p),
            Timestamp::from_nanos(0)
        );
        assert_eq!(
            Timestamp::from_nanos(1).ceil_to(p),
            Timestamp::from_nanos(100_000_000)
        );
        assert_eq!(
            Timestamp::from_nanos(200_000_000).ceil_to(p),
            Timestamp::from_nanos(200_000_000)
        );
        assert_eq!(
            Timestamp::from_nanos(u64::MAX).ceil_to(p).as_nanos(),
            u64::MAX
        );
    }

    #[test]
    fn saturating_arithmetic() {
        let a = Timestamp::from_micros(10);
        let b = Timestamp::from_micros(4);
        assert_eq!(a.saturating_since(b), Duration::from_micros(6));
        assert_eq!(b.saturating_since(a), Duration::ZERO);
        assert_eq!(
            Timestamp::from_nanos(u64::MAX - 1).saturating_add(Duration::from_secs(1)),
            Timestamp::from_nanos(u64::MAX)
        );
    }
}
