//! `chassisd check` with the receiver profiles on a pty. u-blox: MON-VER identifies it,
//! `--configure` sets its messages with CFG-VALSET (RAM unless `--flash`) and reads them back
//! with CFG-VALGET, and a receiver that refuses, or predates CFG-VALSET, is reported with the
//! reason; the receiver's side answers as the ZED-F9P interface description lays out, while
//! it streams real NAV frames from gpsd's ZED-F9P log. Unicore: the real UM98x capture's
//! heading is shown, and a receiver without one is a failure with the fix.

use crate::common;

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use chassisd::devices::gnss::ubx::config::value_size;
use chassisd::devices::gnss::ubx::frame::encode;
use chassisd::devices::gnss::{Frame, GnssFramer};
use common::pty::{Port, Talker};

/// The pty tests take turns so no child inherits another test's descriptors.
static SERIAL: Mutex<()> = Mutex::new(());

/// How the scripted receiver behaves.
#[derive(Clone, Copy)]
struct Behaviour {
    /// PROTVER it states.
    protocol: &'static str,
    /// Answers CFG-VALSET with ACK-NAK.
    refuse: bool,
}

/// What the receiver was asked: each VALSET's layers and items.
type Asked = Arc<Mutex<Vec<(u8, Vec<(u32, u64)>)>>>;

struct Receiver {
    running: Arc<AtomicBool>,
    asked: Asked,
}

impl Drop for Receiver {
    fn drop(&mut self) {
        self.running.store(false, Ordering::Relaxed);
    }
}

fn mon_ver(protocol: &str) -> Vec<u8> {
    let mut p = vec![0u8; 40 + 30 * 3];
    for (at, s) in [
        (0, "EXT CORE 1.00 (0fa0ae)".to_owned()),
        (30, "00190000".to_owned()),
        (40, "FWVER=HPG 1.32".to_owned()),
        (70, format!("PROTVER={protocol}")),
        (100, "MOD=ZED-F9P".to_owned()),
    ] {
        p[at..at + s.len()].copy_from_slice(s.as_bytes());
    }
    encode(0x0a, 0x04, &p).unwrap()
}

/// Key/value pairs of a CFG payload after its 4-byte header.
fn items(mut rest: &[u8]) -> Vec<(u32, u64)> {
    let mut out = Vec::new();
    while rest.len() >= 4 {
        let key = u32::from_le_bytes(rest[..4].try_into().unwrap());
        let size = value_size(key).unwrap();
        let mut value = [0u8; 8];
        value[..size].copy_from_slice(&rest[4..4 + size]);
        out.push((key, u64::from_le_bytes(value)));
        rest = &rest[4 + size..];
    }
    out
}

fn start(port: Port, behaviour: Behaviour) -> Receiver {
    let running = Arc::new(AtomicBool::new(true));
    let asked: Asked = Arc::default();
    let nav = {
        let log = std::fs::read(common::shared_gnss_dir().join("ublox-zed-f9p-rtk.log")).unwrap();
        let mut frames = Vec::new();
        GnssFramer::new().push_frames(&log, |f| {
            if let Frame::Ubx(f) = f {
                frames.extend(encode(f.class, f.id, f.payload).unwrap());
            }
        });
        frames
    };
    let mut writer = port.master.try_clone().unwrap();
    let flag = running.clone();
    std::thread::spawn(move || {
        // The receiver's own output, a tenth of the log every 100 ms, whether or not the
        // port is open at the other end (each probe opens it anew).
        for chunk in nav.chunks(nav.len() / 10 + 1).cycle() {
            if !flag.load(Ordering::Relaxed) {
                break;
            }
            let _ = writer.write_all(chunk);
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
    });
    let mut master = port.master;
    let (flag, log) = (running.clone(), asked.clone());
    std::thread::spawn(move || {
        let mut framer = GnssFramer::new();
        let mut config: BTreeMap<u32, u64> = BTreeMap::new();
        let mut buf = [0u8; 1024];
        while flag.load(Ordering::Relaxed) {
            // Between two probes no one holds the port, and reading fails until the next.
            let n = match master.read(&mut buf) {
                Ok(n) if n > 0 => n,
                _ => {
                    std::thread::sleep(std::time::Duration::from_millis(10));
                    continue;
                }
            };
            let mut answers = Vec::new();
            framer.push_frames(&buf[..n], |frame| {
                let Frame::Ubx(f) = frame else { return };
                match (f.class, f.id) {
                    (0x0a, 0x04) => answers.push(mon_ver(behaviour.protocol)),
                    (0x06, 0x8a) => {
                        let set = items(&f.payload[4..]);
                        log.lock().unwrap().push((f.payload[1], set.clone()));
                        if behaviour.refuse {
                            answers.push(encode(0x05, 0x00, &[0x06, 0x8a]).unwrap());
                        } else {
                            config.extend(set);
                            answers.push(encode(0x05, 0x01, &[0x06, 0x8a]).unwrap());
                        }
                    }
                    (0x06, 0x8b) => {
                        let mut p = vec![1, 0, 0, 0];
                        for chunk in f.payload[4..].chunks(4) {
                            let key = u32::from_le_bytes(chunk.try_into().unwrap());
                            let value = config.get(&key).copied().unwrap_or(0);
                            p.extend_from_slice(&key.to_le_bytes());
                            p.extend_from_slice(&value.to_le_bytes()[..value_size(key).unwrap()]);
                        }
                        answers.push(encode(0x06, 0x8b, &p).unwrap());
                        answers.push(encode(0x05, 0x01, &[0x06, 0x8b]).unwrap());
                    }
                    _ => {}
                }
            });
            for answer in answers {
                let _ = master.write_all(&answer);
            }
        }
    });
    Receiver { running, asked }
}

fn check(dir: &std::path::Path, receiver: &str, args: &[&str]) -> (Option<i32>, String) {
    let config = format!(
        "[gnss]\nport = \"{}\"\nreceiver = \"{receiver}\"\n",
        dir.join("gnss-port").display()
    );
    common::check(&config, dir, args)
}

const F9P: Behaviour = Behaviour {
    protocol: "27.31",
    refuse: false,
};

#[test]
fn a_u_blox_receiver_is_identified_and_configured_in_ram_unless_flash_is_asked() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let dir = common::tempdir("check-ublox");
    let receiver = start(Port::open_at(&dir.join("gnss-port")), F9P);
    let (code, table) = check(&dir, "ublox", &[]);
    assert_eq!(code, Some(0), "{table}");
    assert!(
        table.contains("UBX frames") && table.contains("NAV-PVT"),
        "{table}"
    );
    assert!(
        table.contains("ok: u-blox ZED-F9P, firmware HPG 1.32, protocol 27.31"),
        "{table}"
    );
    // Without --configure nothing is set.
    assert!(receiver.asked.lock().unwrap().is_empty());

    let (code, table) = check(&dir, "ublox", &["--configure"]);
    assert_eq!(code, Some(0), "{table}");
    assert!(table.contains("u-blox configure (uart1)"), "{table}");
    assert!(
        table.contains("8 items set in RAM (lost at power off) and read back"),
        "{table}"
    );
    {
        let asked = receiver.asked.lock().unwrap();
        let (layers, items) = &asked[0];
        assert_eq!(*layers, 0x01, "RAM only");
        // NAV-PVT once per epoch on UART1, UBX out on UART1.
        assert!(items.contains(&(0x2091_0007, 1)) && items.contains(&(0x1074_0001, 1)));
    }
    let (code, table) = check(&dir, "ublox", &["--configure", "--flash"]);
    assert_eq!(code, Some(0), "{table}");
    assert!(table.contains("in RAM and flash"), "{table}");
    assert_eq!(receiver.asked.lock().unwrap()[1].0, 0x05, "RAM and flash");
}

#[test]
fn a_refusal_and_a_receiver_before_valset_are_reported_with_the_reason() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let dir = common::tempdir("check-ublox-refuse");
    let refusing = start(
        Port::open_at(&dir.join("gnss-port")),
        Behaviour {
            refuse: true,
            ..F9P
        },
    );
    let (code, table) = check(&dir, "ublox", &["--configure"]);
    assert_eq!(code, Some(1), "{table}");
    assert!(
        table.contains("FAILED: the receiver refused CFG-VALSET (ACK-NAK)"),
        "{table}"
    );
    drop(refusing);

    let dir = common::tempdir("check-ublox-m8");
    let m8 = start(
        Port::open_at(&dir.join("gnss-port")),
        Behaviour {
            protocol: "20.30",
            refuse: false,
        },
    );
    let (code, table) = check(&dir, "ublox", &["--configure"]);
    assert_eq!(code, Some(1), "{table}");
    assert!(
        table.contains("protocol 20.30 predates CFG-VALSET"),
        "{table}"
    );
    assert!(m8.asked.lock().unwrap().is_empty(), "nothing sent to an M8");

    // --configure asks for a u-blox receiver in the configuration.
    let (code, out) = check(&dir, "nmea", &["--configure"]);
    assert_ne!(code, Some(0), "{out}");
    assert!(out.contains("set gnss.receiver = \"ublox\""), "{out}");
}

/// Streams `bytes` on `port` every 200 ms until the flag drops.
fn stream(mut port: Port, bytes: Vec<u8>) -> Arc<AtomicBool> {
    let running = Arc::new(AtomicBool::new(true));
    let flag = running.clone();
    std::thread::spawn(move || {
        while flag.load(Ordering::Relaxed) {
            let _ = port.master.write_all(&bytes);
            std::thread::sleep(std::time::Duration::from_millis(200));
        }
    });
    running
}

fn line(body: &str) -> String {
    let sum = body.bytes().fold(0u8, |a, b| a ^ b);
    format!("${body}*{sum:02X}\r\n")
}

#[test]
fn a_unicore_receiver_shows_its_heading_and_one_without_fails() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    // The real UM98x capture (the second antenna's `H` forms and the heading sentences)
    // with the first antenna's GGA and RMC, as a UM982 set for a vehicle sends them.
    let capture =
        std::fs::read_to_string(common::shared_gnss_dir().join("unicore-um98x-nmea.log")).unwrap();
    let first_antenna = [
        line("GNGGA,120000.00,2301.5,N,11301.17918515,E,4,20,0.6,12.3,M,-6.1,M,1.0,0123"),
        line("GNRMC,120000.00,A,2301.5,N,11301.17918515,E,0.0,0.0,241126,,,R"),
    ]
    .concat();
    let dir = common::tempdir("check-unicore");
    let running = stream(
        Port::open_at(&dir.join("gnss-port")),
        [capture.as_str(), &first_antenna].concat().into_bytes(),
    );
    let (code, table) = check(&dir, "unicore", &[]);
    running.store(false, Ordering::Relaxed);
    assert_eq!(code, Some(0), "{table}");
    assert!(table.contains("HPR"), "{table}");
    assert!(table.contains("dual-antenna heading"), "{table}");

    // The capture alone holds only the second antenna's positions: not the vehicle's, and
    // check says so.
    let dir = common::tempdir("check-unicore-second");
    let running = stream(Port::open_at(&dir.join("gnss-port")), capture.into_bytes());
    let (code, table) = check(&dir, "unicore", &[]);
    running.store(false, Ordering::Relaxed);
    assert_eq!(code, Some(1), "{table}");
    assert!(
        table.contains("only the second antenna's positions"),
        "{table}"
    );

    // Positions but no heading.
    let dir = common::tempdir("check-unicore-none");
    let _plain = Talker::start(Port::open_at(&dir.join("gnss-port")));
    let (code, table) = check(&dir, "unicore", &[]);
    assert_eq!(code, Some(1), "{table}");
    assert!(
        table.contains("but no valid dual-antenna heading"),
        "{table}"
    );
    assert!(table.contains("set gnss.receiver = \"nmea\""), "{table}");
}
