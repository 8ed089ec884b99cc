//! systemd's notify protocol for `chassisd run` under a `Type=notify` unit: READY once every
//! configured device and the broker have come up (or, with some still missing, after a grace
//! period, saying which in STATUS), WATCHDOG pings from the control loop itself (a hung core
//! stops them, and systemd restarts it), and STOPPING on the way out. Without
//! `NOTIFY_SOCKET` every call does nothing. READY and the pings leave from a thread of their
//! own: a datagram send blocks when systemd's queue is full, and the control loop must never
//! wait on a socket.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use sd_notify::NotifyState;

/// What the sending thread passes on.
#[derive(Debug)]
enum Note {
    Ready(String),
    Watchdog,
}

/// Notes waiting for the sending thread; beyond this they are dropped (a sender that far
/// behind is stuck, and a missed ping is what systemd should then see).
const OUTBOX: usize = 4;

/// Starts the thread that hands notes to the service manager.
fn spawn_sender() -> Option<std::sync::mpsc::SyncSender<Note>> {
    let (tx, rx) = std::sync::mpsc::sync_channel::<Note>(OUTBOX);
    let spawned = std::thread::Builder::new()
        .name("sd-notify".into())
        .spawn(move || {
            for note in rx {
                let result = match &note {
                    Note::Ready(status) => {
                        sd_notify::notify(&[NotifyState::Ready, NotifyState::Status(status)])
                    }
                    Note::Watchdog => sd_notify::notify(&[NotifyState::Watchdog]),
                };
                if let Err(e) = result {
                    tracing::warn!(error = %e, "cannot notify the service manager");
                }
            }
        });
    match spawned {
        Ok(_) => Some(tx),
        Err(e) => {
            tracing::error!(error = %e, "cannot start the notify thread: systemd hears nothing");
            None
        }
    }
}

/// The service manager as the run loop tells it how things stand.
#[derive(Debug)]
pub struct ServiceManager {
    /// The sending thread, when anyone listens (`NOTIFY_SOCKET` is set).
    outbox: Option<std::sync::mpsc::SyncSender<Note>>,
    /// Ping at least this often (a quarter of `WatchdogSec`), when the watchdog is on.
    feed_every: Option<Duration>,
    last_feed: Option<Instant>,
    /// Sources that have not come up yet.
    waiting: BTreeSet<String>,
    ready: bool,
    /// READY goes out by then even with sources missing.
    ready_by: Instant,
}

impl ServiceManager {
    /// A manager that waits for `sources` (their link records) for up to `grace` from `now`.
    pub fn new(sources: impl IntoIterator<Item = String>, grace: Duration, now: Instant) -> Self {
        Self::with(
            std::env::var_os("NOTIFY_SOCKET").is_some(),
            sd_notify::watchdog_enabled(),
            sources,
            grace,
            now,
        )
    }

    fn with(
        listening: bool,
        watchdog: Option<Duration>,
        sources: impl IntoIterator<Item = String>,
        grace: Duration,
        now: Instant,
    ) -> Self {
        Self {
            outbox: listening.then(spawn_sender).flatten(),
            feed_every: watchdog.map(|w| w / 4),
            last_feed: None,
            waiting: sources.into_iter().collect(),
            ready: false,
            ready_by: now + grace,
        }
    }

    /// The watchdog's period as systemd set it, for the log.
    pub fn watchdog(&self) -> Option<Duration> {
        self.feed_every.map(|f| f * 4)
    }

    /// Whether READY has gone out.
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// `source`'s link came up.
    pub fn link_up(&mut self, source: &str, now: Instant) {
        if self.waiting.remove(source) {
            self.check_ready(now);
        }
    }

    /// A control tick ran at `now`: feeds the watchdog when due, and sends READY once the
    /// grace period is over.
    pub fn tick(&mut self, now: Instant) {
        self.check_ready(now);
        if let Some(every) = self.feed_every
            && self
                .last_feed
                .is_none_or(|l| now.duration_since(l) >= every)
        {
            self.last_feed = Some(now);
            self.post(Note::Watchdog);
        }
    }

    /// The daemon is shutting down for `why` (sent from the calling thread: the control loop
    /// has ended).
    pub fn stopping(&self, why: &str) {
        if self.outbox.is_none() {
            return;
        }
        let status = format!("stopping ({why}): drives quick-stopped, targets zero");
        if let Err(e) = sd_notify::notify(&[NotifyState::Stopping, NotifyState::Status(&status)]) {
            tracing::warn!(error = %e, "cannot notify the service manager");
        }
    }

    fn check_ready(&mut self, now: Instant) {
        if self.ready || (!self.waiting.is_empty() && now < self.ready_by) {
            return;
        }
        self.ready = true;
        let status = if self.waiting.is_empty() {
            "running: every device and the broker are up".to_owned()
        } else {
            let missing: Vec<&str> = self.waiting.iter().map(String::as_str).collect();
            format!("running; not up yet: {}", missing.join(", "))
        };
        tracing::info!(%status, "ready");
        self.post(Note::Ready(status));
    }

    /// Hands a note to the sending thread without waiting.
    fn post(&self, note: Note) {
        if let Some(outbox) = &self.outbox {
            let _ = outbox.try_send(note);
        }
    }
}

/// A deliberate stall of the control loop, for checking the watchdog on a real system:
/// `CHASSISD_INJECT_CORE_STALL=SECONDS@AFTER` blocks the loop once for SECONDS, AFTER
/// seconds from start. Never set on a vehicle in service (the drives stop by themselves, and
/// systemd kills the daemon); its use is logged as a warning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InjectedStall {
    at: Instant,
    length: Duration,
}

/// The environment variable of [`InjectedStall`].
pub const INJECT_CORE_STALL: &str = "CHASSISD_INJECT_CORE_STALL";

impl InjectedStall {
    /// The stall the environment asks for, if any (a malformed value is logged and ignored).
    pub fn from_env(now: Instant) -> Option<Self> {
        let text = std::env::var(INJECT_CORE_STALL).ok()?;
        let parsed = text.split_once('@').and_then(|(length, after)| {
            let length: f64 = length.trim().parse().ok()?;
            let after: f64 = after.trim().parse().ok()?;
            let ok = |v: f64| v.is_finite() && (0.0..=3600.0).contains(&v);
            (ok(length) && ok(after)).then(|| Self {
                at: now + Duration::from_secs_f64(after),
                length: Duration::from_secs_f64(length),
            })
        });
        match parsed {
            Some(_) => tracing::warn!(
                value = %text,
                "{INJECT_CORE_STALL} is set: the control loop will stall on purpose"
            ),
            None => tracing::warn!(
                value = %text,
                "{INJECT_CORE_STALL} ignored: give SECONDS@AFTER, e.g. 3@5"
            ),
        }
        parsed
    }

    /// Blocks the calling thread for the stall's length once its time has come; true when
    /// it did (the stall is then spent).
    pub fn block_if_due(&self, now: Instant) -> bool {
        if now < self.at {
            return false;
        }
        tracing::warn!(
            seconds = self.length.as_secs_f64(),
            "injected control-loop stall"
        );
        std::thread::sleep(self.length);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manager(sources: &[&str], now: Instant) -> ServiceManager {
        ServiceManager::with(
            false,
            Some(Duration::from_secs(2)),
            sources.iter().map(|s| (*s).to_owned()),
            Duration::from_secs(10),
            now,
        )
    }

    #[test]
    fn ready_once_every_source_is_up_or_the_grace_is_over() {
        let t0 = Instant::now();
        let mut m = manager(&["gnss", "can0"], t0);
        m.tick(t0 + Duration::from_secs(1));
        assert!(!m.is_ready());
        m.link_up("gnss", t0 + Duration::from_secs(2));
        assert!(!m.is_ready());
        m.link_up("can0", t0 + Duration::from_secs(3));
        assert!(m.is_ready());
        let mut late = manager(&["gnss"], t0);
        late.tick(t0 + Duration::from_secs(9));
        assert!(!late.is_ready());
        late.tick(t0 + Duration::from_secs(10));
        assert!(
            late.is_ready(),
            "READY after the grace, saying what is missing"
        );
    }

    #[test]
    fn the_watchdog_is_fed_a_quarter_period_apart_only_by_ticks() {
        let t0 = Instant::now();
        let mut m = manager(&[], t0);
        assert_eq!(m.watchdog(), Some(Duration::from_secs(2)));
        m.tick(t0);
        assert_eq!(m.last_feed, Some(t0));
        m.tick(t0 + Duration::from_millis(400));
        assert_eq!(m.last_feed, Some(t0), "not yet due");
        m.tick(t0 + Duration::from_millis(500));
        assert_eq!(m.last_feed, Some(t0 + Duration::from_millis(500)));
        // A link event is not a tick: it feeds nothing.
        m.link_up("gnss", t0 + Duration::from_secs(5));
        assert_eq!(m.last_feed, Some(t0 + Duration::from_millis(500)));
    }
}
