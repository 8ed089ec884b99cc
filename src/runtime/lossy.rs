//! The control loop's end of a bounded queue to a worker thread: sending never blocks; when
//! the queue is full (or the worker is gone) the item is dropped, counted, and the drop
//! logged at powers of two so a flood makes a handful of lines.

use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

/// A never-blocking sender that counts what it had to drop.
pub struct LossySender<T> {
    tx: Option<SyncSender<T>>,
    sent: u64,
    dropped: u64,
    /// What a drop means, for the log.
    what: &'static str,
}

impl<T> LossySender<T> {
    /// A queue of `capacity` items; the worker takes the receiver. `what` says in the log
    /// what is lost when an item is dropped.
    pub fn new(capacity: usize, what: &'static str) -> (Self, Receiver<T>) {
        let (tx, rx) = sync_channel(capacity);
        let sender = Self {
            tx: Some(tx),
            sent: 0,
            dropped: 0,
            what,
        };
        (sender, rx)
    }

    /// Queues `item` without waiting; returns whether it was taken.
    pub fn send(&mut self, item: T) -> bool {
        let Some(tx) = &self.tx else { return false };
        match tx.try_send(item) {
            Ok(()) => {
                self.sent += 1;
                true
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.dropped += 1;
                if self.dropped.is_power_of_two() {
                    tracing::warn!(dropped = self.dropped, "{}", self.what);
                }
                false
            }
        }
    }

    /// Items taken so far.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    /// Items dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Closes the queue: the worker sees the end once it has taken what is queued.
    pub fn close(&mut self) {
        self.tx.take();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_queue_drops_and_counts_without_blocking() {
        let (mut tx, rx) = LossySender::new(2, "test items dropped");
        assert!(tx.send(1));
        assert!(tx.send(2));
        assert!(!tx.send(3));
        assert_eq!((tx.sent(), tx.dropped()), (2, 1));
        assert_eq!(rx.recv().ok(), Some(1));
        assert!(tx.send(4));
        tx.close();
        assert_eq!(rx.iter().collect::<Vec<_>>(), [2, 4]);
        assert!(!tx.send(5), "closed");
    }
}
