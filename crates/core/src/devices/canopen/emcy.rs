//! Emergency (EMCY) messages: error code, error register and vendor bytes, with the
//! CiA 301 / CiA 402 meanings of the codes.

use std::fmt;

use super::NodeId;
use crate::devices::can::Frame;

/// One emergency message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Emcy {
    /// Emergency error code; 0x0000 means the error was reset.
    pub code: u16,
    /// Error register (object 0x1001).
    pub register: u8,
    /// Manufacturer-specific bytes.
    pub vendor: [u8; 5],
}

/// An EMCY frame that is too short.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("EMCY frame has {0} bytes; at least 3 are needed")]
pub struct EmcyLengthError(pub usize);

impl Emcy {
    /// Decodes an EMCY frame (0x080 + node). Eight bytes are standard; fewer than three
    /// cannot hold the code and register.
    pub fn decode(frame: &Frame) -> Result<Self, EmcyLengthError> {
        let d = frame.data();
        if d.len() < 3 {
            return Err(EmcyLengthError(d.len()));
        }
        let mut vendor = [0u8; 5];
        let n = (d.len() - 3).min(5);
        vendor[..n].copy_from_slice(&d[3..3 + n]);
        Ok(Self {
            code: u16::from_le_bytes([d[0], d[1]]),
            register: d[2],
            vendor,
        })
    }

    /// The EMCY frame `node` sends.
    pub fn frame(&self, node: NodeId) -> Frame {
        let [lo, hi] = self.code.to_le_bytes();
        let v = self.vendor;
        Frame::std(
            0x080 + u32::from(node.get()),
            [lo, hi, self.register, v[0], v[1], v[2], v[3], v[4]],
        )
    }

    /// Whether this message clears a previous error.
    pub fn is_reset(&self) -> bool {
        self.code == 0
    }

    /// The meaning of the error code.
    pub fn description(&self) -> &'static str {
        describe(self.code)
    }
}

impl fmt::Display for Emcy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "EMCY 0x{:04X} {} (error register 0x{:02X})",
            self.code,
            self.description(),
            self.register
        )
    }
}

/// The meaning of an emergency error code: the exact code where CiA 301/402 name it, else
/// its class.
pub fn describe(code: u16) -> &'static str {
    match code {
        0x0000 => "error reset or no error",
        0x1000 => "generic error",
        0x2310 => "continuous over-current",
        0x2320 => "short circuit or earth leakage at the motor side",
        0x2330 => "earth leakage",
        0x2340 => "short circuit",
        0x3110 => "mains over-voltage",
        0x3120 => "mains under-voltage",
        0x3210 => "DC link over-voltage",
        0x3220 => "DC link under-voltage",
        0x4110 => "excess ambient temperature",
        0x4210 => "excess device temperature",
        0x4310 => "excess drive temperature",
        0x5530 => "data storage (EEPROM) error",
        0x6100 => "internal software error",
        0x6320 => "parameter error",
        0x7121 => "motor blocked",
        0x7305 => "incremental sensor 1 fault (encoder)",
        0x7310 => "speed sensor fault",
        0x8110 => "CAN overrun: objects lost",
        0x8120 => "CAN in error passive mode",
        0x8130 => "life guard or heartbeat error",
        0x8140 => "recovered from bus off",
        0x8210 => "PDO not processed due to length error",
        0x8220 => "PDO length exceeded",
        0x8400 => "velocity controller error",
        0x8611 => "following error",
        0x8612 => "reference limit",
        _ => match code >> 8 {
            0x10 => "generic error",
            0x20..=0x2F => "current",
            0x30..=0x3F => "voltage",
            0x40..=0x4F => "temperature",
            0x50..=0x5F => "device hardware",
            0x60..=0x6F => "device software",
            0x70..=0x7F => "additional modules",
            0x81 => "communication",
            0x82 => "protocol error",
            0x80..=0x8F => "monitoring",
            0x90..=0x9F => "external error",
            0xF0..=0xFE => "additional functions",
            0xFF => "device specific",
            _ => "unknown error class",
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_and_describes() {
        let f = Frame::std(0x081, [0x10, 0x23, 0x01, 0xAA, 0, 0, 0, 0]);
        let e = Emcy::decode(&f).unwrap();
        assert_eq!(e.code, 0x2310);
        assert_eq!(e.register, 0x01);
        assert_eq!(e.vendor[0], 0xAA);
        assert_eq!(
            e.to_string(),
            "EMCY 0x2310 continuous over-current (error register 0x01)"
        );
        assert_eq!(e.frame(NodeId::new(1).unwrap()), f);
        assert_eq!(describe(0x2399), "current");
        assert_eq!(describe(0xFF42), "device specific");
        assert!(Emcy::decode(&Frame::std(0x081, [0, 0])).is_err());
        assert!(
            Emcy::decode(&Frame::std(0x081, [0, 0, 0]))
                .unwrap()
                .is_reset()
        );
    }
}
