//! UBX framing: `B5 62`, class, id, a little-endian payload length, the payload, and an
//! 8-bit Fletcher checksum over everything between the sync bytes and the checksum.

/// The two sync bytes that open every UBX frame.
pub const SYNC: [u8; 2] = [0xb5, 0x62];
/// Sync, class, id and length before the payload.
pub const HEADER_LEN: usize = 6;
/// Header and checksum around the payload.
pub const OVERHEAD: usize = HEADER_LEN + 2;
/// Largest payload accepted. The longest messages a receiver sends in normal operation
/// (RXM-RAWX with 255 signals, 8,176 bytes) fit; a longer length field is a false sync,
/// not a frame, and must not make the framer wait for bytes that never come.
pub const MAX_PAYLOAD: usize = 8192;

/// A whole UBX frame whose checksum matched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UbxFrame<'a> {
    /// Message class (`0x01` NAV, `0x02` RXM, `0x05` ACK, `0x06` CFG, `0x0A` MON, ...).
    pub class: u8,
    /// Message id within the class.
    pub id: u8,
    /// The payload, without header or checksum.
    pub payload: &'a [u8],
}

/// The classes u-blox receivers send or take. A sync pattern followed by any other class is
/// taken for binary noise (an RTCM payload, say) without waiting for a length's worth of bytes.
pub fn is_known_class(class: u8) -> bool {
    matches!(
        class,
        0x01 | 0x02
            | 0x04
            | 0x05
            | 0x06
            | 0x09
            | 0x0a
            | 0x0b
            | 0x0d
            | 0x10
            | 0x13
            | 0x21
            | 0x27
            | 0x28
            | 0x29
    )
}

/// The 8-bit Fletcher checksum (`CK_A`, `CK_B`) of `bytes`: class, id, length and payload.
pub fn fletcher(bytes: &[u8]) -> [u8; 2] {
    let (a, b) = bytes.iter().fold((0u8, 0u8), |(a, b), &byte| {
        let a = a.wrapping_add(byte);
        (a, b.wrapping_add(a))
    });
    [a, b]
}

/// A whole frame for `class`, `id` and `payload`, as sent to a receiver. `None` when the
/// payload is longer than a length field can say.
pub fn encode(class: u8, id: u8, payload: &[u8]) -> Option<Vec<u8>> {
    let len = u16::try_from(payload.len()).ok()?;
    let mut frame = Vec::with_capacity(OVERHEAD + payload.len());
    frame.extend_from_slice(&SYNC);
    frame.extend_from_slice(&[class, id]);
    frame.extend_from_slice(&len.to_le_bytes());
    frame.extend_from_slice(payload);
    let checksum = fletcher(&frame[2..]);
    frame.extend_from_slice(&checksum);
    Some(frame)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_checksum_of_a_real_frame() {
        // RXM-RTCM from the NEO-M8P log in gpsd's regression suite: trailer 10 3e.
        let frame = [
            0xb5, 0x62, 0x02, 0x32, 0x08, 0x00, 0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0xce, 0x04,
            0x10, 0x3e,
        ];
        assert_eq!(fletcher(&frame[2..14]), [0x10, 0x3e]);
        assert_eq!(encode(0x02, 0x32, &frame[6..14]).unwrap(), frame);
    }

    #[test]
    fn a_payload_too_long_for_the_length_field_is_not_encoded() {
        assert!(encode(0x06, 0x8a, &vec![0; 70_000]).is_none());
        assert_eq!(encode(0x0a, 0x04, &[]).unwrap().len(), OVERHEAD);
    }
}
