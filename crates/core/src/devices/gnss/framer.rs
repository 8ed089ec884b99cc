//! Byte-stream framer: cuts NMEA 0183 sentences and u-blox UBX frames out of a raw serial
//! stream.
//!
//! The stream is whatever the port delivered: UBX and NMEA interleaved, RTCM echoed back,
//! partial sentences after a reconnect, any mix of CR and LF, and
//! sentences longer than the standard's 82 characters (u-blox high-precision mode, Unicore,
//! SkyTraq PSTI). A sentence is `$`, printable ASCII, `*`, two hex digits; it ends at its
//! checksum, so line endings are optional. Everything else is counted and skipped.
//!
//! Two other forms share the stream: a `$` sentence checked by eight hex digits, the CRC-32
//! NovAtel and Unicore use (`$KSXT` is sent with either), and a `#` ASCII log (Unicore's
//! `#UNIHEADINGA`), which always carries that CRC. A `#` log is delivered with its `#`.
//!
//! A UBX frame starts at `B5 62` between sentences. Its class must be one u-blox uses and its
//! length at most [`MAX_PAYLOAD`]; a frame whose checksum fails gives back every byte after
//! its first, which is skipped, so a false sync in binary noise never swallows what follows.
//! A frame still in progress when the input runs out, that already holds a whole sentence or a
//! whole UBX frame, gives its bytes back then ([`super::false_sync`]), so what follows a false
//! sync is not held back for a length's worth of bytes either.

use std::collections::VecDeque;

use crc::{Algorithm, Crc};

use super::false_sync::FalseSyncWitness;
use super::ubx::frame::{
    HEADER_LEN, MAX_PAYLOAD, OVERHEAD, SYNC, UbxFrame, fletcher, is_known_class,
};

/// The CRC-32 of NovAtel's and Unicore's ASCII logs: the reflected IEEE polynomial with no
/// initial value and no final XOR, over every byte between the `$` or `#` and the `*`.
const CRC32_NOVATEL: Crc<u32> = Crc::<u32>::new(&Algorithm {
    width: 32,
    poly: 0x04c1_1db7,
    init: 0,
    refin: true,
    refout: true,
    xorout: 0,
    check: 0x2dfd_2d88,
    residue: 0,
});

/// Longest sentence accepted, from `$` to the checksum inclusive. The standard says 82
/// including CR/LF; real receivers exceed it, so the limit only guards against runaway input.
pub const MAX_SENTENCE_LEN: usize = 512;

/// Counters of what the framer saw. Every input byte is either part of a delivered sentence,
/// a line ending, part of a delivered UBX frame (`ubx_bytes`), or counted in `bytes_skipped`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FramerStats {
    /// Bytes fed in.
    pub bytes_in: u64,
    /// Sentences with a valid checksum, delivered to the caller.
    pub sentences: u64,
    /// Sentences whose checksum did not match, or whose checksum field was not hex.
    pub checksum_errors: u64,
    /// Sentences that ended at a line break without a `*hh` checksum.
    pub missing_checksum: u64,
    /// Sentences cut short by a new `$` or a non-printable byte.
    pub truncated: u64,
    /// Sentences longer than [`MAX_SENTENCE_LEN`].
    pub overlong: u64,
    /// Bytes that were not part of a delivered sentence, a line ending or a UBX frame.
    pub bytes_skipped: u64,
    /// UBX frames with a valid checksum, delivered to the caller.
    pub ubx_frames: u64,
    /// Bytes of those frames, sync to checksum.
    pub ubx_bytes: u64,
    /// UBX frames (plausible class and length) whose checksum did not match.
    pub ubx_checksum_errors: u64,
}

/// What the framer cuts from the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame<'a> {
    /// An NMEA sentence's body between `$` and `*`, or a `#` log with its `#`.
    Text(&'a str),
    /// A UBX frame.
    Ubx(UbxFrame<'a>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Between sentences, hunting for `$`.
    Idle,
    /// Inside a sentence body, after `$`.
    Body,
    /// After `*`, waiting for the first checksum digit.
    ChecksumHigh,
    /// After the first checksum digit.
    ChecksumLow(u8),
    /// After two digits that were not the XOR (or a `#` log's first two): the rest of an
    /// eight-digit CRC-32, its value and digits so far.
    Crc32(u32, u8),
    /// Inside a UBX frame, whose bytes so far are in `ubx`.
    Ubx,
}

/// Incremental framer. Feed it chunks of any size; it keeps partial frames between calls.
#[derive(Debug)]
pub struct GnssFramer {
    state: State,
    /// Body bytes between `$` and `*` (exclusive), printable ASCII only.
    body: Vec<u8>,
    /// Running XOR of `body`.
    xor: u8,
    /// The sentence began with `#` (an ASCII log: CRC-32 only).
    log: bool,
    /// The UBX frame in progress, from its sync.
    ubx: Vec<u8>,
    /// Watches `ubx` for proof of a false sync.
    witness: FalseSyncWitness,
    /// Bytes of a failed UBX frame to be framed again before new input.
    replay: VecDeque<u8>,
    stats: FramerStats,
}

impl Default for GnssFramer {
    fn default() -> Self {
        Self::new()
    }
}

impl GnssFramer {
    /// A framer in the idle state with zeroed counters.
    pub fn new() -> Self {
        Self {
            state: State::Idle,
            body: Vec::with_capacity(128),
            xor: 0,
            log: false,
            ubx: Vec::new(),
            witness: FalseSyncWitness::default(),
            replay: VecDeque::new(),
            stats: FramerStats::default(),
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> FramerStats {
        self.stats
    }

    /// Bytes of an unfinished sentence held until more input arrives.
    pub fn pending(&self) -> usize {
        let consumed_markers = match self.state {
            State::Idle => return 0,
            State::Body => 1,
            State::ChecksumHigh => 2,
            State::ChecksumLow(_) => 3,
            State::Crc32(_, digits) => 2 + usize::from(digits),
            State::Ubx => return self.ubx.len(),
        };
        consumed_markers + self.body.len()
    }

    /// Feeds `data`, calling `on_frame` with each complete frame (checksum verified) in
    /// stream order.
    pub fn push_frames(&mut self, data: &[u8], mut on_frame: impl FnMut(Frame<'_>)) {
        self.stats.bytes_in += data.len() as u64;
        for &byte in data {
            self.step(byte, &mut on_frame);
            self.step_replayed(&mut on_frame);
        }
        while self.state == State::Ubx && self.witness.proves_false(&self.ubx) {
            self.resync_ubx();
            self.step_replayed(&mut on_frame);
        }
    }

    /// Frames again the bytes a failed UBX frame gave back.
    fn step_replayed(&mut self, on_frame: &mut impl FnMut(Frame<'_>)) {
        while let Some(again) = self.replay.pop_front() {
            self.step(again, on_frame);
        }
    }

    /// Feeds `data`, calling `on_sentence` with each complete sentence body (the text between
    /// `$` and `*`, checksum verified) in stream order. UBX frames are framed and counted but
    /// not handed over.
    pub fn push(&mut self, data: &[u8], mut on_sentence: impl FnMut(&str)) {
        self.push_frames(data, |frame| {
            if let Frame::Text(body) = frame {
                on_sentence(body);
            }
        });
    }

    fn step(&mut self, byte: u8, on_frame: &mut impl FnMut(Frame<'_>)) {
        match self.state {
            State::Idle => match byte {
                b'$' => self.start(false),
                b'#' => self.start(true),
                b'\r' | b'\n' => {}
                _ if byte == SYNC[0] => self.start_ubx(),
                _ => self.stats.bytes_skipped += 1,
            },
            State::Body => match byte {
                b'*' => self.state = State::ChecksumHigh,
                b'$' => {
                    self.abandon(0);
                    self.stats.truncated += 1;
                    self.start(false);
                }
                _ if byte == SYNC[0] => {
                    self.abandon(0);
                    self.stats.truncated += 1;
                    self.start_ubx();
                }
                b'\r' | b'\n' => {
                    self.abandon(0);
                    self.stats.missing_checksum += 1;
                }
                0x20..=0x7e => {
                    // `$` + body + `*hh` must fit in MAX_SENTENCE_LEN.
                    if self.body.len() + 4 >= MAX_SENTENCE_LEN {
                        self.abandon(1);
                        self.stats.overlong += 1;
                    } else {
                        self.body.push(byte);
                        self.xor ^= byte;
                    }
                }
                _ => {
                    self.abandon(1);
                    self.stats.truncated += 1;
                }
            },
            State::ChecksumHigh => match hex_value(byte) {
                Some(high) => self.state = State::ChecksumLow(high),
                None => self.bad_checksum_field(byte),
            },
            State::ChecksumLow(high) => match hex_value(byte) {
                Some(low) => {
                    let expected = (high << 4) | low;
                    if expected == self.xor && !self.log {
                        self.deliver(on_frame);
                    } else {
                        // Maybe the first two digits of a CRC-32.
                        self.state = State::Crc32(u32::from(expected), 2);
                    }
                }
                None => {
                    // The first digit was consumed too.
                    self.stats.bytes_skipped += 1;
                    self.bad_checksum_field(byte);
                }
            },
            State::Crc32(value, digits) => match hex_value(byte) {
                Some(digit) => {
                    let value = (value << 4) | u32::from(digit);
                    if digits + 1 < 8 {
                        self.state = State::Crc32(value, digits + 1);
                    } else if value == CRC32_NOVATEL.checksum(&self.body) {
                        self.deliver(on_frame);
                    } else {
                        // `$`, body, `*` and the eight digits are dropped.
                        self.abandon(9);
                        self.stats.checksum_errors += 1;
                    }
                }
                None => {
                    // Two to seven digits that check nothing: dropped with the sentence.
                    self.stats.bytes_skipped += u64::from(digits);
                    self.bad_checksum_field(byte);
                }
            },
            State::Ubx => self.step_ubx(byte, on_frame),
        }
    }

    fn step_ubx(&mut self, byte: u8, on_frame: &mut impl FnMut(Frame<'_>)) {
        self.ubx.push(byte);
        let plausible = match self.ubx.len() {
            2 => byte == SYNC[1],
            3 => is_known_class(byte),
            HEADER_LEN => self.ubx_payload_len() <= MAX_PAYLOAD,
            _ => true,
        };
        if !plausible {
            self.resync_ubx();
            return;
        }
        if self.ubx.len() < HEADER_LEN || self.ubx.len() < OVERHEAD + self.ubx_payload_len() {
            return;
        }
        let end = self.ubx.len() - 2;
        if fletcher(&self.ubx[2..end]) != self.ubx[end..] {
            self.stats.ubx_checksum_errors += 1;
            self.resync_ubx();
            return;
        }
        self.stats.ubx_frames += 1;
        self.stats.ubx_bytes += self.ubx.len() as u64;
        self.state = State::Idle;
        on_frame(Frame::Ubx(UbxFrame {
            class: self.ubx[2],
            id: self.ubx[3],
            payload: &self.ubx[HEADER_LEN..end],
        }));
        self.ubx.clear();
    }

    /// The payload length a UBX header in progress states (its length field is complete).
    fn ubx_payload_len(&self) -> usize {
        usize::from(u16::from_le_bytes([self.ubx[4], self.ubx[5]]))
    }

    fn start_ubx(&mut self) {
        self.state = State::Ubx;
        self.ubx.clear();
        self.ubx.push(SYNC[0]);
        self.witness.clear();
    }

    /// Not a UBX frame after all: its first byte is skipped and the rest framed again.
    fn resync_ubx(&mut self) {
        self.stats.bytes_skipped += 1;
        self.state = State::Idle;
        for &byte in self.ubx[1..].iter().rev() {
            self.replay.push_front(byte);
        }
        self.ubx.clear();
    }

    fn start(&mut self, log: bool) {
        self.state = State::Body;
        self.body.clear();
        self.xor = 0;
        self.log = log;
    }

    /// Drops the sentence in progress: `$`, the body and `extra` more consumed bytes.
    fn abandon(&mut self, extra: u64) {
        self.stats.bytes_skipped += 1 + self.body.len() as u64 + extra;
        self.body.clear();
        self.state = State::Idle;
    }

    /// A non-hex byte where a checksum digit belongs. A `$` there starts the next sentence.
    fn bad_checksum_field(&mut self, byte: u8) {
        self.stats.checksum_errors += 1;
        // `$`, body and `*`.
        self.abandon(1);
        match byte {
            b'$' => self.start(false),
            b'#' => self.start(true),
            b'\r' | b'\n' => {}
            _ if byte == SYNC[0] => self.start_ubx(),
            _ => self.stats.bytes_skipped += 1,
        }
    }

    fn deliver(&mut self, on_frame: &mut impl FnMut(Frame<'_>)) {
        self.state = State::Idle;
        // The body holds only bytes 0x20..=0x7e, so it is always valid UTF-8; a failure here
        // would be a framer bug, and the sentence is then counted as skipped rather than lost
        // silently.
        match std::str::from_utf8(&self.body) {
            Ok(body) if self.log => {
                self.stats.sentences += 1;
                on_frame(Frame::Text(&format!("#{body}")));
            }
            Ok(body) => {
                self.stats.sentences += 1;
                on_frame(Frame::Text(body));
            }
            Err(_) => self.stats.bytes_skipped += self.body.len() as u64 + 4,
        }
        self.body.clear();
    }
}

fn hex_value(byte: u8) -> Option<u8> {
    match byte {
        b'0'..=b'9' => Some(byte - b'0'),
        b'a'..=b'f' => Some(byte - b'a' + 10),
        b'A'..=b'F' => Some(byte - b'A' + 10),
        _ => None,
    }
}

/// The NMEA checksum of a sentence body: XOR of every byte between `$` and `*`.
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |acc, b| acc ^ b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame_all(chunks: &[&[u8]]) -> (Vec<String>, FramerStats) {
        let mut framer = GnssFramer::new();
        let mut out = Vec::new();
        for chunk in chunks {
            framer.push(chunk, |s| out.push(s.to_owned()));
        }
        (out, framer.stats())
    }

    const GGA: &[u8] =
        b"$GPGGA,150119.000,5104.0859,N,11405.7387,W,2,8,0.94,1102.4,M,-17.5,M,,*53\r\n";

    #[test]
    fn frames_one_sentence_with_crlf() {
        let (out, stats) = frame_all(&[GGA]);
        assert_eq!(out.len(), 1);
        assert!(out[0].starts_with("GPGGA,150119.000"));
        assert_eq!(stats.sentences, 1);
        assert_eq!(stats.bytes_skipped, 0);
    }

    #[test]
    fn any_line_ending_or_none() {
        let body = &GGA[..GGA.len() - 2];
        for ending in [&b"\r\n"[..], b"\n", b"\r", b"\n\r", b""] {
            let mut stream = Vec::new();
            for _ in 0..3 {
                stream.extend_from_slice(body);
                stream.extend_from_slice(ending);
            }
            let (out, stats) = frame_all(&[&stream]);
            assert_eq!(out.len(), 3, "ending {ending:?}");
            assert_eq!(stats.bytes_skipped, 0, "ending {ending:?}");
        }
    }

    #[test]
    fn survives_split_at_every_byte() {
        for cut in 0..GGA.len() {
            let (out, stats) = frame_all(&[&GGA[..cut], &GGA[cut..]]);
            assert_eq!(out.len(), 1, "cut at {cut}");
            assert_eq!(stats.bytes_skipped, 0);
        }
    }

    #[test]
    fn skips_binary_garbage_around_sentences() {
        let mut stream = vec![0xb5, 0x62, 0x01, 0x07, 0x00, 0xff, b'*', b'$'];
        stream.extend_from_slice(GGA);
        stream.extend_from_slice(&[0xd3, 0x00, 0x13, b'G']);
        let (out, stats) = frame_all(&[&stream]);
        assert_eq!(out.len(), 1);
        // 7 garbage bytes, a lone `$` cut short by the real `$`, then 4 trailing bytes.
        assert_eq!(stats.bytes_skipped, 7 + 1 + 4);
        assert_eq!(stats.truncated, 1);
    }

    /// A sync, a known class and a length of 4,096: a false frame that would swallow 4 KiB.
    const FALSE_SYNC: [u8; 6] = [0xb5, 0x62, 0x01, 0x00, 0x00, 0x10];

    #[test]
    fn a_sentence_after_a_false_sync_is_not_held_back() {
        let mut stream = FALSE_SYNC.to_vec();
        stream.extend_from_slice(GGA);
        for cut in 0..stream.len() {
            let (out, stats) = frame_all(&[&stream[..cut], &stream[cut..]]);
            assert_eq!(out.len(), 1, "cut at {cut}");
            assert_eq!(stats.bytes_skipped, FALSE_SYNC.len() as u64);
        }
        // Without its line end the sentence is no proof yet: the frame may still be real.
        let (out, _) = frame_all(&[&stream[..stream.len() - 2]]);
        assert!(out.is_empty());
    }

    #[test]
    fn a_ubx_frame_after_a_false_sync_is_not_held_back() {
        let real = crate::devices::gnss::ubx::frame::encode(0x01, 0x07, &[7; 92]).unwrap();
        let mut stream = FALSE_SYNC.to_vec();
        stream.extend_from_slice(&real);
        let mut framer = GnssFramer::new();
        let mut payloads = Vec::new();
        framer.push_frames(&stream, |frame| {
            if let Frame::Ubx(ubx) = frame {
                payloads.push((ubx.class, ubx.id, ubx.payload.len()));
            }
        });
        assert_eq!(payloads, vec![(0x01, 0x07, 92)]);
        assert_eq!(framer.pending(), 0);
        assert_eq!(framer.stats().bytes_skipped, FALSE_SYNC.len() as u64);
    }

    #[test]
    fn a_real_frame_holding_sentence_like_text_is_delivered() {
        // An INF-NOTICE whose text looks like a sentence but fails its checksum, and one with a
        // sync pattern whose inner frame fails its own: neither is proof, both frames arrive.
        let mut text = b"$GPGGA,1*00\r\n".to_vec();
        text.extend_from_slice(&[0xb5, 0x62, 0x01, 0x07, 0x01, 0x00, 0x00, 0x00, 0x00]);
        let real = crate::devices::gnss::ubx::frame::encode(0x04, 0x02, &text).unwrap();
        let mut framer = GnssFramer::new();
        let mut frames = 0;
        framer.push_frames(&real, |frame| {
            frames += usize::from(matches!(frame, Frame::Ubx(_)))
        });
        assert_eq!((frames, framer.stats().bytes_skipped), (1, 0));
    }

    #[test]
    fn counts_bad_checksums_and_keeps_going() {
        let mut bad = GGA.to_vec();
        let star = bad.iter().position(|&b| b == b'*').unwrap();
        bad[star + 2] = b'4';
        let mut stream = bad.clone();
        stream.extend_from_slice(GGA);
        let (out, stats) = frame_all(&[&stream]);
        assert_eq!(out.len(), 1);
        assert_eq!(stats.checksum_errors, 1);
        assert_eq!(stats.bytes_skipped, (bad.len() - 2) as u64);
    }

    #[test]
    fn accepts_lowercase_checksum_and_long_sentences() {
        let body = format!("GNGGA,{}", "1,".repeat(100));
        let line = format!("${body}*{:02x}\r\n", checksum(body.as_bytes()));
        assert!(line.len() > 102);
        let (out, _) = frame_all(&[line.as_bytes()]);
        assert_eq!(out, vec![body]);
    }

    #[test]
    fn rejects_runaway_sentence_then_recovers() {
        let mut stream = b"$GPGGA,".to_vec();
        stream.extend(std::iter::repeat_n(b'1', 2 * MAX_SENTENCE_LEN));
        stream.extend_from_slice(GGA);
        let (out, stats) = frame_all(&[&stream]);
        assert_eq!(out.len(), 1);
        assert_eq!(stats.overlong, 1);
    }

    #[test]
    fn missing_checksum_is_counted() {
        let (out, stats) = frame_all(&[b"$GPGGA,1,2,3\r\n", GGA]);
        assert_eq!(out.len(), 1);
        assert_eq!(stats.missing_checksum, 1);
        assert_eq!(stats.bytes_skipped, 12);
    }

    #[test]
    fn double_dollar_starts_over() {
        // Unicore emits `$$GYOACC,...`; the first `$` is dropped, the sentence survives.
        let body = "GYOACC,1,2";
        let line = format!("$${body}*{:02X}\r\n", checksum(body.as_bytes()));
        let (out, stats) = frame_all(&[line.as_bytes()]);
        assert_eq!(out, vec![body.to_owned()]);
        assert_eq!(stats.bytes_skipped, 1);
    }

    /// Unicore's logs as ArduPilot's and Unicore's documents quote them, CRCs as sent.
    const UNIHEADINGA: &str = "#UNIHEADINGA,79,GPS,FINE,2242,167498200,0,0,18,22;SOL_COMPUTED,L1_INT,2.7889,296.7233,-25.7710,0.0000,0.1127,0.1812,\"999\",49,37,37,0,3,00,1,51*d50af0ea\r\n";
    const KSXT_XOR: &str = "$KSXT,20211016083433.00,116.31296102,39.95817066,49.4911,223.57,-11.32,330.19,0.024,,1,3,28,27,,,,-0.012,0.021,0.020,,*2D\r\n";

    #[test]
    fn crc32_logs_and_sentences_are_framed_beside_nmea() {
        let ksxt_body = &KSXT_XOR[1..KSXT_XOR.len() - 5];
        let ksxt_crc = format!(
            "${ksxt_body}*{:08x}\r\n",
            CRC32_NOVATEL.checksum(ksxt_body.as_bytes())
        );
        let stream = [
            UNIHEADINGA,
            KSXT_XOR,
            &ksxt_crc,
            std::str::from_utf8(GGA).unwrap(),
        ]
        .concat();
        // Split at every byte: the CRC's eight digits survive any cut.
        for cut in 0..stream.len() {
            let (out, stats) = frame_all(&[&stream.as_bytes()[..cut], &stream.as_bytes()[cut..]]);
            assert_eq!(out.len(), 4, "cut at {cut}: {stats:?}");
            assert!(out[0].starts_with("#UNIHEADINGA,79,"));
            assert_eq!(out[1], ksxt_body);
            assert_eq!(out[2], ksxt_body);
            assert_eq!(stats.bytes_skipped, 0);
        }
    }

    #[test]
    fn a_wrong_crc32_is_a_checksum_error_and_the_stream_goes_on() {
        let bad = UNIHEADINGA.replace("*d50af0ea", "*d50af0eb");
        let stream = [bad.as_str(), std::str::from_utf8(GGA).unwrap()].concat();
        let (out, stats) = frame_all(&[stream.as_bytes()]);
        assert_eq!(out.len(), 1);
        assert_eq!(stats.checksum_errors, 1);
        assert_eq!(stats.bytes_skipped, (bad.len() - 2) as u64);
        // A `#` log with only a two-digit checksum is no log.
        let short = "#UNIHEADINGA,79;SOL_COMPUTED*4F\r\n";
        let (out, stats) = frame_all(&[short.as_bytes(), GGA]);
        assert_eq!((out.len(), stats.checksum_errors), (1, 1));
    }

    #[test]
    fn byte_accounting_is_complete() {
        let mut stream = b"junk\x00\x01$GP*ZZ$GPGGA,1*00\n".to_vec();
        stream.extend_from_slice(GGA);
        let (out, stats) = frame_all(&[&stream]);
        assert_eq!(out.len(), 1);
        let line_endings = 3;
        let delivered = (GGA.len() - 2) as u64;
        assert_eq!(
            stats.bytes_in,
            delivered + line_endings + stats.bytes_skipped
        );
    }
}
