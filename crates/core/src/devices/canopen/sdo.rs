//! SDO expedited transfers (CiA 301): request and response frames, abort codes, and a
//! client that runs one transfer at a time per node with timeouts and retries.
//!
//! Objects of up to four bytes move in a single frame each way, which covers every object
//! a motor drive or a BMS needs at run time; segmented transfers are refused with an abort.

use std::collections::VecDeque;
use std::fmt;
use std::time::Duration;

use super::{NodeId, ObjectAddress};
use crate::devices::can::Frame;
use crate::time::Timestamp;

/// An SDO abort code with its CiA 301 meaning.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct AbortCode(pub u32);

impl AbortCode {
    /// Toggle bit not alternated.
    pub const TOGGLE_BIT: Self = Self(0x0503_0000);
    /// SDO protocol timed out.
    pub const TIMEOUT: Self = Self(0x0504_0000);
    /// Client/server command specifier not valid or unknown.
    pub const COMMAND_SPECIFIER: Self = Self(0x0504_0001);
    /// Unsupported access to an object.
    pub const UNSUPPORTED_ACCESS: Self = Self(0x0601_0000);
    /// Attempt to write a read-only object.
    pub const READ_ONLY: Self = Self(0x0601_0002);
    /// Object does not exist in the object dictionary.
    pub const NO_OBJECT: Self = Self(0x0602_0000);
    /// Data type does not match, length of service parameter does not match.
    pub const LENGTH_MISMATCH: Self = Self(0x0607_0010);
    /// Sub-index does not exist.
    pub const NO_SUB_INDEX: Self = Self(0x0609_0011);
    /// Invalid value for parameter (download only).
    pub const INVALID_VALUE: Self = Self(0x0609_0030);
    /// General error.
    pub const GENERAL: Self = Self(0x0800_0000);
    /// Data cannot be transferred or stored because of the present device state.
    pub const DEVICE_STATE: Self = Self(0x0800_0022);

    /// The meaning of the code, as CiA 301 gives it.
    pub fn description(self) -> &'static str {
        match self.0 {
            0x0503_0000 => "toggle bit not alternated",
            0x0504_0000 => "SDO protocol timed out",
            0x0504_0001 => "client/server command specifier not valid or unknown",
            0x0504_0002 => "invalid block size",
            0x0504_0003 => "invalid sequence number",
            0x0504_0004 => "CRC error",
            0x0504_0005 => "out of memory",
            0x0601_0000 => "unsupported access to an object",
            0x0601_0001 => "attempt to read a write-only object",
            0x0601_0002 => "attempt to write a read-only object",
            0x0602_0000 => "object does not exist in the object dictionary",
            0x0604_0041 => "object cannot be mapped to the PDO",
            0x0604_0042 => "number and length of mapped objects would exceed the PDO length",
            0x0604_0043 => "general parameter incompatibility",
            0x0604_0047 => "general internal incompatibility in the device",
            0x0606_0000 => "access failed due to a hardware error",
            0x0607_0010 => "data type does not match, length of service parameter does not match",
            0x0607_0012 => "data type does not match, length of service parameter too high",
            0x0607_0013 => "data type does not match, length of service parameter too low",
            0x0609_0011 => "sub-index does not exist",
            0x0609_0030 => "invalid value for parameter",
            0x0609_0031 => "value of parameter written too high",
            0x0609_0032 => "value of parameter written too low",
            0x0609_0036 => "maximum value is less than minimum value",
            0x060A_0023 => "resource not available: SDO connection",
            0x0800_0000 => "general error",
            0x0800_0020 => "data cannot be transferred or stored to the application",
            0x0800_0021 => "data cannot be transferred or stored because of local control",
            0x0800_0022 => {
                "data cannot be transferred or stored because of the present device state"
            }
            0x0800_0023 => "object dictionary dynamic generation failed or no object dictionary",
            0x0800_0024 => "no data available",
            _ => "unknown abort code",
        }
    }
}

impl fmt::Debug for AbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:08X} ({})", self.0, self.description())
    }
}

impl fmt::Display for AbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

/// Up to four data bytes of an expedited transfer.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct SdoData {
    bytes: [u8; 4],
    len: u8,
}

impl SdoData {
    /// Data of 1 to 4 bytes; `None` otherwise.
    pub fn new(bytes: &[u8]) -> Option<Self> {
        let len = u8::try_from(bytes.len())
            .ok()
            .filter(|l| (1..=4).contains(l))?;
        let mut b = [0u8; 4];
        b[..bytes.len()].copy_from_slice(bytes);
        Some(Self { bytes: b, len })
    }

    /// An unsigned 8-bit value.
    pub fn u8(v: u8) -> Self {
        Self::fixed(&[v])
    }

    /// A little-endian 16-bit value.
    pub fn u16(v: u16) -> Self {
        Self::fixed(&v.to_le_bytes())
    }

    /// A little-endian 32-bit value.
    pub fn u32(v: u32) -> Self {
        Self::fixed(&v.to_le_bytes())
    }

    /// A signed 8-bit value.
    pub fn i8(v: i8) -> Self {
        Self::fixed(&v.to_le_bytes())
    }

    /// A little-endian signed 32-bit value.
    pub fn i32(v: i32) -> Self {
        Self::fixed(&v.to_le_bytes())
    }

    fn fixed(bytes: &[u8]) -> Self {
        let mut b = [0u8; 4];
        let len = bytes.len().min(4);
        b[..len].copy_from_slice(&bytes[..len]);
        Self {
            bytes: b,
            len: len as u8,
        }
    }

    /// The bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes[..usize::from(self.len)]
    }

    /// The bytes as a little-endian unsigned value (missing high bytes are zero).
    pub fn as_u32(&self) -> u32 {
        u32::from_le_bytes(self.bytes)
    }

    /// The bytes as a little-endian value sign-extended from its length.
    pub fn as_i32(&self) -> i32 {
        let bits = 8 * u32::from(self.len.max(1));
        let shift = 32 - bits;
        ((self.as_u32() << shift) as i32) >> shift
    }
}

impl fmt::Debug for SdoData {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[")?;
        for (i, b) in self.bytes().iter().enumerate() {
            if i > 0 {
                write!(f, " ")?;
            }
            write!(f, "{b:02X}")?;
        }
        write!(f, "]")
    }
}

/// What a client asks of a server.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoRequest {
    /// Read an object (upload).
    Read(ObjectAddress),
    /// Write an object (download).
    Write(ObjectAddress, SdoData),
}

impl SdoRequest {
    /// The object addressed.
    pub fn address(&self) -> ObjectAddress {
        match self {
            Self::Read(a) | Self::Write(a, _) => *a,
        }
    }

    /// The request frame to `node` (COB-ID 0x600 + node).
    pub fn frame(&self, node: NodeId) -> Frame {
        let (cmd, addr, data) = match self {
            Self::Read(a) => (0x40, *a, SdoData::default()),
            // Expedited download with size: 0x23, 0x27, 0x2B, 0x2F for 4, 3, 2, 1 bytes.
            Self::Write(a, d) => (0x23 | ((4 - d.len.clamp(1, 4)) << 2), *a, *d),
        };
        sdo_frame(0x600, node, cmd, addr, data.bytes)
    }
}

/// A server's reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoResponse {
    /// Expedited upload data.
    Data(ObjectAddress, SdoData),
    /// Download confirmed.
    Written(ObjectAddress),
    /// Transfer aborted.
    Abort(ObjectAddress, AbortCode),
    /// A segmented upload started (the object is longer than four bytes).
    Segmented(ObjectAddress),
}

impl SdoResponse {
    /// The object the response is about.
    pub fn address(&self) -> ObjectAddress {
        match self {
            Self::Data(a, _) | Self::Written(a) | Self::Abort(a, _) | Self::Segmented(a) => *a,
        }
    }

    /// The response frame from `node` (COB-ID 0x580 + node), as a server sends it.
    pub fn frame(&self, node: NodeId) -> Frame {
        match self {
            Self::Data(a, d) => sdo_frame(
                0x580,
                node,
                0x43 | ((4 - d.len.clamp(1, 4)) << 2),
                *a,
                d.bytes,
            ),
            Self::Written(a) => sdo_frame(0x580, node, 0x60, *a, [0; 4]),
            Self::Abort(a, code) => abort_frame(0x580, node, *a, *code),
            Self::Segmented(a) => sdo_frame(0x580, node, 0x41, *a, [0; 4]),
        }
    }
}

/// A malformed SDO frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SdoFrameError {
    /// SDO frames always carry eight bytes.
    #[error("SDO frame has {0} bytes, not 8")]
    Length(usize),
    /// The command byte is not one chassisd understands.
    #[error("SDO command specifier 0x{0:02X} is not an expedited transfer or abort")]
    Command(u8),
}

fn address_of(d: &[u8]) -> ObjectAddress {
    ObjectAddress::new(u16::from_le_bytes([d[1], d[2]]), d[3])
}

fn data_of(d: &[u8], unused: u8, size_indicated: bool) -> SdoData {
    let len = if size_indicated { 4 - unused } else { 4 };
    SdoData::new(&d[4..4 + usize::from(len)]).unwrap_or_default()
}

/// Decodes a server response frame (0x580 + node).
pub fn decode_response(frame: &Frame) -> Result<SdoResponse, SdoFrameError> {
    let d = frame.data();
    if d.len() != 8 {
        return Err(SdoFrameError::Length(d.len()));
    }
    let addr = address_of(d);
    let cmd = d[0];
    match cmd >> 5 {
        // Upload response: expedited (e = bit 1) with optional size (s = bit 0).
        2 if cmd & 0x02 != 0 => Ok(SdoResponse::Data(
            addr,
            data_of(d, (cmd >> 2) & 0x03, cmd & 0x01 != 0),
        )),
        2 => Ok(SdoResponse::Segmented(addr)),
        3 => Ok(SdoResponse::Written(addr)),
        4 => Ok(SdoResponse::Abort(
            addr,
            AbortCode(u32::from_le_bytes([d[4], d[5], d[6], d[7]])),
        )),
        _ => Err(SdoFrameError::Command(cmd)),
    }
}

/// Decodes a client request frame (0x600 + node), as a server sees it.
pub fn decode_request(frame: &Frame) -> Result<SdoRequest, SdoFrameError> {
    let d = frame.data();
    if d.len() != 8 {
        return Err(SdoFrameError::Length(d.len()));
    }
    let addr = address_of(d);
    let cmd = d[0];
    match cmd >> 5 {
        2 => Ok(SdoRequest::Read(addr)),
        1 if cmd & 0x02 != 0 => Ok(SdoRequest::Write(
            addr,
            data_of(d, (cmd >> 2) & 0x03, cmd & 0x01 != 0),
        )),
        _ => Err(SdoFrameError::Command(cmd)),
    }
}

fn sdo_frame(base: u32, node: NodeId, cmd: u8, addr: ObjectAddress, data: [u8; 4]) -> Frame {
    let [lo, hi] = addr.index.to_le_bytes();
    Frame::std(
        base + u32::from(node.get()),
        [cmd, lo, hi, addr.sub, data[0], data[1], data[2], data[3]],
    )
}

/// An abort frame (`base` 0x600 from a client, 0x580 from a server).
pub fn abort_frame(base: u32, node: NodeId, addr: ObjectAddress, code: AbortCode) -> Frame {
    sdo_frame(base, node, 0x80, addr, code.0.to_le_bytes())
}

/// How a transfer ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoOutcome<T> {
    /// Completed; `data` holds what a read returned.
    Done {
        /// The owner's tag.
        tag: T,
        /// The request.
        request: SdoRequest,
        /// Data read, for reads.
        data: Option<SdoData>,
    },
    /// The server (or the client, for a segmented reply) aborted it.
    Aborted {
        /// The owner's tag.
        tag: T,
        /// The request.
        request: SdoRequest,
        /// Why.
        code: AbortCode,
    },
    /// No answer after every retry.
    TimedOut {
        /// The owner's tag.
        tag: T,
        /// The request.
        request: SdoRequest,
    },
}

#[derive(Debug, Clone, Copy)]
struct Pending<T> {
    request: SdoRequest,
    tag: T,
}

#[derive(Debug, Clone, Copy)]
struct InFlight<T> {
    pending: Pending<T>,
    sent_at: Timestamp,
    attempts: u8,
}

/// Counters of an SDO client.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SdoStats {
    /// Requests sent, retries included.
    pub sent: u64,
    /// Retries after a timeout.
    pub retries: u64,
    /// Transfers that timed out after every retry.
    pub timeouts: u64,
    /// Transfers aborted.
    pub aborts: u64,
    /// Responses that matched no transfer in flight.
    pub unexpected: u64,
}

/// An SDO client for one server node. The owner tags each transfer to recognise its outcome.
#[derive(Debug, Clone)]
pub struct SdoClient<T> {
    node: NodeId,
    timeout: Duration,
    retries: u8,
    queue: VecDeque<Pending<T>>,
    in_flight: Option<InFlight<T>>,
    stats: SdoStats,
}

impl<T: Copy> SdoClient<T> {
    /// A client for `node` that waits `timeout` for each answer and retries `retries` times.
    pub fn new(node: NodeId, timeout: Duration, retries: u8) -> Self {
        Self {
            node,
            timeout,
            retries,
            queue: VecDeque::new(),
            in_flight: None,
            stats: SdoStats::default(),
        }
    }

    /// Queues a transfer.
    pub fn push(&mut self, request: SdoRequest, tag: T) {
        self.queue.push_back(Pending { request, tag });
    }

    /// Whether nothing is queued or in flight.
    pub fn is_idle(&self) -> bool {
        self.queue.is_empty() && self.in_flight.is_none()
    }

    /// Transfers queued or in flight.
    pub fn backlog(&self) -> usize {
        self.queue.len() + usize::from(self.in_flight.is_some())
    }

    /// Forgets every transfer (after a reset or a lost link).
    pub fn clear(&mut self) {
        self.queue.clear();
        self.in_flight = None;
    }

    /// Counters so far.
    pub fn stats(&self) -> SdoStats {
        self.stats
    }

    /// Sends the next transfer when none is in flight, and retries or gives up one that has
    /// waited too long. Frames to send go to `out`.
    pub fn poll(&mut self, now: Timestamp, out: &mut Vec<Frame>) -> Option<SdoOutcome<T>> {
        if let Some(flight) = &mut self.in_flight {
            if now.saturating_since(flight.sent_at) < self.timeout {
                return None;
            }
            if flight.attempts <= self.retries {
                flight.attempts += 1;
                flight.sent_at = now;
                self.stats.sent += 1;
                self.stats.retries += 1;
                out.push(flight.pending.request.frame(self.node));
                return None;
            }
            let Pending { request, tag } = flight.pending;
            self.in_flight = None;
            self.stats.timeouts += 1;
            // The server may still be mid-transfer; tell it to stop.
            out.push(abort_frame(
                0x600,
                self.node,
                request.address(),
                AbortCode::TIMEOUT,
            ));
            self.start_next(now, out);
            return Some(SdoOutcome::TimedOut { tag, request });
        }
        self.start_next(now, out);
        None
    }

    fn start_next(&mut self, now: Timestamp, out: &mut Vec<Frame>) {
        if self.in_flight.is_some() {
            return;
        }
        if let Some(pending) = self.queue.pop_front() {
            out.push(pending.request.frame(self.node));
            self.stats.sent += 1;
            self.in_flight = Some(InFlight {
                pending,
                sent_at: now,
                attempts: 1,
            });
        }
    }

    /// Handles a response frame from this client's server (0x580 + node); starts the next
    /// transfer at once.
    pub fn on_response(
        &mut self,
        now: Timestamp,
        frame: &Frame,
        out: &mut Vec<Frame>,
    ) -> Option<SdoOutcome<T>> {
        let Ok(response) = decode_response(frame) else {
            self.stats.unexpected += 1;
            return None;
        };
        let Some(flight) = self.in_flight else {
            self.stats.unexpected += 1;
            return None;
        };
        let Pending { request, tag } = flight.pending;
        if response.address() != request.address() {
            self.stats.unexpected += 1;
            return None;
        }
        let outcome = match (request, response) {
            (SdoRequest::Read(_), SdoResponse::Data(_, data)) => SdoOutcome::Done {
                tag,
                request,
                data: Some(data),
            },
            (SdoRequest::Write(..), SdoResponse::Written(_)) => SdoOutcome::Done {
                tag,
                request,
                data: None,
            },
            (_, SdoResponse::Abort(_, code)) => {
                self.stats.aborts += 1;
                SdoOutcome::Aborted { tag, request, code }
            }
            (_, SdoResponse::Segmented(addr)) => {
                self.stats.aborts += 1;
                out.push(abort_frame(
                    0x600,
                    self.node,
                    addr,
                    AbortCode::COMMAND_SPECIFIER,
                ));
                SdoOutcome::Aborted {
                    tag,
                    request,
                    code: AbortCode::COMMAND_SPECIFIER,
                }
            }
            // A read answered as a write or the reverse: not ours.
            _ => {
                self.stats.unexpected += 1;
                return None;
            }
        };
        self.in_flight = None;
        self.start_next(now, out);
        Some(outcome)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node() -> NodeId {
        NodeId::new(1).unwrap()
    }

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_micros(ms * 1_000)
    }

    #[test]
    fn encodes_expedited_requests() {
        let cw = SdoRequest::Write(ObjectAddress::new(0x6040, 0), SdoData::u16(0x0F));
        assert_eq!(cw.frame(node()).to_string(), "601#2B4060000F000000");
        let mode = SdoRequest::Write(ObjectAddress::new(0x6060, 0), SdoData::i8(3));
        assert_eq!(mode.frame(node()).to_string(), "601#2F60600003000000");
        let vel = SdoRequest::Write(ObjectAddress::new(0x60FF, 3), SdoData::i32(-100));
        assert_eq!(vel.frame(node()).to_string(), "601#23FF60039CFFFFFF");
        let read = SdoRequest::Read(ObjectAddress::new(0x6041, 0));
        assert_eq!(read.frame(node()).to_string(), "601#4041600000000000");
    }

    #[test]
    fn decodes_responses() {
        let f = |bytes: [u8; 8]| Frame::std(0x581, bytes);
        let r = decode_response(&f([0x4B, 0x41, 0x60, 0, 0x37, 0x06, 0, 0])).unwrap();
        let SdoResponse::Data(addr, data) = r else {
            panic!("{r:?}")
        };
        assert_eq!(addr, ObjectAddress::new(0x6041, 0));
        assert_eq!(data.bytes(), &[0x37, 0x06]);
        assert_eq!(data.as_u32(), 0x0637);
        let r = decode_response(&f([0x43, 0x6C, 0x60, 1, 0x18, 0xFC, 0xFF, 0xFF])).unwrap();
        let SdoResponse::Data(_, data) = r else {
            panic!()
        };
        assert_eq!(data.as_i32(), -1000);
        assert_eq!(
            decode_response(&f([0x60, 0x40, 0x60, 0, 0, 0, 0, 0])),
            Ok(SdoResponse::Written(ObjectAddress::new(0x6040, 0)))
        );
        let r = decode_response(&f([0x80, 0x00, 0x20, 0, 0x00, 0x00, 0x02, 0x06])).unwrap();
        assert_eq!(
            r,
            SdoResponse::Abort(ObjectAddress::new(0x2000, 0), AbortCode::NO_OBJECT)
        );
        assert_eq!(
            AbortCode::NO_OBJECT.to_string(),
            "0x06020000 (object does not exist in the object dictionary)"
        );
        assert!(decode_response(&Frame::std(0x581, [0x4B, 0x41])).is_err());
        assert!(decode_response(&f([0xE0, 0, 0, 0, 0, 0, 0, 0])).is_err());
    }

    #[test]
    fn signed_values_extend_from_their_length() {
        assert_eq!(SdoData::new(&[0xFF]).unwrap().as_i32(), -1);
        assert_eq!(SdoData::new(&[0x00, 0x80]).unwrap().as_i32(), -32768);
        assert_eq!(SdoData::new(&[0xFF, 0x7F]).unwrap().as_i32(), 32767);
    }

    #[test]
    fn requests_round_trip_through_the_server_side() {
        for req in [
            SdoRequest::Read(ObjectAddress::new(0x606C, 2)),
            SdoRequest::Write(ObjectAddress::new(0x1017, 0), SdoData::u16(100)),
            SdoRequest::Write(ObjectAddress::new(0x6060, 0), SdoData::i8(3)),
        ] {
            assert_eq!(decode_request(&req.frame(node())), Ok(req));
        }
        for resp in [
            SdoResponse::Data(ObjectAddress::new(0x6064, 1), SdoData::i32(123_456)),
            SdoResponse::Written(ObjectAddress::new(0x6040, 0)),
            SdoResponse::Abort(ObjectAddress::new(0x6040, 0), AbortCode::DEVICE_STATE),
        ] {
            assert_eq!(decode_response(&resp.frame(node())), Ok(resp));
        }
    }

    #[test]
    fn client_runs_one_transfer_at_a_time_and_retries() {
        let mut c = SdoClient::new(node(), Duration::from_millis(50), 1);
        let mut out = Vec::new();
        let a = ObjectAddress::new(0x6041, 0);
        c.push(SdoRequest::Read(a), 1);
        c.push(SdoRequest::Write(a, SdoData::u16(6)), 2);
        assert_eq!(c.poll(at(0), &mut out), None);
        assert_eq!(out.len(), 1, "only the first goes out");
        out.clear();
        // A response to something else is ignored.
        let other = SdoResponse::Written(ObjectAddress::new(0x1017, 0)).frame(node());
        assert_eq!(c.on_response(at(1), &other, &mut out), None);
        assert_eq!(c.stats().unexpected, 1);
        // Timeout → one retry, then give up and start the next.
        assert_eq!(c.poll(at(49), &mut out), None);
        assert!(out.is_empty());
        c.poll(at(50), &mut out);
        assert_eq!(out.len(), 1);
        out.clear();
        let gave_up = c.poll(at(100), &mut out);
        assert!(matches!(gave_up, Some(SdoOutcome::TimedOut { tag: 1, .. })));
        assert_eq!(
            out.len(),
            2,
            "abort for the old transfer and the next request"
        );
        out.clear();
        let done = c.on_response(at(101), &SdoResponse::Written(a).frame(node()), &mut out);
        assert!(matches!(
            done,
            Some(SdoOutcome::Done {
                tag: 2,
                data: None,
                ..
            })
        ));
        assert!(c.is_idle());
        assert_eq!(c.stats().timeouts, 1);
        assert_eq!(c.stats().retries, 1);
    }

    #[test]
    fn segmented_replies_are_aborted() {
        let mut c = SdoClient::new(node(), Duration::from_millis(50), 0);
        let mut out = Vec::new();
        let a = ObjectAddress::new(0x1008, 0);
        c.push(SdoRequest::Read(a), ());
        c.poll(at(0), &mut out);
        out.clear();
        let r = c.on_response(at(1), &SdoResponse::Segmented(a).frame(node()), &mut out);
        assert!(matches!(
            r,
            Some(SdoOutcome::Aborted {
                code: AbortCode::COMMAND_SPECIFIER,
                ..
            })
        ));
        assert_eq!(out[0].to_string(), "601#8008100001000405");
    }
}
