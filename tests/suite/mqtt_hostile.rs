//! Hostile clients on the vehicle's network, round two (issue 48): nobody takes chassisd's
//! seat on a broker, a will is no command, a client without keep-alive is served, and no
//! client's flood of unreleased QoS 2 messages or retained messages grows the embedded
//! broker past its budget or keeps base_status from its subscribers. Raw sockets play the
//! attackers (no client library does what they do); mosquitto's clients are the operator.

use crate::common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::mqtt::{Mosquitto, free_port, raw};
use common::process::Proc;
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(15);
/// The simulator's client id without the part drawn at each start.
const SIM_BASE_ID: &str = "chassisd-sim-mower";

fn sim(port: u16) -> Proc {
    let mut daemon = Proc::start(&["sim", "--broker-port", &port.to_string()]);
    daemon.wait_log(WAIT, "MQTT subscribed");
    daemon
}

/// A last will: its topic, its payload and whether it is retained.
type Will<'a> = (&'a str, &'a [u8], bool);

/// The will of a command: an e-stop release.
const RELEASE: &[u8] = br#"{"messageId": 1, "messageType": 101, "data": 0}"#;

/// A CONNECT of `level` with keep-alive `keep_alive_s`, a `will` if given, and MQTT 5
/// `properties`.
fn connect_packet(
    level: u8,
    client_id: &str,
    keep_alive_s: u16,
    will: Option<Will<'_>>,
    properties: &[u8],
) -> Vec<u8> {
    let mut flags = 0x02;
    if let Some((_, _, retain)) = will {
        flags |= 0x04 | if retain { 0x20 } else { 0 };
    }
    let mut body = vec![0, 4, b'M', b'Q', b'T', b'T', level, flags];
    body.extend_from_slice(&keep_alive_s.to_be_bytes());
    if level == 5 {
        body.push(properties.len() as u8);
        body.extend_from_slice(properties);
    }
    let string = |body: &mut Vec<u8>, s: &[u8]| {
        body.extend_from_slice(&(s.len() as u16).to_be_bytes());
        body.extend_from_slice(s);
    };
    string(&mut body, client_id.as_bytes());
    if let Some((topic, payload, _)) = will {
        if level == 5 {
            body.push(0);
        }
        string(&mut body, topic.as_bytes());
        string(&mut body, payload);
    }
    chassisd::broker::wire::packet(0x10, &body)
}

/// A PUBLISH in MQTT `level` (5: with no properties) of `payload` on `topic` at `qos` with
/// packet id `id`.
fn publish_packet(
    level: u8,
    topic: &str,
    qos: u8,
    retain: bool,
    id: u16,
    payload: &[u8],
) -> Vec<u8> {
    let mut body = (topic.len() as u16).to_be_bytes().to_vec();
    body.extend_from_slice(topic.as_bytes());
    if qos > 0 {
        body.extend_from_slice(&id.to_be_bytes());
    }
    if level == 5 {
        body.push(0);
    }
    body.extend_from_slice(payload);
    chassisd::broker::wire::packet(0x30 | qos << 1 | u8::from(retain), &body)
}

/// Reads until the peer closes (or `wait` passes); the bytes read.
fn read_to_close(s: &mut TcpStream, wait: Duration) -> (Vec<u8>, bool) {
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let deadline = Instant::now() + wait;
    let mut got = Vec::new();
    let mut chunk = [0u8; 4096];
    while Instant::now() < deadline {
        match s.read(&mut chunk) {
            Ok(0) => return (got, true),
            Ok(n) => got.extend_from_slice(&chunk[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(_) => return (got, true),
        }
    }
    (got, false)
}

/// The broker process of `daemon`, and its peak resident memory, kB.
fn broker_peak_kb(daemon: &Proc) -> u64 {
    let out = std::process::Command::new("pgrep")
        .args(["-P", &daemon.child.id().to_string(), "-f", "broker-child"])
        .output()
        .expect("pgrep runs");
    let pid = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("status");
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM")
}

/// Counts base_status messages on the embedded broker at `port` until `stop`.
fn count_status(port: u16, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<Vec<Instant>> {
    let clients = Mosquitto::clients_for(port);
    let sub = clients.subscribe(&["base_status"]);
    sub.next_on("base_status", WAIT).expect("base_status");
    std::thread::spawn(move || {
        let _keep = clients;
        let mut arrivals = Vec::new();
        while !stop.load(Ordering::Relaxed) {
            if sub.next_on("base_status", Duration::from_secs(1)).is_some() {
                arrivals.push(Instant::now());
            }
        }
        arrivals
    })
}

#[test]
fn nobody_else_takes_chassisds_seat_on_the_embedded_broker() {
    let port = free_port();
    let mut daemon = sim(port);
    let clients = Mosquitto::clients_for(port);
    // The attacker presents chassisd's id (the configured part, all an outsider can know)
    // again and again, in both versions, while the operator sends an e-stop.
    let stop = Arc::new(AtomicBool::new(false));
    let codes = Arc::new(Mutex::new(Vec::new()));
    let attacker = {
        let (stop, codes) = (stop.clone(), codes.clone());
        std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                for level in [4, 5] {
                    let (_s, code) = raw::connect(port, level, SIM_BASE_ID, None);
                    codes.lock().unwrap().push((level, code));
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(clients.sim_estop(1), 0, "an e-stop during the attack");
    let status = {
        let sub = clients.subscribe(&["base_status"]);
        serde_json::from_str::<Value>(&sub.next_on("base_status", WAIT).expect("status"))
            .expect("JSON")
    };
    assert!(
        status["robot"]["robot_status"].as_u64().expect("bits") & (1 << 3) != 0,
        "e-stop applied: {status}"
    );
    std::thread::sleep(Duration::from_secs(1));
    stop.store(true, Ordering::Relaxed);
    attacker.join().unwrap();
    let codes = codes.lock().unwrap().clone();
    assert!(codes.len() >= 20, "{} attempts", codes.len());
    for (level, code) in &codes {
        let refused = if *level == 4 { 2 } else { 0x85 };
        assert_eq!(*code, Some(refused), "MQTT {level}: {codes:?}");
    }
    daemon.wait_log(WAIT, "refused_reserved");
    let log = daemon.log.join("\n");
    assert!(!log.contains("MQTT connection lost"), "{log}");
    daemon.stop();
}

#[test]
fn a_will_on_chassisds_topics_is_refused_and_a_client_without_keep_alive_is_served() {
    let port = free_port();
    let daemon = sim(port);
    // A will is no command, and no report of the vehicle's.
    for topic in ["/root/sim/cmd/chassis/set", "chassisd/sim-mower/status"] {
        for level in [4, 5] {
            let packet = connect_packet(level, "willful", 30, Some((topic, RELEASE, false)), &[]);
            let refused = if level == 4 { 5 } else { 0x87 };
            assert_eq!(
                raw::connect_with(port, &packet).1,
                Some(refused),
                "{topic} {level}"
            );
        }
    }
    let (_ok, code) = raw::connect_with(
        port,
        &connect_packet(4, "willful", 30, Some(("app/gone", RELEASE, false)), &[]),
    );
    assert_eq!(code, Some(0));
    // A will to be retained is kept small: the broker holds it after its client is gone.
    for (payload, level, code) in [(2000, 4, 3), (2000, 5, 0x97), (100, 4, 0)] {
        let will = vec![b'w'; payload];
        let id = format!("retainer-{payload}-{level}");
        let packet = connect_packet(level, &id, 30, Some(("app/gone", &will, true)), &[]);
        assert_eq!(
            raw::connect_with(port, &packet).1,
            Some(code),
            "{payload} bytes, MQTT {level}"
        );
    }
    // Keep-alive 0 is legal MQTT (no keep-alive): admitted, and still served seconds later.
    for level in [4, 5] {
        let (mut s, code) = raw::connect_with(
            port,
            &connect_packet(level, &format!("no-keepalive-{level}"), 0, None, &[]),
        );
        assert_eq!(code, Some(0), "MQTT {level}");
        std::thread::sleep(Duration::from_secs(3));
        s.write_all(&[0xc0, 0x00]).expect("PINGREQ");
        let mut pong = [0u8; 2];
        s.read_exact(&mut pong).expect("PINGRESP");
        assert_eq!(pong, [0xd0, 0x00]);
    }
    daemon.stop();
}

#[test]
fn mqtt_5_limits_are_told_and_followed() {
    let port = free_port();
    let daemon = sim(port);
    // Receive Maximum 0 is a protocol error: no session.
    let (_s, code) = raw::connect_with(port, &connect_packet(5, "rm0", 30, None, &[0x21, 0, 0]));
    assert_eq!(code, None);
    // A client that takes packets of at most 64 bytes: the CONNACK tells it the gate's
    // limits, base_status (larger) never reaches it, and it stays served.
    let packet = connect_packet(5, "small", 30, None, &[0x27, 0, 0, 0, 64]);
    let mut s = TcpStream::connect(("127.0.0.1", port)).expect("connect");
    s.write_all(&packet).expect("CONNECT");
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut head = [0u8; 2];
    s.read_exact(&mut head).expect("CONNACK");
    let mut ack = vec![0u8; usize::from(head[1])];
    s.read_exact(&mut ack).expect("CONNACK body");
    assert_eq!((head[0], ack[1]), (0x20, 0), "{ack:?}");
    let receive_maximum = ack.windows(3).any(|w| w == [0x21, 0, 32]);
    assert!(receive_maximum, "Receive Maximum 32 told: {ack:?}");
    // SUBSCRIBE base_status (v5: no properties).
    let mut sub = vec![0x82, 0, 0, 1, 0];
    sub.extend_from_slice(&11u16.to_be_bytes());
    sub.extend_from_slice(b"base_status");
    sub.push(0);
    sub[1] = (sub.len() - 2) as u8;
    s.write_all(&sub).expect("SUBSCRIBE");
    let (got, closed) = read_to_close(&mut s, Duration::from_secs(2));
    assert!(!closed);
    assert_eq!(got.first(), Some(&0x90), "SUBACK only: {got:?}");
    assert!(
        got.len() < 16,
        "{} bytes: base_status reached it",
        got.len()
    );
    s.write_all(&[0xc0, 0x00]).expect("PINGREQ");
    let (pong, _) = read_to_close(&mut s, Duration::from_millis(500));
    assert!(pong.starts_with(&[0xd0, 0x00]), "{pong:?}");
    daemon.stop();
}

#[test]
fn unreleased_qos2_and_retained_floods_are_bounded_and_base_status_flows() {
    let port = free_port();
    let mut daemon = sim(port);
    let stop = Arc::new(AtomicBool::new(false));
    let status = count_status(port, stop.clone());
    let started = Instant::now();
    let attack = Duration::from_secs(12);
    // Unreleased QoS 2: each session is cut at the 33rd, a 5.0 client told why.
    let qos2 = std::thread::spawn(move || {
        let payload = vec![b'q'; 10_000];
        let (mut sessions, mut cut) = (0, 0);
        let mut reasons = Vec::new();
        while started.elapsed() < attack {
            let level = if sessions % 2 == 0 { 4 } else { 5 };
            let id = format!("qos2-{sessions}");
            let (mut s, code) = raw::connect_with(port, &connect_packet(level, &id, 30, None, &[]));
            assert_eq!(code, Some(0));
            sessions += 1;
            for pid in 1..=40u16 {
                let p = publish_packet(level, "flood/qos2", 2, false, pid, &payload);
                if s.write_all(&p).is_err() {
                    break;
                }
            }
            let (got, closed) = read_to_close(&mut s, Duration::from_secs(3));
            if closed {
                cut += 1;
                if level == 5
                    && let Some(i) = got.windows(2).position(|w| w == [0xe0, 0x01])
                {
                    reasons.push(got.get(i + 2).copied());
                }
            }
        }
        (sessions, cut, reasons)
    });
    // Retained 1 MB messages on new topics: kept up to the budget, then refused.
    let retained = std::thread::spawn(move || {
        let payload = vec![b'r'; 1 << 20];
        let (mut sent, mut sessions) = (0, 0);
        while started.elapsed() < attack {
            let (mut s, code) =
                raw::connect_with(port, &connect_packet(4, "retainer", 30, None, &[]));
            if code != Some(0) {
                std::thread::sleep(Duration::from_millis(50));
                continue;
            }
            sessions += 1;
            loop {
                let p = publish_packet(4, &format!("flood/r/{sent}"), 0, true, 0, &payload);
                if s.write_all(&p).is_err() {
                    break;
                }
                sent += 1;
                s.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
                if matches!(s.read(&mut [0u8; 1]), Ok(0)) || started.elapsed() > attack {
                    break;
                }
            }
        }
        (sent, sessions)
    });
    let (sessions, cut, reasons) = qos2.join().unwrap();
    let (sent, retained_sessions) = retained.join().unwrap();
    let span = started.elapsed();
    stop.store(true, Ordering::Relaxed);
    let arrivals = status.join().unwrap();
    let peak_kb = broker_peak_kb(&daemon);
    let told_0x93 = reasons.iter().filter(|r| **r == Some(0x93)).count();
    eprintln!(
        "qos2: {sessions} sessions, {cut} cut, {told_0x93} of {} v5 told 0x93; retained: {sent} sent in \
         {retained_sessions} sessions; base_status {} in {:.1} s; broker peak {} MB",
        reasons.len(),
        arrivals.len(),
        span.as_secs_f64(),
        peak_kb / 1024
    );
    assert!(sessions >= 4 && cut == sessions, "{cut} of {sessions} cut");
    assert!(
        !reasons.is_empty() && told_0x93 == reasons.len(),
        "{told_0x93} of {} told 0x93",
        reasons.len()
    );
    assert!(retained_sessions >= 2, "{retained_sessions} sessions");
    // 1,000 MB of payloads would have been kept before; the budget is 16 MiB.
    assert!(peak_kb < 160 * 1024, "broker peak {} MB", peak_kb / 1024);
    let expected = span.as_secs_f64() * 10.0;
    assert!(
        arrivals.len() as f64 >= 0.97 * expected,
        "{} base_status of {expected:.0}",
        arrivals.len()
    );
    daemon.wait_log(WAIT, "over_budget");
    let log = daemon.log.join("\n");
    assert!(!log.contains("embedded broker stopped"), "{log}");
    daemon.stop();
}

#[test]
fn a_takeover_on_an_external_broker_is_named_and_the_link_comes_back() {
    let broker = Mosquitto::start();
    let mut daemon = Proc::start(&["sim", "--mqtt", &broker.address()]);
    daemon.wait_log(WAIT, "MQTT subscribed");
    let line = daemon
        .log
        .iter()
        .find(|l| l.contains("MQTT connected"))
        .cloned()
        .expect("connected line");
    let id = line
        .split("client_id=")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .expect("client id in the log")
        .to_owned();
    assert!(
        id.starts_with(&format!("{SIM_BASE_ID}-")) && id.len() == SIM_BASE_ID.len() + 17,
        "an unguessable part: {id}"
    );
    // Someone who learnt the id takes it over again and again for 8 s, while commands that
    // need replies keep coming.
    let port: u16 = broker.port;
    let clients = Mosquitto::clients_for(port);
    let started = Instant::now();
    while started.elapsed() < Duration::from_secs(8) {
        let _ = raw::try_connect_with(port, &raw::connect_packet(4, &id, None));
        clients.publish(
            "mqtt_control",
            r#"{"cmd": "cancel_task", "cmd_type": "task_control"}"#,
        );
        std::thread::sleep(Duration::from_millis(150));
    }
    daemon.wait_log(
        WAIT,
        "another client is probably connecting with chassisd's client id",
    );
    // Within seconds of the attack's end, status and commands flow again.
    let sub = clients.subscribe(&["base_status", "feedback"]);
    sub.next_on("base_status", Duration::from_secs(5))
        .expect("base_status back within 5 s");
    clients.publish(
        "mqtt_control",
        r#"{"cmd": "cancel_task", "cmd_type": "task_control"}"#,
    );
    let feedback: Value =
        serde_json::from_str(&sub.next_on("feedback", WAIT).expect("feedback")).expect("JSON");
    assert_eq!(feedback["cmd"], "cancel_task_success");
    let log = daemon.stop_log();
    let loss_lines = log
        .iter()
        .filter(|l| l.contains("MQTT connection lost"))
        .count();
    assert!(
        loss_lines <= 3,
        "{loss_lines} loss lines: one, then summaries"
    );
}

#[test]
fn large_packets_sent_slowly_hold_a_bounded_share_of_the_gates_buffers() {
    let port = free_port();
    let daemon = sim(port);
    // 40 clients each announce a PUBLISH of 4,000,000 bytes (within the packet limit) and
    // send 100 KB of it, then wait: the gate buffers at most 64 MiB of such packets.
    let mut held = Vec::new();
    for i in 0..40 {
        let (mut s, code) = raw::connect(port, 4, &format!("slow-{i}"), None);
        assert_eq!(code, Some(0));
        let mut head = vec![0x30];
        let mut n = 4_000_000usize;
        loop {
            let digit = (n % 128) as u8;
            n /= 128;
            head.push(if n > 0 { digit | 0x80 } else { digit });
            if n == 0 {
                break;
            }
        }
        head.extend_from_slice(&[0, 4, b's', b'l', b'o', b'w']);
        head.resize(100_000, b'x');
        let _ = s.write_all(&head);
        held.push(s);
    }
    std::thread::sleep(Duration::from_secs(1));
    let cut = held
        .iter_mut()
        .map(|s| read_to_close(s, Duration::from_millis(100)).1)
        .filter(|&closed| closed)
        .count();
    assert!(
        (24..=40).contains(&cut),
        "{cut} of 40 cut: 16 may hold 4 MB each"
    );
    let clients = Mosquitto::clients_for(port);
    let sub = clients.subscribe(&["base_status"]);
    assert!(sub.next_on("base_status", WAIT).is_some());
    drop(held);
    daemon.stop();
}
