//! Status lines to standard output on a thread of their own, behind a bounded queue, so a
//! pipe nobody reads never holds up the control loop: when the queue is full the line is
//! dropped and counted.

use std::io::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::runtime::lossy::LossySender;

/// Lines waiting for the writer before new ones are dropped (25 s of base_status).
const QUEUE: usize = 256;

/// The control loop's side of the status writer.
pub struct StatusOut {
    tx: LossySender<String>,
    /// The writer's error, once writing failed (a closed pipe).
    error: Arc<Mutex<Option<std::io::Error>>>,
    /// Lines the writer has finished writing.
    written: Arc<AtomicU64>,
}

impl StatusOut {
    /// Starts the writer thread on `out`.
    pub fn start(out: impl Write + Send + 'static) -> Self {
        let (tx, rx) = LossySender::new(QUEUE, "standard output is not read; status lines dropped");
        let error = Arc::new(Mutex::new(None));
        let written = Arc::new(AtomicU64::new(0));
        let (e, w) = (error.clone(), written.clone());
        let started = std::thread::Builder::new()
            .name("status-out".into())
            .spawn(move || write_loop(out, rx, &e, &w));
        if let Err(e) = started {
            tracing::error!(error = %e, "status writer thread did not start");
        }
        Self { tx, error, written }
    }

    /// Queues a line (with its newline). Never blocks.
    pub fn send(&mut self, line: String) {
        self.tx.send(line);
    }

    /// Lines dropped so far.
    pub fn dropped(&self) -> u64 {
        self.tx.dropped()
    }

    /// The error that stopped the writer, if one did.
    pub fn take_error(&mut self) -> Option<std::io::Error> {
        self.error.lock().ok().and_then(|mut e| e.take())
    }

    /// Stops taking lines and waits, at most `limit`, for the queued ones to be written.
    pub fn finish(mut self, limit: Duration) {
        self.tx.close();
        let deadline = Instant::now() + limit;
        while self.written.load(Ordering::Relaxed) < self.tx.sent() && Instant::now() < deadline {
            if self.error.lock().map(|e| e.is_some()).unwrap_or(true) {
                return;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

fn write_loop(
    mut out: impl Write,
    rx: Receiver<String>,
    error: &Mutex<Option<std::io::Error>>,
    written: &AtomicU64,
) {
    while let Ok(line) = rx.recv() {
        if let Err(e) = out.write_all(line.as_bytes()).and_then(|()| out.flush()) {
            if let Ok(mut slot) = error.lock() {
                *slot = Some(e);
            }
            return;
        }
        written.fetch_add(1, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A writer that blocks until told to go on, as a pipe nobody reads.
    struct Stalled(Arc<Mutex<()>>, Arc<Mutex<Vec<u8>>>);

    impl Write for Stalled {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            let _wait = self.0.lock();
            self.1.lock().map(|mut v| v.extend_from_slice(buf)).ok();
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_stalled_writer_never_blocks_the_sender_and_drops_are_counted() {
        let gate = Arc::new(Mutex::new(()));
        let seen = Arc::new(Mutex::new(Vec::new()));
        let held = gate.lock().unwrap();
        let mut out = StatusOut::start(Stalled(gate.clone(), seen.clone()));
        for i in 0..(QUEUE + 100) {
            out.send(format!("{i}\n"));
        }
        // One line may be in the writer's hands; the queue holds QUEUE more.
        assert!(out.dropped() >= 99, "{}", out.dropped());
        let out_dropped = out.dropped();
        drop(held);
        out.finish(Duration::from_secs(5));
        let text = String::from_utf8(seen.lock().unwrap().clone()).unwrap();
        assert!(text.starts_with("0\n1\n"), "{text}");
        // Every line taken was written, in order; the rest were counted as dropped.
        let lines: Vec<usize> = text.lines().map(|l| l.parse().unwrap()).collect();
        assert_eq!(lines.len() as u64 + out_dropped, (QUEUE + 100) as u64);
        assert!(lines.windows(2).all(|w| w[0] < w[1]));
    }
}
