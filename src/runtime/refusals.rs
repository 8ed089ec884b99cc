//! A server's refusals and drops of clients, counted and summed up in one log line every
//! [`SUMMARY_EVERY`] while any happen, never one line per client: a flood of connections
//! must not become a flood of log lines.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::Duration;

/// How often what was counted goes to the log.
pub const SUMMARY_EVERY: Duration = Duration::from_secs(5);

/// One server's counters, by reason.
#[derive(Debug)]
pub struct Refusals {
    /// The server, as the log names it (`websocket`).
    server: &'static str,
    reasons: &'static [&'static str],
    counts: Box<[AtomicU64]>,
    /// The last peer counted and why, for the summary.
    last: Mutex<Option<(SocketAddr, &'static str)>>,
}

impl Refusals {
    /// Counters for `reasons`, and the task that logs them (on the current runtime, ending
    /// when the counters are dropped).
    pub fn start(server: &'static str, reasons: &'static [&'static str]) -> Arc<Self> {
        let refusals = Arc::new(Self::new(server, reasons));
        tokio::spawn(summarise(Arc::downgrade(&refusals)));
        refusals
    }

    /// Counters for `reasons`, with no summary task.
    pub fn new(server: &'static str, reasons: &'static [&'static str]) -> Self {
        Self {
            server,
            reasons,
            counts: reasons.iter().map(|_| AtomicU64::new(0)).collect(),
            last: Mutex::new(None),
        }
    }

    /// Counts one refusal or drop of `peer` for `reason` (one of the server's reasons).
    pub fn count(&self, reason: &'static str, peer: Option<SocketAddr>) {
        let Some(i) = self.reasons.iter().position(|r| *r == reason) else {
            debug_assert!(false, "{reason} is not one of {:?}", self.reasons);
            return;
        };
        self.counts[i].fetch_add(1, Ordering::Relaxed);
        if let Some(peer) = peer {
            *self
                .last
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = Some((peer, reason));
        }
    }

    /// Counted so far for `reason`.
    pub fn total(&self, reason: &str) -> u64 {
        self.reasons
            .iter()
            .position(|r| *r == reason)
            .map_or(0, |i| self.counts[i].load(Ordering::Relaxed))
    }

    fn snapshot(&self) -> Vec<u64> {
        self.counts
            .iter()
            .map(|c| c.load(Ordering::Relaxed))
            .collect()
    }

    /// What changed between `before` and `now`: `reason=n` for each that did, or `None`.
    fn line(&self, before: &[u64], now: &[u64]) -> Option<String> {
        let parts: Vec<String> = self
            .reasons
            .iter()
            .zip(before.iter().zip(now))
            .filter(|(_, (b, n))| n > b)
            .map(|(r, (b, n))| format!("{r}={}", n - b))
            .collect();
        (!parts.is_empty()).then(|| parts.join(" "))
    }
}

/// Logs what changed every [`SUMMARY_EVERY`], while the counters exist.
async fn summarise(refusals: Weak<Refusals>) {
    let mut every = tokio::time::interval(SUMMARY_EVERY);
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut before = match refusals.upgrade() {
        Some(r) => r.snapshot(),
        None => return,
    };
    loop {
        every.tick().await;
        let Some(refusals) = refusals.upgrade() else {
            return;
        };
        let now = refusals.snapshot();
        if let Some(counts) = refusals.line(&before, &now) {
            let last = *refusals
                .last
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            tracing::warn!(
                last_peer = ?last.map(|l| l.0),
                last_reason = last.map_or("", |l| l.1),
                "{}: clients refused or closed in the last {} s: {counts}",
                refusals.server,
                SUMMARY_EVERY.as_secs()
            );
        }
        before = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_summary_names_what_changed_only() {
        let r = Refusals::new("test", &["full", "timeout", "token"]);
        let before = r.snapshot();
        assert_eq!(r.line(&before, &r.snapshot()), None);
        r.count("full", None);
        r.count("token", Some("127.0.0.1:1".parse().unwrap()));
        r.count("token", None);
        assert_eq!(
            r.line(&before, &r.snapshot()).as_deref(),
            Some("full=1 token=2")
        );
        assert_eq!(r.total("token"), 2);
    }
}
