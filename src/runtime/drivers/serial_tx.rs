//! The engine's side of a serial port's write half: a bounded queue that never blocks the
//! sender. When it is full the oldest item goes (for corrections the newest matter most),
//! and every drop is counted and logged at powers of two.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use bytes::Bytes;
use tokio::sync::Notify;

#[derive(Debug)]
struct Shared {
    queue: Mutex<VecDeque<Bytes>>,
    ready: Notify,
    capacity: usize,
    dropped: AtomicU64,
    written: AtomicU64,
    written_bytes: AtomicU64,
    /// What a drop loses, for the log.
    what: &'static str,
}

/// A drop-oldest queue of writes to one port; cloned by the engine's loop and the driver.
#[derive(Debug, Clone)]
pub struct SerialTx(Arc<Shared>);

impl SerialTx {
    /// A queue of at most `capacity` writes (at least one); `what` names a drop in the log.
    pub fn new(capacity: usize, what: &'static str) -> Self {
        Self(Arc::new(Shared {
            queue: Mutex::new(VecDeque::with_capacity(capacity.clamp(1, 1024))),
            ready: Notify::new(),
            capacity: capacity.max(1),
            dropped: AtomicU64::new(0),
            written: AtomicU64::new(0),
            written_bytes: AtomicU64::new(0),
            what,
        }))
    }

    fn queue(&self) -> std::sync::MutexGuard<'_, VecDeque<Bytes>> {
        self.0.queue.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Queues `bytes` without waiting; a full queue loses its oldest write.
    pub fn send(&self, bytes: Bytes) {
        let dropped = {
            let mut q = self.queue();
            let dropped = if q.len() >= self.0.capacity {
                q.pop_front();
                true
            } else {
                false
            };
            q.push_back(bytes);
            dropped
        };
        if dropped {
            self.count_drops(1);
        }
        self.0.ready.notify_one();
    }

    fn count_drops(&self, n: u64) {
        let before = self.0.dropped.fetch_add(n, Ordering::Relaxed);
        let after = before + n;
        // Logged when the count reaches or passes a power of two (its bit length grows).
        if after.leading_zeros() < before.leading_zeros() {
            tracing::warn!(dropped = after, "{}", self.0.what);
        }
    }

    /// The next write, waiting for one.
    pub async fn next(&self) -> Bytes {
        loop {
            let notified = self.0.ready.notified();
            if let Some(b) = self.queue().pop_front() {
                return b;
            }
            notified.await;
        }
    }

    /// Drops what waits (a port just reopened: what was queued for the old one is stale).
    pub fn clear(&self) {
        let n = {
            let mut q = self.queue();
            let n = q.len();
            q.clear();
            n
        };
        if n > 0 {
            self.count_drops(n as u64);
        }
    }

    /// A write went out whole.
    pub fn written(&self, bytes: usize) {
        self.0.written.fetch_add(1, Ordering::Relaxed);
        self.0
            .written_bytes
            .fetch_add(bytes as u64, Ordering::Relaxed);
    }

    /// Writes dropped so far (queue full, port down or reopened, write failed).
    pub fn dropped(&self) -> u64 {
        self.0.dropped.load(Ordering::Relaxed)
    }

    /// A write that failed on the port.
    pub fn failed(&self) {
        self.count_drops(1);
    }

    /// Writes and bytes that went out.
    pub fn sent(&self) -> (u64, u64) {
        (
            self.0.written.load(Ordering::Relaxed),
            self.0.written_bytes.load(Ordering::Relaxed),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_full_queue_loses_its_oldest_and_counts_it() {
        let q = SerialTx::new(2, "test writes dropped");
        for b in [&b"a"[..], b"b", b"c"] {
            q.send(Bytes::copy_from_slice(b));
        }
        assert_eq!(q.dropped(), 1);
        assert_eq!(&q.next().await[..], b"b");
        assert_eq!(&q.next().await[..], b"c");
        q.send(Bytes::from_static(b"d"));
        q.clear();
        assert_eq!(q.dropped(), 2);
        let waiting = tokio::time::timeout(std::time::Duration::from_millis(20), q.next()).await;
        assert!(waiting.is_err(), "nothing left");
    }

    #[tokio::test]
    async fn a_waiting_writer_wakes_for_the_next_write() {
        let q = SerialTx::new(4, "test writes dropped");
        let writer = tokio::spawn({
            let q = q.clone();
            async move { q.next().await }
        });
        tokio::task::yield_now().await;
        q.send(Bytes::from_static(b"x"));
        assert_eq!(&writer.await.unwrap()[..], b"x");
    }
}
