//! Whether a broker delivers a link's own messages back to it. A broker whose ACL denies
//! the vehicle's topics may say nothing: mosquitto grants the subscription and drops what it
//! may not deliver, so the link would wait for commands that never come. Each session the
//! link subscribes to its own status topic, and its `online` should come back within
//! [`Echo::WAIT`]; when it does not, the link says so once.

use std::time::{Duration, Instant};

/// The echo of one session's `online`.
#[derive(Debug, Default)]
pub struct Echo {
    /// When the echo is overdue; `None` once heard (or before the first session).
    due: Option<Instant>,
    /// It was overdue and said so this session.
    told: bool,
}

impl Echo {
    /// How long the broker may take to deliver `online` back.
    pub const WAIT: Duration = Duration::from_secs(5);

    /// A session began and `online` was handed over at `now`.
    pub fn sent(&mut self, now: Instant) {
        self.due = Some(now + Self::WAIT);
        self.told = false;
    }

    /// `online` came back. True when it had been said to be missing (worth a line).
    pub fn heard(&mut self) -> bool {
        self.due = None;
        std::mem::take(&mut self.told)
    }

    /// The session ended before the echo came: nothing is overdue.
    pub fn lost(&mut self) {
        self.due = None;
    }

    /// True once per session, when the echo is overdue at `now`.
    pub fn overdue(&mut self, now: Instant) -> bool {
        if self.due.is_some_and(|due| now >= due) && !self.told {
            self.told = true;
            return true;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_echo_is_told_once_per_session_and_its_return_too() {
        let t0 = Instant::now();
        let mut e = Echo::default();
        assert!(!e.overdue(t0 + Duration::from_secs(60)), "no session yet");
        e.sent(t0);
        assert!(!e.overdue(t0 + Duration::from_secs(4)));
        assert!(e.overdue(t0 + Duration::from_secs(5)));
        assert!(!e.overdue(t0 + Duration::from_secs(6)), "told once");
        assert!(e.heard(), "its return is worth a line");
        e.sent(t0 + Duration::from_secs(10));
        assert!(!e.heard(), "heard in time: nothing to say");
        assert!(!e.overdue(t0 + Duration::from_secs(30)));
        e.sent(t0 + Duration::from_secs(40));
        e.lost();
        assert!(
            !e.overdue(t0 + Duration::from_secs(50)),
            "the session ended first"
        );
    }
}
