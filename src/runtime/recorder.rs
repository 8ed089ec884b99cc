//! Writes live records to a recording folder on its own thread, so disk stalls never hold
//! up the engine.

use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::Duration;

use super::lossy::LossySender;
use crate::record::{Record, RecordingWriter};
use crate::time::Timestamp;

/// Records queued for the writer thread before new ones are dropped (and counted).
const QUEUE: usize = 65_536;
/// How often buffered lines reach the file system.
const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// Handle to the recorder thread.
pub struct Recorder {
    tx: LossySender<Record>,
    thread: Option<JoinHandle<RecordingWriter>>,
}

impl Recorder {
    /// Starts the writer thread.
    pub fn start(writer: RecordingWriter) -> Self {
        let (tx, rx) = LossySender::new(QUEUE, "recording cannot keep up; records dropped");
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || write_loop(writer, rx))
            .map_err(|e| tracing::error!(error = %e, "recorder thread did not start"))
            .ok();
        Self { tx, thread }
    }

    /// Queues a record. Never blocks; a full queue drops the record and counts it.
    pub fn record(&mut self, record: Record) {
        self.tx.send(record);
    }

    /// Records dropped so far.
    pub fn dropped(&self) -> u64 {
        self.tx.dropped()
    }

    /// Writes what is queued, stops the thread and marks the recording's clean end.
    pub fn finish(mut self, end: Timestamp) {
        self.tx.close();
        let Some(thread) = self.thread.take() else {
            return;
        };
        match thread.join() {
            Ok(writer) => {
                if let Err(e) = writer.finish(end) {
                    tracing::error!(error = %e, "recording: cannot mark its end");
                }
            }
            Err(_) => tracing::error!("recorder thread panicked"),
        }
    }
}

fn write_loop(mut writer: RecordingWriter, rx: Receiver<Record>) -> RecordingWriter {
    let mut failures: u64 = 0;
    loop {
        let result = match rx.recv_timeout(FLUSH_EVERY) {
            Ok(record) => writer.write(&record),
            Err(RecvTimeoutError::Timeout) => writer.flush(),
            Err(RecvTimeoutError::Disconnected) => break,
        };
        if let Err(e) = result {
            failures += 1;
            if failures.is_power_of_two() {
                tracing::error!(error = %e, failures, "recording write failed");
            }
        }
    }
    writer
}
