//! CAN decoding throughput: frames per second through the drive and BMS decoders, and
//! recorded frames per second through a full replay of a CAN session.

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};

use chassisd::config::VehicleConfig;
use chassisd::devices::can::Received;
use chassisd::engine::drivetrain::Drivetrain;
use chassisd::record::{Payload, RecordingReader};
use chassisd::replay::{ReplayOptions, replay};
use chassisd::time::Timestamp;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every frame on the bus in the recorded session, with its time.
fn session_frames() -> Vec<(Timestamp, Received)> {
    let (_, reader) = RecordingReader::open(&repo().join("fixtures/can-drive")).expect("fixture");
    reader
        .filter_map(|r| match &r.payload {
            Payload::Can(f) | Payload::CanTx(f) => Some((r.t, Received::from_socketcan(f))),
            _ => None,
        })
        .collect()
}

fn decode(c: &mut Criterion) {
    // The session's vehicle as a bus monitor: every frame is decoded, nothing is sent.
    let config = VehicleConfig::load(&repo().join("tests/vm/vehicle-vcan-listen.toml"))
        .expect("listen-only configuration");
    let frames = session_frames();
    let mut group = c.benchmark_group("can_decode");
    group.throughput(Throughput::Elements(frames.len() as u64));
    group.bench_function("drives-and-bms", |b| {
        b.iter(|| {
            let mut drivetrain = Drivetrain::new(&config);
            let mut tx = Vec::new();
            let mut updates = 0u64;
            for (t, frame) in &frames {
                updates += u64::from(drivetrain.on_frame(*t, "vcan0", frame, &mut tx));
            }
            black_box((updates, drivetrain.feedback()))
        })
    });
    group.finish();
}

fn replay_session(c: &mut Criterion) {
    let path = repo().join("fixtures/can-drive");
    let (_, reader) = RecordingReader::open(&path).expect("fixture");
    let records = reader.count() as u64;
    let mut group = c.benchmark_group("replay");
    group.throughput(Throughput::Elements(records));
    group.bench_function("can-drive", |b| {
        b.iter(|| {
            let summary =
                replay(&path, &ReplayOptions::default(), &mut std::io::sink()).expect("replay");
            black_box(summary.engine.ticks)
        })
    });
    group.finish();
}

criterion_group!(benches, decode, replay_session);
criterion_main!(benches);
