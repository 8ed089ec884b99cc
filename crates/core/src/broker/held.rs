//! What the broker holds on behalf of every session at once, and the budgets that bound it:
//! topic and filter names (each costs rumqttd a log of its own), retained messages (kept
//! until replaced), and QoS 2 messages a client sent but has not released (kept until its
//! PUBREL). Each is counted here as the gate passes the packet that creates it, so the
//! broker's memory is bounded by what it holds, never by what it is sent.

use std::collections::{HashMap, HashSet};

/// Distinct topic and filter names the broker may hold logs for. A vehicle's own dialects
/// use a few dozen; beyond this, a session that brings a new name is ended.
pub const MAX_TOPIC_NAMES: usize = 4096;
/// The longest topic or filter name, bytes: the protocols' topics are under 100; each name
/// is kept by the broker for as long as it runs.
pub const MAX_TOPIC_BYTES: usize = 1024;
/// Retained messages the broker keeps at once (chassisd's own a handful).
pub const MAX_RETAINED: usize = 1024;
/// Bytes of retained messages (topic and payload) the broker keeps at once.
pub const MAX_RETAINED_BYTES: usize = 16 << 20;
/// The largest payload of a will to be retained, bytes (`offline` and its kind): the broker
/// publishes a will after the gate has seen its client go, so retained wills are bounded by
/// this and the topic names' budget ([`MAX_TOPIC_NAMES`] × 1 KiB = 4 MiB), not counted.
pub const MAX_RETAINED_WILL: usize = 1024;
/// QoS 1 and 2 messages one client may have in flight towards the broker (MQTT 5's
/// `Receive Maximum`, told to 5.0 clients in the CONNACK).
pub const MAX_IN_FLIGHT: u16 = 32;
/// Bytes of unreleased QoS 2 messages the broker keeps for all clients together, at least
/// two of the largest packet.
pub const MAX_IN_FLIGHT_BYTES: usize = 32 << 20;

/// Bytes of packets still arriving that the gate buffers for all clients together: each
/// large packet is whole before it is judged, so a client that announces one and sends it
/// slowly holds its announced size. A packet of up to [`SMALL_PACKET`] bytes needs none.
pub const MAX_BUFFERED_BYTES: usize = 64 << 20;
/// Packets this small are buffered without a reservation (a socket read's worth).
pub const SMALL_PACKET: usize = 64 << 10;

/// Why a packet would make the broker hold more than its budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OverBudget {
    /// A new topic or filter name beyond the session's share or the broker's.
    TopicNames,
    /// A retained message beyond the count or bytes kept.
    Retained,
    /// More QoS 1 and 2 messages in flight than [`MAX_IN_FLIGHT`].
    InFlight,
    /// Unreleased QoS 2 bytes beyond the client's share or the broker's.
    InFlightBytes,
    /// A large packet still arriving beyond what the gate buffers for all clients.
    Buffered,
}

/// Topic and filter names the broker holds, shared by every session.
#[derive(Debug, Default)]
pub struct TopicNames {
    names: HashSet<String>,
    /// chassisd's own topics (its commands and reports): always served, never counted, so
    /// names invented by others can never lock the vehicle's own out.
    reserved: HashSet<String>,
}

impl TopicNames {
    /// Names with `reserved` always admitted.
    pub fn with_reserved(reserved: impl IntoIterator<Item = String>) -> Self {
        Self {
            names: HashSet::new(),
            reserved: reserved.into_iter().collect(),
        }
    }

    /// Holds `name` as chassisd's own, beyond the limit.
    pub fn reserve(&mut self, name: &str) {
        self.reserved.insert(name.to_owned());
    }

    /// Whether `name` is held already (or reserved).
    pub fn holds(&self, name: &str) -> bool {
        self.reserved.contains(name) || self.names.contains(name)
    }

    /// Whether `name` is one of chassisd's own.
    pub fn is_reserved(&self, name: &str) -> bool {
        self.reserved.contains(name)
    }

    /// Admits `name` (already known, or new with room left).
    pub fn admit(&mut self, name: &str) -> Result<(), OverBudget> {
        if self.holds(name) {
            return Ok(());
        }
        if self.names.len() >= MAX_TOPIC_NAMES {
            return Err(OverBudget::TopicNames);
        }
        self.names.insert(name.to_owned());
        Ok(())
    }

    /// Names held.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Whether none is held.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }
}

/// Retained messages by topic, as the broker keeps them: a message replaces the one on
/// its topic, and an empty payload removes it (rumqttd removes it whatever the retain
/// flag says).
#[derive(Debug, Default)]
pub struct Retained {
    sizes: HashMap<String, usize>,
    bytes: usize,
}

impl Retained {
    /// Notes a PUBLISH on `topic` with `payload_len` bytes; `retain` its flag. Refused when
    /// it would keep more than the budget; `forced` (chassisd's own) is never refused.
    pub fn publish(
        &mut self,
        topic: &str,
        payload_len: usize,
        retain: bool,
        forced: bool,
    ) -> Result<(), OverBudget> {
        if payload_len == 0 {
            if let Some(size) = self.sizes.remove(topic) {
                self.bytes -= size;
            }
            return Ok(());
        }
        if !retain {
            return Ok(());
        }
        let size = topic.len() + payload_len;
        let replaced = self.sizes.get(topic).copied();
        let count = self.sizes.len() + usize::from(replaced.is_none());
        let bytes = self.bytes - replaced.unwrap_or(0) + size;
        if !forced && (count > MAX_RETAINED || bytes > MAX_RETAINED_BYTES) {
            return Err(OverBudget::Retained);
        }
        self.sizes.insert(topic.to_owned(), size);
        self.bytes = bytes;
        Ok(())
    }

    /// Messages kept.
    pub fn len(&self) -> usize {
        self.sizes.len()
    }

    /// Whether none is kept.
    pub fn is_empty(&self) -> bool {
        self.sizes.is_empty()
    }

    /// Bytes kept.
    pub fn bytes(&self) -> usize {
        self.bytes
    }
}

/// Everything the broker holds for all sessions.
#[derive(Debug, Default)]
pub struct Held {
    /// Topic and filter names.
    pub names: TopicNames,
    /// Retained messages.
    pub retained: Retained,
    /// Bytes of QoS 2 messages awaiting their PUBREL, all clients together.
    pub in_flight_bytes: usize,
    /// The most [`Held::in_flight_bytes`] may reach.
    pub max_in_flight_bytes: usize,
    /// Bytes reserved for large packets still arriving, all clients together.
    pub buffered_bytes: usize,
    /// The most [`Held::buffered_bytes`] may reach.
    pub max_buffered_bytes: usize,
}

impl Held {
    /// Nothing held yet; chassisd's own topic names always admitted; packets of up to
    /// `max_packet` bytes.
    pub fn new(reserved: impl IntoIterator<Item = String>, max_packet: usize) -> Self {
        Self {
            names: TopicNames::with_reserved(reserved),
            retained: Retained::default(),
            in_flight_bytes: 0,
            max_in_flight_bytes: MAX_IN_FLIGHT_BYTES.max(2 * max_packet),
            buffered_bytes: 0,
            max_buffered_bytes: MAX_BUFFERED_BYTES.max(2 * max_packet),
        }
    }

    /// The share of unreleased QoS 2 bytes one client may hold: a quarter of the whole,
    /// at least one of the largest packet.
    pub fn client_in_flight_bytes(&self, max_packet: usize) -> usize {
        (self.max_in_flight_bytes / 4).max(max_packet)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retained_messages_are_bounded_by_count_and_bytes_and_replaced_in_place() {
        let mut r = Retained::default();
        for i in 0..MAX_RETAINED {
            assert_eq!(r.publish(&format!("t/{i}"), 10, true, false), Ok(()));
        }
        assert_eq!(
            r.publish("one/more", 10, true, false),
            Err(OverBudget::Retained)
        );
        // Replacing one, removing one, and plain messages cost nothing new.
        assert_eq!(r.publish("t/5", 20, true, false), Ok(()));
        assert_eq!(r.publish("other", 10, false, false), Ok(()));
        assert_eq!(r.publish("t/6", 0, false, false), Ok(()));
        assert_eq!(r.len(), MAX_RETAINED - 1);
        assert_eq!(r.publish("one/more", 10, true, false), Ok(()));
        // chassisd's own always fit.
        assert_eq!(r.publish("chassisd/status", 10, true, true), Ok(()));
        let mut big = Retained::default();
        let payload = MAX_RETAINED_BYTES / 4;
        for i in 0..3 {
            assert_eq!(big.publish(&format!("b/{i}"), payload, true, false), Ok(()));
        }
        assert_eq!(
            big.publish("b/3", payload, true, false),
            Err(OverBudget::Retained)
        );
        assert_eq!(big.bytes(), 3 * (3 + payload));
    }
}
