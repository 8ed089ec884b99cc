//! Writes live records to a recording folder on its own thread, so disk stalls never hold
//! up the engine.

use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::record::segments::SegmentedWriter;
use crate::record::{Payload, Record, RecordError, RecordingWriter};
use crate::runtime::lossy::LossySender;
use crate::time::Timestamp;

/// Records queued for the writer thread before new ones are dropped (and counted).
const QUEUE: usize = 65_536;
/// How often every file's buffered lines reach the file system, together: a killed
/// recording's files then end within this of each other, and replay cuts them there.
const FLUSH_EVERY: Duration = Duration::from_millis(100);

/// Where the recorder thread writes: one recording folder, or a series of them.
pub trait RecordSink: Send + 'static {
    /// Appends one record.
    fn write(&mut self, record: &Record) -> Result<(), RecordError>;
    /// Puts what is written on disk and notes how far it reaches.
    fn checkpoint(&mut self) -> Result<(), RecordError>;
    /// Puts everything on disk and marks the clean end at `end`.
    fn finish(self: Box<Self>, end: Timestamp) -> Result<(), RecordError>;
}

impl RecordSink for RecordingWriter {
    fn write(&mut self, record: &Record) -> Result<(), RecordError> {
        RecordingWriter::write(self, record)
    }

    fn checkpoint(&mut self) -> Result<(), RecordError> {
        RecordingWriter::checkpoint(self)
    }

    fn finish(self: Box<Self>, end: Timestamp) -> Result<(), RecordError> {
        RecordingWriter::finish(*self, end)
    }
}

impl RecordSink for SegmentedWriter {
    fn write(&mut self, record: &Record) -> Result<(), RecordError> {
        SegmentedWriter::write(self, record)
    }

    fn checkpoint(&mut self) -> Result<(), RecordError> {
        SegmentedWriter::checkpoint(self)
    }

    fn finish(self: Box<Self>, end: Timestamp) -> Result<(), RecordError> {
        SegmentedWriter::finish(*self, end)
    }
}

/// Handle to the recorder thread.
pub struct Recorder {
    tx: LossySender<Record>,
    thread: Option<JoinHandle<Box<dyn RecordSink>>>,
}

impl Recorder {
    /// Starts the writer thread.
    pub fn start(writer: impl RecordSink) -> Self {
        let writer: Box<dyn RecordSink> = Box::new(writer);
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

fn write_loop(mut writer: Box<dyn RecordSink>, rx: Receiver<Record>) -> Box<dyn RecordSink> {
    let mut failures: u64 = 0;
    let mut next_flush = Instant::now() + FLUSH_EVERY;
    loop {
        let wait = next_flush.saturating_duration_since(Instant::now());
        let (result, flush_now) = match rx.recv_timeout(wait) {
            // A command is rare and matters most to a replay: on disk at once.
            Ok(record) => {
                let command = matches!(record.payload, Payload::Command { .. });
                (writer.write(&record), command)
            }
            Err(RecvTimeoutError::Timeout) => (Ok(()), false),
            Err(RecvTimeoutError::Disconnected) => break,
        };
        let result = if flush_now || Instant::now() >= next_flush {
            next_flush = Instant::now() + FLUSH_EVERY;
            result.and_then(|()| writer.checkpoint())
        } else {
            result
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
