//! Throughput benchmarks: NMEA sentences and u-blox UBX frames decoded per second, the bytes
//! per second of each beside the other, and replay frames per second.
//!
//! Inputs ship with the repo (`fixtures/rtk-drive`); the shared receiver logs are used too
//! when `../shared/data/gnss` is present.

use std::hint::black_box;
use std::path::{Path, PathBuf};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};

use chassisd::devices::gnss::GnssReceiver;
use chassisd::record::{Payload, RecordingReader};
use chassisd::replay::{ReplayOptions, replay};
use chassisd::time::Timestamp;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The raw serial bytes of the fixture recording, as the port delivered them.
fn fixture_bytes() -> Vec<u8> {
    let (_, reader) = RecordingReader::open(&repo().join("fixtures/rtk-drive")).expect("fixture");
    let mut bytes = Vec::new();
    for record in reader {
        if let Payload::Serial(chunk) = record.payload {
            bytes.extend_from_slice(&chunk);
        }
    }
    bytes
}

/// All shared receiver logs, concatenated (comments included: the framer skips them).
fn shared_bytes() -> Option<Vec<u8>> {
    let dir = repo().join("../shared/data/gnss");
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "log"))
        .collect();
    paths.sort();
    let mut bytes = Vec::new();
    for p in paths {
        bytes.extend(std::fs::read(p).ok()?);
    }
    Some(bytes)
}

/// The shared u-blox logs that hold only UBX (comments included).
fn shared_ubx_bytes() -> Option<Vec<u8>> {
    let dir = repo().join("../shared/data/gnss");
    let mut bytes = Vec::new();
    for name in [
        "ublox-neo-m8p.log",
        "ublox-zed-f9p-hp.log",
        "ublox-zed-f9p-rtk.log",
    ] {
        bytes.extend(std::fs::read(dir.join(name)).ok()?);
    }
    Some(bytes)
}

fn ubx_frames_in(bytes: &[u8]) -> u64 {
    let mut receiver = GnssReceiver::new();
    receiver.push(Timestamp::default(), bytes, |_| {});
    receiver.stats().framer.ubx_frames
}

/// Decoding the whole of `bytes` through a fresh receiver.
fn decode_all(bytes: &[u8]) -> u64 {
    let mut receiver = GnssReceiver::new();
    let mut fixes = 0u64;
    receiver.push(Timestamp::default(), black_box(bytes), |_| fixes += 1);
    black_box(fixes)
}

fn ubx(c: &mut Criterion) {
    let Some(ubx) = shared_ubx_bytes() else {
        return;
    };
    let mut group = c.benchmark_group("ubx_decode");
    group.throughput(Throughput::Elements(ubx_frames_in(&ubx)));
    group.bench_function("shared-ubx-logs", |b| b.iter(|| decode_all(&ubx)));
    group.finish();
    // NMEA and UBX side by side, in bytes.
    let mut group = c.benchmark_group("gnss_bytes");
    for (name, bytes) in [
        ("nmea-rtk-drive", fixture_bytes()),
        ("ubx-shared-logs", ubx),
    ] {
        group.throughput(Throughput::Bytes(bytes.len() as u64));
        group.bench_function(name, |b| b.iter(|| decode_all(&bytes)));
    }
    group.finish();
}

fn sentences_in(bytes: &[u8]) -> u64 {
    let mut receiver = GnssReceiver::new();
    receiver.push(Timestamp::default(), bytes, |_| {});
    receiver.stats().framer.sentences
}

fn decode(c: &mut Criterion) {
    let mut inputs = vec![("rtk-drive", fixture_bytes())];
    if let Some(shared) = shared_bytes() {
        inputs.push(("shared-logs", shared));
    }
    let mut group = c.benchmark_group("nmea_decode");
    for (name, bytes) in &inputs {
        group.throughput(Throughput::Elements(sentences_in(bytes)));
        group.bench_function(*name, |b| b.iter(|| decode_all(bytes)));
    }
    group.finish();
}

fn replay_fixture(c: &mut Criterion) {
    let path = repo().join("fixtures/rtk-drive");
    let frames = count_frames(&path);
    let mut group = c.benchmark_group("replay");
    group.throughput(Throughput::Elements(frames));
    group.bench_function("rtk-drive", |b| {
        b.iter(|| {
            let summary =
                replay(&path, &ReplayOptions::default(), &mut std::io::sink()).expect("replay");
            black_box(summary.engine.ticks)
        })
    });
    group.finish();
}

fn count_frames(path: &Path) -> u64 {
    let (_, reader) = RecordingReader::open(path).expect("fixture");
    reader.count() as u64
}

criterion_group!(benches, decode, ubx, replay_fixture);
criterion_main!(benches);
