//! The RTCM 3 framer and the NTRIP parsers on the real captures of `../shared/data/rtcm`:
//! reference-station streams (RTKLIB, u-blox), a chunked NTRIP 2.0 body (pygnssutils) and a
//! caster's sourcetable (gpsd).

use crate::common;

use chassisd::devices::gnss::rtcm::{RtcmFramer, RtcmStats};
use chassisd::ntrip::chunked::Dechunker;
use chassisd::ntrip::response::{Status, parse_head};
use chassisd::ntrip::sourcetable;

fn read(name: &str) -> Vec<u8> {
    let path = common::shared_data("rtcm").join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Where `marker` first occurs in a capture (the caster's answer after gpsd's comments).
fn position_of(bytes: &[u8], marker: &[u8]) -> usize {
    bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .unwrap_or_else(|| panic!("no {:?} in the capture", String::from_utf8_lossy(marker)))
}

/// Frames `bytes` in slices of `step`: the frames, and the stats.
fn frame(bytes: &[u8], step: usize) -> (Vec<Vec<u8>>, RtcmStats, usize) {
    let mut framer = RtcmFramer::new();
    let mut frames = Vec::new();
    for piece in bytes.chunks(step) {
        framer.push(piece, |f, _| frames.push(f.to_vec()));
    }
    (frames, framer.stats().clone(), framer.pending())
}

#[test]
fn a_reference_station_stream_frames_whole_whatever_the_reads() {
    let bytes = read("rtklib-GMSD7_20121014.rtcm3");
    let (frames, stats, pending) = frame(&bytes, 4096);
    println!("{stats:?}");
    assert_eq!(stats.crc_errors, 0);
    assert!(frames.len() > 1000, "{} frames", frames.len());
    for t in [1077, 1087, 1117, 1127, 1019, 1020] {
        assert!(
            stats.by_type.get(&t).is_some_and(|&n| n > 0),
            "no {t}: {stats:?}"
        );
    }
    // The file is cut inside a frame: that frame stays pending, and every byte is accounted.
    assert!(pending > 0);
    assert_eq!(
        stats.frame_bytes + stats.invalid_bytes + pending as u64,
        bytes.len() as u64
    );
    // Reads of any size give the same frames.
    for step in [1, 7, 1029, 100_000] {
        let (again, s, _) = frame(&bytes, step);
        assert_eq!(again, frames, "step {step}");
        assert_eq!(s, stats);
    }
}

#[test]
fn ascii_before_the_frames_is_counted_and_dropped() {
    let bytes = read("rtklib-testglo.rtcm3");
    let (frames, stats, _) = frame(&bytes, 512);
    assert_eq!(stats.crc_errors, 0);
    assert!(frames.len() > 400, "{stats:?}");
    assert_eq!(stats.invalid_bytes, 58, "{stats:?}");
    for t in [1004, 1012, 1005, 1019, 1020] {
        assert!(stats.by_type.contains_key(&t), "no {t}: {stats:?}");
    }
}

#[test]
fn a_u_blox_base_stream_and_flipped_bits() {
    let bytes = read("pygnssutils-pygpsdata-rtcm3.log");
    let (frames, stats, _) = frame(&bytes, 4096);
    assert_eq!(stats.crc_errors, 0, "{stats:?}");
    assert!(stats.by_type.contains_key(&1077) && stats.by_type.contains_key(&4072));
    // Flip one bit in every 500th frame: exactly those are lost, the rest come through.
    let mut damaged = Vec::new();
    let mut lost = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let mut f = f.clone();
        if i % 500 == 0 {
            let at = 3 + i % (f.len() - 3);
            f[at] ^= 0x10;
            lost.push(i);
        }
        damaged.extend_from_slice(&f);
    }
    let (through, s, _) = frame(&damaged, 333);
    let expected: Vec<Vec<u8>> = frames
        .iter()
        .enumerate()
        .filter(|(i, _)| !lost.contains(i))
        .map(|(_, f)| f.clone())
        .collect();
    assert_eq!(through, expected);
    assert!(s.crc_errors as usize >= lost.len());
}

#[test]
fn the_chunked_ntrip_2_body_decodes_to_valid_frames() {
    let body = read("pygnssutils-ntrip_chunked.bin");
    let mut d = Dechunker::new();
    let mut out = Vec::new();
    for piece in body.chunks(97) {
        d.push(piece, &mut out).expect("a valid chunked body");
    }
    let (frames, stats, _) = frame(&out, 4096);
    println!("{stats:?}");
    assert!(frames.len() > 50, "{stats:?}");
    assert_eq!(stats.crc_errors, 0, "{stats:?}");
    // The capture starts inside a frame: that tail is the only invalid part.
    assert!(stats.invalid_bytes < 1029, "{stats:?}");
    for t in [1006, 1230, 4094] {
        assert!(stats.by_type.contains_key(&t), "no {t}: {stats:?}");
    }
    // Written to a receiver undecoded (OpenMower #322), the chunk sizes break frames.
    let (_, raw, _) = frame(&body, 4096);
    assert!(raw.crc_errors > 0 || raw.frames < stats.frames);
}

#[test]
fn gpsd_s_ntrip_1_exchange_and_sourcetable() {
    let log = read("gpsd-naujoks-ntrip.log");
    let at = position_of(&log, b"ICY");
    let head = parse_head(&log[at..]).unwrap().unwrap();
    assert_eq!(head.status, Status::Icy);
    // RTCM 2 follows at once: the head ends at the blank line.
    assert_eq!(&log[at + head.length..at + head.length + 3], b"YFh");

    let table = read("gpsd-ntrip_sourcetable.log");
    let at = position_of(&table, b"SOURCETABLE");
    let head = parse_head(&table[at..]).unwrap().unwrap();
    assert_eq!(head.status, Status::Sourcetable);
    let text = String::from_utf8_lossy(&table[at + head.length..]);
    let streams = sourcetable::parse(&text);
    assert!(streams.len() >= 3, "{streams:?}");
    let vrs = streams
        .iter()
        .find(|s| s.mountpoint == "VRS_3_2G")
        .expect("VRS_3_2G");
    assert!(vrs.wants_gga);
    assert_eq!(vrs.format, "RTCM3.1");
    assert!(sourcetable::is_complete(&text));
}
