//! The fuzzing campaign (stable toolchain): a mutation loop over every parser that takes
//! outside bytes. Each target starts from a seed corpus of real bytes (the fixtures, the
//! shipped device files, `../shared/data` and the protocol documents), mutates them (bit and
//! byte changes, cuts, copies, splices, protocol tokens, extreme numbers), and keeps an input
//! in its corpus when it makes the parser behave in a way not seen before (a new signature
//! of its counters and outcome). A panic is caught, counted, and its input saved under
//! `fuzz/crashes/` to become a regression test.
//!
//! cargo run --release --example fuzz -- [--seconds S | --inputs N] [--jobs J] [--seed K] [TARGET...]
//! cargo run --release --example fuzz -- --replay DIR
//!
//! Without targets it runs all of them; the last line is JSON with the figures per target.
//! `--replay DIR` runs each `TARGET-*.bin` of DIR once through its target (the regression
//! inputs in `fuzz/regressions/`, where a fixed crash's input goes) and fails on a panic.

use std::collections::{HashMap, HashSet};
use std::hash::{DefaultHasher, Hash, Hasher};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use bytes::Bytes;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use chassisd::api::mqtt::MQTT_SOURCE;
use chassisd::api::trajectory::MemoryStore;
use chassisd::config::VehicleConfig;
use chassisd::config::calibration::CalibrationFile;
use chassisd::config::imu::ImuProtocol;
use chassisd::config::mqtt::{
    DeviceDialectConfig, MqttConfig, RootDialectConfig, RtkDialectConfig,
};
use chassisd::devices::bms::profile::BmsProfile;
use chassisd::devices::can::{Frame, Received};
use chassisd::devices::cia402::profile::DriveProfile;
use chassisd::devices::gnss::GnssReceiver;
use chassisd::devices::imu::ImuDecoder;
use chassisd::devices::imu::{hipnuc::HiPnuc, witmotion::WitMotion};
use chassisd::engine::EngineOutput;
use chassisd::engine::drivetrain::Drivetrain;
use chassisd::geodesy::{Enu, Geodetic};
use chassisd::record::meta::Meta;
use chassisd::record::reader::parse_line;
use chassisd::record::{Payload, Record, RecordingReader, SourceKind};
use chassisd::sim::lockstep::{Lockstep, Sink, vehicle_config};
use chassisd::sim::plant::{GnssCondition, PlantConfig};
use chassisd::time::Timestamp;
use chassisd::zones::ZoneSet;
use chassisd::zones::local::LocalZones;

#[path = "../tests/common/spec.rs"]
mod spec;

#[path = "fuzz/ubx.rs"]
mod ubx;

/// Longest input a mutation makes.
const MAX_INPUT: usize = 8192;
/// Inputs kept per target's corpus (seeds included).
const MAX_CORPUS: usize = 4096;
/// Signatures remembered per target.
const MAX_SIGNATURES: usize = 1 << 16;
/// An input slower than this is reported (a hang in the making).
const SLOW: Duration = Duration::from_millis(200);

/// Feeds one input and returns a signature of what happened.
type Runner = Box<dyn FnMut(&[u8]) -> u64>;

/// One parser under test: its seeds, its tokens, and a runner made once per job.
struct Target {
    name: &'static str,
    about: &'static str,
    seeds: fn() -> Vec<Vec<u8>>,
    tokens: &'static [&'static [u8]],
    /// A mutation that knows the input's structure, used for half of the inputs.
    structured: Option<fn(&mut ChaCha8Rng, &mut Vec<u8>)>,
    /// Makes the runner: it feeds one input and returns a signature of what happened.
    runner: fn() -> Runner,
}

fn targets() -> Vec<Target> {
    vec![
        Target {
            name: "nmea",
            about: "NMEA framer, sentence decoders and fix assembly (GnssReceiver)",
            seeds: nmea_seeds,
            tokens: NMEA_TOKENS,
            structured: None,
            runner: nmea_runner,
        },
        Target {
            name: "ubx",
            about: "u-blox UBX frames in a mixed stream: framer (every byte accounted for), decoders, fix assembly",
            seeds: ubx::stream_seeds,
            tokens: ubx::TOKENS,
            structured: Some(ubx::mutate_frames),
            runner: ubx::stream_runner,
        },
        Target {
            name: "ubx-messages",
            about: "each UBX decoder on any payload (class, id, payload; past the checksum) and the fix assembly",
            seeds: ubx::message_seeds,
            tokens: ubx::TOKENS,
            structured: None,
            runner: ubx::message_runner,
        },
        Target {
            name: "witmotion",
            about: "WitMotion 0x55 framer and decoder",
            seeds: || imu_seeds(ImuProtocol::Witmotion),
            tokens: &[b"\x55\x51", b"\x55\x52", b"\x55\x53", b"\x55\x59", b"\x55"],
            structured: None,
            runner: || imu_runner(ImuProtocol::Witmotion),
        },
        Target {
            name: "hipnuc",
            about: "HiPNUC 0x5A 0xA5 framer (CRC-16) and decoder",
            seeds: || imu_seeds(ImuProtocol::Hipnuc),
            tokens: &[b"\x5a\xa5", b"\x91", b"\x00\x00", b"\xff\xff"],
            structured: None,
            runner: || imu_runner(ImuProtocol::Hipnuc),
        },
        Target {
            name: "candump",
            about: "candump -L reader of the recording's CAN files",
            seeds: candump_seeds,
            tokens: &[b"(", b")", b"#", b"##", b"R", b" T", b"\n", b"vcan0 ", b"."],
            structured: None,
            runner: candump_runner,
        },
        Target {
            name: "recording",
            about: "recording envelope lines (serial, commands, CAN events) and meta.toml",
            seeds: recording_seeds,
            tokens: &[
                b"(",
                b")",
                b"#",
                b"!link-up",
                b"!link-down",
                b"\\",
                b"%",
                b"\n",
            ],
            structured: None,
            runner: recording_runner,
        },
        Target {
            name: "config",
            about: "vehicle configuration loader (profiles and TLS files named by it)",
            seeds: config_seeds,
            tokens: TOML_TOKENS,
            structured: None,
            runner: config_runner,
        },
        Target {
            name: "profiles",
            about: "CiA 402 drive, BMS and e-stop profile loaders, the plant and calibration files",
            seeds: profile_seeds,
            tokens: TOML_TOKENS,
            structured: None,
            runner: profile_runner,
        },
        Target {
            name: "dbc",
            about: "DBC loader and its BMS mapping",
            seeds: dbc_seeds,
            tokens: &[
                b"BO_ ", b"SG_ ", b" : ", b"@1+", b"@0-", b"|", b"(", b")", b"[", b"]", b"\"",
                b"\n",
            ],
            structured: None,
            runner: dbc_runner,
        },
        Target {
            name: "dialects",
            about: "MQTT payloads of the rtk, root and device dialects, through the engine",
            seeds: dialect_seeds,
            tokens: JSON_TOKENS,
            structured: Some(mutate_json_command),
            runner: dialect_runner,
        },
        Target {
            name: "canopen",
            about: "CAN frames into the drive train: NMT, SDO, PDO, EMCY, heartbeat, Daly BMS, e-stop",
            seeds: canopen_seeds,
            tokens: &[
                b"\x81\x00",
                b"\x01\x07",
                b"\x02\x07",
                b"\x81\x01",
                b"\x82\x01",
                b"\x81\x05",
                b"\x18\x00",
            ],
            structured: None,
            runner: canopen_runner,
        },
        Target {
            name: "rosbridge",
            about: "rosbridge v2 operations of WebSocket clients; /cmd_vel and /goal_pose into the engine",
            seeds: rosbridge_seeds,
            tokens: JSON_TOKENS,
            structured: Some(mutate_json_document),
            runner: rosbridge_runner,
        },
        Target {
            name: "broker",
            about: "a client's TCP stream to the embedded broker: the gate's CONNECT, admission and session checks, then rumqttd's own MQTT 3.1.1 and 5 parsers on every packet the gate lets through",
            seeds: broker::seeds,
            tokens: broker::TOKENS,
            structured: Some(broker::mutate_packets),
            runner: broker::runner,
        },
        #[cfg(feature = "ros1")]
        Target {
            name: "ros1",
            about: "ROS1 wire messages the node takes (Twist, Int16, SetNaviCmd), into the engine",
            seeds: ros1::seeds,
            tokens: &[
                b"\x00\x00\x00\x00",
                b"\x01\x00\x00\x00",
                b"\x05\x00",
                b"\xff\xff\xff\x7f",
            ],
            structured: None,
            runner: ros1::runner,
        },
        #[cfg(feature = "ros2")]
        Target {
            name: "ros2",
            about: "what the ROS 2 node takes: each taken type's CDR (and a NavigateToPose goal) decoded as its process decodes it, the lines that process hands up, into the engine",
            seeds: ros2::seeds,
            tokens: &[
                b"\x00\x00\x00\x00",
                b"\x04\x00\x00\x00map\x00",
                b"\x00\x00\x00\x00\x00\x00\xf0\x3f",
                b"\xff\xff\xff\x7f",
                b"{\"kind\":\"message\",\"topic\":\"/cmd_vel\",\"msg\":",
            ],
            structured: None,
            runner: ros2::runner,
        },
        Target {
            name: "zones",
            about: "zones files (GeoJSON): the checks, writing back, placing and the distance queries",
            seeds: zones_seeds,
            tokens: &[
                b"\"Polygon\"",
                b"\"Point\"",
                b"\"LineString\"",
                b"\"keep_out\"",
                b"\"boundary\"",
                b"\"wall\"",
                b"\"radius_m\"",
                b"\"id\"",
                b"[[",
                b"]]",
                b"-180.0",
                b"90",
                b"1e308",
            ],
            structured: Some(mutate_json_document),
            runner: zones_runner,
        },
        Target {
            name: "rtcm",
            about: "RTCM 3 framer (CRC-24Q, resynchronisation), every byte accounted for",
            seeds: rtcm_seeds,
            tokens: &[
                b"\xd3",
                b"\xd3\x00",
                b"\xd3\x03\xff",
                b"\xd3\x00\x00",
                b"\x3e\xd0",
            ],
            structured: None,
            runner: rtcm_runner,
        },
        Target {
            name: "ntrip",
            about: "NTRIP caster answers: status line and head, chunked body, sourcetable",
            seeds: ntrip_seeds,
            tokens: &[
                b"ICY 200 OK\r\n",
                b"HTTP/1.1 200 OK",
                b"SOURCETABLE 200 OK\r\n",
                b"Transfer-Encoding: chunked\r\n",
                b"\r\n\r\n",
                b"\r\n",
                b"0\r\n\r\n",
                b"ffffffff\r\n",
                b"STR;",
                b";1;",
                b"ENDSOURCETABLE",
            ],
            structured: None,
            runner: ntrip_runner,
        },
    ]
}

fn zones_seeds() -> Vec<Vec<u8>> {
    let mut seeds: Vec<Vec<u8>> = std::fs::read(repo().join("devices/zones.example.geojson"))
        .into_iter()
        .collect();
    // One feature of each shape alone, and a polygon with a hole.
    seeds.push(
        br#"{"type": "Feature", "properties": {"kind": "keep_out", "radius_m": 2},
        "geometry": {"type": "Point", "coordinates": [8.5456, 47.3977]}}"#
            .to_vec(),
    );
    seeds.push(
        br#"{"type": "FeatureCollection", "features": [{"type": "Feature", "id": 9,
        "properties": {"kind": "boundary", "name": "ring"}, "geometry": {"type": "Polygon",
        "coordinates": [[[8.5450, 47.3970], [8.5470, 47.3970], [8.5470, 47.3985],
        [8.5450, 47.3985], [8.5450, 47.3970]], [[8.5455, 47.3975], [8.5458, 47.3975],
        [8.5458, 47.3977], [8.5455, 47.3975]]]}}, {"type": "Feature", "properties":
        {"kind": "wall"}, "geometry": {"type": "LineString", "coordinates": [[8.5461,
        47.3972], [8.5461, 47.3982], [8.5466, 47.3982]]}}]}"#
            .to_vec(),
    );
    seeds
}

fn zones_runner() -> Runner {
    let datum = Geodetic {
        lat_deg: 47.397742,
        lon_deg: 8.545594,
        h_m: 488.0,
    };
    let frame = Enu::new(datum);
    Box::new(move |input| {
        let text = String::from_utf8_lossy(input);
        match ZoneSet::from_geojson(&text) {
            Ok(set) => {
                // What a map frame and the plan-time check do with zones that load.
                let local = LocalZones::new(&set, |lat_deg, lon_deg| {
                    let p = frame.to_enu(&Geodetic {
                        lat_deg,
                        lon_deg,
                        h_m: datum.h_m,
                    });
                    (p.x, p.y)
                });
                let disc = local.disc_conflict((0.0, 0.0), 0.6).is_some();
                let way = [(0.0, 0.0), (40.0, 10.0), (-30.0, -5.0), (1e7, 0.0)];
                let path = local.path_conflict(&way, 0.6).is_some();
                // Zones that load write back to the same zones.
                let again = ZoneSet::from_geojson(&set.to_geojson());
                assert_eq!(
                    again.as_ref(),
                    Ok(&set),
                    "zones written back read differently"
                );
                signature(&[
                    1,
                    set.zones().len() as u64,
                    u64::from(disc),
                    u64::from(path),
                ])
            }
            Err(e) => signature(&[0, std::mem::discriminant(&e).hash_u64()]),
        }
    })
}

/// Slices of the shared RTCM 3 streams.
fn rtcm_seeds() -> Vec<Vec<u8>> {
    let mut seeds = Vec::new();
    for file in files_in(&shared().join("rtcm"), "rtcm3")
        .into_iter()
        .chain(files_in(&shared().join("rtcm"), "log"))
    {
        if let Ok(bytes) = std::fs::read(&file) {
            seeds.extend(pieces(&bytes, 2048, 20));
        }
    }
    seeds
}

fn rtcm_runner() -> Runner {
    use chassisd::devices::gnss::rtcm::{RtcmFramer, message_number};
    Box::new(|input| {
        let mut framer = RtcmFramer::new();
        let mut frames: Vec<Vec<u8>> = Vec::new();
        for piece in input.chunks(input.len() / 3 + 1) {
            framer.push(piece, |f, n| {
                assert_eq!(n, message_number(f));
                frames.push(f.to_vec());
            });
        }
        let s = framer.stats().clone();
        // Every byte is a frame's, dropped, or waiting: nothing lost, nothing invented.
        assert_eq!(
            s.frame_bytes + s.invalid_bytes + framer.pending() as u64,
            input.len() as u64
        );
        // A frame passed on is one: framed again alone, it comes out whole.
        for f in &frames {
            let mut again = RtcmFramer::new();
            let mut whole = false;
            again.push(f, |g, _| whole = g == f.as_slice());
            assert!(whole);
        }
        signature(&[
            s.frames.min(16),
            s.crc_errors.min(8),
            (s.by_type.len() as u64).min(8),
            u64::from(framer.pending() > 0),
            u64::from(s.invalid_bytes > 0),
        ])
    })
}

/// Caster answers: gpsd's NTRIP 1.0 exchange and sourcetable, and pygnssutils' chunked
/// body behind a 2.0 head (also with its malformed status line).
fn ntrip_seeds() -> Vec<Vec<u8>> {
    let dir = shared().join("rtcm");
    let from = |name: &str, marker: &[u8]| -> Vec<u8> {
        let bytes = std::fs::read(dir.join(name)).unwrap_or_default();
        let at = bytes
            .windows(marker.len())
            .position(|w| w == marker)
            .unwrap_or(0);
        bytes[at..bytes.len().min(at + 4096)].to_vec()
    };
    let chunked = std::fs::read(dir.join("pygnssutils-ntrip_chunked.bin")).unwrap_or_default();
    let body = &chunked[..chunked.len().min(4000)];
    let mut seeds = vec![
        from("gpsd-naujoks-ntrip.log", b"ICY"),
        from("gpsd-ntrip_sourcetable.log", b"SOURCETABLE"),
    ];
    for head in [
        b"HTTP/1.1 200 OK\r\nNtrip-Version: Ntrip/2.0\r\nTransfer-Encoding: chunked\r\n\r\n"
            .as_slice(),
        b"HTTP/1.1 200 OKNtrip-Version: Ntrip/2.0\r\nTransfer-Encoding: chunked\r\n\r\n",
        b"HTTP/1.1 401 Unauthorized\r\n\r\n",
    ] {
        seeds.push([head, body].concat());
    }
    seeds
}

fn ntrip_runner() -> Runner {
    use chassisd::devices::gnss::rtcm::RtcmFramer;
    use chassisd::ntrip::chunked::Dechunker;
    use chassisd::ntrip::response::{Status, parse_head};
    use chassisd::ntrip::sourcetable;
    Box::new(|input| {
        let head = match parse_head(input) {
            Ok(Some(h)) => h,
            Ok(None) => return signature(&[1]),
            Err(_) => return signature(&[2]),
        };
        assert!(head.length <= input.len());
        let body = &input[head.length..];
        let mut decoded = Vec::new();
        let mut broken = false;
        if head.chunked {
            let mut d = Dechunker::new();
            for piece in body.chunks(body.len() / 2 + 1) {
                if d.push(piece, &mut decoded).is_err() {
                    broken = true;
                    break;
                }
            }
            // The body never grows in decoding.
            assert!(decoded.len() <= body.len());
        } else {
            decoded.extend_from_slice(body);
        }
        let (mut frames, mut streams) = (0u64, 0u64);
        match head.status {
            Status::Sourcetable => {
                streams = sourcetable::parse(&String::from_utf8_lossy(&decoded)).len() as u64;
            }
            Status::Icy | Status::Http => {
                RtcmFramer::new().push(&decoded, |_, _| frames += 1);
            }
            Status::Error(..) => {}
        }
        let status = match head.status {
            Status::Icy => 3,
            Status::Http => 4,
            Status::Sourcetable => 5,
            Status::Error(code, _) => 6 + u64::from(code / 100),
        };
        signature(&[
            status,
            u64::from(head.chunked),
            u64::from(broken),
            frames.min(8),
            streams.min(4),
        ])
    })
}

/// The embedded broker's input: the bytes one client sends after its TCP handshake.
mod broker {
    use super::*;
    use bytes::BytesMut;
    use chassisd::broker::admission::{self, Credentials, Places, Policy};
    use chassisd::broker::held::Held;
    use chassisd::broker::session::{Pass, Session};
    use chassisd::broker::wire::{self, Version};
    use rumqttd::protocol::Protocol;

    /// The gate's packet limit in the fuzzed broker (small, so that limits are met).
    const MAX_PACKET: usize = 4096;
    const USER: &str = "operator";
    const PASSWORD: &str = "s3cret";

    pub const TOKENS: &[&[u8]] = &[
        b"\x10",
        b"\x20",
        b"\x30",
        b"\x32",
        b"\x34",
        b"\x3b",
        b"\x62",
        b"\x82",
        b"\xa2",
        b"\xc0\x00",
        b"\xe0\x00",
        b"\xf0",
        b"\x00\x04MQTT\x04",
        b"\x00\x04MQTT\x05",
        b"\x00\x06MQIsdp\x03",
        b"$share/g/",
        b"#",
        b"+",
        b"/",
        b"\xff\xff\xff\x7f",
        b"\x80\x80\x80\x80",
        b"\x00\x00",
        b"\xff\xff",
        b"\x26\x00\x01k\x00\x01v",
    ];

    fn packet(first: u8, body: &[u8]) -> Vec<u8> {
        wire::packet(first, body)
    }

    fn string(s: &[u8], out: &mut Vec<u8>) {
        out.extend_from_slice(&(s.len() as u16).to_be_bytes());
        out.extend_from_slice(s);
    }

    fn connect(level: u8, id: &str, credentials: bool, will: bool) -> Vec<u8> {
        let mut b = Vec::new();
        string(b"MQTT", &mut b);
        b.push(level);
        b.push(0x02 | if credentials { 0xc0 } else { 0 } | if will { 0x2c } else { 0 });
        b.extend_from_slice(&30u16.to_be_bytes());
        if level == 5 {
            // Session expiry 10 s.
            b.extend_from_slice(&[5, 0x11, 0, 0, 0, 10]);
        }
        string(id.as_bytes(), &mut b);
        if will {
            if level == 5 {
                b.extend_from_slice(&[5, 0x18, 0, 0, 0, 2]);
            }
            string(b"chassisd/will", &mut b);
            string(b"gone", &mut b);
        }
        if credentials {
            string(USER.as_bytes(), &mut b);
            string(PASSWORD.as_bytes(), &mut b);
        }
        packet(0x10, &b)
    }

    /// The packets of a session after CONNECT, in the version of `level`.
    fn session(level: u8) -> Vec<u8> {
        let props = |b: &mut Vec<u8>| {
            if level == 5 {
                b.push(0);
            }
        };
        let mut out = Vec::new();
        // SUBSCRIBE to a filter, a wildcard and a shared subscription.
        let mut b = vec![0, 1];
        props(&mut b);
        for (filter, qos) in [
            (&b"base_status"[..], 1u8),
            (b"device/+/#", 2),
            (b"$share/g/x", 0),
        ] {
            string(filter, &mut b);
            b.push(qos);
        }
        out.extend(packet(0x82, &b));
        // PUBLISH at QoS 0, 1 (retained) and 2.
        for (first, id) in [(0x30u8, None), (0x33, Some(2u16)), (0x34, Some(3))] {
            let mut b = Vec::new();
            string(b"device/SIM0001/goal", &mut b);
            if let Some(id) = id {
                b.extend_from_slice(&id.to_be_bytes());
            }
            props(&mut b);
            b.extend_from_slice(br#"{"data":{"x":1.0}}"#);
            out.extend(packet(first, &b));
        }
        // The QoS 2 flow's release, acks of the broker's deliveries, UNSUBSCRIBE, a ping.
        out.extend(packet(0x62, &[0, 3]));
        out.extend(packet(0x40, &[0, 9]));
        out.extend(packet(0x50, &[0, 10]));
        out.extend(packet(0x70, &[0, 11]));
        let mut b = vec![0, 4];
        props(&mut b);
        string(b"base_status", &mut b);
        out.extend(packet(0xa2, &b));
        out.extend([0xc0, 0x00]);
        if level == 5 {
            // AUTH with a reason and no properties, then DISCONNECT with a reason.
            out.extend(packet(0xf0, &[0x18, 0]));
            out.extend(packet(0xe0, &[0x04, 0]));
        } else {
            out.extend([0xe0, 0x00]);
        }
        out
    }

    pub fn seeds() -> Vec<Vec<u8>> {
        let mut seeds = Vec::new();
        for level in [4u8, 5] {
            for (credentials, will) in [(true, false), (true, true), (false, false)] {
                let mut s = connect(level, "fuzz-client", credentials, will);
                s.extend(session(level));
                seeds.push(s);
            }
            seeds.push(connect(level, "", true, false));
            seeds.push(connect(level, "a/b", true, false));
        }
        let mut old = Vec::new();
        string(b"MQIsdp", &mut old);
        old.extend_from_slice(&[3, 2, 0, 10, 0, 1, b'x']);
        seeds.push(packet(0x10, &old));
        seeds
    }

    /// Swaps, repeats or drops whole packets after the first, or corrupts one's length, so
    /// that mutations reach the packets rumqttd parses behind a valid CONNECT.
    pub fn mutate_packets(rng: &mut ChaCha8Rng, input: &mut Vec<u8>) {
        let mut packets = Vec::new();
        let mut at = 0;
        while let Ok(Some(h)) = wire::header(&input[at..], usize::MAX) {
            if at + h.total() > input.len() {
                break;
            }
            packets.push(input[at..at + h.total()].to_vec());
            at += h.total();
        }
        let tail = input[at..].to_vec();
        if packets.len() < 2 {
            mutate(rng, input, &[], TOKENS);
            return;
        }
        let i = rng.random_range(1..packets.len());
        match rng.random_range(0..5) {
            0 => {
                let j = rng.random_range(1..packets.len());
                packets.swap(i, j);
            }
            1 => {
                let p = packets[i].clone();
                packets.insert(i, p);
            }
            2 => {
                packets.remove(i);
            }
            3 => {
                // One byte of the packet's body changed.
                let p = &mut packets[i];
                if p.len() > 2 {
                    let k = rng.random_range(2..p.len());
                    p[k] = rng.random();
                }
            }
            _ => {
                // The remaining length claims more or less than is there.
                let p = &mut packets[i];
                if p.len() > 1 {
                    p[1] = p[1].wrapping_add(rng.random_range(1..4)) & 0x7f;
                }
            }
        }
        input.clear();
        input.extend(packets.into_iter().flatten());
        input.extend(tail);
    }

    pub fn runner() -> Runner {
        let policy = Policy {
            credentials: Some(Credentials {
                username: USER.into(),
                password: PASSWORD.into(),
            }),
            max_clients: 4,
            own_client_id: Some("chassisd-fuzz".into()),
            reserved_client_ids: vec!["chassisd".into()],
        };
        let mut names = Held::new([], MAX_PACKET);
        let mut n = 0u64;
        Box::new(move |input| {
            // The broker's names fill up over a run; a fresh broker now and then keeps the
            // limit from hiding everything behind it.
            n += 1;
            if n.is_multiple_of(50_000) {
                names = Held::new([], MAX_PACKET);
            }
            // Half the inputs meet a broker without credentials, so that sessions go on.
            let policy = match input.first() {
                Some(b) if b & 1 == 0 => policy.clone(),
                _ => Policy {
                    credentials: None,
                    ..policy.clone()
                },
            };
            let header = match wire::header(input, MAX_PACKET) {
                Ok(Some(h)) if h.kind == wire::kind::CONNECT && input.len() >= h.total() => h,
                Ok(Some(h)) => return signature(&[1, u64::from(h.kind)]),
                Ok(None) => return signature(&[2]),
                Err(e) => return signature(&[3, format!("{e:?}").len() as u64]),
            };
            let connect = match wire::connect(&input[header.header_len..header.total()]) {
                Ok(c) => c,
                Err(e) => return signature(&[4, format!("{e:?}").len() as u64]),
            };
            let mut places = Places::default();
            if let Err(why) = admission::admit(&policy, &mut places, &connect) {
                let refusal = wire::connack_refusal(connect.version, why);
                return signature(&[5, why as u64, refusal.len() as u64]);
            }
            // What the gate forwards, rumqttd parses: the CONNECT first.
            let v5 = connect.version == Version::V5;
            let mut stream = BytesMut::from(&input[..header.total()]);
            let mut parts = vec![rumqttd_parse(v5, &mut stream)];
            let mut session = Session::new(connect.version, MAX_PACKET);
            let mut at = header.total();
            loop {
                let h = match wire::header(&input[at..], MAX_PACKET) {
                    Ok(Some(h)) => h,
                    Ok(None) => break,
                    Err(_) => {
                        parts.push(100);
                        break;
                    }
                };
                if input.len() - at < h.total() {
                    break;
                }
                let packet = &input[at..at + h.total()];
                match session.from_client(&h, packet, &mut names) {
                    Ok(pass) => {
                        // The gate forwards it: rumqttd reads it.
                        let mut stream = BytesMut::from(packet);
                        parts.push(u64::from(h.kind) << 8 | rumqttd_parse(v5, &mut stream));
                        if pass == Pass::LastOne {
                            break;
                        }
                    }
                    Err(v) => {
                        parts.push(200 + format!("{v:?}").len() as u64);
                        break;
                    }
                }
                // The broker delivers what the session subscribed to: a QoS 1 and a QoS 2
                // PUBLISH and a PUBREL, so that acknowledgements can match.
                if parts.len() == 2 {
                    for delivered in [
                        &b"\x32\x05\x00\x01t\x00\x09"[..],
                        b"\x34\x05\x00\x01t\x00\x0a",
                        b"\x62\x02\x00\x0b",
                    ] {
                        if let Ok(Some(dh)) = wire::header(delivered, MAX_PACKET) {
                            session.from_broker(&dh, delivered);
                        }
                    }
                }
                at += h.total();
            }
            // The session ends with the input: what the broker held for it goes.
            session.end(&mut names);
            signature(&parts)
        })
    }

    /// rumqttd's own reading of one packet: 0 when it parsed, else a code for its error.
    fn rumqttd_parse(v5: bool, stream: &mut BytesMut) -> u64 {
        let result = if v5 {
            rumqttd::protocol::v5::V5
                .read_mut(stream, MAX_PACKET)
                .map(|p| std::mem::discriminant(&p).hash_u64())
        } else {
            rumqttd::protocol::v4::V4
                .read_mut(stream, MAX_PACKET)
                .map(|p| std::mem::discriminant(&p).hash_u64())
        };
        match result {
            Ok(kind) => kind & 0xff,
            Err(e) => 1 + (format!("{e:?}").len() as u64 & 0xff),
        }
    }
}

/// The ROS1 node's inputs: a kind byte, then the message as TCPROS carries it.
#[cfg(feature = "ros1")]
mod ros1 {
    use super::*;
    use chassisd::api::ros1 as codec;
    use chassisd::api::ros1::adapter::Ros1Request;
    use chassisd::runtime::links::ros1::messages::{geometry_msgs, map_msgs, std_msgs};
    use roslibrust_serde_rosmsg::{from_slice, to_vec};

    /// What the node subscribes to and serves, in kind-byte order.
    const KINDS: u8 = 4;

    pub fn seeds() -> Vec<Vec<u8>> {
        let with = |kind: u8, body: Vec<u8>| [vec![kind], body].concat();
        let twist = |x: f64, z: f64| geometry_msgs::Twist {
            linear: geometry_msgs::Vector3 { x, y: 0.0, z: 0.0 },
            angular: geometry_msgs::Vector3 { x: 0.0, y: 0.0, z },
        };
        let mut seeds = Vec::new();
        for (x, z) in [(0.3, 0.0), (0.0, 0.5), (0.0, 0.0), (-0.2, -0.1)] {
            seeds.push(with(0, to_vec(&twist(x, z)).unwrap_or_default()));
        }
        for data in [5i16, 1, 0, -1] {
            let int16 = to_vec(&std_msgs::Int16 { data }).unwrap_or_default();
            seeds.push(with(1, int16.clone()));
            seeds.push(with(2, int16));
        }
        for (cmd, distance) in [
            ("1", 50i64),
            ("2", 10),
            ("3", 90),
            ("4", 180),
            ("5", 0),
            ("9", -1),
        ] {
            let request = map_msgs::SetNaviCmdRequest {
                cmd: cmd.into(),
                distance,
            };
            seeds.push(with(3, to_vec(&request).unwrap_or_default()));
        }
        seeds
    }

    fn request(kind: u8, body: &[u8]) -> Option<Result<Ros1Request, String>> {
        Some(match kind % KINDS {
            0 => {
                let t: geometry_msgs::Twist = from_slice(body).ok()?;
                Ok(Ros1Request::CmdVel {
                    linear: [t.linear.x, t.linear.y, t.linear.z],
                    angular: [t.angular.x, t.angular.y, t.angular.z],
                })
            }
            1 => Ros1Request::navi_stop(from_slice::<std_msgs::Int16>(body).ok()?.data),
            2 => Ros1Request::autocharge(from_slice::<std_msgs::Int16>(body).ok()?.data),
            _ => {
                let r: map_msgs::SetNaviCmdRequest = from_slice(body).ok()?;
                Ok(Ros1Request::SetNaviCmd {
                    cmd: r.cmd,
                    distance: r.distance,
                })
            }
        })
    }

    pub fn runner() -> Runner {
        let fresh = || simulated_vehicle(5, None);
        let mut sim = fresh();
        let mut n = 0u64;
        Box::new(move |input| {
            n += 1;
            if n.is_multiple_of(2000) {
                sim = fresh();
            }
            let Some((&kind, body)) = input.split_first() else {
                return 0;
            };
            let outcome = match request(kind, body) {
                None => 0,
                Some(Err(_)) => 1,
                Some(Ok(r)) => {
                    let mut sink = Collect::default();
                    sim.input(
                        codec::SOURCE,
                        Payload::Command {
                            topic: r.name().into(),
                            payload: r.encode(Some(n)),
                        },
                        &mut sink,
                    );
                    settle(&mut sim, n, &mut sink);
                    2 + sink.outputs.min(8)
                }
            };
            signature(&[u64::from(kind % KINDS), outcome])
        })
    }
}

#[cfg(feature = "ros2")]
mod ros2 {
    use super::*;
    use chassisd::api::ros2::topics::TAKEN;
    use chassisd::api::ros2::{self as api, NAVIGATE_TO_POSE, adapter};
    use chassisd::runtime::links::ros2::messages::{cdr, decode};
    use chassisd::runtime::links::ros2::pipe::FromNode;
    use serde_json::json;

    /// The goal's type, after the taken topics' in kind-byte order; then a line of the
    /// node's process.
    const GOAL: &str = "nav2_msgs/msg/NavigateToPoseGoal";

    fn kinds() -> u8 {
        TAKEN.len() as u8 + 2
    }

    pub fn seeds() -> Vec<Vec<u8>> {
        let header = json!({"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "map"});
        let twist = json!({"linear": {"x": 0.3, "y": 0.0, "z": 0.0},
                           "angular": {"x": 0.0, "y": 0.0, "z": 0.2}});
        let pose = json!({"position": {"x": 1.0, "y": 2.0, "z": 0.0},
                          "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}});
        let mut messages = vec![
            twist.clone(),
            json!({"header": header, "twist": twist}),
            json!({"header": header, "pose": pose}),
            json!({"header": header, "pose": {"pose": pose, "covariance": vec![0.0; 36]}}),
            json!({"pose": {"header": header, "pose": pose}, "behavior_tree": ""}),
        ];
        let types = TAKEN.iter().map(|t| t.msg_type).chain([GOAL]);
        let mut seeds: Vec<Vec<u8>> = types
            .zip(messages.iter())
            .enumerate()
            .map(|(kind, (msg_type, msg))| {
                [vec![kind as u8], cdr(msg_type, msg).unwrap_or_default()].concat()
            })
            .collect();
        let line = FromNode::Message {
            topic: "/cmd_vel".into(),
            msg: messages.swap_remove(0),
        };
        seeds.push(
            [
                vec![kinds() - 1],
                serde_json::to_vec(&line).unwrap_or_default(),
            ]
            .concat(),
        );
        seeds
    }

    /// The record (topic, message) an input makes, as the node's process and its parent
    /// would hand it on; `None` where they would drop it.
    fn taken(kind: u8, body: &[u8]) -> Option<(String, serde_json::Value)> {
        let kind = usize::from(kind % kinds());
        if let Some(t) = TAKEN.get(kind) {
            return decode(t.msg_type, body)
                .ok()
                .map(|m| (t.name.to_owned(), m));
        }
        if kind == TAKEN.len() {
            return decode(GOAL, body)
                .ok()
                .map(|m| (NAVIGATE_TO_POSE.to_owned(), m));
        }
        match serde_json::from_slice::<FromNode>(body).ok()? {
            FromNode::Message { topic, msg } => Some((topic, msg)),
            FromNode::Goal { msg, .. } => Some((NAVIGATE_TO_POSE.to_owned(), msg)),
            FromNode::Ready | FromNode::Cancel { .. } => None,
        }
    }

    pub fn runner() -> Runner {
        let fresh = || simulated_vehicle(5, None);
        let mut sim = fresh();
        let mut n = 0u64;
        Box::new(move |input| {
            n += 1;
            if n.is_multiple_of(2000) {
                sim = fresh();
            }
            let Some((&kind, body)) = input.split_first() else {
                return 0;
            };
            let outcome = match taken(kind, body) {
                None => 0,
                Some((topic, msg)) => {
                    let mut sink = Collect::default();
                    sim.input(
                        api::SOURCE,
                        Payload::Command {
                            topic,
                            payload: adapter::encode(Some(n), &msg),
                        },
                        &mut sink,
                    );
                    settle(&mut sim, n, &mut sink);
                    1 + sink.outputs.min(8)
                }
            };
            signature(&[u64::from(kind % kinds()), outcome])
        })
    }
}

const NMEA_TOKENS: &[&[u8]] = &[
    b"$GPGGA,", b"$GNRMC,", b"$GPVTG,", b"$GPGST,", b"$GNGNS,", b"$GPHDT,", b"$GPZDA,", b"$PSTI,",
    b"$GPTHS,", b"*", b"\r\n", b",,", b",A,", b",N,", b",E,", b"-", b".",
];
const TOML_TOKENS: &[&[u8]] = &[
    b"[", b"]", b"[[", b"]]", b" = ", b"\"", b"'''", b"\n", b"true", b"-1", b"1e308", b"nan",
    b"inf", b"{", b"}", b",", b"#",
];
const JSON_TOKENS: &[&[u8]] = &[
    b"{",
    b"}",
    b"[",
    b"]",
    b"\"",
    b":",
    b",",
    b"null",
    b"true",
    b"-1",
    b"1e308",
    b"-1e308",
    b"18446744073709551616",
    b"\"cmd\"",
    b"\"data\"",
    b"\"messageType\"",
    b"\\u0000",
];
/// Numbers that break arithmetic, put in place of a number.
const NUMBERS: &[&[u8]] = &[
    b"0",
    b"-0",
    b"-1",
    b"1e308",
    b"-1e308",
    b"NaN",
    b"inf",
    b"4294967296",
    b"9223372036854775808",
    b"99999999999999999999999",
    b"0.0000000001",
    b"255",
    b"65535",
    b"-32768",
];

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn shared() -> PathBuf {
    std::env::var_os("CHASSISD_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("../shared/data"))
}

fn files_in(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    files.retain(|p| p.extension().is_some_and(|e| e == ext));
    files.sort();
    files
}

/// `bytes` cut into pieces of about `size`, at most `n` of them, spread over the whole.
fn pieces(bytes: &[u8], size: usize, n: usize) -> Vec<Vec<u8>> {
    if bytes.is_empty() {
        return Vec::new();
    }
    let count = bytes.len().div_ceil(size);
    let step = count.div_ceil(n).max(1);
    (0..count)
        .step_by(step)
        .map(|i| bytes[i * size..((i + 1) * size).min(bytes.len())].to_vec())
        .collect()
}

fn signature(parts: &[u64]) -> u64 {
    let mut h = DefaultHasher::new();
    parts.hash(&mut h);
    h.finish()
}

// ---- targets -------------------------------------------------------------------------------

/// The vendors' sentences no shared log holds, as their documents quote them.
const VENDOR_SENTENCES: &[&str] = &[
    "$PTNL,AVR,181059.6,+149.4688,Yaw,+0.0134,Tilt,,,60.191,3,2.5,6*00\r\n",
    "$PSSN,HRP,142657.80,061222,152.236,,-0.708,0.084,,0.181,21,2,2.400,E*23\r\n",
    "$PASHR,183944.821,74.52,T,-1.63,1.51,0.14,0.020,0.020,0.012,2,1*05\r\n",
    "$KSXT,20211016083433.00,116.31296102,39.95817066,49.4911,223.57,-11.32,330.19,0.024,,1,3,28,27,,,,-0.012,0.021,0.020,,*2D\r\n",
    "#UNIHEADINGA,79,GPS,FINE,2242,167498200,0,0,18,22;SOL_COMPUTED,L1_INT,2.7889,296.7233,-25.7710,0.0000,0.1127,0.1812,\"999\",49,37,37,0,3,00,1,51*d50af0ea\r\n",
    "$GNGNS,014035.00,4332.69262,S,17235.48549,E,RR,13,0.9,25.63,11.24,,,U*09\r\n$GPGNS,014035.00,,,,,,8,,,,1.0,23*76\r\n",
];

fn nmea_seeds() -> Vec<Vec<u8>> {
    let mut seeds: Vec<Vec<u8>> = VENDOR_SENTENCES
        .iter()
        .map(|s| s.as_bytes().to_vec())
        .collect();
    for log in files_in(&shared().join("gnss"), "log") {
        if let Ok(bytes) = std::fs::read(&log) {
            seeds.extend(pieces(&bytes, 1024, 40));
        }
    }
    seeds
}

fn nmea_runner() -> Runner {
    Box::new(|input| {
        let mut receiver = GnssReceiver::new();
        let mut fixes = 0u64;
        // Two chunks: a sentence split across reads is the framer's daily work.
        let cut = input.len() / 2;
        receiver.push(Timestamp::default(), &input[..cut], |_| fixes += 1);
        receiver.push(Timestamp::from_micros(500_000), &input[cut..], |_| {
            fixes += 1
        });
        let s = receiver.stats();
        let f = s.framer;
        signature(&[
            fixes.min(8),
            f.sentences.min(16),
            f.checksum_errors.min(4),
            f.missing_checksum.min(4),
            f.truncated.min(4),
            f.overlong.min(4),
            f.ubx_frames.min(8),
            s.sentences_by_kind.len() as u64,
            s.decode_errors.min(4),
        ])
    })
}

/// IMU bytes from the simulator's plant speaking `protocol`.
fn imu_seeds(protocol: ImuProtocol) -> Vec<Vec<u8>> {
    let Ok(mut plant) = PlantConfig::builtin() else {
        return Vec::new();
    };
    plant.imu.protocol = protocol;
    let Ok(mut sim) = Lockstep::new(plant, 7, Timestamp::from_micros(1_000_000)) else {
        return Vec::new();
    };
    let mut sink = Collect::default();
    let gnss = GnssCondition {
        quality: None,
        offset: (0.0, 0.0),
    };
    for _ in 0..500 {
        sim.step(gnss, &mut sink);
    }
    let bytes: Vec<u8> = sink
        .records
        .iter()
        .filter(|r| r.source == "imu")
        .filter_map(|r| match &r.payload {
            Payload::Serial(b) => Some(b.to_vec()),
            _ => None,
        })
        .flatten()
        .collect();
    eprintln!(
        "fuzz: {} bytes of {protocol:?} from the simulator",
        bytes.len()
    );
    pieces(&bytes, 128, 64)
}

fn imu_runner(protocol: ImuProtocol) -> Runner {
    Box::new(move |input| {
        let mut decoder = match protocol {
            ImuProtocol::Witmotion => ImuDecoder::WitMotion(WitMotion::new()),
            ImuProtocol::Hipnuc => ImuDecoder::HiPnuc(HiPnuc::new()),
        };
        let mut plausible = 0u64;
        let cut = input.len() / 3;
        decoder.push(Timestamp::default(), &input[..cut], |s| {
            plausible += u64::from(s.is_plausible())
        });
        decoder.push(Timestamp::from_micros(10_000), &input[cut..], |s| {
            plausible += u64::from(s.is_plausible())
        });
        let s = decoder.stats();
        signature(&[
            s.frames.min(16),
            s.checksum_errors.min(4),
            s.samples.min(16),
            plausible.min(16),
            (s.bytes_skipped > 0) as u64,
        ])
    })
}

#[derive(Default)]
struct Collect {
    records: Vec<Record>,
    outputs: u64,
    /// What the replies said, numbers left out: a new error text is a new behaviour.
    replies: u64,
}

impl Sink for Collect {
    fn record(&mut self, record: &Record) {
        if self.records.len() < 100_000 {
            self.records.push(record.clone());
        }
    }

    fn output(&mut self, output: EngineOutput) {
        self.outputs += 1;
        if let EngineOutput::Publish(p) = output {
            let text: Vec<u8> = p
                .payload
                .iter()
                .copied()
                .filter(|b| !b.is_ascii_digit())
                .collect();
            self.replies = self.replies.rotate_left(7) ^ (p.topic.as_str(), text).hash_u64();
        }
    }
}

fn fixture_files(name: &str) -> Vec<Vec<u8>> {
    ["rtk-drive", "can-drive", "sim-drive"]
        .iter()
        .filter_map(|f| std::fs::read(repo().join("fixtures").join(f).join(name)).ok())
        .collect()
}

fn candump_seeds() -> Vec<Vec<u8>> {
    let mut seeds = Vec::new();
    for name in ["can0.log", "vcan0.log", "sim0.log"] {
        for bytes in fixture_files(name) {
            seeds.extend(pieces(&bytes, 512, 30));
        }
    }
    seeds
}

fn candump_runner() -> Runner {
    Box::new(|input| {
        let mut reader = socketcan::dump::Reader::from_reader(input);
        let (mut ok, mut bad) = (0u64, 0u64);
        // The recording reader's loop: a parse error skips the line, the end stops.
        for _ in 0..10_000 {
            match reader.next_record() {
                Ok(Some(_)) => ok += 1,
                Ok(None) => break,
                Err(socketcan::dump::ParseError::Io(_)) => break,
                Err(_) => bad += 1,
            }
        }
        signature(&[ok.min(16), bad.min(16)])
    })
}

fn recording_seeds() -> Vec<Vec<u8>> {
    let mut seeds = Vec::new();
    for name in [
        "commands.log",
        "gnss.log",
        "imu.log",
        "mqtt.log",
        "host.log",
        "process.log",
        "sim0.events.log",
        "vcan0.events.log",
        "meta.toml",
    ] {
        for bytes in fixture_files(name) {
            seeds.extend(pieces(&bytes, 400, 12));
        }
    }
    seeds
}

fn recording_runner() -> Runner {
    Box::new(|input| {
        let text = String::from_utf8_lossy(input);
        let mut parts = Vec::new();
        for kind in [SourceKind::Serial, SourceKind::Commands, SourceKind::Can] {
            let (mut ok, mut bad) = (0u64, 0u64);
            for line in text.lines() {
                match parse_line(kind, line) {
                    Ok(_) => ok += 1,
                    Err(_) => bad += 1,
                }
            }
            parts.extend([ok.min(8), bad.min(8)]);
        }
        let meta = toml::from_str::<Meta>(&text).map(|m| m.check().is_ok());
        parts.push(match meta {
            Ok(true) => 2,
            Ok(false) => 1,
            Err(_) => 0,
        });
        // The reader that merges the files, on records rebuilt from what parsed.
        let records: Vec<Record> = text
            .lines()
            .filter_map(|l| parse_line(SourceKind::Commands, l).ok())
            .collect();
        parts.push(RecordingReader::from_records(records).count().min(8) as u64);
        signature(&parts)
    })
}

fn config_seeds() -> Vec<Vec<u8>> {
    let mut seeds = fixture_files("vehicle.toml");
    seeds.extend(std::fs::read(repo().join("devices/vehicle.example.toml")));
    for dir in ["tests/vm"] {
        for file in files_in(&repo().join(dir), "toml") {
            seeds.extend(std::fs::read(file));
        }
    }
    seeds
}

fn config_runner() -> Runner {
    // Profiles named by the configuration are found beside the shipped examples.
    let file = repo().join("devices/fuzzed.toml");
    Box::new(move |input| {
        let text = String::from_utf8_lossy(input);
        match VehicleConfig::from_toml(&text, &file) {
            Ok(config) => {
                // A configuration that loads also starts a drive train.
                let mut drivetrain = Drivetrain::new(&config);
                signature(&[
                    1,
                    config.drive.len() as u64,
                    drivetrain.feedback().drives.len() as u64,
                ])
            }
            Err(e) => signature(&[0, std::mem::discriminant(&e).hash_u64()]),
        }
    })
}

trait HashU64 {
    fn hash_u64(&self) -> u64;
}

impl<T: Hash> HashU64 for T {
    fn hash_u64(&self) -> u64 {
        let mut h = DefaultHasher::new();
        self.hash(&mut h);
        h.finish()
    }
}

/// A calibration file as `chassisd calibrate` writes it, with every key.
const CALIBRATION_SEED: &str = "[chassis]\ntrack_m = 0.42\n\
[chassis.wheel_radius_m]\nvalue = [0.11, 0.1122]\ndate = \"2026-11-24T09:12:03Z\"\n\
method = \"runs\"\nverdict = \"ok\"\n[chassis.wheel_radius_m.residuals]\nposition_rms_m = 0.0095\n\
[imu]\ngyro_bias_rps = [0.0, 0.0, 0.0035]\nmounting_rpy_deg = [0.1, -0.2, 0.0]\n\
[gnss]\nantenna = [0.2, 0.0]\nheading_offset_deg = 2.0\n";

fn profile_seeds() -> Vec<Vec<u8>> {
    let mut seeds: Vec<Vec<u8>> = vec![CALIBRATION_SEED.as_bytes().to_vec()];
    seeds.extend(profile_files());
    seeds
}

fn profile_files() -> Vec<Vec<u8>> {
    files_in(&repo().join("devices"), "toml")
        .into_iter()
        .filter(|p| {
            !p.file_name().is_some_and(|n| {
                n.to_string_lossy().starts_with("plant")
                    || n.to_string_lossy().starts_with("vehicle")
            })
        })
        .filter_map(|p| std::fs::read(p).ok())
        .collect()
}

fn profile_runner() -> Runner {
    let file = repo().join("devices/fuzzed.toml");
    Box::new(move |input| {
        let text = String::from_utf8_lossy(input);
        let drive = DriveProfile::from_toml(&text, &file).is_ok();
        let bms = toml::from_str::<BmsProfile>(&text).map(|p| p.validate(&file).is_ok());
        let plant = PlantConfig::from_toml(&text, &file).is_ok();
        // A calibration file that loads is also put in force on a configuration.
        let calibration = CalibrationFile::from_toml(&text, &file).map(|c| {
            let mut config = VehicleConfig::default();
            c.apply(&mut config).len() as u64
        });
        signature(&[
            u64::from(drive),
            match bms {
                Ok(true) => 2,
                Ok(false) => 1,
                Err(_) => 0,
            },
            u64::from(plant),
            calibration.map_or(0, |n| n + 1),
        ])
    })
}

fn dbc_seeds() -> Vec<Vec<u8>> {
    let mut seeds: Vec<Vec<u8>> = std::fs::read(repo().join("devices/pylontech.dbc"))
        .into_iter()
        .collect();
    if let Some(whole) = seeds.first().cloned() {
        seeds.extend(pieces(&whole, 700, 8));
    }
    seeds
}

fn dbc_runner() -> Runner {
    let profile_text =
        std::fs::read_to_string(repo().join("devices/pylontech-bms.toml")).unwrap_or_default();
    Box::new(move |input| {
        let Ok(BmsProfile::Dbc(mut profile)) = toml::from_str::<BmsProfile>(&profile_text) else {
            return 0;
        };
        profile.dbc_text = String::from_utf8_lossy(input).into_owned();
        // The loader's check of a DBC is this mapping (the rest of it reads the profile).
        let mapped = chassisd::devices::bms::dbc::DbcBms::new(&profile);
        let checked = mapped.is_ok();
        let mut updates = 0u64;
        if let Ok(mut bms) = mapped {
            // Frames on every id the input names, with data from the input itself.
            for (i, chunk) in input.chunks(8).take(64).enumerate() {
                let id = 0x350 + (i as u32 % 0x30);
                if let Some(frame) = Frame::standard(id, chunk) {
                    let t = Timestamp::from_micros(i as u64 * 1000);
                    updates += u64::from(bms.on_frame(t, &frame));
                }
            }
        }
        signature(&[u64::from(checked), updates.min(16)])
    })
}

/// The topics the simulated vehicle's dialects answer (vehicle id `sim`, serial `SIM0001`),
/// each with the document whose examples are its seeds.
const DIALECT_TOPICS: &[(&str, &str)] = &[
    ("mqtt_control", "rtk-mqtt-protocol.md"),
    ("/root/sim/cmd/chassis/set", "root-mqtt-api.rst"),
    ("/root/sim/cmd/navigation/set", "root-mqtt-api.rst"),
    ("/root/sim/cmd/map/set", "root-mqtt-api.rst"),
    ("/root/sim/setting/navigation/set", "root-mqtt-api.rst"),
    ("/root/sim/setting/map/set", "root-mqtt-api.rst"),
    ("/root/sim/heartbeat/set", "root-mqtt-api.rst"),
    ("device/SIM0001/goal", "device-mqtt-api.md"),
    ("device/SIM0001/start_mapping", "device-mqtt-api.md"),
    ("device/SIM0001/stop_mapping", "device-mqtt-api.md"),
    ("device/SIM0001/use_map", "device-mqtt-api.md"),
];

fn dialect_seeds() -> Vec<Vec<u8>> {
    // Every JSON example of the protocol documents, as the protocol tests read them: a root
    // example behind the topic the document names for it, the others behind each topic of
    // their document.
    let spec = std::env::var_os("CHASSISD_SHARED_SPEC")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("../shared/spec"));
    let read = |doc: &str| std::fs::read_to_string(spec.join(doc)).unwrap_or_default();
    let topic_index = |topic: &str| DIALECT_TOPICS.iter().position(|(t, _)| *t == topic);
    let mut seeds = Vec::new();
    let mut push = |index: usize, value: &serde_json::Value| {
        let mut seed = vec![index as u8];
        seed.extend(serde_json::to_vec(value).unwrap_or_default());
        seeds.push(seed);
    };
    for example in spec::rst_json_examples(&read("root-mqtt-api.rst"), "sim") {
        let json = spec::strip_json_comments(&example.text);
        if let (Some(i), Ok(value)) = (topic_index(&example.topic), serde_json::from_str(&json)) {
            push(i, &value);
        }
    }
    for doc in ["rtk-mqtt-protocol.md", "device-mqtt-api.md"] {
        let examples = spec::markdown_json_examples(&read(doc));
        for (i, _) in DIALECT_TOPICS
            .iter()
            .enumerate()
            .filter(|(_, (_, d))| *d == doc)
        {
            for (_, value) in &examples {
                push(i, value);
            }
        }
    }
    seeds
}

/// The built-in simulated vehicle with noise `seed`, speaking the dialects of `mqtt`.
fn simulated_vehicle(seed: u64, mqtt: Option<MqttConfig>) -> Lockstep {
    let plant = PlantConfig::builtin().expect("built-in plant");
    Lockstep::with_mqtt(
        plant,
        seed,
        Timestamp::from_micros(1_000_000),
        mqtt,
        Box::new(MemoryStore::default()),
    )
    .expect("simulated vehicle")
}

/// What roslibjs and roslibpy send, and the two topics that become commands.
fn rosbridge_seeds() -> Vec<Vec<u8>> {
    [
        r#"{"op":"subscribe","id":"subscribe:/pose:1","type":"geometry_msgs/PoseWithCovarianceStamped","topic":"/pose","compression":"none","throttle_rate":100,"queue_length":2}"#,
        r#"{"op":"unsubscribe","id":"subscribe:/pose:1","topic":"/pose"}"#,
        r#"{"op":"advertise","id":"advertise:/cmd_vel:2","type":"geometry_msgs/Twist","topic":"/cmd_vel"}"#,
        r#"{"op":"publish","id":"publish:/cmd_vel:3","topic":"/cmd_vel","msg":{"linear":{"x":0.3,"y":0,"z":0},"angular":{"x":0,"y":0,"z":0.2}}}"#,
        r#"{"op":"publish","topic":"/goal_pose","msg":{"header":{"frame_id":"map","stamp":{"sec":0,"nanosec":0}},"pose":{"position":{"x":2.0,"y":1.0,"z":0.0},"orientation":{"x":0,"y":0,"z":0.7071,"w":0.7071}}}}"#,
        r#"{"op":"call_service","id":"call_service:/rosapi/topics:4","service":"/rosapi/topics","args":[]}"#,
        r#"{"op":"set_level","level":"warning"}"#,
        r#"{"op":"auth","mac":"0123456789abcdef","client":"","dest":"","rand":"","t":0,"level":"admin","end":0}"#,
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect()
}

fn rosbridge_runner() -> Runner {
    use chassisd::api::rosbridge::{SOURCE, adapter, ops, topics};
    let mut sim = simulated_vehicle(5, None);
    let mut n = 0u64;
    Box::new(move |input| {
        n += 1;
        if n.is_multiple_of(2000) {
            sim = simulated_vehicle(5, None);
        }
        let Ok(text) = std::str::from_utf8(input) else {
            return 0;
        };
        let op = match ops::parse(text) {
            Ok(op) => op,
            Err(refusal) => return refusal.status().len() as u64,
        };
        let ops::ClientOp::Publish { topic, msg, .. } = op else {
            return 1;
        };
        let Some(name) = topics::find(&topic)
            .filter(|t| matches!(t.flow, topics::Flow::Subscribed))
            .map(|t| t.name)
        else {
            return 2;
        };
        if let Err(reason) = adapter::check(name, &topic, &msg) {
            return reason.len() as u64;
        }
        let mut sink = Collect::default();
        sim.input(
            SOURCE,
            Payload::Command {
                topic: name.into(),
                payload: adapter::encode(n, &msg),
            },
            &mut sink,
        );
        settle(&mut sim, n, &mut sink);
        signature(&[
            3 + u64::from(name == topics::GOAL_POSE),
            sink.outputs.min(8),
        ])
    })
}

/// Every 50th input, lets what the commands started run for 10 plant steps with RTK fixed.
fn settle(sim: &mut Lockstep, n: u64, sink: &mut Collect) {
    if n.is_multiple_of(50) {
        let gnss = GnssCondition {
            quality: Some(chassisd::devices::gnss::FixQuality::RtkFixed),
            offset: (0.0, 0.0),
        };
        for _ in 0..10 {
            sim.step(gnss, sink);
        }
    }
}

fn dialect_runner() -> Runner {
    let fresh = || {
        let mqtt = MqttConfig {
            rtk: Some(RtkDialectConfig::default()),
            root: Some(RootDialectConfig {
                vehicle_id: "sim".into(),
                heartbeat_timeout_s: 3.0,
                require_heartbeat: false,
                heartbeat_client_id: None,
            }),
            device: Some(DeviceDialectConfig {
                serial_number: "SIM0001".into(),
                mapping_forward: None,
            }),
            ..MqttConfig::default()
        };
        simulated_vehicle(3, Some(mqtt))
    };
    let mut sim = fresh();
    let mut n = 0u64;
    Box::new(move |input| {
        n += 1;
        // A fresh vehicle now and then: saved trajectories and missions pile up otherwise.
        if n.is_multiple_of(2000) {
            sim = fresh();
        }
        let Some((&which, payload)) = input.split_first() else {
            return 0;
        };
        let (topic, _) = DIALECT_TOPICS[usize::from(which) % DIALECT_TOPICS.len()];
        let mut sink = Collect::default();
        sim.input(
            MQTT_SOURCE,
            Payload::Command {
                topic: topic.into(),
                payload: Bytes::copy_from_slice(payload),
            },
            &mut sink,
        );
        settle(&mut sim, n, &mut sink);
        signature(&[
            u64::from(which) % DIALECT_TOPICS.len() as u64,
            sink.outputs.min(8),
        ])
    })
}

/// A dialect input (topic byte, JSON payload) with one value of its JSON changed: a number
/// made extreme, a string made odd, a key dropped, a value's type swapped. Inputs that are not
/// JSON get a new topic byte.
/// A whole input that is one JSON document: its values mutated as in a command's.
fn mutate_json_document(rng: &mut ChaCha8Rng, input: &mut Vec<u8>) {
    let Ok(mut value) = serde_json::from_slice::<serde_json::Value>(input) else {
        return;
    };
    for _ in 0..rng.random_range(1..=3) {
        mutate_json_value(rng, &mut value, 0);
    }
    *input = serde_json::to_vec(&value).unwrap_or_default();
}

fn mutate_json_command(rng: &mut ChaCha8Rng, input: &mut Vec<u8>) {
    if input.is_empty() {
        input.push(rng.random());
        return;
    }
    let Ok(mut value) = serde_json::from_slice::<serde_json::Value>(&input[1..]) else {
        input[0] = rng.random();
        return;
    };
    for _ in 0..rng.random_range(1..=3) {
        mutate_json_value(rng, &mut value, 0);
    }
    if rng.random_bool(0.2) {
        input[0] = rng.random();
    }
    input.truncate(1);
    input.extend(serde_json::to_vec(&value).unwrap_or_default());
}

fn mutate_json_value(rng: &mut ChaCha8Rng, value: &mut serde_json::Value, depth: u32) {
    use serde_json::{Value, json};
    // Walk down to a random node.
    let children = match value {
        Value::Object(map) => map.len(),
        Value::Array(items) => items.len(),
        _ => 0,
    };
    if children > 0 && depth < 8 && rng.random_bool(0.7) {
        let i = rng.random_range(0..children);
        match value {
            Value::Object(map) => {
                if rng.random_bool(0.1) {
                    let key = map.keys().nth(i).cloned().unwrap_or_default();
                    map.remove(&key);
                } else if let Some(child) = map.values_mut().nth(i) {
                    mutate_json_value(rng, child, depth + 1);
                }
            }
            Value::Array(items) => mutate_json_value(rng, &mut items[i], depth + 1),
            _ => {}
        }
        return;
    }
    let odd_strings = [
        "",
        " ",
        "\u{0}",
        "\u{202e}",
        "../../etc/passwd",
        "9999999999",
        "-1",
        "NaN",
        "true",
        "é",
    ];
    let new = match rng.random_range(0..9) {
        0 => json!(null),
        1 => json!(rng.random::<bool>()),
        2 => json!([1e308, -1e308, f64::MAX, f64::MIN_POSITIVE, 0.0, -0.0][rng.random_range(0..6)]),
        3 => json!([i64::MIN, i64::MAX, -1, 0, 1, 255, 65536][rng.random_range(0..7)]),
        4 => json!(u64::MAX),
        5 => json!(odd_strings[rng.random_range(0..odd_strings.len())]),
        6 => json!([]),
        7 => json!({}),
        8 if rng.random_bool(0.2) => json!("x".repeat(300)),
        _ => match &*value {
            Value::Number(n) => {
                json!(n.as_f64().unwrap_or(0.0) * [-1.0, 10.0, 0.1, 1e6][rng.random_range(0..4)])
            }
            Value::String(s) => json!(format!("{s}{s}")),
            other => other.clone(),
        },
    };
    *value = new;
}

/// Input encoding: per frame, two bytes of id (little-endian, 11 bits used), a length byte,
/// then the data (cut to 8).
fn canopen_seeds() -> Vec<Vec<u8>> {
    let mut seeds = Vec::new();
    for name in ["can0.log", "vcan0.log", "sim0.log"] {
        for bytes in fixture_files(name) {
            let mut reader = socketcan::dump::Reader::from_reader(&bytes[..]);
            let mut seed = Vec::new();
            while let Ok(Some(record)) = reader.next_record() {
                use socketcan::{EmbeddedFrame, Frame as _};
                let socketcan::CanAnyFrame::Normal(f) = record.frame else {
                    continue;
                };
                let id = f.raw_id() as u16;
                seed.extend(id.to_le_bytes());
                seed.push(f.dlc() as u8);
                seed.extend(f.data());
                if seed.len() > 600 {
                    seeds.push(std::mem::take(&mut seed));
                    if seeds.len() > 100 {
                        return seeds;
                    }
                }
            }
            if !seed.is_empty() {
                seeds.push(seed);
            }
        }
    }
    seeds
}

fn canopen_runner() -> Runner {
    // The simulated vehicle's configuration: two CiA 402 wheel drives and a blade, a Daly
    // BMS and an e-stop input on one bus.
    let plant = PlantConfig::builtin().expect("built-in plant");
    let config = vehicle_config(&plant).expect("simulated vehicle's configuration");
    let bus = config
        .can
        .first()
        .map(|c| c.interface.clone())
        .unwrap_or_default();
    Box::new(move |input| {
        let mut drivetrain = Drivetrain::new(&config);
        let mut tx = Vec::new();
        let mut rest = input;
        let (mut frames, mut updates) = (0u64, 0u64);
        while rest.len() >= 3 {
            let id = u32::from(u16::from_le_bytes([rest[0], rest[1]])) & 0x7ff;
            let len = usize::from(rest[2] % 9).min(rest.len() - 3);
            let frame = Frame::standard(id, &rest[3..3 + len]);
            rest = &rest[3 + len..];
            let Some(frame) = frame else { continue };
            let t = Timestamp::from_micros(1_000_000 + frames * 1000);
            updates += u64::from(drivetrain.on_frame(t, &bus, &Received::Data(frame), &mut tx));
            frames += 1;
        }
        signature(&[frames.min(8), updates.min(8), tx.len().min(16) as u64])
    })
}

// ---- the loop ------------------------------------------------------------------------------

fn mutate(rng: &mut ChaCha8Rng, input: &mut Vec<u8>, corpus: &[Vec<u8>], tokens: &[&[u8]]) {
    for _ in 0..rng.random_range(1..=6) {
        let len = input.len();
        match rng.random_range(0..10) {
            0 if len > 0 => {
                let i = rng.random_range(0..len);
                input[i] ^= 1 << rng.random_range(0..8);
            }
            1 if len > 0 => {
                let i = rng.random_range(0..len);
                input[i] = *[
                    0u8, 0xff, 0x7f, 0x80, b'$', b'*', b',', b'\r', b'\n', b'"', b'{',
                ]
                .get(rng.random_range(0..12))
                .unwrap_or(&rng.random());
            }
            2 if len > 0 => {
                let a = rng.random_range(0..len);
                let b = (a + rng.random_range(1..=32)).min(len);
                input.drain(a..b);
            }
            3 => {
                let at = rng.random_range(0..=len);
                let n = rng.random_range(1..=16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.random()).collect();
                input.splice(at..at, bytes);
            }
            4 if len > 0 => {
                let a = rng.random_range(0..len);
                let b = (a + rng.random_range(1..=64)).min(len);
                let copy = input[a..b].to_vec();
                let at = rng.random_range(0..=len);
                input.splice(at..at, copy);
            }
            5 if !tokens.is_empty() => {
                let token = tokens[rng.random_range(0..tokens.len())];
                let at = rng.random_range(0..=len);
                input.splice(at..at, token.iter().copied());
            }
            6 if !corpus.is_empty() => {
                let other = &corpus[rng.random_range(0..corpus.len())];
                if !other.is_empty() {
                    let at = rng.random_range(0..=len);
                    let from = rng.random_range(0..other.len());
                    input.truncate(at);
                    input.extend_from_slice(&other[from..]);
                }
            }
            7 if len > 0 => input.truncate(rng.random_range(0..len)),
            8 => replace_number(rng, input),
            _ => {
                let at = rng.random_range(0..=len);
                let number = NUMBERS[rng.random_range(0..NUMBERS.len())];
                input.splice(at..at, number.iter().copied());
            }
        }
    }
    input.truncate(MAX_INPUT);
}

/// Replaces one run of digits with an extreme number.
fn replace_number(rng: &mut ChaCha8Rng, input: &mut Vec<u8>) {
    let starts: Vec<usize> = (0..input.len())
        .filter(|&i| input[i].is_ascii_digit() && (i == 0 || !input[i - 1].is_ascii_digit()))
        .collect();
    if starts.is_empty() {
        return;
    }
    let a = starts[rng.random_range(0..starts.len())];
    let b = (a..input.len())
        .find(|&i| !(input[i].is_ascii_digit() || input[i] == b'.'))
        .unwrap_or(input.len());
    let number = NUMBERS[rng.random_range(0..NUMBERS.len())];
    input.splice(a..b, number.iter().copied());
}

#[derive(Debug, Default, Clone, serde::Serialize)]
struct Figures {
    target: &'static str,
    inputs: u64,
    panics: u64,
    slow: u64,
    seeds: usize,
    corpus: usize,
    signatures: usize,
    seconds: f64,
    per_second: f64,
}

fn run_target(target: &Target, budget: Budget, seed: u64, crashes: &Path) -> Figures {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ target.name.hash_u64());
    let seeds = (target.seeds)();
    let mut corpus: Vec<Vec<u8>> = seeds.clone();
    if corpus.is_empty() {
        corpus.push(Vec::new());
    }
    let mut runner = (target.runner)();
    let mut seen: HashSet<u64> = HashSet::new();
    let mut figures = Figures {
        target: target.name,
        seeds: seeds.len(),
        ..Figures::default()
    };
    let start = Instant::now();
    let mut last_report = start;
    let mut input = Vec::with_capacity(MAX_INPUT);
    // The seeds run as they are first.
    let mut next_seed = 0usize;
    loop {
        if budget.done(figures.inputs, start.elapsed()) {
            break;
        }
        input.clear();
        if next_seed < corpus.len().min(seeds.len()) {
            input.extend_from_slice(&corpus[next_seed]);
            next_seed += 1;
        } else {
            input.extend_from_slice(&corpus[rng.random_range(0..corpus.len())]);
            match target.structured {
                Some(structured) if rng.random_bool(0.5) => structured(&mut rng, &mut input),
                _ => mutate(&mut rng, &mut input, &corpus, target.tokens),
            }
        }
        let began = Instant::now();
        let outcome = catch_unwind(AssertUnwindSafe(|| runner(&input)));
        let took = began.elapsed();
        figures.inputs += 1;
        match outcome {
            Ok(sig) => {
                if seen.len() < MAX_SIGNATURES && seen.insert(sig) && corpus.len() < MAX_CORPUS {
                    corpus.push(input.clone());
                }
            }
            Err(_) => {
                figures.panics += 1;
                save(crashes, target.name, "panic", &input);
                // The runner may hold broken state after a panic.
                runner = (target.runner)();
            }
        }
        if took > SLOW {
            figures.slow += 1;
            save(crashes, target.name, "slow", &input);
        }
        if last_report.elapsed() > Duration::from_secs(30) {
            last_report = Instant::now();
            eprintln!(
                "fuzz {}: {} inputs, {} panics, corpus {}, {:.0}/s",
                target.name,
                figures.inputs,
                figures.panics,
                corpus.len(),
                figures.inputs as f64 / start.elapsed().as_secs_f64()
            );
        }
    }
    figures.seconds = start.elapsed().as_secs_f64();
    figures.per_second = figures.inputs as f64 / figures.seconds.max(1e-9);
    figures.corpus = corpus.len();
    figures.signatures = seen.len();
    figures
}

fn save(dir: &Path, target: &str, kind: &str, input: &[u8]) {
    let _ = std::fs::create_dir_all(dir);
    let path = dir.join(format!("{target}-{kind}-{:016x}.bin", input.hash_u64()));
    match std::fs::write(&path, input) {
        Ok(()) => eprintln!("fuzz {target}: {kind}, input saved to {}", path.display()),
        Err(e) => eprintln!("fuzz {target}: {kind}; cannot save {}: {e}", path.display()),
    }
}

#[derive(Debug, Clone, Copy)]
enum Budget {
    Seconds(Duration),
    Inputs(u64),
}

impl Budget {
    fn done(self, inputs: u64, elapsed: Duration) -> bool {
        match self {
            Self::Seconds(d) => elapsed >= d,
            Self::Inputs(n) => inputs >= n,
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut budget = Budget::Seconds(Duration::from_secs(60));
    let mut jobs = 1usize;
    let mut seed = 1u64;
    let mut wanted: Vec<String> = Vec::new();
    while let Some(arg) = args.next() {
        let mut value = |what: &str| {
            args.next()
                .unwrap_or_else(|| fail(&format!("{arg} needs {what}")))
        };
        match arg.as_str() {
            "--seconds" => {
                let s: f64 = value("seconds")
                    .parse()
                    .unwrap_or_else(|_| fail("--seconds: a number"));
                if !(s.is_finite() && s > 0.0 && s < 1e7) {
                    fail("--seconds: a positive number");
                }
                budget = Budget::Seconds(Duration::from_secs_f64(s));
            }
            "--inputs" => {
                budget = Budget::Inputs(
                    value("a count")
                        .parse()
                        .unwrap_or_else(|_| fail("--inputs: a count")),
                )
            }
            "--jobs" => {
                jobs = value("a count")
                    .parse()
                    .unwrap_or_else(|_| fail("--jobs: a count"))
            }
            "--seed" => {
                seed = value("a number")
                    .parse()
                    .unwrap_or_else(|_| fail("--seed: a number"))
            }
            "--replay" => {
                let dir = PathBuf::from(value("a folder"));
                std::process::exit(replay(&dir));
            }
            "--list" => {
                for t in targets() {
                    println!("{:10} {}", t.name, t.about);
                }
                return;
            }
            "-h" | "--help" => {
                println!(
                    "cargo run --release --example fuzz -- [--seconds S | --inputs N] [--jobs J] [--seed K] [--list] [TARGET...]"
                );
                return;
            }
            name => wanted.push(name.to_owned()),
        }
    }
    let all = targets();
    for w in &wanted {
        if !all.iter().any(|t| t.name == w) {
            let names: Vec<&str> = all.iter().map(|t| t.name).collect();
            fail(&format!("no target {w:?}; there are {}", names.join(", ")));
        }
    }
    let chosen: Vec<usize> = (0..all.len())
        .filter(|&i| wanted.is_empty() || wanted.iter().any(|w| w == all[i].name))
        .collect();
    // The panics are expected to be caught; their messages would drown the progress lines.
    std::panic::set_hook(Box::new(|info| {
        let location = info.location().map(|l| l.to_string()).unwrap_or_default();
        let message = chassisd::runtime::panics::message_of(info);
        eprintln!("fuzz: panic at {location}: {message}");
    }));
    let crashes = repo().join("fuzz/crashes");
    let queue = Arc::new(Mutex::new(chosen));
    let results = Arc::new(Mutex::new(HashMap::new()));
    let workers: Vec<_> = (0..jobs.max(1))
        .map(|_| {
            let queue = Arc::clone(&queue);
            let results = Arc::clone(&results);
            let crashes = crashes.clone();
            std::thread::spawn(move || {
                let targets = targets();
                loop {
                    let next = queue.lock().ok().and_then(|mut q| q.pop());
                    let Some(i) = next else { break };
                    let figures = run_target(&targets[i], budget, seed, &crashes);
                    eprintln!(
                        "fuzz {}: done, {} inputs in {:.0} s ({:.0}/s), {} panics, {} slow, corpus {} from {} seeds",
                        figures.target,
                        figures.inputs,
                        figures.seconds,
                        figures.per_second,
                        figures.panics,
                        figures.slow,
                        figures.corpus,
                        figures.seeds
                    );
                    if let Ok(mut r) = results.lock() {
                        r.insert(i, figures);
                    }
                }
            })
        })
        .collect();
    for w in workers {
        let _ = w.join();
    }
    let results = results.lock().map(|r| r.clone()).unwrap_or_default();
    let mut ordered: Vec<(usize, Figures)> = results.into_iter().collect();
    ordered.sort_by_key(|(i, _)| *i);
    let figures: Vec<Figures> = ordered.into_iter().map(|(_, f)| f).collect();
    println!("| target | inputs | panics | slow (>200 ms) | inputs/s | corpus (seeds) |");
    println!("|---|---|---|---|---|---|");
    for f in &figures {
        println!(
            "| {} | {} | {} | {} | {:.0} | {} ({}) |",
            f.target, f.inputs, f.panics, f.slow, f.per_second, f.corpus, f.seeds
        );
    }
    let clean = figures.iter().all(|f| f.panics == 0 && f.seeds > 0);
    println!(
        "{}",
        serde_json::json!({ "targets": figures, "pass": clean })
    );
    if !clean {
        std::process::exit(1);
    }
}

/// Runs every saved input of `dir` once through the target its name starts with; the exit
/// status.
fn replay(dir: &Path) -> i32 {
    let all = targets();
    let mut runners: HashMap<&str, Runner> = HashMap::new();
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    files.sort();
    let (mut ran, mut panics) = (0, 0);
    for file in files {
        let name = file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let Some(target) = all
            .iter()
            .find(|t| name.starts_with(&format!("{}-", t.name)))
        else {
            continue;
        };
        let Ok(input) = std::fs::read(&file) else {
            eprintln!("fuzz: cannot read {}", file.display());
            return 1;
        };
        let runner = runners
            .entry(target.name)
            .or_insert_with(|| (target.runner)());
        ran += 1;
        if catch_unwind(AssertUnwindSafe(|| runner(&input))).is_err() {
            panics += 1;
            eprintln!("fuzz: {} panics", file.display());
            runners.remove(target.name);
        }
    }
    println!(
        "fuzz: {ran} saved inputs replayed from {}, {panics} panics",
        dir.display()
    );
    i32::from(panics > 0)
}

fn fail(message: &str) -> ! {
    eprintln!("fuzz: {message}");
    std::process::exit(2);
}
