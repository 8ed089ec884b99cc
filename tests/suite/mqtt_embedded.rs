//! The embedded broker of the no-hardware default (rumqttd behind chassisd's gate, in a
//! process of its own): real clients use it like any broker; a port someone else holds is a
//! loud start-up failure; it holds against clients that flood it, lie to it or hang up on
//! it; it refuses credentials as mosquitto does for the same settings; and when it dies
//! anyway, chassisd restarts it within a second.

use crate::common;

use std::time::{Duration, Instant};

use std::path::{Path, PathBuf};

use common::mqtt::{Mosquitto, TestPki, free_port, raw};
use common::process::Proc;
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(15);

#[test]
fn real_clients_talk_to_the_embedded_broker() {
    let port = free_port();
    let mut daemon = Proc::start(&["sim", "--broker-port", &port.to_string()]);
    daemon.wait_log(WAIT, "embedded MQTT broker listening");
    daemon.wait_log(WAIT, "MQTT subscribed");
    let clients = Mosquitto::clients_for(port);
    let sub = clients.subscribe(&["base_status", "feedback", "/root/sim/cmd/chassis/ack"]);
    let status: Value =
        serde_json::from_str(&sub.next_on("base_status", WAIT).expect("base_status"))
            .expect("JSON");
    assert!(status["rtk"].is_object(), "{status}");
    clients.publish(
        "mqtt_control",
        r#"{"cmd": "cancel_task", "cmd_type": "task_control"}"#,
    );
    let feedback: Value =
        serde_json::from_str(&sub.next_on("feedback", WAIT).expect("feedback")).expect("JSON");
    assert_eq!(feedback["cmd"], "cancel_task_success");
    clients.publish(
        "/root/sim/cmd/chassis/set",
        r#"{"messageId": 7, "timestamp": "x", "messageType": 100, "data": {"linear": 0.2, "angular": 0.0}}"#,
    );
    let ack: Value = serde_json::from_str(
        &sub.next_on("/root/sim/cmd/chassis/ack", WAIT)
            .expect("DRIVE ack"),
    )
    .expect("JSON");
    assert_eq!(ack["messageId"], 7);
    assert_eq!(ack["data"]["code"], 0, "{ack}");
    daemon.stop();
}

#[test]
fn a_port_held_by_another_broker_fails_loudly() {
    let other = Mosquitto::start();
    let mut daemon = Proc::start(&["sim", "--broker-port", &other.port.to_string()]);
    let exit = daemon.wait_exit(WAIT, "chassisd kept running");
    assert!(!exit.success(), "{exit}");
    daemon.log.extend(daemon.stderr.iter());
    let log = daemon.log.join("\n");
    assert!(
        log.contains(&format!("127.0.0.1:{}", other.port)) && log.contains("another broker"),
        "{log}"
    );
}

/// A base_status within the wait, through `clients`.
fn one_status(clients: &Mosquitto) -> Value {
    let sub = clients.subscribe(&["base_status"]);
    serde_json::from_str(&sub.next_on("base_status", WAIT).expect("base_status")).expect("JSON")
}

#[test]
fn a_connection_flood_is_refused_cleanly_and_the_vehicle_stays_commandable() {
    let port = free_port();
    let mut daemon = Proc::start(&["sim", "--broker-port", &port.to_string()]);
    daemon.wait_log(WAIT, "MQTT subscribed");
    // Every place the broker has, held by raw clients with identifiers of their own.
    let held: Vec<_> = (0..64)
        .map(|i| {
            let (socket, code) = raw::connect(port, 4, &format!("flood-{i}"), None);
            assert_eq!(code, Some(0), "client {i} admitted");
            socket
        })
        .collect();
    // Beyond the limit: a CONNACK refusal in each client's own version, never a hang.
    for i in 0..16 {
        assert_eq!(raw::connect(port, 4, &format!("over-{i}"), None).1, Some(3));
    }
    assert_eq!(raw::connect(port, 5, "over-v5", None).1, Some(0x89));
    // chassisd's own link keeps its place: status still flows to the flood's end.
    // Identifiers rumqttd cannot route (twice each: the second used to panic it).
    for _ in 0..2 {
        assert_eq!(raw::connect(port, 4, "a/b", None).1, Some(2));
        assert_eq!(raw::connect(port, 5, "x+y", None).1, Some(0x85));
    }
    drop(held);
    // Clients that hang up right after CONNECT, under one identifier (the other panic).
    for _ in 0..20 {
        let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).expect("connect");
        std::io::Write::write_all(&mut s, &raw::connect_packet(4, "hangup", None)).expect("send");
    }
    std::thread::sleep(Duration::from_millis(500));
    let clients = Mosquitto::clients_for(port);
    assert!(one_status(&clients)["rtk"].is_object());
    assert_eq!(clients.sim_estop(1), 0);
    let status = one_status(&clients);
    assert!(
        status["robot"]["robot_status"].as_u64().expect("bits") & (1 << 3) != 0,
        "e-stop applied: {status}"
    );
    daemon.wait_log(WAIT, "embedded broker: connections refused or closed");
    let log = daemon.log.join("\n");
    assert!(!log.contains("panicked"), "{log}");
    assert!(
        !log.contains("embedded broker stopped"),
        "no restart was needed: {log}"
    );
    daemon.stop();
}

/// The broker process's id: the child of `daemon` running `broker-child`.
fn broker_pid(daemon: &Proc) -> i32 {
    let out = std::process::Command::new("pgrep")
        .args(["-P", &daemon.child.id().to_string(), "-f", "broker-child"])
        .output()
        .expect("pgrep runs");
    String::from_utf8_lossy(&out.stdout)
        .trim()
        .parse()
        .expect("one broker process")
}

#[test]
fn a_killed_broker_is_noticed_and_restarted_within_a_second() {
    let port = free_port();
    let mut daemon = Proc::start(&["sim", "--broker-port", &port.to_string()]);
    daemon.wait_log(WAIT, "MQTT subscribed");
    let first = broker_pid(&daemon);
    let killed = Instant::now();
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(first),
        nix::sys::signal::Signal::SIGKILL,
    )
    .expect("kill the broker");
    daemon.wait_log(WAIT, "embedded broker stopped");
    daemon.wait_log(WAIT, "embedded broker running again");
    let back = killed.elapsed();
    assert!(back < Duration::from_secs(1), "back after {back:?}");
    assert!(
        daemon.log.iter().any(|l| l.contains("killed by signal 9")),
        "{:#?}",
        daemon.log
    );
    assert_ne!(broker_pid(&daemon), first);
    // chassisd's own link reconnects, and the vehicle answers commands again.
    daemon.wait_log(WAIT, "MQTT subscribed");
    let clients = Mosquitto::clients_for(port);
    assert_eq!(clients.sim_estop(1), 0);
    // The restart is counted where monitoring and `check` read it.
    let health = clients.subscribe(&["chassisd/sim-mower/status/broker"]);
    let deadline = Instant::now() + WAIT;
    loop {
        let report: Value = serde_json::from_str(
            &health
                .next_on("chassisd/sim-mower/status/broker", WAIT)
                .expect("health report"),
        )
        .expect("JSON");
        if report["restarts"] == 1 && report["connected"].is_number() {
            assert!(
                report["last_exit"]
                    .as_str()
                    .is_some_and(|s| s.contains("signal 9")),
                "{report}"
            );
            break;
        }
        assert!(Instant::now() < deadline, "{report}");
    }
    daemon.stop();
}

const USER: &str = "operator";
const PASSWORD: &str = "correct horse battery staple";

/// A vehicle running the embedded broker on `host:port`, with `extra` lines in `[mqtt]`, and
/// a receiver on a port that is not there (a run needs a device; the link works regardless).
fn embedded_config(dir: &Path, host: &str, port: u16, extra: &str) -> PathBuf {
    let path = dir.join("vehicle.toml");
    let text = format!(
        "[vehicle]\nname = \"guarded\"\n\n[gnss]\nport = \"{}\"\n\n[mqtt]\nhost = \"{host}\"\n\
         port = {port}\nembedded_broker = true\nreconnect_max_s = 0.5\n{extra}\n[mqtt.rtk]\n",
        dir.join("no-such-receiver").display(),
    );
    std::fs::write(&path, text).expect("config written");
    path
}

fn run(config: &Path) -> Proc {
    Proc::start(&["run".as_ref(), "--config".as_ref(), config.as_os_str()])
}

/// The CONNACK codes a broker on `port` gives: anonymous, wrong password, unknown user, the
/// right credentials; in MQTT 3.1.1 then 5.
fn credential_answers(port: u16) -> Vec<Option<u8>> {
    let mut codes = Vec::new();
    for level in [4, 5] {
        for (i, credentials) in [
            None,
            Some((USER, "wrong")),
            Some(("evil", PASSWORD)),
            Some((USER, PASSWORD)),
        ]
        .into_iter()
        .enumerate()
        {
            codes.push(raw::connect(port, level, &format!("probe-{level}-{i}"), credentials).1);
        }
    }
    codes
}

#[test]
fn credentials_are_refused_exactly_as_mosquitto_refuses_them() {
    let dir = common::tempdir("embedded-credentials");
    let port = free_port();
    let config = embedded_config(
        &dir,
        "0.0.0.0",
        port,
        &format!("username = \"{USER}\"\npassword = \"{PASSWORD}\"\n"),
    );
    let mut daemon = run(&config);
    daemon.wait_log(WAIT, "MQTT subscribed");
    let mosquitto = Mosquitto::start_with_password(&dir, USER, PASSWORD);
    let ours = credential_answers(port);
    assert_eq!(ours, credential_answers(mosquitto.port));
    assert_eq!(
        ours,
        [
            Some(5),
            Some(5),
            Some(5),
            Some(0),
            Some(0x87),
            Some(0x87),
            Some(0x87),
            Some(0)
        ]
    );
    // Real clients: an anonymous reader and a publisher with a wrong password get nothing in.
    let anonymous = std::process::Command::new("mosquitto_sub")
        .args(["-p", &port.to_string(), "-t", "#", "-C", "1", "-W", "3"])
        .output()
        .expect("mosquitto_sub runs");
    assert!(!anonymous.status.success() && anonymous.stdout.is_empty());
    assert!(
        String::from_utf8_lossy(&anonymous.stderr).contains("not authorised"),
        "{}",
        String::from_utf8_lossy(&anonymous.stderr)
    );
    let evil = std::process::Command::new("mosquitto_pub")
        .args(["-p", &port.to_string(), "-u", "evil", "-P", "wrong", "-t"])
        .args(["/root/sim/cmd/chassis/set", "-m", "{}"])
        .output()
        .expect("mosquitto_pub runs");
    assert!(!evil.status.success());
    let clients = Mosquitto::clients_with(port, &["-u", USER, "-P", PASSWORD]);
    assert!(one_status(&clients)["rtk"].is_object());
    daemon.wait_log(WAIT, "refused_credentials=");
    // `check` sees the running broker and what it refused.
    std::thread::sleep(Duration::from_secs(6));
    let check = std::process::Command::new(common::chassisd())
        .args(["check", "--config"])
        .arg(&config)
        .output()
        .expect("check runs");
    let table = String::from_utf8_lossy(&check.stdout);
    assert!(
        table.contains("embedded, running") && table.contains("0 restarts"),
        "{table}"
    );
    let refused: u64 = table
        .split("refused since the last restart: ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("the refusals in the table");
    // Six probes, the anonymous reader and the wrong publisher.
    assert!(refused >= 8, "refusals counted: {table}");
    daemon.stop();
}

#[test]
fn a_broker_open_to_the_network_without_credentials_is_refused_at_load() {
    let dir = common::tempdir("embedded-open");
    let config = embedded_config(&dir, "0.0.0.0", free_port(), "");
    for command in ["run", "check"] {
        let out = std::process::Command::new(common::chassisd())
            .args([command, "--config"])
            .arg(&config)
            .output()
            .expect("chassisd runs");
        assert_eq!(out.status.code(), Some(78), "{command}");
        let message = String::from_utf8_lossy(&out.stderr);
        assert!(
            message.contains("mqtt.username") && message.contains("127.0.0.1"),
            "{message}"
        );
    }
}

#[test]
fn the_embedded_broker_serves_tls_to_chassisd_and_to_clients() {
    let dir = common::tempdir("embedded-tls");
    let pki = TestPki::create(&dir, "embedded");
    let port = free_port();
    let config = embedded_config(
        &dir,
        "127.0.0.1",
        port,
        &format!(
            "username = \"{USER}\"\npassword = \"{PASSWORD}\"\n\n[mqtt.tls]\nca_file = \"{}\"\n\
             cert_file = \"{}\"\nkey_file = \"{}\"\n",
            pki.ca.display(),
            pki.cert.display(),
            pki.key.display()
        ),
    );
    let mut daemon = run(&config);
    // chassisd's own link is a TLS client of its own broker.
    daemon.wait_log(WAIT, "MQTT subscribed");
    let ca = pki.ca.display().to_string();
    let clients = Mosquitto::clients_with(port, &["--cafile", &ca, "-u", USER, "-P", PASSWORD]);
    assert!(one_status(&clients)["rtk"].is_object());
    // A client without TLS gets no CONNACK: the gate wants a TLS handshake first.
    assert_eq!(
        raw::connect(port, 4, "plain", Some((USER, PASSWORD))).1,
        None
    );
    daemon.stop();
}

/// Random but well-formed MQTT sessions, for the broker's record under load.
mod chaos {
    use std::io::{Read, Write};
    use std::net::TcpStream;
    use std::time::{Duration, Instant};

    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::raw;

    use chassisd::broker::wire::packet;

    fn string(s: &str, out: &mut Vec<u8>) {
        out.extend_from_slice(&(s.len() as u16).to_be_bytes());
        out.extend_from_slice(s.as_bytes());
    }

    const FILTERS: &[&str] = &[
        "#",
        "+",
        "chaos/#",
        "chaos/+/x",
        "chaos/a",
        "$share/g/chaos/a",
        "$share/g/#",
        "$share/h/chaos/+/x",
        "base_status",
        "$SYS/#",
    ];
    const TOPICS: &[&str] = &["chaos/a", "chaos/b/x", "chaos/c", "chaos"];

    /// One packet a client may send, with random fields.
    fn any_packet(rng: &mut ChaCha8Rng, v5: bool) -> Vec<u8> {
        let props = |b: &mut Vec<u8>| {
            if v5 {
                b.push(0);
            }
        };
        let id: u16 = rng.random_range(1..20);
        match rng.random_range(0..9) {
            0 | 1 => {
                let mut b = id.to_be_bytes().to_vec();
                props(&mut b);
                for _ in 0..rng.random_range(1..4) {
                    string(FILTERS[rng.random_range(0..FILTERS.len())], &mut b);
                    b.push(rng.random_range(0..3));
                }
                packet(0x82, &b)
            }
            2 => {
                let mut b = id.to_be_bytes().to_vec();
                props(&mut b);
                string(FILTERS[rng.random_range(0..FILTERS.len())], &mut b);
                packet(0xa2, &b)
            }
            3..=5 => {
                let qos: u8 = rng.random_range(0..3);
                let retain = u8::from(rng.random_bool(0.2));
                let mut b = Vec::new();
                string(TOPICS[rng.random_range(0..TOPICS.len())], &mut b);
                if qos > 0 {
                    b.extend_from_slice(&id.to_be_bytes());
                }
                props(&mut b);
                b.extend(std::iter::repeat_n(b'p', rng.random_range(0..300)));
                packet(0x30 | qos << 1 | retain, &b)
            }
            6 => {
                let first = [0x40, 0x50, 0x62, 0x70][rng.random_range(0..4)];
                packet(first, &id.to_be_bytes())
            }
            _ => vec![0xc0, 0x00],
        }
    }

    /// Runs random sessions against `port` until `until`; returns how many it ran.
    pub fn sessions(port: u16, seed: u64, until: Instant) -> u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut n = 0;
        while Instant::now() < until {
            n += 1;
            let v5 = rng.random_bool(0.5);
            // A small pool of identifiers, so that sessions take each other over.
            let id = format!("chaos-{}", rng.random_range(0..6));
            let connect = raw::connect_packet(if v5 { 5 } else { 4 }, &id, None);
            let Some((mut s, Some(0))) = raw::try_connect_with(port, &connect) else {
                std::thread::sleep(Duration::from_millis(20));
                continue;
            };
            let _ = s.set_read_timeout(Some(Duration::from_millis(2)));
            let mut sink = [0u8; 4096];
            for _ in 0..rng.random_range(0..30) {
                if s.write_all(&any_packet(&mut rng, v5)).is_err() {
                    break;
                }
                let _ = s.read(&mut sink);
            }
            match rng.random_range(0..4) {
                0 => {
                    let _ = s.write_all(&[0xe0, 0x00]);
                }
                1 => {
                    let _ = s.shutdown(std::net::Shutdown::Write);
                    let _ = s.read(&mut sink);
                }
                // Hang up without a word, or leave a half packet behind.
                2 => {}
                _ => {
                    let _ = s.write_all(&[0x32, 0x40, 0x00]);
                }
            }
            drop(s);
            let _ = TcpStream::connect(("127.0.0.1", port)).map(drop);
        }
        n
    }
}

#[test]
fn random_sessions_never_bring_the_broker_down() {
    let port = free_port();
    let mut daemon = Proc::start(&["sim", "--broker-port", &port.to_string()]);
    daemon.wait_log(WAIT, "MQTT subscribed");
    let until = Instant::now() + Duration::from_secs(20);
    let workers: Vec<_> = (0..6)
        .map(|seed| std::thread::spawn(move || chaos::sessions(port, seed, until)))
        .collect();
    let sessions: u64 = workers
        .into_iter()
        .map(|w| w.join().expect("a chaos client"))
        .sum();
    eprintln!("{sessions} random sessions");
    assert!(sessions > 100, "{sessions} sessions");
    let clients = Mosquitto::clients_for(port);
    assert!(one_status(&clients)["rtk"].is_object());
    assert_eq!(clients.sim_estop(1), 0);
    daemon.log.extend(daemon.stderr.try_iter());
    let log = daemon.log.join("\n");
    assert!(
        !log.contains("embedded broker stopped") && !log.contains("panicked"),
        "after {sessions} sessions: {log}"
    );
    daemon.stop();
}

#[test]
fn silent_malformed_and_unread_clients_cost_the_broker_nothing() {
    use std::io::{Read, Write};
    let port = free_port();
    let mut daemon = Proc::start(&["sim", "--broker-port", &port.to_string()]);
    daemon.wait_log(WAIT, "MQTT subscribed");
    let clients = Mosquitto::clients_for(port);
    // 100 connections that never say a word: 64 wait their handshake out, the rest are
    // closed at once; after the 5 s handshake limit, all of them.
    let silent: Vec<std::net::TcpStream> = (0..100)
        .map(|_| std::net::TcpStream::connect(("127.0.0.1", port)).expect("connect"))
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let closed = |s: &std::net::TcpStream| {
        s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
        matches!((&*s).read(&mut [0u8; 1]), Ok(0))
    };
    let early = silent.iter().filter(|s| closed(s)).count();
    assert!(early >= 36, "{early} closed at once");
    // A client in its handshake meanwhile still gets in.
    assert!(one_status(&clients)["rtk"].is_object());
    std::thread::sleep(Duration::from_secs(6));
    assert_eq!(silent.iter().filter(|s| closed(s)).count(), 100);
    // Garbage after a good CONNECT: the session ends, nothing else does.
    let (mut s, code) = raw::connect(port, 4, "garbage", None);
    assert_eq!(code, Some(0));
    s.write_all(&[0xff; 64]).expect("garbage");
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    assert!(
        matches!(s.read(&mut [0u8; 16]), Ok(0)),
        "closed by the gate"
    );
    // A subscriber to everything that never reads delays nobody else.
    let (mut lazy, code) = raw::connect(port, 4, "lazy", None);
    assert_eq!(code, Some(0));
    lazy.write_all(&[0x82, 0x06, 0x00, 0x01, 0x00, 0x01, b'#', 0x00])
        .expect("subscribe");
    let status = clients.subscribe(&["base_status"]);
    let start = Instant::now();
    let mut arrivals = Vec::new();
    while start.elapsed() < Duration::from_secs(10) {
        if status.next_on("base_status", WAIT).is_some() {
            arrivals.push(Instant::now());
        }
    }
    let largest = arrivals
        .windows(2)
        .map(|w| (w[1] - w[0]).as_secs_f64())
        .fold(0.0, f64::max);
    assert!(arrivals.len() >= 90, "{} statuses in 10 s", arrivals.len());
    assert!(largest < 0.5, "largest gap {largest:.3} s");
    daemon.log.extend(daemon.stderr.try_iter());
    assert!(
        !daemon
            .log
            .iter()
            .any(|l| l.contains("embedded broker stopped")),
        "{:#?}",
        daemon.log
    );
    drop(lazy);
    daemon.stop();
}

/// A `save_trajectory` of `points` points called `name` (some 100 bytes a point).
fn save_message(name: &str, points: usize) -> String {
    let data: Vec<Value> = (0..points)
        .map(|i| {
            serde_json::json!({"angle": 0.0, "latitude": 47.397742 + i as f64 * 1e-7,
                "longitude": 8.5455966, "x": 0.0, "y": i as f64 * 0.01, "yaw": 0.0})
        })
        .collect();
    serde_json::json!({"cmd": "save_trajectory", "cmd_type": "trajectory_control",
        "data": {"name": name, "data": data}})
    .to_string()
}

#[test]
fn a_trajectory_listing_larger_than_a_packet_is_refused_and_the_session_survives() {
    let port = free_port();
    let mut daemon = Proc::start(&["sim", "--broker-port", &port.to_string()]);
    daemon.wait_log(WAIT, "MQTT subscribed");
    let clients = Mosquitto::clients_for(port);
    let answers = clients.subscribe(&["feedback", "trajectory_data"]);
    let dir = common::tempdir("big-trajectories");
    // Seven saves of 0.7 MB, each within max_payload (1 MiB): 4.7 MB together, more than
    // the 4 MiB a packet may carry.
    for k in 0..7 {
        let file = dir.join(format!("t{k}.json"));
        std::fs::write(&file, save_message(&format!("t{k}"), 7000)).expect("write");
        clients.publish_file("mqtt_control", &file);
        let answer = answers.next_on("feedback", WAIT).expect("save answered");
        assert!(answer.contains("save_trajectory_success"), "{answer}");
    }
    let list = r#"{"cmd": "get_all_trajectory", "cmd_type": "trajectory_control"}"#;
    clients.publish("mqtt_control", list);
    let (topic, answer) = answers.next(WAIT).expect("listing answered");
    let answer: Value = serde_json::from_str(&answer).expect("JSON");
    assert_eq!(
        (topic.as_str(), answer["cmd"].as_str()),
        ("feedback", Some("get_all_trajectory_failse")),
        "{answer}"
    );
    let reason = answer["message"].as_str().expect("a reason");
    assert!(
        reason.contains("7 trajectories stored (49000 points)")
            && reason.contains("mqtt.max_payload")
            && reason.contains("delete trajectories"),
        "{reason}"
    );
    // The link was never lost, and with one trajectory fewer the listing fits and comes.
    clients.publish(
        "mqtt_control",
        r#"{"cmd": "delete_trajectory", "cmd_type": "trajectory_control", "name": "t0"}"#,
    );
    let answer = answers.next_on("feedback", WAIT).expect("delete answered");
    assert!(answer.contains("delete_trajectory_success"), "{answer}");
    clients.publish("mqtt_control", list);
    let listing = answers
        .next_on("trajectory_data", WAIT)
        .expect("the listing");
    let listing: Value = serde_json::from_str(&listing).expect("JSON");
    assert_eq!(listing.as_array().map(Vec::len), Some(6));
    assert_eq!(
        daemon.log_count("MQTT connection lost"),
        0,
        "{:?}",
        daemon.log
    );
    daemon.stop();
}
