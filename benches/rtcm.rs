//! Throughput of the corrections relay: a caster's bytes through the engine (RTCM 3
//! framing, CRC-24Q, the core told the frames' time, one write for the receiver's port per
//! chunk), over the shared reference-station streams, in chunks from 1 byte to 16 KiB (a
//! caster's reads come in any size). Needs `../shared/data/rtcm`.

use std::hint::black_box;
use std::path::PathBuf;

use bytes::Bytes;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

use chassisd::config::VehicleConfig;
use chassisd::config::ntrip::NtripConfig;
use chassisd::engine::{CORRECTIONS_SOURCE, Decoder, Engine, EngineOutput, GNSS_SOURCE};
use chassisd::record::{Payload, Record};
use chassisd::time::Timestamp;

fn stream() -> Vec<u8> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/rtcm");
    let mut bytes = Vec::new();
    for file in [
        "rtklib-GMSD7_20121014.rtcm3",
        "pygnssutils-pygpsdata-rtcm3.log",
    ] {
        bytes.extend(std::fs::read(dir.join(file)).expect("../shared/data/rtcm"));
    }
    bytes
}

/// Relays `bytes` in `chunk`-byte records, one per millisecond; returns the bytes written.
fn relay(bytes: &[u8], chunk: usize) -> usize {
    let config = VehicleConfig {
        ntrip: Some(NtripConfig::with_url("ntrip://u:p@127.0.0.1:2101/M")),
        ..VehicleConfig::default()
    };
    let mut engine = Engine::new(&config, &[(GNSS_SOURCE.into(), Decoder::Nmea)]);
    let mut out = Vec::new();
    let mut written = 0;
    for (i, piece) in bytes.chunks(chunk).enumerate() {
        let record = Record {
            t: Timestamp::from_micros(i as u64 * 1000),
            source: CORRECTIONS_SOURCE.into(),
            payload: Payload::Serial(Bytes::copy_from_slice(piece)),
        };
        engine.handle(&record, &mut out);
        for o in out.drain(..) {
            if let EngineOutput::SerialTx { bytes, .. } = o {
                written += bytes.len();
            }
        }
    }
    written
}

fn corrections(c: &mut Criterion) {
    let bytes = stream();
    let mut group = c.benchmark_group("rtcm_relay");
    group.throughput(Throughput::Bytes(bytes.len() as u64));
    group.sample_size(10);
    for chunk in [1, 64, 1024, 16 * 1024] {
        group.bench_with_input(BenchmarkId::from_parameter(chunk), &chunk, |b, &chunk| {
            b.iter(|| black_box(relay(&bytes, chunk)));
        });
    }
    group.finish();
}

criterion_group!(benches, corrections);
criterion_main!(benches);
