//! The live record clock: monotonic, anchored to wall time once at start.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio::time::Instant;

use crate::time::Timestamp;

/// Produces [`Timestamp`]s for live records: wall time at start plus monotonic elapsed time,
/// truncated to the microseconds a recording keeps. It never steps, whatever NTP does.
#[derive(Debug, Clone, Copy)]
pub struct RecordClock {
    wall_at_start: Timestamp,
    mono_at_start: Instant,
}

impl RecordClock {
    /// Anchors the clock now.
    pub fn start() -> Self {
        let wall = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or(Duration::ZERO);
        Self {
            wall_at_start: Timestamp::from_nanos(u64::try_from(wall.as_nanos()).unwrap_or(0)),
            mono_at_start: Instant::now(),
        }
    }

    /// The current time.
    pub fn now(&self) -> Timestamp {
        self.wall_at_start
            .saturating_add(self.mono_at_start.elapsed())
            .truncate_to_micros()
    }

    /// The monotonic instant at which this clock reads `t`.
    pub fn instant_at(&self, t: Timestamp) -> Instant {
        self.mono_at_start + t.saturating_since(self.wall_at_start)
    }
}
