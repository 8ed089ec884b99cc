//! Connections in their HTTP exchange, at most a fixed number: when all places are taken, a
//! new connection takes the oldest one's, and that one is closed. A client's handshake
//! takes a round trip, while a connection that sends its request slowly or never holds its
//! place for up to the header timeout: a flood of those, from however many addresses,
//! closes itself rather than the clients that come after it.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use tokio::sync::oneshot;

/// The places, oldest first.
#[derive(Debug)]
pub struct Handshakes {
    most: usize,
    next: AtomicU64,
    queue: Mutex<VecDeque<(u64, oneshot::Sender<()>)>>,
}

/// One connection's place; dropping it leaves.
#[derive(Debug)]
pub struct Place {
    of: Arc<Handshakes>,
    id: u64,
    /// Fires when a newer connection took the place.
    pub evicted: oneshot::Receiver<()>,
}

impl Handshakes {
    /// At most `most` places.
    pub fn new(most: usize) -> Arc<Self> {
        Arc::new(Self {
            most: most.max(1),
            next: AtomicU64::new(0),
            queue: Mutex::new(VecDeque::new()),
        })
    }

    /// A place for a new connection, and whether the oldest was told to go for it.
    pub fn enter(self: &Arc<Self>) -> (Place, bool) {
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let (tx, rx) = oneshot::channel();
        let mut queue = self.lock();
        let mut evicted = false;
        while queue.len() >= self.most {
            if let Some((_, oldest)) = queue.pop_front() {
                // Gone already when the send fails: its place was free anyway.
                evicted |= oldest.send(()).is_ok();
            }
        }
        queue.push_back((id, tx));
        let place = Place {
            of: self.clone(),
            id,
            evicted: rx,
        };
        (place, evicted)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, VecDeque<(u64, oneshot::Sender<()>)>> {
        // A plain queue: a panic elsewhere cannot leave it half-written.
        self.queue
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl Drop for Place {
    fn drop(&mut self) {
        let mut queue = self.of.lock();
        if let Some(i) = queue.iter().position(|(id, _)| *id == self.id) {
            queue.remove(i);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_newest_connection_takes_the_oldest_ones_place() {
        let places = Handshakes::new(2);
        let (mut first, evicted) = places.enter();
        assert!(!evicted);
        let (second, _) = places.enter();
        let (third, evicted) = places.enter();
        assert!(evicted);
        assert!(first.evicted.try_recv().is_ok(), "the oldest is told");
        assert_eq!(places.lock().len(), 2);
        drop(first);
        drop(second);
        assert_eq!(places.lock().len(), 1);
        drop(third);
        assert_eq!(places.lock().len(), 0);
    }
}
