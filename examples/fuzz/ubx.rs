//! Fuzz targets for u-blox UBX: the mixed-stream framer and every decoder.

use chassisd::devices::gnss::fix::FixAssembler;
use chassisd::devices::gnss::ubx::frame::{OVERHEAD, encode, fletcher};
use chassisd::devices::gnss::ubx::{self, UbxFrame, config};
use chassisd::devices::gnss::{Frame, GnssFramer, GnssReceiver};
use chassisd::time::Timestamp;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::{Runner, files_in, pieces, shared, signature};

/// Sync, and the class and id pairs chassisd reads.
pub const TOKENS: &[&[u8]] = &[
    b"\xb5\x62",
    b"\x01\x07",
    b"\x01\x06",
    b"\x01\x20",
    b"\x01\x14",
    b"\x01\x36",
    b"\x01\x3c",
    b"\x01\x03",
    b"\x01\x35",
    b"\x01\x04",
    b"\x02\x32",
    b"\x0a\x04",
    b"\x05\x01",
    b"\x06\x8b",
    b"\x00\x00",
    b"\xff\xff",
];

/// Whole UBX frames from gpsd's u-blox logs, with the frames no log holds built from the
/// interface description (RELPOSNED v1, COV, MON-VER, VALGET's answer, ACK).
fn real_frames() -> Vec<Vec<u8>> {
    let mut frames = Vec::new();
    for log in files_in(&shared().join("gnss"), "log") {
        let Ok(bytes) = std::fs::read(&log) else {
            continue;
        };
        let mut framer = GnssFramer::new();
        let mut kinds = std::collections::HashMap::<(u8, u8), usize>::new();
        framer.push_frames(&bytes, |frame| {
            if let Frame::Ubx(f) = frame {
                let seen = kinds.entry((f.class, f.id)).or_default();
                // A few of each kind per log.
                if *seen < 3 {
                    *seen += 1;
                    frames.extend(encode(f.class, f.id, f.payload));
                }
            }
        });
    }
    let mut relposned = vec![0u8; 64];
    relposned[0] = 1;
    relposned[60] = 0x25;
    relposned[61] = 0x01;
    let mut cov = vec![0u8; 64];
    cov[5] = 1;
    cov[16..20].copy_from_slice(&0.0004f32.to_le_bytes());
    cov[28..32].copy_from_slice(&0.0009f32.to_le_bytes());
    let mut mon_ver = vec![0u8; 100];
    mon_ver[40..54].copy_from_slice(b"FWVER=HPG 1.32");
    mon_ver[70..83].copy_from_slice(b"PROTVER=27.31");
    let mut sol = vec![0u8; 52];
    sol[8] = 0x8e;
    sol[9] = 0x08;
    sol[10] = 3;
    sol[11] = 0x0f;
    sol[12..16].copy_from_slice(&441_000_000i32.to_le_bytes());
    let mut timegps = vec![0u8; 16];
    timegps[10] = 18;
    timegps[11] = 0x07;
    let mut valget = vec![1, 0, 0, 0];
    valget.extend_from_slice(&0x2091_0007u32.to_le_bytes());
    valget.push(1);
    for (class, id, payload) in [
        (0x01, 0x3c, relposned),
        (0x01, 0x36, cov),
        (0x01, 0x06, sol),
        (0x01, 0x20, timegps),
        (0x0a, 0x04, mon_ver),
        (0x06, 0x8b, valget),
        (0x05, 0x01, vec![0x06, 0x8a]),
    ] {
        frames.extend(encode(class, id, &payload));
    }
    frames
}

pub fn stream_seeds() -> Vec<Vec<u8>> {
    let mut seeds = real_frames();
    for log in files_in(&shared().join("gnss"), "log") {
        if let Ok(bytes) = std::fs::read(&log)
            && bytes.windows(2).any(|w| w == [0xb5, 0x62])
        {
            seeds.extend(pieces(&bytes, 1024, 40));
        }
    }
    seeds
}

/// Changes one frame's payload (bytes, length) and mends its length and checksum, so the
/// decoders see what a checksum would otherwise turn away.
pub fn mutate_frames(rng: &mut ChaCha8Rng, input: &mut Vec<u8>) {
    let starts: Vec<usize> = input
        .windows(2)
        .enumerate()
        .filter(|(_, w)| *w == [0xb5, 0x62])
        .map(|(i, _)| i)
        .collect();
    if starts.is_empty() {
        return;
    }
    let at = starts[rng.random_range(0..starts.len())];
    let Some(header) = input.get(at..at + 6) else {
        return;
    };
    let (class, id) = (header[2], header[3]);
    let len = usize::from(u16::from_le_bytes([header[4], header[5]]));
    let end = (at + OVERHEAD + len).min(input.len());
    let mut payload = input[(at + 6).min(end)..end.saturating_sub(2).max(at + 6).min(end)].to_vec();
    match rng.random_range(0..4) {
        0 => payload.truncate(rng.random_range(0..=payload.len())),
        1 => payload.extend((0..rng.random_range(1..64)).map(|_| rng.random::<u8>())),
        _ => {
            for _ in 0..rng.random_range(1..4) {
                if !payload.is_empty() {
                    let i = rng.random_range(0..payload.len());
                    payload[i] = rng.random();
                }
            }
        }
    }
    if let Some(frame) = encode(class, id, &payload) {
        input.splice(at..end, frame);
    }
}

pub fn stream_runner() -> Runner {
    Box::new(|input| {
        let mut framer = GnssFramer::new();
        let mut receiver = GnssReceiver::new();
        // A sentence's bytes beyond its body: `$`, `*` and two or eight digits; a `#` log's
        // body holds its `#`, and eight digits follow.
        let (mut text_lo, mut text_hi) = (0u64, 0u64);
        let mut decoded = 0u64;
        for piece in input.chunks(input.len() / 3 + 1) {
            framer.push_frames(piece, |frame| match frame {
                Frame::Text(body) if body.starts_with('#') => {
                    text_lo += body.len() as u64 + 9;
                    text_hi += body.len() as u64 + 9;
                }
                Frame::Text(body) => {
                    text_lo += body.len() as u64 + 4;
                    text_hi += body.len() as u64 + 10;
                }
                Frame::Ubx(f) => {
                    assert_eq!(
                        encode(f.class, f.id, f.payload).map(|e| e.len()),
                        Some(f.payload.len() + OVERHEAD)
                    );
                    decoded += u64::from(matches!(ubx::decode(&f), Ok(Some(_))));
                }
            });
            receiver.push(Timestamp::default(), piece, |_| {});
        }
        let s = framer.stats();
        // Every byte is a sentence's, a frame's, skipped, a line ending or waiting.
        let line_endings = input.iter().filter(|&&b| b == b'\r' || b == b'\n').count() as u64;
        let rest = s.ubx_bytes + s.bytes_skipped + framer.pending() as u64;
        assert!(
            text_lo + rest <= s.bytes_in && s.bytes_in <= text_hi + rest + line_endings,
            "bytes unaccounted: {s:?}, text {text_lo}..{text_hi}, pending {}",
            framer.pending()
        );
        assert!(framer.pending() <= OVERHEAD + ubx::frame::MAX_PAYLOAD);
        assert_eq!(receiver.stats().framer, s);
        signature(&[
            s.ubx_frames.min(16),
            s.ubx_checksum_errors.min(4),
            s.sentences.min(4),
            decoded.min(16),
            receiver.stats().decode_errors.min(4),
        ])
    })
}

pub fn message_seeds() -> Vec<Vec<u8>> {
    real_frames()
        .into_iter()
        .map(|f| {
            let mut seed = vec![f[2], f[3]];
            seed.extend_from_slice(&f[6..f.len() - 2]);
            seed
        })
        .collect()
}

pub fn message_runner() -> Runner {
    Box::new(|input| {
        let [class, id, payload @ ..] = input else {
            return 0;
        };
        let frame = UbxFrame {
            class: *class,
            id: *id,
            payload,
        };
        let mut assembler = FixAssembler::new();
        let outcome = match ubx::decode(&frame) {
            Ok(Some(message)) => {
                // Twice: a second epoch on top of the first.
                let changed = assembler.apply_ubx(Timestamp::default(), &message);
                assembler.apply_ubx(Timestamp::from_micros(100_000), &message);
                let fix = assembler.fix();
                if let Some(p) = fix.position {
                    assert!(
                        p.value.latitude_deg.abs() <= 215.0 && p.value.longitude_deg.abs() <= 215.0
                    );
                }
                if let Some(h) = fix.heading_deg {
                    assert!((0.0..360.0).contains(&h.value), "heading {}", h.value);
                }
                1 + u64::from(changed)
            }
            Ok(None) => 0,
            Err(_) => 3,
        };
        // The configuration answer's decoder on any payload.
        let valget =
            config::ValGetAnswer::decode(payload).map_or(0, |a| a.items.len().min(8) as u64);
        assert_eq!(fletcher(&[]), [0, 0]);
        signature(&[
            u64::from(*class),
            u64::from(*id),
            outcome,
            valget,
            payload.len().min(100) as u64 / 4,
        ])
    })
}
