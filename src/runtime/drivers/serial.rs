//! Serial driver: one task per port. Reads, timestamps and forwards raw chunks; writes what
//! the engine queues for the port (a receiver's corrections) without ever holding up the
//! reading; reports the link state; reconnects with back-off when the port disappears or
//! fails.

use std::time::{Duration, Instant};

use bytes::{Bytes, BytesMut};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::mpsc;
use tokio_serial::SerialPortBuilderExt;

use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::drivers::serial_tx::SerialTx;
use crate::runtime::outage_log::{OutageLog, Say};
use crate::vehicle::LinkState;

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
    /// What to write to the port, when anything is.
    pub writes: Option<SerialTx>,
    /// Whether what the port sends becomes records (a port only written to, `[ntrip]
    /// port`, reads and drops it).
    pub forward_reads: bool,
}

/// Runs until the receiving side of `tx` closes.
pub async fn run(spec: SerialSpec, clock: RecordClock, tx: mpsc::Sender<Record>) {
    let mut backoff = BACKOFF_START;
    let mut failed_attempts: u64 = 0;
    let mut outage = OutageLog::default();
    let mut outage_since: Option<Instant> = None;
    loop {
        match tokio_serial::new(&spec.port, spec.baud).open_native_async() {
            Ok(port) => {
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
                if let Some(w) = &spec.writes {
                    w.clear();
                }
                let (reason, got_data) = match serve(port, &spec, &clock, &tx).await {
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
                        let advice = super::serial_open::advice(&spec.port, &e);
                        tracing::warn!(device = %spec.source, port = %spec.port, error = %e, %advice, "cannot open port; retrying");
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

/// Reads and writes until the port fails. Returns why, and whether any data arrived.
async fn serve(
    port: tokio_serial::SerialStream,
    spec: &SerialSpec,
    clock: &RecordClock,
    tx: &mpsc::Sender<Record>,
) -> Result<(String, bool), Closed> {
    let (mut reader, writer) = tokio::io::split(port);
    let Some(writes) = &spec.writes else {
        return read_until_failure(&mut reader, spec, clock, tx).await;
    };
    tokio::select! {
        read = read_until_failure(&mut reader, spec, clock, tx) => read,
        reason = write_until_failure(writer, writes) => Ok((reason, false)),
    }
}

/// Writes what is queued, each write whole, until a write fails; returns why.
async fn write_until_failure(
    mut writer: tokio::io::WriteHalf<tokio_serial::SerialStream>,
    writes: &SerialTx,
) -> String {
    loop {
        let bytes = writes.next().await;
        match writer.write_all(&bytes).await {
            Ok(()) => writes.written(bytes.len()),
            Err(e) => {
                writes.failed();
                return format!("write failed: {e}");
            }
        }
    }
}

/// Reads until the port fails. Returns why, and whether any data arrived.
async fn read_until_failure(
    port: &mut tokio::io::ReadHalf<tokio_serial::SerialStream>,
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
                if spec.forward_reads {
                    send(tx, spec, clock, Payload::Serial(chunk)).await?;
                }
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
    if !spec.forward_reads {
        // A write-only port has no records; its link shows in the log.
        return if tx.is_closed() { Err(Closed) } else { Ok(()) };
    }
    let record = Record {
        t: clock.now(),
        source: spec.source.clone(),
        payload,
    };
    tx.send(record).await.map_err(|_| Closed)
}
