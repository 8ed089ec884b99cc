//! The recording format: what the writer writes, the reader reads back exactly, merged in
//! time order; CAN files are plain `candump -L`; malformed lines are skipped and reported.

use crate::common;

use std::path::Path;

use bytes::Bytes;
use chassisd::record::{Payload, Record, RecordingReader, RecordingWriter, SourceKind, SourceMeta};
use chassisd::time::Timestamp;
use chassisd::vehicle::LinkState;
use socketcan::{CanAnyFrame, CanDataFrame, CanRemoteFrame, EmbeddedFrame, ExtendedId, StandardId};

fn sources() -> Vec<SourceMeta> {
    vec![
        SourceMeta {
            name: "gnss".into(),
            kind: SourceKind::Serial,
            file: "gnss.log".into(),
            protocol: Some("nmea0183".into()),
            events: None,
        },
        SourceMeta {
            name: "can0".into(),
            kind: SourceKind::Can,
            file: "can0.log".into(),
            protocol: None,
            events: None,
        },
        SourceMeta {
            name: "mqtt".into(),
            kind: SourceKind::Commands,
            file: "commands.log".into(),
            protocol: None,
            events: None,
        },
    ]
}

fn at(us: u64) -> Timestamp {
    Timestamp::from_micros(us)
}

/// A comparable rendering of a record.
fn render(r: &Record) -> String {
    let payload = match &r.payload {
        Payload::Serial(b) => format!("serial {b:?}"),
        Payload::Link(s) => format!("link {s:?}"),
        Payload::Can(f) => format!("can {f:X}"),
        Payload::CanTx(f) => format!("can-tx {f:X}"),
        Payload::Command { topic, payload } => format!("cmd {topic:?} {payload:?}"),
    };
    format!("{} {} {payload}", r.t, r.source)
}

fn records() -> Vec<Record> {
    let data = CanDataFrame::new(StandardId::new(0x701).unwrap(), &[0x05]).unwrap();
    let ext = CanDataFrame::new(
        ExtendedId::new(0x1890_4001).unwrap(),
        &[1, 2, 3, 4, 5, 6, 7, 8],
    )
    .unwrap();
    let remote = CanRemoteFrame::new_remote(StandardId::new(0x181).unwrap(), 4).unwrap();
    vec![
        Record {
            t: at(1_700_000_000_000_001),
            source: "gnss".into(),
            payload: Payload::Link(LinkState::Up),
        },
        Record {
            t: at(1_700_000_000_000_010),
            source: "gnss".into(),
            payload: Payload::Serial(Bytes::from_static(b"\xb5\x62\x00$GPGGA,1*\r\n")),
        },
        Record {
            t: at(1_700_000_000_000_010),
            source: "can0".into(),
            payload: Payload::Can(CanAnyFrame::Normal(data)),
        },
        Record {
            t: at(1_700_000_000_500_000),
            source: "can0".into(),
            payload: Payload::Can(CanAnyFrame::Normal(ext)),
        },
        Record {
            t: at(1_700_000_000_550_000),
            source: "can0".into(),
            payload: Payload::Link(LinkState::Down),
        },
        Record {
            t: at(1_700_000_000_560_000),
            source: "can0".into(),
            payload: Payload::Link(LinkState::Up),
        },
        Record {
            t: at(1_700_000_000_600_000),
            source: "can0".into(),
            payload: Payload::Can(CanAnyFrame::Remote(remote)),
        },
        Record {
            t: at(1_700_000_000_650_000),
            source: "mqtt".into(),
            payload: Payload::Link(LinkState::Up),
        },
        Record {
            t: at(1_700_000_000_700_000),
            source: "mqtt".into(),
            payload: Payload::Command {
                topic: "/root/robot 1/cmd#x".into(),
                payload: Bytes::from_static(br#"{"messageType":"DRIVE"}"#),
            },
        },
        Record {
            t: at(1_700_000_000_800_000),
            source: "mqtt".into(),
            payload: Payload::Link(LinkState::Down),
        },
        Record {
            t: at(1_700_000_001_000_000),
            source: "gnss".into(),
            payload: Payload::Link(LinkState::Down),
        },
    ]
}

fn write(dir: &Path, records: &[Record]) {
    let mut w = RecordingWriter::create(
        dir,
        "test-vehicle",
        at(1_700_000_000_000_000),
        Some("[vehicle]\nname = \"test-vehicle\"\n"),
        sources(),
    )
    .unwrap();
    for r in records {
        w.write(r).unwrap();
    }
    w.finish(at(1_700_000_002_000_000)).unwrap();
}

#[test]
fn writes_and_reads_back_in_time_order() {
    let dir = common::tempdir("rec-roundtrip");
    let records = records();
    // Written source by source, out of global order, as separate driver tasks would.
    let mut shuffled = records.clone();
    shuffled.sort_by_key(|r| r.source.clone());
    write(&dir, &shuffled);

    let (meta, reader) = RecordingReader::open(&dir).unwrap();
    assert_eq!(meta.start_us, Some(1_700_000_000_000_000));
    assert_eq!(meta.end_us, Some(1_700_000_002_000_000));
    assert_eq!(meta.vehicle_config.as_deref(), Some("vehicle.toml"));
    let back: Vec<String> = reader.map(|r| render(&r)).collect();
    // Equal times: can0 sorts before gnss.
    let mut want: Vec<String> = records.iter().map(render).collect();
    want.swap(1, 2);
    assert_eq!(back, want);
}

#[test]
fn can_files_are_candump_lines() {
    let dir = common::tempdir("rec-candump");
    write(&dir, &records());
    let text = std::fs::read_to_string(dir.join("can0.log")).unwrap();
    assert_eq!(
        text,
        "(1700000000.000010) can0 701#05\n\
         (1700000000.500000) can0 18904001#0102030405060708\n\
         (1700000000.600000) can0 181#R4\n"
    );
    // Link events of a CAN source live beside its candump file, which canplayer must read.
    let events = std::fs::read_to_string(dir.join("can0.events.log")).unwrap();
    assert_eq!(
        events,
        "(1700000000.550000) can0 !link-down\n\
         (1700000000.560000) can0 !link-up\n"
    );
    let meta = std::fs::read_to_string(dir.join("meta.toml")).unwrap();
    assert!(meta.contains("events = \"can0.events.log\""), "{meta}");
    let serial = std::fs::read_to_string(dir.join("gnss.log")).unwrap();
    assert_eq!(
        serial,
        "(1700000000.000001) gnss !link-up\n\
         (1700000000.000010) gnss B562002447504747412C312A0D0A\n\
         (1700000001.000000) gnss !link-down\n"
    );
    let commands = std::fs::read_to_string(dir.join("commands.log")).unwrap();
    let lines: Vec<&str> = commands.lines().collect();
    assert_eq!(lines.len(), 3, "{commands}");
    assert_eq!(lines[0], "(1700000000.650000) mqtt !link-up");
    assert!(
        lines[1].starts_with("(1700000000.700000) mqtt /root/robot%201/cmd%23x#7B22"),
        "{commands}"
    );
    assert_eq!(lines[2], "(1700000000.800000) mqtt !link-down");
}

#[test]
fn malformed_lines_are_skipped_and_reported() {
    let dir = common::tempdir("rec-malformed");
    write(&dir, &records());
    let path = dir.join("gnss.log");
    let mut text = std::fs::read_to_string(&path).unwrap();
    text.insert_str(
        0,
        "(12.5) gnss 00\nnot a line\n(1700000000.000005) gnss 0G\n\n",
    );
    std::fs::write(&path, text).unwrap();
    let can = dir.join("can0.log");
    let mut text = std::fs::read_to_string(&can).unwrap();
    text.push_str("(1700000003.000000) can0 7FF#0102030405060708090A\n");
    std::fs::write(&can, text).unwrap();

    let events = dir.join("can0.events.log");
    let mut text = std::fs::read_to_string(&events).unwrap();
    text.push_str("(1700000003.000000) can0 7FF#01\n");
    std::fs::write(&events, text).unwrap();

    let (_, mut reader) = RecordingReader::open(&dir).unwrap();
    let count = reader.by_ref().count();
    assert_eq!(count, records().len());
    let (skipped, total) = reader.skipped();
    assert_eq!(total, 5);
    assert!(skipped.iter().any(|s| s.file == "can0.events.log"));
    let lines: Vec<(String, u64)> = skipped.iter().map(|s| (s.file.clone(), s.line)).collect();
    assert!(lines.contains(&("gnss.log".into(), 1)));
    assert!(lines.contains(&("gnss.log".into(), 2)));
    assert!(lines.contains(&("gnss.log".into(), 3)));
    assert!(lines.iter().any(|(f, _)| f == "can0.log"));
}

#[test]
fn refuses_to_overwrite_a_recording() {
    let dir = common::tempdir("rec-exists");
    write(&dir, &records());
    let again = RecordingWriter::create(&dir, "v", at(0), None, sources());
    assert!(again.is_err());
}

#[test]
fn meta_with_bad_paths_is_rejected() {
    let dir = common::tempdir("rec-badmeta");
    write(&dir, &records());
    let meta = std::fs::read_to_string(dir.join("meta.toml")).unwrap();
    std::fs::write(
        dir.join("meta.toml"),
        meta.replace("\"can0.log\"", "\"../can0.log\""),
    )
    .unwrap();
    let err = RecordingReader::open(&dir).err().expect("rejected");
    assert!(err.to_string().contains("source.file"), "{err}");
}
