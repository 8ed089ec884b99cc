//! One client's session as the gate follows it, packet by packet in both directions, so that
//! nothing reaches the broker that would make it drop a connection on its own initiative.
//!
//! rumqttd 0.20 frees a connection's slot when it drops one for a protocol error, while the
//! connection's own task may still report the same slot as closed a moment later; if a new
//! client took the slot in between, that client is dropped mid-handshake and leaves a stale
//! entry that panics the next connection under its identifier. So the gate refuses what
//! the broker would refuse (acknowledgements of packets never sent, malformed topics and
//! filters, subscription identifiers of 0, `$` filters), and ends such a session itself.
//! It also keeps the broker's memory bounded: every topic and filter name the broker ever
//! sees costs it a log of its own, so the names are counted across all sessions.

use std::collections::{HashMap, HashSet};

use super::cursor::Cursor;
use super::held::{Held, MAX_IN_FLIGHT, MAX_TOPIC_BYTES, OverBudget, SMALL_PACKET, TopicNames};
use super::wire::{Header, Version, WireError, kind};

/// New names one session may bring: a client that invents names is ended long before it
/// fills the broker, and must reconnect for every few dozen more.
pub const MAX_NEW_NAMES_PER_SESSION: usize = 64;

/// Why a session is ended by the gate.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Violation {
    /// The packet is malformed.
    Wire(WireError),
    /// An acknowledgement (PUBACK, PUBREC, PUBCOMP, PUBREL) for a packet id the other side
    /// never used.
    UnknownPacketId { kind: u8, id: u16 },
    /// A PUBLISH topic that is empty, holds a wildcard, or is not text.
    BadTopic,
    /// A subscription filter that is malformed or starts with `$` (shared and system
    /// subscriptions are not served).
    BadFilter,
    /// MQTT 5 features the broker does not serve safely: topic aliases, subscription
    /// identifiers in PUBLISH or of 0, enhanced authentication.
    Unsupported(&'static str),
    /// The packet would make the broker hold more than its budget.
    OverBudget(OverBudget),
}

impl Violation {
    /// The MQTT 5 DISCONNECT reason code that tells a 5.0 client why (section 3.14.2.1).
    pub fn reason_code(&self) -> u8 {
        match self {
            Self::Wire(WireError::TooLarge { .. }) => 0x95,
            Self::Wire(_) => 0x81,
            Self::UnknownPacketId { .. } => 0x82,
            Self::BadTopic => 0x90,
            Self::BadFilter => 0x8f,
            Self::Unsupported("a topic alias") => 0x94,
            Self::Unsupported(_) => 0x83,
            Self::OverBudget(OverBudget::InFlight) => 0x93,
            Self::OverBudget(_) => 0x97,
        }
    }
}

impl std::fmt::Display for Violation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Wire(e) => write!(f, "{e}"),
            Self::UnknownPacketId { kind, id } => {
                write!(
                    f,
                    "packet type {kind} acknowledges id {id}, which was never sent"
                )
            }
            Self::BadTopic => write!(f, "PUBLISH topic is empty, has a wildcard or is not text"),
            Self::BadFilter => write!(f, "subscription filter is malformed or starts with $"),
            Self::Unsupported(what) => write!(f, "{what} is not served"),
            Self::OverBudget(OverBudget::TopicNames) => write!(
                f,
                "a new topic name beyond the session's {MAX_NEW_NAMES_PER_SESSION} or the \
                 broker's {}",
                super::held::MAX_TOPIC_NAMES
            ),
            Self::OverBudget(OverBudget::Retained) => write!(
                f,
                "a retained message beyond the broker's {} messages or {} bytes",
                super::held::MAX_RETAINED,
                super::held::MAX_RETAINED_BYTES
            ),
            Self::OverBudget(OverBudget::InFlight) => write!(
                f,
                "more than {MAX_IN_FLIGHT} QoS 1 and 2 messages in flight (receive maximum)"
            ),
            Self::OverBudget(OverBudget::InFlightBytes) => {
                write!(f, "unreleased QoS 2 messages beyond the broker's budget")
            }
            Self::OverBudget(OverBudget::Buffered) => write!(
                f,
                "a large packet arriving while the gate buffers {} bytes of others",
                super::held::MAX_BUFFERED_BYTES
            ),
        }
    }
}

impl From<WireError> for Violation {
    fn from(e: WireError) -> Self {
        Self::Wire(e)
    }
}

impl From<OverBudget> for Violation {
    fn from(e: OverBudget) -> Self {
        Self::OverBudget(e)
    }
}

/// What to do with a client's packet that passed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pass {
    /// Forward it; the session goes on.
    Forward,
    /// Forward it, then read nothing more: the client said DISCONNECT.
    LastOne,
}

/// Packet ids in flight, each side's.
#[derive(Debug)]
pub struct Session {
    version: Version,
    /// QoS 1 PUBLISHes the broker sent, awaiting the client's PUBACK.
    out_qos1: HashSet<u16>,
    /// QoS 2 PUBLISHes the broker sent, awaiting the client's PUBREC.
    out_qos2: HashSet<u16>,
    /// PUBRELs the broker sent, awaiting the client's PUBCOMP.
    out_pubrel: HashSet<u16>,
    /// QoS 1 PUBLISHes the client sent, awaiting the broker's PUBACK.
    in_qos1: HashSet<u16>,
    /// QoS 2 PUBLISHes the client sent, awaiting its PUBREL, with their sizes (the broker
    /// keeps each until then).
    in_qos2: HashMap<u16, usize>,
    /// Bytes of `in_qos2`.
    in_qos2_bytes: usize,
    /// The largest packet the client may send, bytes.
    max_packet: usize,
    /// Bytes reserved in [`Held::buffered_bytes`] for a large packet still arriving.
    buffering: usize,
    /// Names this session brought to the broker.
    new_names: usize,
    /// chassisd's own link: its names are admitted without a budget.
    trusted: bool,
}

impl Session {
    /// A session in `version` (3.1.1 or 5) whose packets are at most `max_packet` bytes.
    pub fn new(version: Version, max_packet: usize) -> Self {
        Self {
            version,
            out_qos1: HashSet::new(),
            out_qos2: HashSet::new(),
            out_pubrel: HashSet::new(),
            in_qos1: HashSet::new(),
            in_qos2: HashMap::new(),
            in_qos2_bytes: 0,
            max_packet,
            buffering: 0,
            new_names: 0,
            trusted: false,
        }
    }

    /// chassisd's own link's session: the same checks, but its topic names (its reports)
    /// and retained messages are always admitted.
    pub fn trusted(version: Version, max_packet: usize) -> Self {
        Self {
            trusted: true,
            ..Self::new(version, max_packet)
        }
    }

    /// Gives back what the broker held for this session (its unreleased QoS 2 messages,
    /// dropped with the session, which is always clean).
    pub fn end(&mut self, held: &mut Held) {
        held.in_flight_bytes = held.in_flight_bytes.saturating_sub(self.in_qos2_bytes);
        self.in_qos2.clear();
        self.in_qos2_bytes = 0;
        self.release_buffer(held);
    }

    /// Reserves room for a packet of `total` bytes that is still arriving, when it is
    /// larger than a read's worth: the gate buffers it whole before judging it.
    pub fn reserve_buffer(&mut self, total: usize, held: &mut Held) -> Result<(), Violation> {
        self.release_buffer(held);
        if self.trusted || total <= SMALL_PACKET {
            return Ok(());
        }
        if held.buffered_bytes + total > held.max_buffered_bytes {
            return Err(OverBudget::Buffered.into());
        }
        held.buffered_bytes += total;
        self.buffering = total;
        Ok(())
    }

    /// Gives back the room reserved for a packet that arrived (or never will).
    pub fn release_buffer(&mut self, held: &mut Held) {
        held.buffered_bytes = held.buffered_bytes.saturating_sub(self.buffering);
        self.buffering = 0;
    }

    /// Notes a QoS 1 or 2 PUBLISH `id` of `size` bytes from the client, within the
    /// budgets. A repeated id (a DUP) is the same message.
    fn in_flight(
        &mut self,
        qos: u8,
        id: u16,
        size: usize,
        held: &mut Held,
    ) -> Result<(), Violation> {
        if self.in_qos1.contains(&id) || self.in_qos2.contains_key(&id) {
            return Ok(());
        }
        let trusted = self.trusted;
        if !trusted && self.in_qos1.len() + self.in_qos2.len() >= usize::from(MAX_IN_FLIGHT) {
            return Err(OverBudget::InFlight.into());
        }
        if qos == 1 {
            self.in_qos1.insert(id);
            return Ok(());
        }
        let over_client = self.in_qos2_bytes + size > held.client_in_flight_bytes(self.max_packet);
        let over_all = held.in_flight_bytes + size > held.max_in_flight_bytes;
        if !trusted && (over_client || over_all) {
            return Err(OverBudget::InFlightBytes.into());
        }
        self.in_qos2.insert(id, size);
        self.in_qos2_bytes += size;
        held.in_flight_bytes += size;
        Ok(())
    }

    /// The client released QoS 2 message `id`: the broker passes it on and lets it go.
    fn released(&mut self, id: u16, held: &mut Held) -> Result<(), Violation> {
        let size = self.in_qos2.remove(&id).ok_or(Violation::UnknownPacketId {
            kind: kind::PUBREL,
            id,
        })?;
        self.in_qos2_bytes -= size;
        held.in_flight_bytes = held.in_flight_bytes.saturating_sub(size);
        Ok(())
    }

    /// Admits `name` into `names`, within this session's budget of new ones.
    fn admit(&mut self, name: &str, names: &mut TopicNames) -> Result<(), Violation> {
        if names.holds(name) {
            return Ok(());
        }
        if self.trusted {
            names.reserve(name);
            return Ok(());
        }
        if name.len() > MAX_TOPIC_BYTES || self.new_names >= MAX_NEW_NAMES_PER_SESSION {
            return Err(OverBudget::TopicNames.into());
        }
        names.admit(name)?;
        self.new_names += 1;
        Ok(())
    }

    /// Judges a whole packet from the client (`packet` includes its fixed header `h`).
    pub fn from_client(
        &mut self,
        h: &Header,
        packet: &[u8],
        held: &mut Held,
    ) -> Result<Pass, Violation> {
        super::wire::check_client_packet(h, self.version)?;
        let body = &packet[h.header_len..h.total()];
        let mut f = Cursor::new(body);
        let v5 = self.version == Version::V5;
        match h.kind {
            kind::PUBLISH => {
                let qos = (h.flags >> 1) & 0b11;
                let topic = f.string("topic")?;
                if !valid_topic(topic) {
                    return Err(Violation::BadTopic);
                }
                let id = if qos > 0 { Some(f.packet_id()?) } else { None };
                if v5 {
                    let properties = f.read_properties()?;
                    super::wire::check_user_properties(&properties)?;
                    let ids: Vec<u8> = properties.iter().map(|p| p.id).collect();
                    if ids.contains(&0x23) {
                        return Err(Violation::Unsupported("a topic alias"));
                    }
                    if ids.contains(&0x0b) {
                        return Err(Violation::Unsupported(
                            "a subscription identifier in PUBLISH",
                        ));
                    }
                }
                self.admit(topic, &mut held.names)?;
                if let Some(id) = id {
                    self.in_flight(qos, id, h.total(), held)?;
                }
                let retain = h.flags & 1 != 0;
                let trusted = self.trusted;
                held.retained.publish(topic, f.left(), retain, trusted)?;
            }
            kind::PUBACK => ack(&mut self.out_qos1, h.kind, f.packet_id()?)?,
            kind::PUBREC => ack(&mut self.out_qos2, h.kind, f.packet_id()?)?,
            kind::PUBCOMP => ack(&mut self.out_pubrel, h.kind, f.packet_id()?)?,
            kind::PUBREL => self.released(f.packet_id()?, held)?,
            kind::SUBSCRIBE => {
                f.packet_id()?;
                if v5 && f.subscription_id_of_zero()? {
                    return Err(Violation::Unsupported("a subscription identifier of 0"));
                }
                let mut filters = 0;
                while !f.done() {
                    let filter = f.string("filter")?;
                    let options = f.u8("subscription options")?;
                    let reserved = if v5 { options & 0xc0 } else { options & 0xfc };
                    let bad_options =
                        reserved != 0 || options & 0b11 == 3 || (v5 && (options >> 4) & 0b11 == 3);
                    if bad_options {
                        return Err(Violation::Wire(WireError::Truncated(
                            "subscription options",
                        )));
                    }
                    if !valid_filter(filter) {
                        return Err(Violation::BadFilter);
                    }
                    self.admit(filter, &mut held.names)?;
                    filters += 1;
                }
                if filters == 0 {
                    return Err(Violation::BadFilter);
                }
            }
            kind::UNSUBSCRIBE => {
                f.packet_id()?;
                if v5 {
                    f.properties()?;
                }
                let mut filters = 0;
                while !f.done() {
                    f.string("filter")?;
                    filters += 1;
                }
                if filters == 0 {
                    return Err(Violation::BadFilter);
                }
            }
            kind::AUTH => return Err(Violation::Unsupported("enhanced authentication (AUTH)")),
            kind::DISCONNECT => return Ok(Pass::LastOne),
            // PINGREQ: nothing to check beyond its header.
            _ => {}
        }
        Ok(Pass::Forward)
    }

    /// Notes a whole packet from the broker (PUBLISH and PUBREL ids the client may then
    /// acknowledge). The broker is trusted: a packet it sends that cannot be read is
    /// passed on unnoted.
    pub fn from_broker(&mut self, h: &Header, packet: &[u8]) {
        let body = &packet[h.header_len.min(packet.len())..h.total().min(packet.len())];
        let mut f = Cursor::new(body);
        match h.kind {
            kind::PUBACK => {
                if let Ok(id) = f.packet_id() {
                    self.in_qos1.remove(&id);
                }
            }
            kind::PUBLISH => {
                let qos = (h.flags >> 1) & 0b11;
                if qos > 0
                    && f.string("topic").is_ok()
                    && let Ok(id) = f.packet_id()
                {
                    if qos == 1 {
                        self.out_qos1.insert(id);
                    } else {
                        self.out_qos2.insert(id);
                    }
                }
            }
            kind::PUBREL => {
                if let Ok(id) = f.packet_id() {
                    self.out_pubrel.insert(id);
                }
            }
            _ => {}
        }
    }
}

fn ack(pending: &mut HashSet<u16>, kind: u8, id: u16) -> Result<(), Violation> {
    if pending.remove(&id) {
        Ok(())
    } else {
        Err(Violation::UnknownPacketId { kind, id })
    }
}

/// A PUBLISH topic: non-empty, no wildcard (MQTT 3.1.1 section 4.7.3).
pub fn valid_topic(topic: &str) -> bool {
    !topic.is_empty() && !topic.contains(['+', '#'])
}

/// A subscription filter: non-empty, `#` only as the whole last level, `+` only as a
/// whole level, and not one of the `$` families (system topics, shared subscriptions).
pub fn valid_filter(filter: &str) -> bool {
    if filter.is_empty() || filter.starts_with('$') {
        return false;
    }
    let levels: Vec<&str> = filter.split('/').collect();
    levels.iter().enumerate().all(|(i, level)| {
        let multi_ok = !level.contains('#') || (*level == "#" && i == levels.len() - 1);
        let single_ok = !level.contains('+') || *level == "+";
        multi_ok && single_ok
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::broker::held::MAX_TOPIC_NAMES;
    use crate::broker::wire::header;

    fn judge(session: &mut Session, packet: &[u8], names: &mut Held) -> Result<Pass, Violation> {
        let h = header(packet, 1 << 16).unwrap().unwrap();
        session.from_client(&h, packet, names)
    }

    fn broker_sends(session: &mut Session, packet: &[u8]) {
        let h = header(packet, 1 << 16).unwrap().unwrap();
        session.from_broker(&h, packet);
    }

    fn publish(qos: u8, topic: &str, id: u16, v5: bool) -> Vec<u8> {
        let mut body = (topic.len() as u16).to_be_bytes().to_vec();
        body.extend_from_slice(topic.as_bytes());
        if qos > 0 {
            body.extend_from_slice(&id.to_be_bytes());
        }
        if v5 {
            body.push(0);
        }
        body.extend_from_slice(b"payload");
        crate::broker::wire::packet(0x30 | qos << 1, &body)
    }

    fn subscribe(filters: &[&str], v5_props: Option<&[u8]>) -> Vec<u8> {
        let mut body = vec![0, 7];
        if let Some(props) = v5_props {
            body.push(props.len() as u8);
            body.extend_from_slice(props);
        }
        for f in filters {
            body.extend_from_slice(&(f.len() as u16).to_be_bytes());
            body.extend_from_slice(f.as_bytes());
            body.push(1);
        }
        let mut p = vec![0x82, body.len() as u8];
        p.extend(body);
        p
    }

    #[test]
    fn acknowledgements_must_answer_what_was_sent() {
        let mut s = Session::new(Version::V4, 1 << 16);
        let mut names = Held::new([], 1 << 16);
        assert_eq!(
            judge(&mut s, &[0x40, 2, 0, 9], &mut names),
            Err(Violation::UnknownPacketId { kind: 4, id: 9 })
        );
        broker_sends(&mut s, &publish(1, "base_status", 9, false));
        assert_eq!(
            judge(&mut s, &[0x40, 2, 0, 9], &mut names),
            Ok(Pass::Forward)
        );
        // Only once.
        assert!(judge(&mut s, &[0x40, 2, 0, 9], &mut names).is_err());
        // The QoS 2 flow, both ways.
        broker_sends(&mut s, &publish(2, "feedback", 4, false));
        assert_eq!(
            judge(&mut s, &[0x50, 2, 0, 4], &mut names),
            Ok(Pass::Forward)
        );
        assert!(judge(&mut s, &[0x70, 2, 0, 4], &mut names).is_err());
        broker_sends(&mut s, &[0x62, 2, 0, 4]);
        assert_eq!(
            judge(&mut s, &[0x70, 2, 0, 4], &mut names),
            Ok(Pass::Forward)
        );
        assert!(judge(&mut s, &[0x62, 2, 0, 5], &mut names).is_err());
        assert_eq!(
            judge(&mut s, &publish(2, "mqtt_control", 5, false), &mut names),
            Ok(Pass::Forward)
        );
        assert_eq!(
            judge(&mut s, &[0x62, 2, 0, 5], &mut names),
            Ok(Pass::Forward)
        );
    }

    #[test]
    fn topics_and_filters_are_those_the_broker_serves() {
        let mut s = Session::new(Version::V4, 1 << 16);
        let mut names = Held::new([], 1 << 16);
        for bad in ["", "a/+", "a/#"] {
            assert_eq!(
                judge(&mut s, &publish(0, bad, 0, false), &mut names),
                Err(Violation::BadTopic),
                "{bad:?}"
            );
        }
        for good in ["#", "+", "a/+/b", "a/#", "base_status", "/root/x/+/+/set"] {
            assert!(valid_filter(good), "{good}");
        }
        for bad in ["", "a#", "a/#/b", "a+", "$SYS/#", "$share/g/a", "#/a"] {
            assert!(!valid_filter(bad), "{bad}");
        }
        assert_eq!(
            judge(&mut s, &subscribe(&["$SYS/#"], None), &mut names),
            Err(Violation::BadFilter)
        );
        assert_eq!(
            judge(&mut s, &subscribe(&[], None), &mut names),
            Err(Violation::BadFilter)
        );
        assert_eq!(
            judge(&mut s, &subscribe(&["a/+", "b/#"], None), &mut names),
            Ok(Pass::Forward)
        );
        // A zero packet id is malformed.
        assert!(judge(&mut s, &[0x40, 2, 0, 0], &mut names).is_err());
    }

    #[test]
    fn v5_features_the_broker_mishandles_are_refused() {
        let mut s = Session::new(Version::V5, 1 << 16);
        let mut names = Held::new([], 1 << 16);
        // Subscription identifier 0, then 5.
        assert_eq!(
            judge(&mut s, &subscribe(&["a"], Some(&[0x0b, 0])), &mut names),
            Err(Violation::Unsupported("a subscription identifier of 0"))
        );
        assert_eq!(
            judge(&mut s, &subscribe(&["a"], Some(&[0x0b, 5])), &mut names),
            Ok(Pass::Forward)
        );
        // A topic alias in PUBLISH.
        let mut p = publish(0, "a", 0, true);
        let props_at = 2 + 2 + 1;
        p[props_at] = 3;
        p.splice(props_at + 1..props_at + 1, [0x23, 0, 1]);
        p[1] += 3;
        assert_eq!(
            judge(&mut s, &p, &mut names),
            Err(Violation::Unsupported("a topic alias"))
        );
        assert!(judge(&mut s, &[0xf0, 2, 0x18, 0], &mut names).is_err());
        assert_eq!(judge(&mut s, &[0xe0, 0], &mut names), Ok(Pass::LastOne));
    }

    #[test]
    fn a_session_brings_a_bounded_number_of_new_names() {
        let mut names = Held::new(["mqtt_control".to_owned()], 1 << 16);
        let mut s = Session::new(Version::V4, 1 << 16);
        for i in 0..MAX_NEW_NAMES_PER_SESSION {
            let p = publish(0, &format!("t/{i}"), 0, false);
            assert_eq!(judge(&mut s, &p, &mut names), Ok(Pass::Forward));
        }
        assert_eq!(
            judge(&mut s, &publish(0, "one/more", 0, false), &mut names),
            Err(Violation::OverBudget(OverBudget::TopicNames))
        );
        // Names held, and reserved ones, go on being served.
        assert_eq!(
            judge(&mut s, &publish(0, "t/3", 0, false), &mut names),
            Ok(Pass::Forward)
        );
        assert_eq!(
            judge(&mut s, &publish(0, "mqtt_control", 0, false), &mut names),
            Ok(Pass::Forward)
        );
    }

    #[test]
    fn the_broker_holds_a_bounded_number_of_names() {
        let mut names = Held::new(["mqtt_control".to_owned()], 1 << 16);
        for i in 0..MAX_TOPIC_NAMES {
            // A fresh session now and then, as a client that reconnects to go on.
            let mut s = Session::new(Version::V4, 1 << 16);
            let p = publish(0, &format!("t/{i}"), 0, false);
            assert_eq!(judge(&mut s, &p, &mut names), Ok(Pass::Forward));
        }
        let mut s = Session::new(Version::V4, 1 << 16);
        assert_eq!(
            judge(&mut s, &publish(0, "one/more", 0, false), &mut names),
            Err(Violation::OverBudget(OverBudget::TopicNames))
        );
        // Names already held, and chassisd's own, go on being served.
        assert_eq!(
            judge(&mut s, &publish(0, "t/7", 0, false), &mut names),
            Ok(Pass::Forward)
        );
        assert_eq!(
            judge(&mut s, &publish(0, "mqtt_control", 0, false), &mut names),
            Ok(Pass::Forward)
        );
        assert_eq!(names.names.len(), MAX_TOPIC_NAMES);
    }

    #[test]
    fn messages_in_flight_are_bounded_and_released_by_their_acknowledgement() {
        let mut held = Held::new([], 1 << 16);
        let mut s = Session::new(Version::V4, 1 << 16);
        let max = usize::from(MAX_IN_FLIGHT);
        for id in 1..=max as u16 {
            let qos = if id % 2 == 0 { 2 } else { 1 };
            assert_eq!(
                judge(&mut s, &publish(qos, "t", id, false), &mut held),
                Ok(Pass::Forward)
            );
        }
        // A repeat (DUP) of one in flight is the same message.
        assert_eq!(
            judge(&mut s, &publish(2, "t", 2, false), &mut held),
            Ok(Pass::Forward)
        );
        assert_eq!(
            judge(&mut s, &publish(1, "t", 999, false), &mut held),
            Err(Violation::OverBudget(OverBudget::InFlight))
        );
        assert_eq!(
            Violation::OverBudget(OverBudget::InFlight).reason_code(),
            0x93
        );
        assert_eq!(
            held.in_flight_bytes,
            (max / 2) * publish(2, "t", 2, false).len()
        );
        // The broker's PUBACK frees a QoS 1 place, the client's PUBREL a QoS 2 one.
        broker_sends(&mut s, &[0x40, 2, 0, 1]);
        assert_eq!(
            judge(&mut s, &publish(1, "t", 1000, false), &mut held),
            Ok(Pass::Forward)
        );
        assert_eq!(
            judge(&mut s, &[0x62, 2, 0, 2], &mut held),
            Ok(Pass::Forward)
        );
        assert_eq!(
            judge(&mut s, &publish(2, "t", 1001, false), &mut held),
            Ok(Pass::Forward)
        );
        // The session's end gives back what the broker held for it.
        s.end(&mut held);
        assert_eq!(held.in_flight_bytes, 0);
    }

    #[test]
    fn unreleased_bytes_are_bounded_for_all_clients_together() {
        let max_packet = 1 << 20;
        let mut held = Held::new([], max_packet);
        let big = |id: u16| {
            let mut body = vec![0, 1, b't'];
            body.extend_from_slice(&id.to_be_bytes());
            body.resize(max_packet - 8, b'x');
            crate::broker::wire::packet(0x34, &body)
        };
        let mut refused_at = None;
        'clients: for client in 0..64 {
            let mut s = Session::new(Version::V4, max_packet);
            for id in 1..=8u16 {
                let p = big(id);
                let h = header(&p, max_packet).unwrap().unwrap();
                match s.from_client(&h, &p, &mut held) {
                    Ok(_) => {}
                    Err(Violation::OverBudget(OverBudget::InFlightBytes)) if id > 1 => break,
                    Err(e) => {
                        refused_at = Some((client, e));
                        break 'clients;
                    }
                }
            }
            // Each client keeps its share: a quarter of the whole.
            std::mem::forget(s);
        }
        assert!(held.in_flight_bytes <= held.max_in_flight_bytes);
        assert!(
            matches!(
                refused_at,
                Some((4, Violation::OverBudget(OverBudget::InFlightBytes)))
            ),
            "{refused_at:?}"
        );
    }

    #[test]
    fn large_packets_still_arriving_are_bounded_for_all_clients_together() {
        let max_packet = 4 << 20;
        let mut held = Held::new([], max_packet);
        let mut sessions: Vec<Session> = Vec::new();
        let mut refused = None;
        for i in 0..64 {
            let mut s = Session::new(Version::V4, max_packet);
            match s.reserve_buffer(max_packet, &mut held) {
                Ok(()) => sessions.push(s),
                Err(e) => {
                    refused = Some((i, e));
                    break;
                }
            }
        }
        assert_eq!(
            refused,
            Some((16, Violation::OverBudget(OverBudget::Buffered)))
        );
        // A small packet needs no room; a session's end gives its room back.
        let mut small = Session::new(Version::V4, max_packet);
        assert_eq!(small.reserve_buffer(1000, &mut held), Ok(()));
        sessions[0].end(&mut held);
        let mut next = Session::new(Version::V4, max_packet);
        assert_eq!(next.reserve_buffer(max_packet, &mut held), Ok(()));
        // Reserving again for the same session replaces its reservation.
        assert_eq!(next.reserve_buffer(max_packet, &mut held), Ok(()));
        assert_eq!(held.buffered_bytes, 16 * max_packet);
    }

    #[test]
    fn retained_messages_count_against_the_broker_and_topics_are_bounded() {
        let mut held = Held::new([], 1 << 16);
        let mut s = Session::new(Version::V4, 1 << 16);
        let mut retained = publish(0, "r/0", 0, false);
        retained[0] |= 1;
        assert_eq!(judge(&mut s, &retained, &mut held), Ok(Pass::Forward));
        assert_eq!(held.retained.len(), 1);
        let long = "x".repeat(crate::broker::held::MAX_TOPIC_BYTES + 1);
        assert_eq!(
            judge(&mut s, &publish(0, &long, 0, false), &mut held),
            Err(Violation::OverBudget(OverBudget::TopicNames))
        );
    }

    #[test]
    fn truncated_packets_are_errors_never_panics() {
        let whole = publish(1, "device/x/goal", 3, true);
        let mut names = Held::new([], 1 << 16);
        // Up to the properties' end (the payload may have any length).
        for cut in 2..2 + 2 + 13 + 2 + 1 {
            let mut p = whole[..cut].to_vec();
            p[1] = (cut - 2) as u8;
            let mut s = Session::new(Version::V5, 1 << 16);
            assert!(judge(&mut s, &p, &mut names).is_err(), "cut at {cut}");
        }
    }
}
