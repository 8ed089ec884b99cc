//! The MQTT link's lost sessions, told once and then summarised: a link that keeps losing its
//! session soon after connecting is what a client taking over chassisd's client id looks
//! like (MQTT hands an id to its newest connection, and MQTT 3.1.1 says nothing of why), so
//! the summary names that cause and its remedy instead of a line per loss.

use std::time::{Duration, Instant};

/// Losses are counted over this window.
const WINDOW: Duration = Duration::from_secs(60);
/// A session lost within this long of its CONNACK counts as cut short.
const SHORT: Duration = Duration::from_secs(10);
/// Sessions cut short within the window that make a takeover the likely cause.
const TAKEOVER_AFTER: u32 = 3;
/// The summary period while losses go on.
const SUMMARY_EVERY: Duration = Duration::from_secs(5);

/// What to log for a lost session.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Tell {
    /// The first loss of a calm period: one warning.
    Lost,
    /// Sessions keep being cut short: a takeover of the client id is likely (told once
    /// per window).
    LikelyTakeover { cut_short: u32 },
    /// Nothing now; the count goes into the next summary.
    Quiet,
}

/// The link's recent sessions.
#[derive(Debug, Default)]
pub struct Losses {
    connected_at: Option<Instant>,
    window_start: Option<Instant>,
    lost: u32,
    cut_short: u32,
    takeover_told: bool,
    last_summary: Option<Instant>,
    unsummarised: u32,
}

impl Losses {
    /// A session began (CONNACK) at `now`.
    pub fn connected(&mut self, now: Instant) {
        self.connected_at = Some(now);
    }

    /// The session was lost at `now`.
    pub fn lost(&mut self, now: Instant) -> Tell {
        let short = self
            .connected_at
            .take()
            .is_some_and(|at| now.duration_since(at) < SHORT);
        if self
            .window_start
            .is_none_or(|start| now.duration_since(start) > WINDOW)
        {
            *self = Self {
                window_start: Some(now),
                last_summary: Some(now),
                ..Self::default()
            };
        }
        self.lost += 1;
        self.cut_short += u32::from(short);
        if self.lost == 1 {
            return Tell::Lost;
        }
        self.unsummarised += 1;
        if self.cut_short >= TAKEOVER_AFTER && !self.takeover_told {
            self.takeover_told = true;
            return Tell::LikelyTakeover {
                cut_short: self.cut_short,
            };
        }
        Tell::Quiet
    }

    /// Losses not yet told, when a summary is due at `now`.
    pub fn due_summary(&mut self, now: Instant) -> Option<u32> {
        let due = self
            .last_summary
            .is_some_and(|at| now.duration_since(at) >= SUMMARY_EVERY);
        if !due || self.unsummarised == 0 {
            return None;
        }
        self.last_summary = Some(now);
        Some(std::mem::take(&mut self.unsummarised))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sessions_cut_short_again_and_again_are_told_once_as_a_takeover() {
        let mut l = Losses::default();
        let t0 = Instant::now();
        let mut told = Vec::new();
        for i in 0..90u64 {
            let at = t0 + Duration::from_millis(160 * i);
            l.connected(at);
            told.push(l.lost(at + Duration::from_millis(50)));
        }
        assert_eq!(told[0], Tell::Lost);
        assert_eq!(told[1], Tell::Quiet);
        assert_eq!(told[2], Tell::LikelyTakeover { cut_short: 3 });
        assert!(told[3..].iter().all(|t| *t == Tell::Quiet));
        let summary = l.due_summary(t0 + Duration::from_secs(15));
        assert_eq!(summary, Some(89));
        assert_eq!(l.due_summary(t0 + Duration::from_secs(16)), None);
    }

    #[test]
    fn a_rare_loss_of_a_long_session_is_no_takeover() {
        let mut l = Losses::default();
        let t0 = Instant::now();
        for i in 0..5u64 {
            let at = t0 + Duration::from_secs(70 * i);
            l.connected(at);
            assert_eq!(l.lost(at + Duration::from_secs(60)), Tell::Lost);
        }
    }
}
