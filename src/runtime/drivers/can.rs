//! SocketCAN driver: one task per interface. Reads, timestamps and forwards every frame
//! (error frames included, decoded into their causes downstream); writes the engine's frames
//! from a bounded queue; reports the link state and reconnects with back-off when the
//! interface goes down, fails or goes bus-off. Frames that cannot be written are counted and
//! reported, never dropped silently.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use socketcan::tokio::CanSocket;
use socketcan::{CanAnyFrame, CanError, CanFrame, SocketOptions};
use tokio::sync::mpsc;

use crate::devices::can::Frame;
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::outage_log::{OutageLog, Say};
use crate::vehicle::LinkState;

/// First reconnect delay; it doubles up to the configured maximum.
const BACKOFF_START: Duration = Duration::from_millis(100);
/// How long one frame may wait for room in the socket's send buffer.
const WRITE_TIMEOUT: Duration = Duration::from_millis(100);
/// How often an open interface is checked for having been set down.
const LINK_CHECK: Duration = Duration::from_millis(200);

/// Which interface and how.
#[derive(Debug, Clone)]
pub struct CanSpec {
    /// Interface name.
    pub interface: String,
    /// Longest reconnect delay.
    pub reconnect_max: Duration,
}

/// The engine's side of a CAN driver: a bounded queue of frames to write.
#[derive(Debug, Clone)]
pub struct CanTx {
    queue: mpsc::Sender<Frame>,
    dropped: Arc<AtomicU64>,
    /// Frames queued and not yet written (or dropped) by the driver.
    pending: Arc<AtomicU64>,
}

impl CanTx {
    /// Queues a frame without waiting. A full queue drops it; the drop is counted.
    pub fn send(&self, frame: Frame) {
        self.pending.fetch_add(1, Ordering::Relaxed);
        if self.queue.try_send(frame).is_err() {
            self.pending.fetch_sub(1, Ordering::Relaxed);
            let n = self.dropped.fetch_add(1, Ordering::Relaxed) + 1;
            if n.is_power_of_two() {
                tracing::error!(dropped = n, "CAN transmit queue full; frames dropped");
            }
        }
    }

    /// Waits until every queued frame has been written (or dropped), at most `limit`.
    /// Returns whether the queue drained.
    pub async fn flush(&self, limit: Duration) -> bool {
        let deadline = tokio::time::Instant::now() + limit;
        while self.pending.load(Ordering::Relaxed) > 0 {
            if tokio::time::Instant::now() >= deadline {
                return false;
            }
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        true
    }

    /// Frames dropped so far (queue full, interface down, or write failed).
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// Starts the driver for `spec`. Frames and link events go to `records`.
pub fn spawn(
    spec: CanSpec,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
    queue_len: usize,
) -> CanTx {
    let (queue, frames) = mpsc::channel(queue_len.max(1));
    let dropped = Arc::new(AtomicU64::new(0));
    let pending = Arc::new(AtomicU64::new(0));
    let counters = Counters {
        dropped: dropped.clone(),
        pending: pending.clone(),
    };
    // The drives' link: a panic here stops them and ends the process (`panics`).
    tokio::spawn(crate::runtime::panics::safety_relevant(run(
        spec, clock, records, frames, counters,
    )));
    CanTx {
        queue,
        dropped,
        pending,
    }
}

/// The driver's side of the transmit counters.
struct Counters {
    dropped: Arc<AtomicU64>,
    pending: Arc<AtomicU64>,
}

impl Counters {
    /// A frame left the queue: written, or dropped when `dropped`.
    fn done(&self, dropped: bool) {
        if dropped {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        self.pending.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Whether the kernel says the interface is administratively up (IFF_UP).
pub(crate) fn interface_up(name: &str) -> Result<bool, String> {
    let flags = std::fs::read_to_string(format!("/sys/class/net/{name}/flags"))
        .map_err(|e| format!("no interface {name}: {e}"))?;
    let flags = u32::from_str_radix(flags.trim().trim_start_matches("0x"), 16)
        .map_err(|e| format!("flags of {name}: {e}"))?;
    Ok(flags & 0x1 != 0)
}

pub(crate) fn open(name: &str) -> Result<CanSocket, String> {
    if !interface_up(name)? {
        return Err(format!("{name} is down"));
    }
    let socket = CanSocket::open(name).map_err(|e| e.to_string())?;
    // Error frames carry bus-off, error-passive and the like; they are decoded downstream.
    socket
        .set_error_filter_accept_all()
        .map_err(|e| e.to_string())?;
    Ok(socket)
}

async fn run(
    spec: CanSpec,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
    mut frames: mpsc::Receiver<Frame>,
    counters: Counters,
) {
    let name = spec.interface.clone();
    let mut backoff = BACKOFF_START;
    let mut failures: u64 = 0;
    let mut outage = OutageLog::default();
    let mut outage_since: Option<Instant> = None;
    loop {
        match open(&name) {
            Ok(socket) => {
                tracing::info!(device = %name, after_failed_attempts = failures, "link up");
                failures = 0;
                outage.recovered();
                outage_since = None;
                backoff = BACKOFF_START;
                if send(&records, &clock, &name, Payload::Link(LinkState::Up))
                    .await
                    .is_err()
                {
                    return;
                }
                let reason =
                    match serve(&socket, &name, &clock, &records, &mut frames, &counters).await {
                        Ok(reason) => reason,
                        Err(Closed) => return,
                    };
                tracing::warn!(device = %name, %reason, "link down; reconnecting");
                if send(&records, &clock, &name, Payload::Link(LinkState::Down))
                    .await
                    .is_err()
                {
                    return;
                }
            }
            Err(e) => {
                failures += 1;
                let since = *outage_since.get_or_insert_with(Instant::now);
                match outage.failed(since.elapsed()) {
                    Say::First => {
                        tracing::warn!(device = %name, error = %e, "cannot open CAN interface; retrying");
                    }
                    Say::Still(attempts) => {
                        tracing::warn!(device = %name, error = %e, attempts,
                            for_s = since.elapsed().as_secs(), "CAN interface still unavailable; retrying");
                    }
                    Say::Quiet => {}
                }
            }
        }
        // While down, queued frames cannot go anywhere: count them.
        let deadline = tokio::time::sleep(backoff);
        tokio::pin!(deadline);
        loop {
            tokio::select! {
                () = &mut deadline => break,
                frame = frames.recv() => match frame {
                    Some(_) => counters.done(true),
                    None => return,
                },
            }
        }
        backoff = (backoff * 2).min(spec.reconnect_max.max(BACKOFF_START));
    }
}

/// The engine is gone; the driver stops.
struct Closed;

/// Reads and writes until the interface fails. Returns why.
async fn serve(
    socket: &CanSocket,
    name: &str,
    clock: &RecordClock,
    records: &mpsc::Sender<Record>,
    frames: &mut mpsc::Receiver<Frame>,
    counters: &Counters,
) -> Result<String, Closed> {
    let mut check = tokio::time::interval(LINK_CHECK);
    loop {
        tokio::select! {
            read = socket.read_frame() => match read {
                Ok(frame) => {
                    let bus_off = matches!(&frame, CanFrame::Error(e) if CanError::from(*e).is_bus_off());
                    send(records, clock, name, Payload::Can(CanAnyFrame::from(frame))).await?;
                    if bus_off {
                        return Ok("bus-off".into());
                    }
                }
                Err(e) => return Ok(e.to_string()),
            },
            frame = frames.recv() => {
                let Some(frame) = frame else { return Err(Closed) };
                match tokio::time::timeout(WRITE_TIMEOUT, socket.write_frame(frame.to_socketcan())).await {
                    Ok(Ok(())) => counters.done(false),
                    Ok(Err(e)) => {
                        counters.done(true);
                        // A full buffer (no one acknowledging) is not a lost interface.
                        if e.raw_os_error() != Some(105) {
                            return Ok(format!("write failed: {e}"));
                        }
                    }
                    Err(_) => counters.done(true),
                }
            }
            _ = check.tick() => {
                if !interface_up(name).unwrap_or(false) {
                    return Ok("interface set down".into());
                }
            }
        }
    }
}

async fn send(
    records: &mpsc::Sender<Record>,
    clock: &RecordClock,
    name: &str,
    payload: Payload,
) -> Result<(), Closed> {
    let record = Record {
        t: clock.now(),
        source: name.to_owned(),
        payload,
    };
    records.send(record).await.map_err(|_| Closed)
}
