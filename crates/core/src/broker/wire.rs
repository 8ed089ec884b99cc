//! MQTT 3.1.1 and 5.0 wire reading for the embedded broker's gate: fixed headers framed,
//! CONNECT read field by field, and CONNACK refusals written. Nothing here trusts a length
//! it is given: every one is checked against the bytes present and the configured bound.

pub use super::cursor::WireError;
use super::cursor::{Cursor, Property};

/// MQTT control packet types (the fixed header's high nibble).
pub mod kind {
    pub const CONNECT: u8 = 1;
    pub const CONNACK: u8 = 2;
    pub const PUBLISH: u8 = 3;
    pub const PUBACK: u8 = 4;
    pub const PUBREC: u8 = 5;
    pub const PUBREL: u8 = 6;
    pub const PUBCOMP: u8 = 7;
    pub const SUBSCRIBE: u8 = 8;
    pub const SUBACK: u8 = 9;
    pub const UNSUBSCRIBE: u8 = 10;
    pub const UNSUBACK: u8 = 11;
    pub const PINGREQ: u8 = 12;
    pub const PINGRESP: u8 = 13;
    pub const DISCONNECT: u8 = 14;
    pub const AUTH: u8 = 15;
}

/// The largest remaining length the encoding can carry (four 7-bit digits).
pub const MAX_REMAINING_LENGTH: usize = 268_435_455;

/// A packet's fixed header: its type, flags and where its body lies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// Packet type (1..=15).
    pub kind: u8,
    /// The low nibble of the first byte.
    pub flags: u8,
    /// Bytes of the fixed header (type byte and remaining length).
    pub header_len: usize,
    /// Bytes of the body (the remaining length).
    pub body_len: usize,
}

impl Header {
    /// The whole packet's length, bytes.
    pub fn total(&self) -> usize {
        self.header_len + self.body_len
    }
}

/// Reads the fixed header at the start of `buf`. `Ok(None)`: more bytes are needed.
/// A packet over `limit` bytes is refused before its body is waited for.
pub fn header(buf: &[u8], limit: usize) -> Result<Option<Header>, WireError> {
    let Some(&first) = buf.first() else {
        return Ok(None);
    };
    let mut body_len = 0usize;
    for i in 0..4 {
        let Some(&digit) = buf.get(1 + i) else {
            return Ok(None);
        };
        body_len |= usize::from(digit & 0x7f) << (7 * i);
        if digit & 0x80 == 0 {
            let header = Header {
                kind: first >> 4,
                flags: first & 0x0f,
                header_len: 2 + i,
                body_len,
            };
            if header.total() > limit {
                return Err(WireError::TooLarge {
                    size: header.total(),
                    limit,
                });
            }
            return Ok(Some(header));
        }
    }
    Err(WireError::BadRemainingLength)
}

/// Checks a packet a connected client sends: its type is one a client may send with the
/// version in use, and its header flags are those the type requires.
pub fn check_client_packet(h: &Header, version: Version) -> Result<(), WireError> {
    use kind::*;
    let allowed = match h.kind {
        PUBLISH | PUBACK | PUBREC | PUBREL | PUBCOMP | SUBSCRIBE | UNSUBSCRIBE | PINGREQ
        | DISCONNECT => true,
        AUTH => version == Version::V5,
        _ => false,
    };
    if !allowed {
        return Err(WireError::Forbidden(h.kind));
    }
    let flags_ok = match h.kind {
        // QoS 3 is malformed; DUP and RETAIN are free.
        PUBLISH => (h.flags >> 1) & 0b11 != 0b11,
        PUBREL | SUBSCRIBE | UNSUBSCRIBE => h.flags == 0b0010,
        _ => h.flags == 0,
    };
    if !flags_ok {
        return Err(WireError::BadFlags {
            kind: h.kind,
            flags: h.flags,
        });
    }
    Ok(())
}

/// The protocol a client asked for in its CONNECT.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Version {
    /// MQTT 3.1 (`MQIsdp`, level 3): refused, as the broker does not speak it.
    V3,
    /// MQTT 3.1.1 (level 4).
    V4,
    /// MQTT 5.0 (level 5).
    V5,
    /// `MQTT` with a level other than 4 or 5: refused as an unacceptable version.
    Other(u8),
}

/// The fields of a CONNECT the gate decides on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Connect {
    /// The protocol version asked for.
    pub version: Version,
    /// The client identifier (may be empty).
    pub client_id: String,
    /// Keep-alive interval, s (0: none).
    pub keep_alive_s: u16,
    /// The user name, when the flag is set.
    pub username: Option<String>,
    /// The password bytes, when the flag is set.
    pub password: Option<Vec<u8>>,
    /// The last will's topic, when a will is set.
    pub will_topic: Option<String>,
    /// MQTT 5: the largest packet the client accepts (`Maximum Packet Size`), bytes.
    pub max_packet_to_client: Option<usize>,
    /// The will's payload length, when the will is to be retained.
    pub retained_will: Option<usize>,
}

/// User properties one packet may carry: MQTT sets no bound, and each is two strings the
/// broker keeps with the message.
pub const MAX_USER_PROPERTIES: usize = 32;

/// Reads a CONNECT body (the bytes after the fixed header). A version the broker does not
/// speak is returned, not refused, so that the caller can answer it with a CONNACK.
pub fn connect(body: &[u8]) -> Result<Connect, WireError> {
    let mut f = Cursor::new(body);
    let name = f.binary("protocol name")?;
    let level = f.u8("protocol level")?;
    let version = match (name, level) {
        (b"MQTT", 4) => Version::V4,
        (b"MQTT", 5) => Version::V5,
        (b"MQTT", other) => return Ok(refused_version(Version::Other(other))),
        (b"MQIsdp", _) => return Ok(refused_version(Version::V3)),
        _ => return Err(WireError::UnknownProtocol),
    };
    let flags = f.u8("connect flags")?;
    let will = flags & 0x04 != 0;
    let will_qos = (flags >> 3) & 0b11;
    let will_retain = flags & 0x20 != 0;
    let has_password = flags & 0x40 != 0;
    let has_username = flags & 0x80 != 0;
    let contradictory = flags & 0x01 != 0
        || will_qos == 3
        || (!will && (will_qos != 0 || will_retain))
        || (version == Version::V4 && has_password && !has_username);
    if contradictory {
        return Err(WireError::BadConnectFlags(flags));
    }
    let keep_alive_s = f.u16("keep alive")?;
    let mut max_packet_to_client = None;
    if version == Version::V5 {
        let properties = f.read_properties()?;
        check_user_properties(&properties)?;
        for p in properties {
            match (p.id, p.value) {
                // Receive Maximum and Maximum Packet Size of 0 are protocol errors (MQTT 5
                // sections 3.1.2.11.3 and 3.1.2.11.4).
                (0x21, Some(0)) => return Err(WireError::Truncated("receive maximum (0)")),
                (0x27, Some(0)) => return Err(WireError::Truncated("maximum packet size (0)")),
                (0x27, Some(n)) => max_packet_to_client = Some(n),
                _ => {}
            }
        }
    }
    let client_id = f.string("client identifier")?.to_owned();
    let mut will_topic = None;
    let mut retained_will = None;
    if will {
        if version == Version::V5 {
            check_user_properties(&f.read_properties()?)?;
        }
        will_topic = Some(f.string("will topic")?.to_owned());
        let payload = f.binary("will payload")?;
        retained_will = will_retain.then_some(payload.len());
    }
    let username = has_username
        .then(|| f.string("user name").map(str::to_owned))
        .transpose()?;
    let password = has_password
        .then(|| f.binary("password").map(<[u8]>::to_vec))
        .transpose()?;
    let left = f.left();
    if left != 0 {
        return Err(WireError::TrailingBytes(left));
    }
    Ok(Connect {
        version,
        client_id,
        keep_alive_s,
        username,
        password,
        will_topic,
        max_packet_to_client,
        retained_will,
    })
}

/// Refuses more than [`MAX_USER_PROPERTIES`] user properties (identifier 0x26).
pub(crate) fn check_user_properties(properties: &[Property]) -> Result<(), WireError> {
    if properties.iter().filter(|p| p.id == 0x26).count() > MAX_USER_PROPERTIES {
        return Err(WireError::Truncated("user properties (too many)"));
    }
    Ok(())
}

fn refused_version(version: Version) -> Connect {
    Connect {
        version,
        client_id: String::new(),
        keep_alive_s: 0,
        username: None,
        password: None,
        will_topic: None,
        max_packet_to_client: None,
        retained_will: None,
    }
}

/// The keep-alive the broker is told for a client that asked for none (0): rumqttd takes 0
/// as "no silence allowed at all" and drops the client at once, where MQTT means "no
/// keep-alive". The longest it can be told, some 18 hours; the gate watches such a client
/// with TCP keep-alive instead.
pub const NO_KEEP_ALIVE_UPSTREAM: u16 = u16::MAX;

/// Sets the keep-alive of a whole CONNECT packet that [`connect`] read, whose fixed header
/// is `h`.
pub fn set_keep_alive(packet: &mut [u8], h: &Header, seconds: u16) {
    // The keep-alive follows the name (6 bytes), the level and the flags.
    let at = h.header_len + 8;
    if let Some(field) = packet.get_mut(at..at + 2) {
        field.copy_from_slice(&seconds.to_be_bytes());
    }
}

/// An MQTT 5 DISCONNECT with `reason` (the gate tells a 5.0 client why it ends a session).
pub fn disconnect_v5(reason: u8) -> [u8; 3] {
    [kind::DISCONNECT << 4, 0x01, reason]
}

/// The broker's MQTT 5 CONNACK (whole packet) with the gate's own limits told to the
/// client: `Receive Maximum` (QoS 1 and 2 messages it may have in flight) and `Maximum
/// Packet Size`, replacing what the broker said of either. `None` if it cannot be read.
pub fn connack_v5_with_limits(
    connack: &[u8],
    receive_maximum: u16,
    max_packet: usize,
) -> Option<Vec<u8>> {
    let h = header(connack, usize::MAX).ok()??;
    let body = connack.get(h.header_len..h.total())?;
    let mut f = Cursor::new(body);
    let flags = f.u8("acknowledge flags").ok()?;
    let reason = f.u8("reason code").ok()?;
    let mut properties = Vec::new();
    if !f.done() {
        for p in f.read_properties().ok()? {
            if !matches!(p.id, 0x21 | 0x27) {
                properties.extend_from_slice(body.get(p.span)?);
            }
        }
    }
    properties.push(0x21);
    properties.extend_from_slice(&receive_maximum.to_be_bytes());
    properties.push(0x27);
    let max_packet = u32::try_from(max_packet).unwrap_or(u32::MAX);
    properties.extend_from_slice(&max_packet.to_be_bytes());
    let mut out = vec![flags, reason];
    out.extend(variable_length(properties.len()));
    out.extend(properties);
    Some(packet(kind::CONNACK << 4, &out))
}

/// A length in MQTT's variable byte encoding.
fn variable_length(mut n: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(4);
    loop {
        let digit = (n % 128) as u8;
        n /= 128;
        out.push(if n > 0 { digit | 0x80 } else { digit });
        if n == 0 {
            return out;
        }
    }
}

/// Sets the clean-session (3.1.1) or clean-start (5) flag of a whole CONNECT packet that
/// [`connect`] read, whose fixed header is `h`: the embedded broker keeps no sessions, as a
/// session kept per client identifier is memory any client could grow without bound.
pub fn force_clean_session(packet: &mut [u8], h: &Header) {
    // The flags follow the protocol name "MQTT" (2 + 4 bytes) and the level (1 byte).
    if let Some(flags) = packet.get_mut(h.header_len + 7) {
        *flags |= 0x02;
    }
}

/// Why a CONNECT is refused with a CONNACK.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Refusal {
    /// MQTT 3.1 or an unknown level.
    UnacceptableVersion,
    /// The client identifier is one the broker cannot route.
    IdentifierRejected,
    /// The broker holds as many clients as it may.
    ServerUnavailable,
    /// Wrong user name or password.
    BadCredentials,
    /// No credentials where they are required.
    NotAuthorized,
    /// The client identifier is chassisd's own, or one the configuration reserves.
    ReservedIdentifier,
    /// The last will would publish on one of chassisd's own topics (a will is no
    /// command, and no report of the vehicle's).
    ReservedWill,
    /// The will would be retained with a payload over what the broker keeps for one.
    QuotaExceeded,
}

impl Refusal {
    /// A short name for logs and counters.
    pub fn name(self) -> &'static str {
        match self {
            Self::UnacceptableVersion => "unacceptable protocol version",
            Self::IdentifierRejected => "client identifier rejected",
            Self::ServerUnavailable => "client limit reached",
            Self::BadCredentials => "wrong user name or password",
            Self::NotAuthorized => "no credentials",
            Self::ReservedIdentifier => "client identifier reserved for chassisd",
            Self::ReservedWill => "last will on one of chassisd's own topics",
            Self::QuotaExceeded => "retained will over the broker's budget",
        }
    }
}

/// The CONNACK that refuses a client, in its own protocol version. Credentials are refused
/// as mosquitto 2 refuses them: "not authorised" (3.1.1 code 5, 5.0 reason 0x87) whether
/// they are missing, unknown or wrong, so a prober learns nothing of which part failed.
pub fn connack_refusal(version: Version, why: Refusal) -> Vec<u8> {
    if version == Version::V5 {
        let reason = match why {
            Refusal::UnacceptableVersion => 0x84,
            Refusal::IdentifierRejected | Refusal::ReservedIdentifier => 0x85,
            Refusal::ReservedWill => 0x87,
            Refusal::QuotaExceeded => 0x97,
            // Server busy: the limit is a passing condition, worth a later retry.
            Refusal::ServerUnavailable => 0x89,
            Refusal::BadCredentials | Refusal::NotAuthorized => 0x87,
        };
        // Session present 0, reason, no properties.
        vec![0x20, 0x03, 0x00, reason, 0x00]
    } else {
        let code = match why {
            Refusal::UnacceptableVersion => 1,
            Refusal::IdentifierRejected | Refusal::ReservedIdentifier => 2,
            Refusal::ServerUnavailable | Refusal::QuotaExceeded => 3,
            Refusal::BadCredentials | Refusal::NotAuthorized | Refusal::ReservedWill => 5,
        };
        vec![0x20, 0x02, 0x00, code]
    }
}

/// A whole packet: the first byte (type and flags), the remaining length, the body.
pub fn packet(first: u8, body: &[u8]) -> Vec<u8> {
    let mut p = Vec::with_capacity(body.len() + 5);
    p.push(first);
    p.extend(variable_length(body.len()));
    p.extend_from_slice(body);
    p
}

/// An MQTT 3.1.1 CONNECT with a clean session, `keep_alive_s` and nothing else (the broker's
/// own probe, and load tools).
pub fn plain_connect(client_id: &str, keep_alive_s: u16) -> Vec<u8> {
    let mut body = vec![0, 4, b'M', b'Q', b'T', b'T', 4, 0x02];
    body.extend_from_slice(&keep_alive_s.to_be_bytes());
    body.extend_from_slice(&(client_id.len() as u16).to_be_bytes());
    body.extend_from_slice(client_id.as_bytes());
    packet(kind::CONNECT << 4, &body)
}

/// A DISCONNECT that ends a session normally (the same bytes in 3.1.1 and 5.0): the gate
/// sends it to the broker for a client that left during the handshake, so no will fires.
pub const DISCONNECT: [u8; 2] = [0xe0, 0x00];

/// Whether a CONNACK (whole packet) accepts the connection.
pub fn connack_accepts(packet: &[u8]) -> bool {
    packet.len() >= 4 && packet[0] == 0x20 && packet[3] == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CONNECT packet (whole) with the given fields.
    pub(crate) fn connect_packet(
        level: u8,
        client_id: &str,
        credentials: Option<(&str, &[u8])>,
        will: bool,
    ) -> Vec<u8> {
        let mut body = vec![0, 4, b'M', b'Q', b'T', b'T', level];
        let mut flags = 0x02;
        if will {
            flags |= 0x04;
        }
        if credentials.is_some() {
            flags |= 0xc0;
        }
        body.push(flags);
        body.extend_from_slice(&30u16.to_be_bytes());
        if level == 5 {
            body.push(0);
        }
        let string = |body: &mut Vec<u8>, s: &[u8]| {
            body.extend_from_slice(&(s.len() as u16).to_be_bytes());
            body.extend_from_slice(s);
        };
        string(&mut body, client_id.as_bytes());
        if will {
            if level == 5 {
                body.push(0);
            }
            string(&mut body, b"will/topic");
            string(&mut body, b"gone");
        }
        if let Some((user, password)) = credentials {
            string(&mut body, user.as_bytes());
            string(&mut body, password);
        }
        packet(0x10, &body)
    }

    fn parse(packet: &[u8]) -> Result<Connect, WireError> {
        let h = header(packet, 1 << 20).unwrap().unwrap();
        assert_eq!(h.kind, kind::CONNECT);
        connect(&packet[h.header_len..h.total()])
    }

    #[test]
    fn a_311_connect_with_credentials_and_a_will_is_read() {
        let c = parse(&connect_packet(4, "robot", Some(("op", b"s3cret")), true)).unwrap();
        assert_eq!(c.version, Version::V4);
        assert_eq!(c.client_id, "robot");
        assert_eq!(c.keep_alive_s, 30);
        assert_eq!(c.username.as_deref(), Some("op"));
        assert_eq!(c.password.as_deref(), Some(&b"s3cret"[..]));
        assert_eq!(c.will_topic.as_deref(), Some("will/topic"));
        assert_eq!(c.retained_will, None);
        let mut retained = connect_packet(4, "robot", None, true);
        retained[9] |= 0x20;
        assert_eq!(parse(&retained).unwrap().retained_will, Some(4));
    }

    #[test]
    fn a_v5_connect_skips_its_properties() {
        let c = parse(&connect_packet(5, "", None, true)).unwrap();
        assert_eq!(c.version, Version::V5);
        assert_eq!(c.client_id, "");
        assert_eq!(c.username, None);
    }

    #[test]
    fn old_and_unknown_versions_are_returned_for_a_refusal() {
        let mut p = connect_packet(4, "x", None, false);
        p[8] = 3;
        assert_eq!(parse(&p).unwrap().version, Version::Other(3));
        let mut body = vec![0, 6];
        body.extend_from_slice(b"MQIsdp");
        body.extend_from_slice(&[3, 2, 0, 10, 0, 1, b'x']);
        let mut old = vec![0x10, body.len() as u8];
        old.extend_from_slice(&body);
        assert_eq!(parse(&old).unwrap().version, Version::V3);
    }

    #[test]
    fn every_truncation_of_a_connect_is_an_error_never_a_panic() {
        let whole = connect_packet(5, "robot", Some(("op", b"pw")), true);
        let h = header(&whole, 1 << 20).unwrap().unwrap();
        let body = &whole[h.header_len..];
        for cut in 0..body.len() {
            assert!(connect(&body[..cut]).is_err(), "cut at {cut}");
        }
        let mut longer = body.to_vec();
        longer.push(0);
        assert_eq!(connect(&longer), Err(WireError::TrailingBytes(1)));
    }

    /// A v5 CONNECT of client `x` whose properties are `props`.
    fn v5_with_properties(props: &[u8]) -> Vec<u8> {
        let mut body = vec![0, 4, b'M', b'Q', b'T', b'T', 5, 0x02, 0, 30];
        body.extend(variable_length(props.len()));
        body.extend_from_slice(props);
        body.extend_from_slice(&[0, 1, b'x']);
        packet(0x10, &body)
    }

    #[test]
    fn v5_limits_are_read_and_zero_ones_refused() {
        // Maximum Packet Size 1000, Receive Maximum 10.
        let c = parse(&v5_with_properties(&[0x27, 0, 0, 0x03, 0xe8, 0x21, 0, 10])).unwrap();
        assert_eq!(c.max_packet_to_client, Some(1000));
        // Receive Maximum 0 and Maximum Packet Size 0 are protocol errors.
        assert!(parse(&v5_with_properties(&[0x21, 0, 0])).is_err());
        assert!(parse(&v5_with_properties(&[0x27, 0, 0, 0, 0])).is_err());
        // At most MAX_USER_PROPERTIES user properties.
        let user = [0x26, 0, 1, b'k', 0, 1, b'v'];
        let many: Vec<u8> = user.repeat(MAX_USER_PROPERTIES);
        assert!(parse(&v5_with_properties(&many)).is_ok());
        let too_many: Vec<u8> = user.repeat(MAX_USER_PROPERTIES + 1);
        assert!(parse(&v5_with_properties(&too_many)).is_err());
    }

    #[test]
    fn no_keep_alive_is_told_to_the_broker_as_the_longest() {
        let mut p = connect_packet(4, "x", None, false);
        let h = header(&p, 1 << 20).unwrap().unwrap();
        set_keep_alive(&mut p, &h, NO_KEEP_ALIVE_UPSTREAM);
        let c = parse(&p).unwrap();
        assert_eq!((c.keep_alive_s, c.client_id.as_str()), (u16::MAX, "x"));
    }

    #[test]
    fn a_v5_connack_carries_the_gates_limits() {
        // rumqttd's CONNACK: session present 0, success, with a Maximum QoS and a Receive
        // Maximum of its own.
        let ack = packet(0x20, &[0x00, 0x00, 0x05, 0x24, 0x01, 0x21, 0x00, 0x64]);
        let out = connack_v5_with_limits(&ack, 32, 4096).unwrap();
        let h = header(&out, 1 << 20).unwrap().unwrap();
        assert_eq!((h.kind, h.total()), (kind::CONNACK, out.len()));
        let mut f = Cursor::new(&out[h.header_len..]);
        assert_eq!((f.u8("").unwrap(), f.u8("").unwrap()), (0, 0));
        let props: Vec<(u8, Option<usize>)> = f
            .read_properties()
            .unwrap()
            .into_iter()
            .map(|p| (p.id, p.value))
            .collect();
        assert_eq!(
            props,
            [(0x24, Some(1)), (0x21, Some(32)), (0x27, Some(4096))]
        );
        assert!(connack_accepts(&out));
        assert_eq!(connack_v5_with_limits(&[0x20, 0x05, 0], 32, 1), None);
    }

    #[test]
    fn a_persistent_session_is_made_clean() {
        let mut p = connect_packet(4, "x", None, false);
        p[9] &= !0x02;
        let h = header(&p, 1 << 20).unwrap().unwrap();
        force_clean_session(&mut p, &h);
        assert_eq!(p[9] & 0x02, 0x02);
        assert_eq!(parse(&p).unwrap().client_id, "x");
    }

    #[test]
    fn contradictory_flags_are_refused() {
        let mut p = connect_packet(4, "x", None, false);
        // Password without user name (3.1.1).
        p[9] |= 0x40;
        assert!(matches!(parse(&p), Err(WireError::BadConnectFlags(_))));
        let mut p = connect_packet(4, "x", None, false);
        p[9] |= 0x01;
        assert!(matches!(parse(&p), Err(WireError::BadConnectFlags(_))));
        let mut p = connect_packet(4, "x", None, false);
        // Will QoS without a will.
        p[9] |= 0x08;
        assert!(matches!(parse(&p), Err(WireError::BadConnectFlags(_))));
    }

    #[test]
    fn strings_must_be_utf8_without_nul() {
        let mut p = connect_packet(4, "ab", None, false);
        let at = p.len() - 1;
        p[at] = 0;
        assert_eq!(parse(&p), Err(WireError::BadString("client identifier")));
        p[at] = 0xff;
        assert_eq!(parse(&p), Err(WireError::BadString("client identifier")));
    }

    #[test]
    fn headers_need_their_bytes_and_respect_the_limit() {
        assert_eq!(header(&[], 100), Ok(None));
        assert_eq!(header(&[0x30], 100), Ok(None));
        assert_eq!(header(&[0x30, 0x80], 100), Ok(None));
        assert_eq!(
            header(&[0x30, 0x05], 100),
            Ok(Some(Header {
                kind: 3,
                flags: 0,
                header_len: 2,
                body_len: 5
            }))
        );
        assert_eq!(
            header(&[0x30, 0xff, 0xff, 0xff, 0x7f], usize::MAX),
            Ok(Some(Header {
                kind: 3,
                flags: 0,
                header_len: 5,
                body_len: MAX_REMAINING_LENGTH
            }))
        );
        assert_eq!(
            header(&[0x30, 0xff, 0xff, 0xff, 0xff, 0x01], usize::MAX),
            Err(WireError::BadRemainingLength)
        );
        assert_eq!(
            header(&[0x30, 0x80, 0x01], 100),
            Err(WireError::TooLarge {
                size: 131,
                limit: 100
            })
        );
    }

    #[test]
    fn clients_may_send_only_their_own_packets_with_their_flags() {
        let h = |kind, flags| Header {
            kind,
            flags,
            header_len: 2,
            body_len: 0,
        };
        assert!(check_client_packet(&h(kind::PUBLISH, 0b1011), Version::V4).is_ok());
        assert!(check_client_packet(&h(kind::PUBLISH, 0b0110), Version::V4).is_err());
        assert!(check_client_packet(&h(kind::SUBSCRIBE, 0b0010), Version::V4).is_ok());
        assert!(check_client_packet(&h(kind::SUBSCRIBE, 0), Version::V4).is_err());
        assert!(check_client_packet(&h(kind::CONNECT, 0), Version::V4).is_err());
        assert!(check_client_packet(&h(kind::CONNACK, 0), Version::V4).is_err());
        assert!(check_client_packet(&h(kind::SUBACK, 0), Version::V4).is_err());
        assert!(check_client_packet(&h(0, 0), Version::V4).is_err());
        assert!(check_client_packet(&h(kind::AUTH, 0), Version::V4).is_err());
        assert!(check_client_packet(&h(kind::AUTH, 0), Version::V5).is_ok());
        assert!(check_client_packet(&h(kind::PINGREQ, 1), Version::V4).is_err());
    }

    #[test]
    fn refusals_are_written_in_the_clients_version() {
        assert_eq!(
            connack_refusal(Version::V4, Refusal::BadCredentials),
            [0x20, 2, 0, 5]
        );
        assert_eq!(
            connack_refusal(Version::V5, Refusal::NotAuthorized),
            [0x20, 3, 0, 0x87, 0]
        );
        assert!(connack_accepts(&[0x20, 2, 0, 0]));
        assert!(!connack_accepts(&[0x20, 2, 0, 5]));
    }
}
