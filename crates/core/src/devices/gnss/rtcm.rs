//! RTCM 3 framing: finds whole frames in a byte stream (a caster's, a receiver's) and checks
//! their CRC-24Q, so only valid frames are passed on, whole and in order.
//!
//! A frame is the preamble 0xD3, six reserved bits (zero), a 10-bit payload length, the
//! payload, and a 24-bit CRC-24Q over everything before it. Bytes that are not part of a
//! valid frame are counted and dropped; a stream that starts mid-frame, or a frame whose CRC
//! fails, resynchronises at the next preamble after the bad one's first byte.

use std::collections::BTreeMap;

use crc::{CRC_24_LTE_A, Crc};

/// The first byte of every frame.
pub const PREAMBLE: u8 = 0xD3;
/// The largest payload the 10-bit length allows.
pub const MAX_PAYLOAD: usize = 1023;
/// Preamble and length, bytes.
const HEADER: usize = 3;
/// The CRC, bytes.
const CRC_LEN: usize = 3;
/// The longest frame, bytes.
pub const MAX_FRAME: usize = HEADER + MAX_PAYLOAD + CRC_LEN;

/// CRC-24Q (Qualcomm): polynomial 0x864CFB, initial 0, not reflected. The catalogue knows it
/// as CRC-24/LTE-A.
const CRC24Q: Crc<u32> = Crc::<u32>::new(&CRC_24_LTE_A);

/// What the framer has seen.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RtcmStats {
    /// Valid frames.
    pub frames: u64,
    /// Bytes of valid frames.
    pub frame_bytes: u64,
    /// Bytes dropped: outside any frame, or in a frame whose CRC failed.
    pub invalid_bytes: u64,
    /// Candidate frames whose CRC failed.
    pub crc_errors: u64,
    /// Valid frames by message number (0 for a payload too short to hold one).
    pub by_type: BTreeMap<u16, u64>,
}

/// The framer's state between chunks. Holds at most one partial frame.
#[derive(Debug, Clone, Default)]
pub struct RtcmFramer {
    pending: Vec<u8>,
    stats: RtcmStats,
}

/// A frame's message number: the payload's first 12 bits (0 when it has fewer than two
/// bytes).
pub fn message_number(frame: &[u8]) -> u16 {
    match frame.get(HEADER..HEADER + 2) {
        Some(&[a, b]) => (u16::from(a) << 4) | (u16::from(b) >> 4),
        _ => 0,
    }
}

impl RtcmFramer {
    /// A framer at the start of a stream.
    pub fn new() -> Self {
        Self::default()
    }

    /// What it has seen so far.
    pub fn stats(&self) -> &RtcmStats {
        &self.stats
    }

    /// Bytes held for a frame not yet complete.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// Forgets a partial frame (the stream it came from ended); its bytes count as invalid.
    pub fn reset(&mut self) {
        self.stats.invalid_bytes += self.pending.len() as u64;
        self.pending.clear();
    }

    /// Feeds `bytes`; `frame` gets every whole valid frame (preamble to CRC) with its message
    /// number, in order.
    pub fn push(&mut self, bytes: &[u8], mut frame: impl FnMut(&[u8], u16)) {
        self.pending.extend_from_slice(bytes);
        let mut start = 0;
        loop {
            let rest = &self.pending[start..];
            // Skip to the next preamble.
            let Some(at) = rest.iter().position(|&b| b == PREAMBLE) else {
                self.stats.invalid_bytes += rest.len() as u64;
                start = self.pending.len();
                break;
            };
            self.stats.invalid_bytes += at as u64;
            start += at;
            let rest = &self.pending[start..];
            if rest.len() < HEADER {
                break;
            }
            if rest[1] & 0xFC != 0 {
                // Reserved bits set: not a frame's start.
                self.stats.invalid_bytes += 1;
                start += 1;
                continue;
            }
            let length = (usize::from(rest[1] & 0x03) << 8) | usize::from(rest[2]);
            let total = HEADER + length + CRC_LEN;
            if rest.len() < total {
                break;
            }
            let (body, crc) = rest[..total].split_at(HEADER + length);
            let expected = (u32::from(crc[0]) << 16) | (u32::from(crc[1]) << 8) | u32::from(crc[2]);
            if CRC24Q.checksum(body) == expected {
                let whole = &rest[..total];
                let number = message_number(whole);
                self.stats.frames += 1;
                self.stats.frame_bytes += total as u64;
                *self.stats.by_type.entry(number).or_default() += 1;
                frame(whole, number);
                start += total;
            } else {
                // Not a frame after all (or a damaged one): resynchronise after its preamble.
                self.stats.crc_errors += 1;
                self.stats.invalid_bytes += 1;
                start += 1;
            }
        }
        self.pending.drain(..start);
    }
}

/// A valid frame around `payload` (at most [`MAX_PAYLOAD`] bytes; longer is cut), for tests
/// and the simulator.
pub fn encode(payload: &[u8]) -> Vec<u8> {
    let payload = &payload[..payload.len().min(MAX_PAYLOAD)];
    let mut out = Vec::with_capacity(HEADER + payload.len() + CRC_LEN);
    out.push(PREAMBLE);
    out.push((payload.len() >> 8) as u8 & 0x03);
    out.push(payload.len() as u8);
    out.extend_from_slice(payload);
    let crc = CRC24Q.checksum(&out);
    out.extend_from_slice(&[(crc >> 16) as u8, (crc >> 8) as u8, crc as u8]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames_of(chunks: &[&[u8]]) -> (Vec<Vec<u8>>, RtcmStats) {
        let mut f = RtcmFramer::new();
        let mut out = Vec::new();
        for c in chunks {
            f.push(c, |frame, _| out.push(frame.to_vec()));
        }
        (out, f.stats().clone())
    }

    #[test]
    fn a_frame_round_trips_and_names_its_message() {
        // Message 1005 in the first 12 bits.
        let frame = encode(&[0x3E, 0xD0, 0x00, 0x01, 0x02]);
        assert_eq!(message_number(&frame), 1005);
        let (out, stats) = frames_of(&[&frame]);
        assert_eq!(out, vec![frame.clone()]);
        assert_eq!(stats.by_type.get(&1005), Some(&1));
        assert_eq!(stats.invalid_bytes, 0);
    }

    #[test]
    fn frames_split_anywhere_come_out_whole() {
        let a = encode(&[0x3E, 0xD0, 1, 2, 3]);
        let b = encode(&[0x43, 0x50, 9]);
        let stream: Vec<u8> = [a.clone(), b.clone()].concat();
        for cut in 0..=stream.len() {
            let (out, stats) = frames_of(&[&stream[..cut], &stream[cut..]]);
            assert_eq!(out, vec![a.clone(), b.clone()], "cut at {cut}");
            assert_eq!(stats.invalid_bytes, 0);
        }
    }

    #[test]
    fn garbage_and_a_damaged_frame_are_counted_and_dropped() {
        let good = encode(&[0x3E, 0xD0, 1, 2, 3]);
        let mut bad = encode(&[0x3E, 0xD0, 7, 7, 7]);
        bad[5] ^= 0x40;
        // Starts mid-frame: the tail of a frame, then a damaged one, then a good one.
        let stream: Vec<u8> = [&good[4..], &bad[..], &good[..]].concat();
        let (out, stats) = frames_of(&[&stream]);
        assert_eq!(out, vec![good.clone()]);
        assert_eq!(stats.crc_errors, 1);
        assert_eq!(
            stats.invalid_bytes as usize,
            good.len() - 4 + bad.len(),
            "every byte outside the good frame is counted"
        );
    }

    #[test]
    fn a_false_preamble_with_a_huge_length_does_not_swallow_the_stream() {
        let good = encode(&[0x3E, 0xD0, 1]);
        // 0xD3 0x03 0xFF claims 1023 bytes; the good frame follows at once.
        let mut stream = vec![0xD3, 0x03, 0xFF];
        for _ in 0..400 {
            stream.extend_from_slice(&good);
        }
        let (out, stats) = frames_of(&[&stream]);
        // The false start is dropped when its CRC fails; everything after it is recovered.
        assert_eq!(out.len(), 400);
        assert_eq!(stats.invalid_bytes, 3);
    }

    #[test]
    fn the_pending_bytes_never_exceed_one_frame() {
        let mut f = RtcmFramer::new();
        let mut rng = 12345u64;
        for _ in 0..20_000 {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let chunk = rng.to_le_bytes();
            f.push(&chunk, |_, _| {});
            assert!(f.pending() < MAX_FRAME, "{}", f.pending());
        }
    }
}
