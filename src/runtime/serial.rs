//! Serial driver: one task per port. Reads, timestamps and forwards raw chunks; reports the
//! link state; reconnects with back-off when the port disappears or fails.

use std::time::{Duration, Instant};

use bytes::{Bytes, BytesMut};
use tokio::io::AsyncReadExt;
use tokio::sync::mpsc;
use tokio_serial::SerialPortBuilderExt;

use super::clock::RecordClock;
use super::outage_log::{OutageLog, Say};
use crate::core::LinkState;
use crate::record::{Payload, Record};

/// First reconnect delay; it doubles up to the configured maximum.
const BACKOFF_START: Duration = Duration::from_millis(100);
/// Read buffer size; a read returns whatever the port has, up to this.
const READ_BUFFER: usize = 4096;

/// Which port to read and how.
#[derive(Debug, Clone)]
pub struct SerialSpec {
    /// Source name in records (`gnss`).
    pub source: String,
    /// Device path.
    pub port: String,
    /// Baud rate.
    pub baud: u32,
    /// Longest reconnect delay.
    pub reconnect_max: Duration,
}

/// Runs until the receiving side of `tx` closes.
pub async fn run(spec: SerialSpec, clock: RecordClock, tx: mpsc::Sender<Record>) {
    let mut backoff = BACKOFF_START;
    let mut failed_attempts: u64 = 0;
    let mut outage = OutageLog::default();
    let mut outage_since: Option<Instant> = None;
    loop {
        match tokio_serial::new(&spec.port, spec.baud).open_native_async() {
            Ok(mut port) => {
                tracing::info!(device = %spec.source, port = %spec.port, baud = spec.baud,
                    after_failed_attempts = failed_attempts, "link up");
                failed_attempts = 0;
                outage.recovered();
                outage_since = None;
                if send(&tx, &spec, &clock, Payload::Link(LinkState::Up))
                    .await
                    .is_err()
                {
                    return;
                }
                let (reason, got_data) =
                    match read_until_failure(&mut port, &spec, &clock, &tx).await {
                        Ok(outcome) => outcome,
                        Err(Closed) => return,
                    };
                tracing::warn!(device = %spec.source, port = %spec.port, %reason, "link down; reconnecting");
                if send(&tx, &spec, &clock, Payload::Link(LinkState::Down))
                    .await
                    .is_err()
                {
                    return;
                }
                if got_data {
                    backoff = BACKOFF_START;
                }
            }
            Err(e) => {
                failed_attempts += 1;
                let since = *outage_since.get_or_insert_with(Instant::now);
                match outage.failed(since.elapsed()) {
                    Say::First => {
                        tracing::warn!(device = %spec.source, port = %spec.port, error = %e, "cannot open port; retrying");
                    }
                    Say::Still(attempts) => {
                        tracing::warn!(device = %spec.source, port = %spec.port, error = %e,
                            attempts, for_s = since.elapsed().as_secs(), "port still unavailable; retrying");
                    }
                    Say::Quiet => {
                        tracing::debug!(device = %spec.source, port = %spec.port, error = %e, "open failed");
                    }
                }
            }
        }
        if tx.is_closed() {
            return;
        }
        tokio::time::sleep(backoff).await;
        backoff = (backoff * 2).min(spec.reconnect_max.max(BACKOFF_START));
    }
}

/// The engine is gone; the driver stops.
struct Closed;

/// Reads until the port fails. Returns why, and whether any data arrived.
async fn read_until_failure(
    port: &mut tokio_serial::SerialStream,
    spec: &SerialSpec,
    clock: &RecordClock,
    tx: &mpsc::Sender<Record>,
) -> Result<(String, bool), Closed> {
    let mut buf = BytesMut::with_capacity(READ_BUFFER);
    let mut got_data = false;
    loop {
        buf.reserve(READ_BUFFER);
        match port.read_buf(&mut buf).await {
            Ok(0) => return Ok(("end of file".into(), got_data)),
            Ok(_) => {
                got_data = true;
                let chunk: Bytes = buf.split().freeze();
                send(tx, spec, clock, Payload::Serial(chunk)).await?;
            }
            Err(e) => return Ok((e.to_string(), got_data)),
        }
    }
}

async fn send(
    tx: &mpsc::Sender<Record>,
    spec: &SerialSpec,
    clock: &RecordClock,
    payload: Payload,
) -> Result<(), Closed> {
    let record = Record {
        t: clock.now(),
        source: spec.source.clone(),
        payload,
    };
    tx.send(record).await.map_err(|_| Closed)
}
