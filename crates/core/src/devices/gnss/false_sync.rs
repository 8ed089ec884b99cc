//! Proof that a UBX frame in progress began at a false sync.
//!
//! A `B5 62` in binary noise, with a plausible class and length, makes the framer wait for up
//! to [`MAX_PAYLOAD`] bytes before the checksum tells it the frame was never one: 8 s of a
//! 9600-baud stream, every sentence in it held back. A whole checksummed NMEA sentence with its
//! line end, or a whole UBX frame whose checksum matches, found inside the bytes so far is
//! (short of a coincidence of both a pattern and a checksum) what the receiver really sent, so
//! the framer gives the bytes back at once instead of waiting.
//!
//! The framer asks when its input runs out inside a frame, not at every byte: a frame that
//! completes within the bytes at hand costs nothing, and a sentence held by a false sync is
//! released with the read that brought its line end.

use super::ubx::frame::{HEADER_LEN, MAX_PAYLOAD, OVERHEAD, SYNC, fletcher, is_known_class};

/// Inner syncs watched at once. A real payload rarely holds one; noise that holds many is
/// proven false by the first few as well as by all.
const MAX_INNER_SYNCS: usize = 8;

/// Watches the bytes of one UBX frame in progress.
#[derive(Debug, Default)]
pub(super) struct FalseSyncWitness {
    /// The latest `$` followed only by printable bytes: its offset and the XOR of those bytes.
    sentence: Option<(usize, u8)>,
    /// Offsets of inner `B5 62`s whose frames are still plausible and incomplete.
    syncs: Vec<usize>,
    /// Bytes of the frame already looked at.
    scanned: usize,
}

impl FalseSyncWitness {
    /// Forgets everything: a new frame begins.
    pub(super) fn clear(&mut self) {
        self.sentence = None;
        self.syncs.clear();
        self.scanned = 0;
    }

    /// Looks at the bytes of `frame` (the frame so far, sync first) not looked at before. True
    /// when the frame holds a whole sentence or a whole UBX frame after its own sync.
    pub(super) fn proves_false(&mut self, frame: &[u8]) -> bool {
        while self.scanned < frame.len() {
            self.scanned += 1;
            let seen = &frame[..self.scanned];
            let byte = seen[seen.len() - 1];
            if self.sentence_ends(seen, byte) || self.inner_frame_ends(seen, byte) {
                return true;
            }
        }
        false
    }

    fn sentence_ends(&mut self, frame: &[u8], byte: u8) -> bool {
        let newest = frame.len() - 1;
        match (byte, self.sentence) {
            (b'$', _) => self.sentence = Some((newest, 0)),
            (b'\r' | b'\n', Some((start, xor))) => {
                self.sentence = None;
                return ends_with_checksum(&frame[start + 1..newest], xor);
            }
            (0x20..=0x7e, Some((start, xor))) => self.sentence = Some((start, xor ^ byte)),
            _ => self.sentence = None,
        }
        false
    }

    fn inner_frame_ends(&mut self, frame: &[u8], byte: u8) -> bool {
        let newest = frame.len() - 1;
        if byte == SYNC[1]
            && newest >= 2
            && frame[newest - 1] == SYNC[0]
            && self.syncs.len() < MAX_INNER_SYNCS
        {
            self.syncs.push(newest - 1);
        }
        let mut proven = false;
        self.syncs.retain(|&start| {
            let inner = &frame[start..];
            if inner.len() < HEADER_LEN {
                return inner.len() < 3 || is_known_class(inner[2]);
            }
            let payload = usize::from(u16::from_le_bytes([inner[4], inner[5]]));
            if !is_known_class(inner[2]) || payload > MAX_PAYLOAD {
                return false;
            }
            if inner.len() < OVERHEAD + payload {
                return true;
            }
            let end = inner.len() - 2;
            proven |= fletcher(&inner[2..end]) == inner[end..];
            false
        });
        proven
    }
}

/// Whether `text` (what followed a `$`, up to a line end) is a body, `*` and the two digits of
/// the body's XOR, given `xor`, the XOR of all of `text`.
fn ends_with_checksum(text: &[u8], xor: u8) -> bool {
    let Some(&[star, high, low]) = text.last_chunk::<3>() else {
        return false;
    };
    let digit = |byte: u8| char::from(byte).to_digit(16);
    match (star, digit(high), digit(low)) {
        (b'*', Some(high_value), Some(low_value)) => {
            u32::from(xor ^ star ^ high ^ low) == (high_value << 4) | low_value
        }
        _ => false,
    }
}
