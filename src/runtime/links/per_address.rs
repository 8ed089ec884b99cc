//! Connections held per peer address, bounded: one host cannot take every place a server
//! has. A place is a guard; dropping it gives the place back.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};

/// The places each address holds, at most `most` each.
#[derive(Debug)]
pub struct PerAddress {
    most: usize,
    held: Mutex<HashMap<IpAddr, usize>>,
}

/// One place of one address.
#[derive(Debug)]
pub struct AddressPlace {
    of: Arc<PerAddress>,
    address: IpAddr,
}

impl PerAddress {
    /// At most `most` places per address.
    pub fn new(most: usize) -> Arc<Self> {
        Arc::new(Self {
            most,
            held: Mutex::new(HashMap::new()),
        })
    }

    /// A place for `address`, or `None` when it holds `most` already. IPv6 addresses count
    /// by their /64: one host is given a whole /64 to pick from.
    pub fn take(self: &Arc<Self>, address: IpAddr) -> Option<AddressPlace> {
        let address = host(address);
        let mut held = self.lock();
        let n = held.entry(address).or_insert(0);
        if *n >= self.most {
            return None;
        }
        *n += 1;
        Some(AddressPlace {
            of: self.clone(),
            address,
        })
    }

    /// Places `address` holds now.
    pub fn held(&self, address: IpAddr) -> usize {
        self.lock().get(&host(address)).copied().unwrap_or(0)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<IpAddr, usize>> {
        // Plain counts: a panic elsewhere cannot leave them half-written.
        self.held
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// The key `address` counts under: an IPv4 address (mapped ones too), or an IPv6 /64.
fn host(address: IpAddr) -> IpAddr {
    match address {
        IpAddr::V4(_) => address,
        IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
            Some(v4) => IpAddr::V4(v4),
            None => IpAddr::V6((u128::from(v6) & !0u128 << 64).into()),
        },
    }
}

impl Drop for AddressPlace {
    fn drop(&mut self) {
        let mut held = self.of.lock();
        if let Some(n) = held.get_mut(&self.address) {
            *n -= 1;
            // Addresses gone leave nothing behind: the map is as large as the places held.
            if *n == 0 {
                held.remove(&self.address);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_address_has_its_own_places_and_gets_them_back() {
        let places = PerAddress::new(2);
        let a: IpAddr = "10.0.0.1".parse().unwrap();
        let b: IpAddr = "10.0.0.2".parse().unwrap();
        let first = places.take(a).unwrap();
        let _second = places.take(a).unwrap();
        assert!(places.take(a).is_none());
        assert!(places.take(b).is_some());
        drop(first);
        assert_eq!(places.held(a), 1);
        assert!(places.take(a).is_some());
        assert_eq!(places.lock().len(), 1, "b's place went back with its guard");
        // One /64 is one host.
        let c: IpAddr = "2001:db8::1".parse().unwrap();
        let d: IpAddr = "2001:db8::ffff:1234".parse().unwrap();
        let _c = places.take(c).unwrap();
        let _d = places.take(d).unwrap();
        assert!(places.take(c).is_none());
        assert!(places.take("2001:db8:0:1::1".parse().unwrap()).is_some());
    }
}
