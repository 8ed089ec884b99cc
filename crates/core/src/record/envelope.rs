//! The line envelope shared by every recording file: `(seconds.micros) source payload`.
//!
//! CAN files are exact `candump -L` lines (handled by the socketcan crate). Serial and
//! command files reuse the envelope:
//! - serial chunk: `(1700000000.123456) gnss 2447504747412C...` — the raw bytes in hex;
//! - serial link event: `(1700000000.123456) gnss !link-down` (or `!link-up`);
//! - command: `(1700000000.123456) mqtt mqtt_control#7B22636D64...` — topic, `#`, payload in
//!   hex. The topic is percent-escaped where it holds `%`, `#`, spaces or non-printable bytes.
//! - command link event: `(1700000000.123456) mqtt !link-up` (or `!link-down`): a command line
//!   always holds `#`, so the two never meet.

use crate::time::Timestamp;

/// A line that does not follow the envelope.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EnvelopeError {
    /// The `(seconds.micros)` field is missing or malformed.
    #[error("bad timestamp {0:?}: expected (seconds.micros) with six digits of micros")]
    Timestamp(String),
    /// The source name is missing.
    #[error("missing source name")]
    Source,
    /// The payload is missing or malformed.
    #[error("bad payload: {0}")]
    Payload(String),
}

/// A line split into its three fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Envelope<'a> {
    /// Timestamp.
    pub t: Timestamp,
    /// Source name (serial device name, CAN interface, command channel).
    pub source: &'a str,
    /// The rest of the line.
    pub payload: &'a str,
}

/// Splits a line (without its line ending) into timestamp, source and payload.
pub fn split(line: &str) -> Result<Envelope<'_>, EnvelopeError> {
    let line = line.trim_end_matches(['\r', '\n']);
    let (stamp, rest) = line
        .split_once(' ')
        .ok_or_else(|| EnvelopeError::Timestamp(line.to_owned()))?;
    let t = parse_timestamp(stamp)?;
    let (source, payload) = rest.split_once(' ').unwrap_or((rest, ""));
    if source.is_empty() {
        return Err(EnvelopeError::Source);
    }
    Ok(Envelope { t, source, payload })
}

/// Parses `(seconds.micros)` exactly, without going through floating point.
pub fn parse_timestamp(field: &str) -> Result<Timestamp, EnvelopeError> {
    let bad = || EnvelopeError::Timestamp(field.to_owned());
    let inner = field
        .strip_prefix('(')
        .and_then(|f| f.strip_suffix(')'))
        .ok_or_else(bad)?;
    let (secs, micros) = inner.split_once('.').ok_or_else(bad)?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if !digits(secs) || micros.len() != 6 || !digits(micros) {
        return Err(bad());
    }
    let secs: u64 = secs.parse().map_err(|_| bad())?;
    let micros: u64 = micros.parse().map_err(|_| bad())?;
    secs.checked_mul(1_000_000)
        .and_then(|us| us.checked_add(micros))
        .map(Timestamp::from_micros)
        .filter(|t| t.as_micros() < u64::MAX / 1_000)
        .ok_or_else(bad)
}

/// Uppercase hex of `bytes`.
pub fn to_hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789ABCDEF";
    let mut s = String::with_capacity(bytes.len() * 2);
    for &b in bytes {
        s.push(char::from(DIGITS[usize::from(b >> 4)]));
        s.push(char::from(DIGITS[usize::from(b & 0x0f)]));
    }
    s
}

/// Bytes of a hex string (either case).
pub fn from_hex(hex: &str) -> Result<Vec<u8>, EnvelopeError> {
    if !hex.len().is_multiple_of(2) {
        return Err(EnvelopeError::Payload(format!(
            "odd number of hex digits ({})",
            hex.len()
        )));
    }
    hex.as_bytes()
        .chunks_exact(2)
        .enumerate()
        .map(|(i, pair)| match (hex_digit(pair[0]), hex_digit(pair[1])) {
            (Some(h), Some(l)) => Ok((h << 4) | l),
            _ => Err(EnvelopeError::Payload(format!(
                "non-hex digit at offset {}",
                2 * i
            ))),
        })
        .collect()
}

fn hex_digit(b: u8) -> Option<u8> {
    char::from(b)
        .to_digit(16)
        .and_then(|d| u8::try_from(d).ok())
}

/// Escapes a topic so it is one token without `#`.
pub fn escape_topic(topic: &str) -> String {
    let mut out = String::with_capacity(topic.len());
    for &b in topic.as_bytes() {
        if b.is_ascii_graphic() && b != b'%' && b != b'#' {
            out.push(char::from(b));
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// Reverses [`escape_topic`].
pub fn unescape_topic(escaped: &str) -> Result<String, EnvelopeError> {
    let bytes = escaped.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let pair = bytes
                .get(i + 1..i + 3)
                .ok_or_else(|| EnvelopeError::Payload("truncated %-escape in topic".into()))?;
            match (hex_digit(pair[0]), hex_digit(pair[1])) {
                (Some(h), Some(l)) => out.push((h << 4) | l),
                _ => return Err(EnvelopeError::Payload("bad %-escape in topic".into())),
            }
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| EnvelopeError::Payload("topic is not UTF-8".into()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_round_trip_exactly() {
        let t = parse_timestamp("(1700000000.123456)").unwrap();
        assert_eq!(t.as_micros(), 1_700_000_000_123_456);
        assert_eq!(format!("({t})"), "(1700000000.123456)");
        for bad in [
            "1700000000.123456",
            "(1700000000.12345)",
            "(1700000000)",
            "(-1.000000)",
            "(1.00000a)",
            "(99999999999999999999.000000)",
        ] {
            assert!(parse_timestamp(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn splits_lines() {
        let e = split("(1.000001) gnss 2447\r\n").unwrap();
        assert_eq!(
            (e.t.as_micros(), e.source, e.payload),
            (1_000_001, "gnss", "2447")
        );
        assert_eq!(split("(1.000001) ").unwrap_err(), EnvelopeError::Source);
        assert!(split("garbage").is_err());
    }

    #[test]
    fn hex_round_trip() {
        let bytes: Vec<u8> = (0..=255).collect();
        assert_eq!(from_hex(&to_hex(&bytes)).unwrap(), bytes);
        assert_eq!(from_hex("0a0B").unwrap(), vec![10, 11]);
        assert!(from_hex("abc").is_err());
        assert!(from_hex("zz").is_err());
    }

    #[test]
    fn topics_round_trip() {
        for topic in ["mqtt_control", "/root/v 1/cmd", "a#b%c", "设备/x"] {
            let escaped = escape_topic(topic);
            assert!(!escaped.contains([' ', '#']));
            assert_eq!(unescape_topic(&escaped).unwrap(), topic);
        }
        assert!(unescape_topic("%4").is_err());
    }
}
