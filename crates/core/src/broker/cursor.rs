//! A cursor over an MQTT packet's body: each field read by its type, and never past the
//! body's end (every length in a packet is the sender's claim).

use std::fmt;

/// Why bytes are not an acceptable MQTT packet. Each one ends the connection.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WireError {
    /// The remaining length runs over four bytes.
    BadRemainingLength,
    /// The packet is larger than the gate lets through, bytes.
    TooLarge { size: usize, limit: usize },
    /// The first packet is not CONNECT.
    NotConnect(u8),
    /// A packet a client may not send (a second CONNECT, a server's packet, type 0).
    Forbidden(u8),
    /// Fixed-header flags the packet type does not allow.
    BadFlags { kind: u8, flags: u8 },
    /// The protocol name is neither `MQTT` nor `MQIsdp`.
    UnknownProtocol,
    /// A field runs past the packet's end, or bytes are left over after the last one.
    Truncated(&'static str),
    /// Trailing bytes after CONNECT's last field.
    TrailingBytes(usize),
    /// A string is not UTF-8, or holds U+0000.
    BadString(&'static str),
    /// The connect flags contradict each other or set the reserved bit.
    BadConnectFlags(u8),
}

impl fmt::Display for WireError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadRemainingLength => write!(f, "remaining length longer than 4 bytes"),
            Self::TooLarge { size, limit } => {
                write!(f, "packet of {size} bytes over the limit of {limit}")
            }
            Self::NotConnect(k) => write!(f, "first packet is type {k}, not CONNECT"),
            Self::Forbidden(k) => write!(f, "packet type {k} is not a client's to send here"),
            Self::BadFlags { kind, flags } => {
                write!(f, "packet type {kind} with header flags {flags:#06b}")
            }
            Self::UnknownProtocol => write!(f, "protocol name is not MQTT"),
            Self::Truncated(field) => write!(f, "{field} runs past the packet's end"),
            Self::TrailingBytes(n) => write!(f, "{n} bytes after CONNECT's last field"),
            Self::BadString(field) => write!(f, "{field} is not valid UTF-8 text"),
            Self::BadConnectFlags(b) => write!(f, "connect flags {b:#010b} are contradictory"),
        }
    }
}

impl std::error::Error for WireError {}

/// One MQTT 5 property as read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Property {
    /// Its identifier.
    pub id: u8,
    /// Its value, for the integer ones.
    pub value: Option<usize>,
    /// Where it lies in the body, identifier included.
    pub span: std::ops::Range<usize>,
}

/// Reads a packet's body without reading past it.
pub(crate) struct Cursor<'a> {
    body: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    /// A cursor at the start of `body`.
    pub(crate) fn new(body: &'a [u8]) -> Self {
        Self { body, at: 0 }
    }

    /// Whether every byte has been read.
    pub(crate) fn done(&self) -> bool {
        self.at >= self.body.len()
    }

    /// Bytes not read yet.
    pub(crate) fn left(&self) -> usize {
        self.body.len().saturating_sub(self.at)
    }

    /// The next `n` bytes; `field` names what they are in the error.
    pub(crate) fn take(&mut self, n: usize, field: &'static str) -> Result<&'a [u8], WireError> {
        let end = self.at.checked_add(n).ok_or(WireError::Truncated(field))?;
        let bytes = self
            .body
            .get(self.at..end)
            .ok_or(WireError::Truncated(field))?;
        self.at = end;
        Ok(bytes)
    }

    /// One byte.
    pub(crate) fn u8(&mut self, field: &'static str) -> Result<u8, WireError> {
        Ok(self.take(1, field)?[0])
    }

    /// A big-endian two-byte integer.
    pub(crate) fn u16(&mut self, field: &'static str) -> Result<u16, WireError> {
        let b = self.take(2, field)?;
        Ok(u16::from_be_bytes([b[0], b[1]]))
    }

    /// A packet identifier, which MQTT forbids to be 0.
    pub(crate) fn packet_id(&mut self) -> Result<u16, WireError> {
        match self.u16("packet identifier")? {
            0 => Err(WireError::Truncated("packet identifier (0)")),
            id => Ok(id),
        }
    }

    /// Two length bytes, then that many bytes.
    pub(crate) fn binary(&mut self, field: &'static str) -> Result<&'a [u8], WireError> {
        let n = self.u16(field)?;
        self.take(usize::from(n), field)
    }

    /// A UTF-8 string without U+0000, as MQTT requires of every string.
    pub(crate) fn string(&mut self, field: &'static str) -> Result<&'a str, WireError> {
        let s =
            std::str::from_utf8(self.binary(field)?).map_err(|_| WireError::BadString(field))?;
        if s.contains('\0') {
            return Err(WireError::BadString(field));
        }
        Ok(s)
    }

    /// A variable byte integer (MQTT 5 lengths and subscription identifiers).
    pub(crate) fn varint(&mut self, field: &'static str) -> Result<usize, WireError> {
        let mut value = 0usize;
        for i in 0..4 {
            let digit = self.u8(field)?;
            value |= usize::from(digit & 0x7f) << (7 * i);
            if digit & 0x80 == 0 {
                return Ok(value);
            }
        }
        Err(WireError::BadRemainingLength)
    }

    /// MQTT 5 properties, each read by its type; returns the identifiers present.
    pub(crate) fn properties(&mut self) -> Result<Vec<u8>, WireError> {
        Ok(self.read_properties()?.into_iter().map(|p| p.id).collect())
    }

    /// Whether the properties carry a subscription identifier of 0.
    pub(crate) fn subscription_id_of_zero(&mut self) -> Result<bool, WireError> {
        Ok(self
            .read_properties()?
            .iter()
            .any(|p| p.id == 0x0b && p.value == Some(0)))
    }

    /// The properties, each with its integer value if it has one and where it lies.
    pub(crate) fn read_properties(&mut self) -> Result<Vec<Property>, WireError> {
        const FIELD: &str = "properties";
        let length = self.varint(FIELD)?;
        let end = self
            .at
            .checked_add(length)
            .ok_or(WireError::Truncated(FIELD))?;
        if end > self.body.len() {
            return Err(WireError::Truncated(FIELD));
        }
        let mut found = Vec::new();
        while self.at < end {
            let start = self.at;
            let id = self.u8(FIELD)?;
            let value = match id {
                0x01 | 0x17 | 0x19 | 0x24 | 0x25 | 0x28 | 0x29 | 0x2a => {
                    Some(usize::from(self.u8(FIELD)?))
                }
                0x13 | 0x21 | 0x22 | 0x23 => Some(usize::from(self.u16(FIELD)?)),
                0x02 | 0x11 | 0x18 | 0x27 => {
                    let b = self.take(4, FIELD)?;
                    Some(u32::from_be_bytes([b[0], b[1], b[2], b[3]]) as usize)
                }
                0x0b => Some(self.varint(FIELD)?),
                0x03 | 0x08 | 0x12 | 0x15 | 0x1a | 0x1c | 0x1f => {
                    self.string(FIELD)?;
                    None
                }
                0x09 | 0x16 => {
                    let n = self.u16(FIELD)?;
                    self.take(usize::from(n), FIELD)?;
                    None
                }
                0x26 => {
                    self.string(FIELD)?;
                    self.string(FIELD)?;
                    None
                }
                _ => return Err(WireError::Truncated("property (unknown identifier)")),
            };
            found.push(Property {
                id,
                value,
                span: start..self.at,
            });
        }
        if self.at != end {
            return Err(WireError::Truncated(FIELD));
        }
        Ok(found)
    }
}
