//! Classic CAN frames as the sans-IO device decoders and encoders see them.
//!
//! The decoders work on this small value type rather than on socket types, so they stay
//! plain and testable; the SocketCAN driver and the recording layer convert at the edge.

use std::fmt;

use socketcan::{CanAnyFrame, CanError, EmbeddedFrame, ExtendedId, Id, StandardId};

/// Highest 11-bit identifier.
pub const MAX_STANDARD_ID: u32 = 0x7FF;
/// Highest 29-bit identifier.
pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;

/// A classic CAN data frame: identifier, format and 0–8 data bytes.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Frame {
    id: u32,
    extended: bool,
    len: u8,
    data: [u8; 8],
}

impl Frame {
    /// A frame with an 11-bit identifier; `None` if the id or the data is too large.
    pub fn standard(id: u32, data: &[u8]) -> Option<Self> {
        (id <= MAX_STANDARD_ID).then(|| Self::build(id, false, data))?
    }

    /// A frame with a 29-bit identifier; `None` if the id or the data is too large.
    pub fn extended(id: u32, data: &[u8]) -> Option<Self> {
        (id <= MAX_EXTENDED_ID).then(|| Self::build(id, true, data))?
    }

    /// An 11-bit frame from a fixed-size payload; the id is masked to 11 bits. For
    /// identifiers built from protocol constants, where no check can fail.
    pub fn std<const N: usize>(id: u32, data: [u8; N]) -> Self {
        const { assert!(N <= 8, "a classic CAN frame holds at most 8 bytes") };
        Self::fixed(id & MAX_STANDARD_ID, false, &data)
    }

    /// A 29-bit frame from a fixed-size payload; the id is masked to 29 bits.
    pub fn ext<const N: usize>(id: u32, data: [u8; N]) -> Self {
        const { assert!(N <= 8, "a classic CAN frame holds at most 8 bytes") };
        Self::fixed(id & MAX_EXTENDED_ID, true, &data)
    }

    fn fixed(id: u32, extended: bool, data: &[u8]) -> Self {
        let mut bytes = [0u8; 8];
        let len = data.len().min(8);
        bytes[..len].copy_from_slice(&data[..len]);
        Self {
            id,
            extended,
            len: len as u8,
            data: bytes,
        }
    }

    fn build(id: u32, extended: bool, data: &[u8]) -> Option<Self> {
        let len = u8::try_from(data.len()).ok().filter(|&l| l <= 8)?;
        let mut bytes = [0u8; 8];
        bytes[..data.len()].copy_from_slice(data);
        Some(Self {
            id,
            extended,
            len,
            data: bytes,
        })
    }

    /// The identifier (11 or 29 bits).
    pub fn id(&self) -> u32 {
        self.id
    }

    /// Whether the identifier is 29 bits.
    pub fn is_extended(&self) -> bool {
        self.extended
    }

    /// The data bytes.
    pub fn data(&self) -> &[u8] {
        &self.data[..usize::from(self.len)]
    }

    /// The frame for a SocketCAN socket.
    pub fn to_socketcan(&self) -> socketcan::CanFrame {
        let id: Id = if self.extended {
            // The constructor checked the range, so both conversions succeed.
            ExtendedId::new(self.id).map_or(Id::Standard(StandardId::ZERO), Id::Extended)
        } else {
            u16::try_from(self.id)
                .ok()
                .and_then(StandardId::new)
                .map_or(Id::Standard(StandardId::ZERO), Id::Standard)
        };
        socketcan::CanFrame::new(id, self.data()).unwrap_or_else(|| {
            // Unreachable: the id is valid and the data is at most 8 bytes.
            socketcan::CanFrame::new(Id::Standard(StandardId::ZERO), &[]).unwrap_or_default()
        })
    }
}

/// Debug shows the candump spelling, which is what people compare against.
impl fmt::Debug for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

/// `123#DEADBEEF` or `18904001#...`, as candump writes it.
impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.extended {
            write!(f, "{:08X}#", self.id)?;
        } else {
            write!(f, "{:03X}#", self.id)?;
        }
        for b in self.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

/// What arrived on a bus, as the decoders need it.
#[derive(Debug, Clone)]
pub enum Received {
    /// A data frame.
    Data(Frame),
    /// A remote (RTR) frame: nothing chassisd's devices send; counted only.
    Remote,
    /// An error frame, decoded into its causes.
    Error(CanError),
    /// A CAN FD frame: not used by chassisd's devices; counted only.
    Fd,
}

impl Received {
    /// Classifies a frame from a socket or a recording.
    pub fn from_socketcan(frame: &CanAnyFrame) -> Self {
        match frame {
            CanAnyFrame::Normal(f) => {
                let data = f.data();
                let frame = match f.id() {
                    Id::Standard(id) => Frame::standard(u32::from(id.as_raw()), data),
                    Id::Extended(id) => Frame::extended(id.as_raw(), data),
                };
                frame.map_or(Self::Remote, Self::Data)
            }
            CanAnyFrame::Remote(_) => Self::Remote,
            CanAnyFrame::Error(e) => Self::Error(CanError::from(*e)),
            CanAnyFrame::Fd(_) => Self::Fd,
        }
    }
}

impl From<Frame> for CanAnyFrame {
    fn from(frame: Frame) -> Self {
        CanAnyFrame::from(frame.to_socketcan())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_ids_and_lengths() {
        assert!(Frame::standard(0x7FF, &[0; 8]).is_some());
        assert!(Frame::standard(0x800, &[]).is_none());
        assert!(Frame::standard(0x100, &[0; 9]).is_none());
        assert!(Frame::extended(0x1FFF_FFFF, &[1]).is_some());
        assert!(Frame::extended(0x2000_0000, &[1]).is_none());
    }

    #[test]
    fn round_trips_through_socketcan() {
        for frame in [
            Frame::standard(0x601, &[0x2B, 0x40, 0x60, 0, 6, 0, 0, 0]).unwrap(),
            Frame::extended(0x1890_0140, &[0; 8]).unwrap(),
            Frame::standard(0x000, &[]).unwrap(),
        ] {
            let any = CanAnyFrame::from(frame);
            match Received::from_socketcan(&any) {
                Received::Data(back) => assert_eq!(back, frame),
                other => panic!("{other:?}"),
            }
        }
    }

    #[test]
    fn error_frames_decode_into_causes() {
        // Class bits 0x40 (bus off) and 0x20 (no acknowledge).
        let frame = socketcan::CanErrorFrame::new_error(0x60, &[0; 8]).unwrap();
        match Received::from_socketcan(&CanAnyFrame::Error(frame)) {
            Received::Error(e) => {
                assert!(e.is_bus_off() && e.is_no_ack());
                let text = e.to_string();
                assert!(text.contains("bus off"), "{text}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn displays_like_candump() {
        let f = Frame::extended(0x1890_4001, &[0x02, 0x12]).unwrap();
        assert_eq!(f.to_string(), "18904001#0212");
        assert_eq!(Frame::standard(0x81, &[]).unwrap().to_string(), "081#");
    }
}
