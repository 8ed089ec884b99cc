//! The server's clients: each one's session (`api::rosbridge::session`: what it subscribed
//! to, with its throttle and queue length) and its outgoing queue. Plain data driven by the
//! server's task, with the time passed in, so the rules are tested without sockets.
//!
//! A client's queue is bounded twice: per subscription by its `queue_length` (its oldest
//! message of that topic goes first) and in all by `websocket.client_queue`. What is dropped
//! is counted. Putting a message in a queue never waits, so a client that does not read
//! never slows the vehicle or another client.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use tokio::sync::Notify;

use crate::api::rosbridge::ops::Level;
use crate::api::rosbridge::session::Session;

/// One message waiting for a client, and the topic it belongs to (`None`: an answer or a
/// status, never dropped for a topic's queue length). Topics are the server's own, from
/// its static table.
type Queued = (Option<&'static str>, String);

/// A client's outgoing queue, shared by the server's task (which fills it) and the client's
/// writer (which empties it).
#[derive(Debug)]
pub struct ClientQueue {
    items: Mutex<VecDeque<Queued>>,
    capacity: usize,
    /// Wakes the writer.
    pub ready: Notify,
    dropped: AtomicU64,
    /// The server asked for the connection to close once the queue is sent.
    closing: std::sync::atomic::AtomicBool,
}

impl ClientQueue {
    /// An empty queue of at most `capacity` messages.
    pub fn new(capacity: usize) -> Self {
        Self {
            items: Mutex::new(VecDeque::with_capacity(capacity.min(64))),
            capacity: capacity.max(1),
            dropped: AtomicU64::new(0),
            ready: Notify::new(),
            closing: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// Asks the writer to close the connection once what is queued has gone.
    pub fn close(&self) {
        self.closing.store(true, Ordering::Relaxed);
        self.ready.notify_one();
    }

    /// Whether the server asked for the connection to close.
    pub fn is_closing(&self) -> bool {
        self.closing.load(Ordering::Relaxed)
    }

    /// Queues `text`; for a topic's message, first drops that topic's oldest ones beyond
    /// `keep - 1`. The oldest message of all goes when the queue is full.
    pub fn push(&self, topic: Option<(&'static str, usize)>, text: String) {
        let mut dropped = 0;
        {
            let Ok(mut items) = self.items.lock() else {
                return;
            };
            if let Some((topic, keep)) = topic {
                let keep = keep.max(1);
                let mut waiting = items.iter().filter(|(t, _)| *t == Some(topic)).count();
                while waiting >= keep {
                    if let Some(i) = items.iter().position(|(t, _)| *t == Some(topic)) {
                        items.remove(i);
                        dropped += 1;
                    }
                    waiting -= 1;
                }
            }
            while items.len() >= self.capacity {
                items.pop_front();
                dropped += 1;
            }
            items.push_back((topic.map(|(t, _)| t), text));
        }
        if dropped > 0 {
            self.dropped.fetch_add(dropped, Ordering::Relaxed);
        }
        self.ready.notify_one();
    }

    /// Takes everything queued, oldest first.
    pub fn take(&self) -> Vec<String> {
        match self.items.lock() {
            Ok(mut items) => items.drain(..).map(|(_, text)| text).collect(),
            Err(_) => Vec::new(),
        }
    }

    /// Messages dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// One connected client: its session (what it asked for) and its outgoing queue.
#[derive(Debug)]
pub struct Client {
    /// Its outgoing queue.
    pub queue: Arc<ClientQueue>,
    /// Its authentication, status level and subscriptions.
    pub session: Session,
}

impl Client {
    /// A new client with `queue`.
    pub fn new(queue: Arc<ClientQueue>, authenticated: bool) -> Self {
        Self {
            queue,
            session: Session::new(authenticated),
        }
    }

    /// Whether any subscription on `topic` would take a message at `now`.
    pub fn wants(&self, topic: &str, now: Instant) -> bool {
        self.session.wants(topic, now)
    }

    /// Queues `text` on `topic` if a subscription is due (once, however many subscribe);
    /// returns whether it was queued.
    pub fn offer(&mut self, topic: &'static str, text: &str, now: Instant) -> bool {
        match self.session.take(topic, now) {
            Some(keep) => {
                self.queue.push(Some((topic, keep)), text.to_owned());
                true
            }
            None => false,
        }
    }

    /// Queues a status message if the client wants its level.
    pub fn status(&self, level: Level, text: String) {
        if self.session.wants_level(level) {
            self.queue.push(None, text);
        }
    }

    /// Queues an answer (a service response).
    pub fn answer(&self, text: String) {
        self.queue.push(None, text);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn client(capacity: usize) -> Client {
        Client::new(Arc::new(ClientQueue::new(capacity)), true)
    }

    #[test]
    fn a_topics_queue_length_keeps_its_newest_and_the_drops_are_counted() {
        let mut c = client(100);
        c.session
            .subscribe("/odom", None, Duration::ZERO, 2)
            .unwrap();
        c.session
            .subscribe("/pose", None, Duration::ZERO, 1)
            .unwrap();
        let now = Instant::now();
        for i in 0..5 {
            c.offer("/odom", &format!("odom {i}"), now);
        }
        c.offer("/pose", "pose", now);
        c.status(Level::Error, "status".into());
        assert_eq!(c.queue.take(), ["odom 3", "odom 4", "pose", "status"]);
        assert_eq!(c.queue.dropped(), 3);
    }

    #[test]
    fn a_full_queue_loses_its_oldest_message() {
        let mut c = client(4);
        c.session
            .subscribe("/odom", None, Duration::ZERO, 100)
            .unwrap();
        let now = Instant::now();
        for i in 0..10 {
            c.offer("/odom", &i.to_string(), now);
        }
        assert_eq!(c.queue.take(), ["6", "7", "8", "9"]);
        assert_eq!(c.queue.dropped(), 6);
    }

    #[test]
    fn status_messages_below_the_clients_level_are_not_sent() {
        let mut c = client(10);
        c.session.level = Level::Error;
        c.status(Level::Info, "info".into());
        c.status(Level::Error, "error".into());
        assert_eq!(c.queue.take(), ["error"]);
    }
}
