//! Which panics stop the vehicle, and which are contained.
//!
//! Safety-relevant code is the control loop (the engine with the core, run by `run`'s main
//! future) and the CAN drivers that carry its frames to the drives. A panic there means
//! the drives can no longer be commanded: every drive is quick-stopped with zero targets
//! straight on its interface, and the process ends with status 101 (systemd restarts it).
//! Every other task (the MQTT link, the serial drivers, the WebSocket and ROS1 servers, the
//! samplers, the writer threads) is auxiliary: its panic is contained, logged once per
//! place in the code, counted, and the task restarted or its service reported down; the
//! control loop, its watchdogs and the drives go on as they were.

use std::cell::Cell;
use std::collections::HashSet;
use std::future::Future;
use std::panic::AssertUnwindSafe;
use std::pin::Pin;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use crate::devices::can::Frame;

thread_local! {
    /// Set while safety-relevant code runs on this thread.
    static SAFETY_RELEVANT: Cell<bool> = const { Cell::new(false) };
}

/// Contained panics since start.
static CONTAINED: AtomicU64 = AtomicU64::new(0);
/// Places in the code whose panic was logged (each once; bounded).
static LOGGED: Mutex<Option<HashSet<String>>> = Mutex::new(None);
/// Places remembered; beyond them, panics are still counted but no longer logged.
const MAX_LOGGED_PLACES: usize = 64;
/// The exit status after a safety-relevant panic (Rust's own for a panic).
pub const SAFETY_PANIC_EXIT: i32 = 101;
/// A restarted task waits this long first, so that a task that panics at once cannot spin.
const RESTART_DELAY: Duration = Duration::from_secs(1);

/// Contained panics since start.
pub fn contained() -> u64 {
    CONTAINED.load(Ordering::Relaxed)
}

/// Whether the calling thread is running safety-relevant code now.
pub fn in_safety_relevant() -> bool {
    SAFETY_RELEVANT.with(Cell::get)
}

/// Marks `future` safety-relevant: a panic while it is polled stops the drives and ends
/// the process.
pub fn safety_relevant<F: Future>(future: F) -> SafetyRelevant<F> {
    SafetyRelevant {
        inner: Box::pin(future),
    }
}

/// A future whose polls run marked safety-relevant.
pub struct SafetyRelevant<F> {
    inner: Pin<Box<F>>,
}

/// Clears the mark when a poll ends, unwinding included (the panic hook has run by then).
struct Unmark(bool);

impl Drop for Unmark {
    fn drop(&mut self) {
        SAFETY_RELEVANT.with(|c| c.set(self.0));
    }
}

impl<F: Future> Future for SafetyRelevant<F> {
    type Output = F::Output;

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<F::Output> {
        let _unmark = Unmark(SAFETY_RELEVANT.with(|c| c.replace(true)));
        self.inner.as_mut().poll(cx)
    }
}

/// Runs `future`, turning a panic inside it into `Err(())` (the hook has logged it).
pub async fn contain<F: Future>(future: F) -> Result<F::Output, ()> {
    CatchUnwind {
        inner: Box::pin(future),
    }
    .await
}

struct CatchUnwind<F> {
    inner: Pin<Box<F>>,
}

impl<F: Future> Future for CatchUnwind<F> {
    type Output = Result<F::Output, ()>;

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        let inner = self.inner.as_mut();
        match std::panic::catch_unwind(AssertUnwindSafe(|| inner.poll(cx))) {
            Ok(Poll::Ready(v)) => Poll::Ready(Ok(v)),
            Ok(Poll::Pending) => Poll::Pending,
            Err(_) => Poll::Ready(Err(())),
        }
    }
}

/// Runs the task `make()` builds, and builds and runs it again after a panic, until it
/// ends by itself. `name` is for the log.
pub async fn restarting<F, Fut>(name: &'static str, mut make: F)
where
    F: FnMut() -> Fut,
    Fut: Future<Output = ()>,
{
    while contain(make()).await.is_err() {
        tracing::error!(task = name, "task restarted after a panic");
        tokio::time::sleep(RESTART_DELAY).await;
    }
}

/// The environment variable that injects a panic, for checking containment on a real
/// system: `CHASSISD_INJECT_PANIC=mqtt` panics the MQTT link at its first command,
/// `control` the control loop at its first command (comma-separated for both). Never set
/// on a vehicle in service; its use is logged as a warning.
pub const INJECT_PANIC: &str = "CHASSISD_INJECT_PANIC";

/// Whether a panic is to be injected into `task` now: true once per task and process.
pub fn inject(task: &str) -> bool {
    static WANTED: std::sync::OnceLock<Mutex<Vec<String>>> = std::sync::OnceLock::new();
    let wanted = WANTED.get_or_init(|| {
        let tasks: Vec<String> = std::env::var(INJECT_PANIC)
            .map(|v| v.split(',').map(|t| t.trim().to_owned()).collect())
            .unwrap_or_default();
        if !tasks.is_empty() {
            tracing::warn!(tasks = ?tasks, "{INJECT_PANIC} is set: panics will be injected on purpose");
        }
        Mutex::new(tasks)
    });
    let mut wanted = wanted
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    match wanted.iter().position(|t| t == task) {
        Some(i) => {
            wanted.remove(i);
            true
        }
        None => false,
    }
}

/// Runs a service that cannot simply start again (it owns listeners and client sessions);
/// after a panic it is reported down, once, and stays down until chassisd restarts.
pub async fn or_report_down<F: Future<Output = ()>>(name: &'static str, service: F) {
    if contain(service).await.is_err() {
        tracing::error!(
            service = name,
            "stopped after a panic; it stays down until chassisd restarts (the vehicle's control goes on)"
        );
    }
}

/// Installs the panic hook: a safety-relevant panic sends `stop_frames` (quick stop, zero
/// targets, by interface) straight to the buses and ends the process; any other is logged
/// once per place and counted.
pub fn install(stop_frames: Vec<(String, Frame)>) {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if in_safety_relevant() {
            report(info);
            if !stop_frames.is_empty() {
                let sent = write_now(&stop_frames);
                crate::runtime::stderr::line(format!(
                    "chassisd: panic in the control loop or a CAN driver: {sent} of {} stop \
                     frames sent; the process ends",
                    stop_frames.len()
                ));
            } else {
                crate::runtime::stderr::line(
                    "chassisd: panic in the control loop or a CAN driver; the process ends".into(),
                );
            }
            std::process::exit(SAFETY_PANIC_EXIT);
        }
        let count = CONTAINED.fetch_add(1, Ordering::Relaxed) + 1;
        let place = info
            .location()
            .map_or_else(|| "an unknown place".to_owned(), ToString::to_string);
        let first = {
            let mut logged = LOGGED
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            let places = logged.get_or_insert_with(HashSet::new);
            places.len() < MAX_LOGGED_PLACES && places.insert(place.clone())
        };
        if first {
            let message = message_of(info);
            let thread = std::thread::current();
            crate::runtime::stderr::line(format!(
                "chassisd: an auxiliary task panicked at {place} (thread {}): {message}; it is \
                 contained, the vehicle's control goes on (panic {count}; further ones from \
                 here are only counted)",
                thread.name().unwrap_or("unnamed")
            ));
        }
    }));
}

/// A panic's message: the text `panic!` was given, or empty for another payload.
pub fn message_of(info: &std::panic::PanicHookInfo<'_>) -> String {
    let payload = info.payload();
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_default()
}

/// How long the last writes of a panicking daemon may block each.
const LAST_WRITE_TIMEOUT: std::time::Duration = std::time::Duration::from_millis(100);

/// Writes `frames` straight to their interfaces with blocking sockets, bypassing the driver
/// tasks and the runtime: the last act of a panicking daemon. Returns how many went out.
fn write_now(frames: &[(String, Frame)]) -> usize {
    use socketcan::Socket;
    let mut sent = 0;
    let mut open: Vec<(&str, socketcan::CanSocket)> = Vec::new();
    for (bus, frame) in frames {
        if !open.iter().any(|(name, _)| name == bus) {
            match socketcan::CanSocket::open(bus) {
                Ok(s) => {
                    let _ = s.set_write_timeout(LAST_WRITE_TIMEOUT);
                    open.push((bus, s));
                }
                Err(_) => continue,
            }
        }
        if let Some((_, socket)) = open.iter().find(|(name, _)| name == bus)
            && socket.write_frame(&frame.to_socketcan()).is_ok()
        {
            sent += 1;
        }
    }
    sent
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn the_mark_holds_while_polled_and_is_cleared_after_a_panic() {
        assert!(!in_safety_relevant());
        let inside = safety_relevant(async { in_safety_relevant() }).await;
        assert!(inside);
        assert!(!in_safety_relevant());
        let caught = contain(safety_relevant(async {
            if in_safety_relevant() {
                panic!("deliberate");
            }
        }))
        .await;
        assert!(caught.is_err());
        assert!(!in_safety_relevant(), "unwinding clears the mark");
    }

    #[tokio::test]
    async fn a_restarting_task_runs_again_after_a_panic() {
        let runs = std::sync::Arc::new(AtomicU64::new(0));
        let counted = runs.clone();
        restarting("test", move || {
            let n = counted.fetch_add(1, Ordering::Relaxed);
            async move {
                if n < 2 {
                    panic!("deliberate");
                }
            }
        })
        .await;
        assert_eq!(runs.load(Ordering::Relaxed), 3);
    }
}
