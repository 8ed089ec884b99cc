//! Byte-stream framer: cuts NMEA 0183 sentences out of a raw serial stream.
//!
//! The stream is whatever the port delivered: binary protocols interleaved with NMEA
//! (u-blox UBX, RTCM), partial sentences after a reconnect, any mix of CR and LF, and
//! sentences longer than the standard's 82 characters (u-blox high-precision mode, Unicore,
//! SkyTraq PSTI). A sentence is `$`, printable ASCII, `*`, two hex digits; it ends at its
//! checksum, so line endings are optional. Everything else is counted and skipped.
//!
//! Two other forms share the stream: a `$` sentence checked by eight hex digits, the CRC-32
//! NovAtel and Unicore use (`$KSXT` is sent with either), and a `#` ASCII log (Unicore's
//! `#UNIHEADINGA`), which always carries that CRC. A `#` log is delivered with its `#`.

use crc::{Algorithm, Crc};

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
/// a line ending, or counted in `bytes_skipped`.
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
    /// Bytes that were not part of a delivered sentence or a line ending.
    pub bytes_skipped: u64,
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
}

/// Incremental NMEA framer. Feed it chunks of any size; it keeps partial sentences between calls.
#[derive(Debug)]
pub struct NmeaFramer {
    state: State,
    /// Body bytes between `$` and `*` (exclusive), printable ASCII only.
    body: Vec<u8>,
    /// Running XOR of `body`.
    xor: u8,
    /// The sentence began with `#` (an ASCII log: CRC-32 only).
    log: bool,
    stats: FramerStats,
}

impl Default for NmeaFramer {
    fn default() -> Self {
        Self::new()
    }
}

impl NmeaFramer {
    /// A framer in the idle state with zeroed counters.
    pub fn new() -> Self {
        Self {
            state: State::Idle,
            body: Vec::with_capacity(128),
            xor: 0,
            log: false,
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
        };
        consumed_markers + self.body.len()
    }

    /// Feeds `data`, calling `on_sentence` with each complete sentence body (the text between
    /// `$` and `*`, checksum verified) in stream order.
    pub fn push(&mut self, data: &[u8], mut on_sentence: impl FnMut(&str)) {
        self.stats.bytes_in += data.len() as u64;
        for &byte in data {
            self.step(byte, &mut on_sentence);
        }
    }

    fn step(&mut self, byte: u8, on_sentence: &mut impl FnMut(&str)) {
        match self.state {
            State::Idle => match byte {
                b'$' => self.start(false),
                b'#' => self.start(true),
                b'\r' | b'\n' => {}
                _ => self.stats.bytes_skipped += 1,
            },
            State::Body => match byte {
                b'*' => self.state = State::ChecksumHigh,
                b'$' => {
                    self.abandon(0);
                    self.stats.truncated += 1;
                    self.start(false);
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
                        self.deliver(on_sentence);
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
                        self.deliver(on_sentence);
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
        }
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
            _ => self.stats.bytes_skipped += 1,
        }
    }

    fn deliver(&mut self, on_sentence: &mut impl FnMut(&str)) {
        self.state = State::Idle;
        // The body holds only bytes 0x20..=0x7e, so it is always valid UTF-8; a failure here
        // would be a framer bug, and the sentence is then counted as skipped rather than lost
        // silently.
        match std::str::from_utf8(&self.body) {
            Ok(body) if self.log => {
                self.stats.sentences += 1;
                on_sentence(&format!("#{body}"));
            }
            Ok(body) => {
                self.stats.sentences += 1;
                on_sentence(body);
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
        let mut framer = NmeaFramer::new();
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
