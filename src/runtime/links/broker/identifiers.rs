//! One session per client identifier at a time. MQTT lets a new connection take over an
//! identifier that is still connected; rumqttd does the takeover itself, and its old and
//! new connections then race to free the same slot (see `broker::session`). So the gate
//! does it: the new session asks the old one to end, and waits until the broker has let
//! the old one go before it forwards its own CONNECT.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::{OwnedMutexGuard, watch};

/// How long a new session waits for the one it takes over to be let go by the broker.
const TAKEOVER_TIMEOUT: Duration = Duration::from_secs(3);

/// The identifiers in use.
#[derive(Debug, Default)]
pub struct Identifiers {
    slots: Mutex<HashMap<String, Arc<Slot>>>,
}

/// One identifier: whose turn it is, and a counter of takeovers the holder watches.
#[derive(Debug)]
struct Slot {
    turn: Arc<tokio::sync::Mutex<()>>,
    takeovers: watch::Sender<u64>,
}

/// A session's turn with its identifier, held while the session lasts.
#[derive(Debug)]
pub struct Turn {
    // Dropped first: the turn passes on before the slot is looked at for removal.
    _held: Option<OwnedMutexGuard<()>>,
    slot: SlotRef,
    takeover: u64,
}

impl Turn {
    /// Resolves when a newer session asks for this identifier.
    pub async fn taken_over(&self) {
        let mut rx = self.slot.slot.takeovers.subscribe();
        let _ = rx.wait_for(|&n| n != self.takeover).await;
    }
}

/// A reference to a slot that removes it from the table when the last one goes.
#[derive(Debug)]
struct SlotRef {
    identifiers: Arc<Identifiers>,
    id: String,
    slot: Arc<Slot>,
}

impl Drop for SlotRef {
    fn drop(&mut self) {
        let mut slots = lock(&self.identifiers.slots);
        // References are made under this lock, so the count is exact here: the table's and
        // this one mean nobody else holds or waits for the identifier.
        if Arc::strong_count(&self.slot) == 2 {
            slots.remove(&self.id);
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A plain table: a panic elsewhere cannot leave it half-written.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Identifiers {
    /// Identifiers held or waited for now.
    #[cfg(test)]
    fn len(&self) -> usize {
        lock(&self.slots).len()
    }

    /// Whether none is.
    #[cfg(test)]
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Takes `id`'s turn: the session holding it is asked to end, and this waits until it
    /// has. `None` when it did not end in time, or a newer session asked in the meantime.
    pub async fn take_turn(self: &Arc<Self>, id: &str) -> Option<Turn> {
        let slot = {
            let mut slots = lock(&self.slots);
            let slot = slots
                .entry(id.to_owned())
                .or_insert_with(|| {
                    Arc::new(Slot {
                        turn: Arc::new(tokio::sync::Mutex::new(())),
                        takeovers: watch::Sender::new(0),
                    })
                })
                .clone();
            SlotRef {
                identifiers: self.clone(),
                id: id.to_owned(),
                slot,
            }
        };
        let mut takeover = 0;
        slot.slot.takeovers.send_modify(|n| {
            *n += 1;
            takeover = *n;
        });
        let held = tokio::time::timeout(TAKEOVER_TIMEOUT, slot.slot.turn.clone().lock_owned())
            .await
            .ok()?;
        if *slot.slot.takeovers.borrow() != takeover {
            return None;
        }
        Some(Turn {
            _held: Some(held),
            slot,
            takeover,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_new_session_takes_over_once_the_old_one_ends() {
        let ids = Arc::new(Identifiers::default());
        let first = ids.take_turn("robot").await.expect("free");
        let waiter = {
            let ids = ids.clone();
            tokio::spawn(async move { ids.take_turn("robot").await.is_some() })
        };
        // The holder hears of the takeover, and the newcomer waits until it ends.
        tokio::time::timeout(Duration::from_secs(1), first.taken_over())
            .await
            .expect("told");
        assert!(!waiter.is_finished());
        drop(first);
        assert!(waiter.await.unwrap());
        assert!(ids.is_empty(), "the table forgets identifiers nobody holds");
    }

    #[tokio::test]
    async fn of_two_newcomers_only_the_last_gets_the_turn() {
        let ids = Arc::new(Identifiers::default());
        let first = ids.take_turn("robot").await.expect("free");
        let second = {
            let ids = ids.clone();
            tokio::spawn(async move { ids.take_turn("robot").await.map(|_| ()) })
        };
        tokio::time::sleep(Duration::from_millis(20)).await;
        let third = {
            let ids = ids.clone();
            tokio::spawn(async move { ids.take_turn("robot").await.map(|_| ()) })
        };
        tokio::time::sleep(Duration::from_millis(20)).await;
        drop(first);
        assert_eq!(second.await.unwrap(), None);
        assert_eq!(third.await.unwrap(), Some(()));
        assert!(ids.is_empty());
    }

    #[tokio::test]
    async fn identifiers_do_not_wait_for_each_other() {
        let ids = Arc::new(Identifiers::default());
        let _a = ids.take_turn("a").await.expect("free");
        let _b = ids.take_turn("b").await.expect("free");
        assert_eq!(ids.len(), 2);
    }
}
