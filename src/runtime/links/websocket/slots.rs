//! The places of WebSocket clients. Authenticated clients (every client when no token is
//! set, else those that presented it) have `websocket.max_clients` places; clients still to
//! present the token have as many again, apart, at most [`UNAUTHENTICATED_PER_ADDRESS`] per
//! address, each for [`AUTH_WINDOW`] at most. A client that never authenticates thus never
//! takes an operator's place, and its own place comes back within seconds.

use std::net::IpAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use crate::runtime::links::per_address::{AddressPlace, PerAddress};

/// A client that has not authenticated this long after its handshake is closed. Longer
/// than the waits after four wrong tokens (1 + 2 + 4 + 8 s), so the fifth try is still
/// answered.
pub const AUTH_WINDOW: Duration = Duration::from_secs(20);
/// Clients waiting to authenticate at once from one address.
pub const UNAUTHENTICATED_PER_ADDRESS: usize = 4;

/// Both kinds of places.
pub struct Slots {
    authenticated: Arc<Semaphore>,
    unauthenticated: Arc<Semaphore>,
    per_address: Arc<PerAddress>,
}

/// One client's place; dropping it gives the place back.
#[derive(Debug)]
pub struct Slot {
    _permit: OwnedSemaphorePermit,
    /// Its address's place, for a client that has still to present the token.
    waiting: Option<AddressPlace>,
}

impl Slots {
    /// `max_clients` places of each kind.
    pub fn new(max_clients: usize) -> Self {
        Self {
            authenticated: Arc::new(Semaphore::new(max_clients)),
            unauthenticated: Arc::new(Semaphore::new(max_clients)),
            per_address: PerAddress::new(UNAUTHENTICATED_PER_ADDRESS),
        }
    }

    /// An authenticated client's place, if one is free.
    pub fn authenticated(&self) -> Option<Slot> {
        let permit = self.authenticated.clone().try_acquire_owned().ok()?;
        Some(Slot {
            _permit: permit,
            waiting: None,
        })
    }

    /// A place for a client from `address` that has still to authenticate, if one is free.
    pub fn unauthenticated(&self, address: IpAddr) -> Option<Slot> {
        let place = self.per_address.take(address)?;
        let permit = self.unauthenticated.clone().try_acquire_owned().ok()?;
        Some(Slot {
            _permit: permit,
            waiting: Some(place),
        })
    }
}

impl Slots {
    /// Whether a place of the kind would be free now (without taking it).
    pub fn has_room(&self, authenticated: bool, address: IpAddr) -> bool {
        if authenticated {
            self.authenticated.available_permits() > 0
        } else {
            self.unauthenticated.available_permits() > 0
                && self.per_address.held(address) < UNAUTHENTICATED_PER_ADDRESS
        }
    }
}

impl Slot {
    /// Whether the client has still to authenticate.
    pub fn is_unauthenticated(&self) -> bool {
        self.waiting.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clients_waiting_for_the_token_never_take_an_authenticated_place() {
        let slots = Slots::new(2);
        let a: IpAddr = "10.0.0.1".parse().unwrap();
        let waiting: Vec<Slot> = (0..4).filter_map(|_| slots.unauthenticated(a)).collect();
        assert_eq!(waiting.len(), 2, "max_clients of them");
        assert!(waiting.iter().all(Slot::is_unauthenticated));
        let operator = slots.authenticated().expect("a place of its own");
        assert!(!operator.is_unauthenticated());
        drop(waiting);
        let slots = Slots::new(16);
        let one_address: Vec<Slot> = (0..8).filter_map(|_| slots.unauthenticated(a)).collect();
        assert_eq!(one_address.len(), UNAUTHENTICATED_PER_ADDRESS);
    }
}
