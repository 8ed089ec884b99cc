//! Commands a hostile or broken client sends, over a real mosquitto with real clients, the
//! daemon running the simulated vehicle: every one is refused in the protocol's own reply
//! format, naming the limit and its configuration key, and none moves the vehicle or its
//! pose; a garbage heartbeat arms nothing; and a flood of invented topic names is refused
//! before anything decodes or logs it message by message.

use crate::common;

use std::io::Write;
use std::time::{Duration, Instant};

use common::mqtt::{Mosquitto, Subscriber, free_port, raw};
use common::process::Proc;
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(15);

fn json(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("not JSON ({e}): {text}"))
}

/// A publish through `broker`, and the answer on `answer_topic`.
fn ask(broker: &Mosquitto, acks: &Subscriber, topic: &str, payload: &str, answer: &str) -> Value {
    acks.clear();
    broker.publish(topic, payload);
    json(
        &acks
            .next_on(answer, WAIT)
            .unwrap_or_else(|| panic!("no answer on {answer}")),
    )
}

/// The simulated vehicle on `broker` (and a WebSocket server on `websocket`, with the
/// local channel on standard input), located: goals need it.
fn located_vehicle(broker: &Mosquitto, websocket: u16) -> Proc {
    let bind = format!("127.0.0.1:{websocket}");
    let mut d = Proc::start(&[
        "sim",
        "--mqtt",
        &broker.address(),
        "--websocket",
        &bind,
        "--commands-stdin",
    ]);
    d.wait_log(WAIT, "MQTT subscribed");
    d.wait_out(Duration::from_secs(30), "LOCATE_TRUE", |l| {
        serde_json::from_str::<Value>(l).is_ok_and(|s| s["nav"]["locate"] == "LOCATE_TRUE")
    });
    d
}

fn last_status(d: &mut Proc) -> Value {
    d.drain_out();
    d.out
        .iter()
        .rev()
        .find_map(|l| serde_json::from_str::<Value>(l).ok())
        .expect("a status line")
}

#[test]
fn goals_and_positions_beyond_their_limits_are_refused_naming_the_key() {
    let broker = Mosquitto::start();
    let acks = broker.subscribe(&["device/SIM0001/goal/ack", "/root/sim/+/+/ack"]);
    let websocket = free_port();
    let mut d = located_vehicle(&broker, websocket);
    let before = last_status(&mut d);

    // The same goal on every channel: the local one (stdin) and rosbridge's /goal_pose.
    d.send(r#"goal {"x": 1e308, "y": 0.0, "yaw": 0.0}"#);
    d.wait_log(WAIT, "motion.max_goal_distance_m");
    let (mut ws, code) =
        common::ws::handshake(websocket, "/", &format!("127.0.0.1:{websocket}"), None);
    assert_eq!(code, 101);
    common::ws::send_text(
        &mut ws,
        r#"{"op": "publish", "topic": "/goal_pose", "msg": {"header": {"frame_id": "map"}, "pose": {"position": {"x": 1e300, "y": 0, "z": 0}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}}}"#,
    )
    .unwrap();
    let refusal = loop {
        let v = common::ws::next_json(&mut ws).expect("a status");
        if v["op"] == "status" {
            break v["msg"].as_str().unwrap_or_default().to_owned();
        }
    };
    assert!(
        refusal.contains("motion.max_goal_distance_m") && refusal.contains("/goal_pose"),
        "{refusal}"
    );

    // A goal 1e308 m away (device dialect): a failure ack naming the limit.
    let ack = ask(
        &broker,
        &acks,
        "device/SIM0001/goal",
        r#"{"msg_id": "far", "timestamp": 1757403776, "data": {"x": 1e308, "y": 0, "z": 0}}"#,
        "device/SIM0001/goal/ack",
    );
    assert_eq!(ack["success"], false, "{ack}");
    let message = ack["message"].as_str().unwrap_or_default();
    assert!(
        message.contains("motion.max_goal_distance_m") && message.contains("1e308"),
        "{ack}"
    );
    // MOVE_TO_POSITION 5 km away (root mission): INVALID, naming the same key.
    let ack = ask(
        &broker,
        &acks,
        "/root/sim/cmd/navigation/set",
        r#"{"messageId": 5, "timestamp": "x", "messageType": 5, "data": [{"action": "MOVE_TO_POSITION", "parameters": {"path": [5000.0, 0.0]}}]}"#,
        "/root/sim/cmd/navigation/ack",
    );
    assert_eq!(ack["data"]["code"], 1, "{ack}");
    assert!(
        ack["data"]["message"]
            .as_str()
            .is_some_and(|m| m.contains("motion.max_goal_distance_m")),
        "{ack}"
    );
    // INIT_POSITION 1e308 m from the datum.
    let ack = ask(
        &broker,
        &acks,
        "/root/sim/cmd/navigation/set",
        r#"{"messageId": 6, "timestamp": "x", "messageType": 0, "data": [1e308, 1e308, 0, 0, 0, 0, 1]}"#,
        "/root/sim/cmd/navigation/ack",
    );
    assert_eq!(ack["data"]["code"], 1, "{ack}");
    assert!(
        ack["data"]["message"]
            .as_str()
            .is_some_and(|m| m.contains("localization.max_position_radius_m")),
        "{ack}"
    );
    // SET_LNG_LAT at a height of 1e308 m, and at latitude 95°.
    for (data, what) in [
        ("[116.0, 40.0, 1e308]", "height"),
        ("[116.0, 95.0, 50.0]", "latitude"),
    ] {
        let ack = ask(
            &broker,
            &acks,
            "/root/sim/setting/navigation/set",
            &format!(r#"{{"messageId": 7, "timestamp": "x", "messageType": 100, "data": {data}}}"#),
            "/root/sim/setting/navigation/ack",
        );
        assert_eq!(ack["data"]["code"], 1, "{ack}");
        assert!(
            ack["data"]["message"]
                .as_str()
                .is_some_and(|m| m.contains(what) && m.contains("outside")),
            "{ack}"
        );
    }
    // Nothing moved: neither the vehicle nor its pose.
    std::thread::sleep(Duration::from_millis(500));
    let after = last_status(&mut d);
    for key in ["x", "y"] {
        let (a, b) = (
            before["pose"][key].as_f64().unwrap(),
            after["pose"][key].as_f64().unwrap(),
        );
        assert!((a - b).abs() < 0.05, "pose.{key} {a} -> {b}");
    }
    assert_eq!(after["nav"]["locate"], "LOCATE_TRUE");
    assert!(after["robot"]["vx"].as_f64().unwrap().abs() < 0.01);
    d.stop();
}

#[test]
fn a_garbage_heartbeat_is_not_answered_and_arms_no_watchdog() {
    let broker = Mosquitto::start();
    let notify = broker.subscribe(&["/root/sim/heartbeat/notify", "base_status"]);
    let mut d = Proc::start(&["sim", "--mqtt", &broker.address()]);
    d.wait_log(WAIT, "MQTT subscribed");
    broker.publish("/root/sim/heartbeat/set", "garbage not json");
    assert_eq!(
        notify.next_on("/root/sim/heartbeat/notify", Duration::from_secs(2)),
        None,
        "a garbage heartbeat is not answered"
    );
    // An operator who sends only DRIVE: after the 3 s heartbeat timeout, still not latched.
    let until = Instant::now() + Duration::from_secs(4);
    while Instant::now() < until {
        broker.publish(
            "/root/sim/cmd/chassis/set",
            r#"{"messageId": 1, "timestamp": "x", "messageType": 100, "data": {"linear": 0.3, "angular": 0.0}}"#,
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    notify.clear();
    let status = json(&notify.next_on("base_status", WAIT).expect("base_status"));
    let bits = status["robot"]["robot_status"].as_u64().unwrap();
    assert_eq!(bits & (1 << 10), 0, "CONTROL_LINK_LOST latched: {status}");
    assert!(status["robot"]["vx"].as_f64().unwrap() > 0.1, "{status}");
    d.log.extend(d.stderr.try_iter());
    assert!(
        d.log
            .iter()
            .any(|l| l.contains("root heartbeat ignored: not a JSON object")),
        "{:#?}",
        d.log
    );
    d.stop();
}

/// A client that publishes at `rate` per second, a new topic name each time, until
/// `until`; it reconnects when the broker closes it. Returns how many it sent.
fn invent_names(port: u16, client: usize, rate: f64, until: Instant) -> u64 {
    let mut sent = 0u64;
    let started = Instant::now();
    'connect: while Instant::now() < until {
        let connect = raw::connect_packet(4, &format!("inventor-{client}"), None);
        let Some((mut s, Some(0))) = raw::try_connect_with(port, &connect) else {
            std::thread::sleep(Duration::from_millis(20));
            continue;
        };
        let _ = s.set_nodelay(true);
        while Instant::now() < until {
            // Keep to the rate: as many as are due by now.
            let due = (started.elapsed().as_secs_f64() * rate) as u64;
            if sent >= due {
                std::thread::sleep(Duration::from_millis(2));
                continue;
            }
            let topic = format!("device/SIM0001/x{client}-{sent}");
            let payload = br#"{"msg_id": "1", "data": {}}"#;
            let mut p = vec![0x30, (2 + topic.len() + payload.len()) as u8];
            p.extend_from_slice(&(topic.len() as u16).to_be_bytes());
            p.extend_from_slice(topic.as_bytes());
            p.extend_from_slice(payload);
            if s.write_all(&p).is_err() {
                continue 'connect;
            }
            sent += 1;
        }
    }
    sent
}

/// Three clients at 2,500 messages per second each, a new topic name every message, for
/// 10 s; the figures the issue sets: at most 100 WARN lines, RSS +5 MB at most, and
/// base_status at its period.
fn invented_names_flood(mut daemon: Proc, port: u16, broker: &str) {
    daemon.wait_log(WAIT, "MQTT subscribed");
    let clients = Mosquitto::clients_for(port);
    let status = clients.subscribe(&["base_status"]);
    status.next_on("base_status", WAIT).expect("base_status");
    std::thread::sleep(Duration::from_secs(1));
    daemon.log.extend(daemon.stderr.try_iter());
    let logged_before = daemon.log.len();
    let pid = daemon.child.id();
    let rss_before = common::rss_with_children_kb(pid);
    let until = Instant::now() + Duration::from_secs(10);
    let inventors: Vec<_> = (0..3)
        .map(|c| std::thread::spawn(move || invent_names(port, c, 2500.0, until)))
        .collect();
    let mut arrivals = Vec::new();
    while Instant::now() < until {
        if let Some((topic, _)) = status.next(Duration::from_millis(50))
            && topic == "base_status"
        {
            arrivals.push(Instant::now());
        }
    }
    let sent: u64 = inventors
        .into_iter()
        .map(|h| h.join().expect("client"))
        .sum();
    std::thread::sleep(Duration::from_secs(1));
    let rss_after = common::rss_with_children_kb(pid);
    daemon.log.extend(daemon.stderr.try_iter());
    let warns = daemon.log[logged_before..]
        .iter()
        .filter(|l| l.contains(" WARN "))
        .count();
    let largest = arrivals
        .windows(2)
        .map(|w| (w[1] - w[0]).as_secs_f64())
        .fold(0.0, f64::max);
    eprintln!(
        "{broker}: {sent} messages on invented names in 10 s; {warns} WARN lines; base_status {} \
         times, largest gap {largest:.3} s; RSS {rss_before} -> {rss_after} kB",
        arrivals.len()
    );
    assert!(
        warns <= 100,
        "{warns} WARN lines: {:#?}",
        &daemon.log[logged_before..]
    );
    assert!(
        rss_after <= rss_before + 5 * 1024,
        "RSS {rss_before} -> {rss_after} kB"
    );
    assert!(arrivals.len() >= 90, "base_status {} times", arrivals.len());
    assert!(largest < 0.5, "base_status stopped for {largest:.3} s");
    // Commands on the vehicle's own topics are still answered at once.
    let acks = clients.subscribe(&["/root/sim/cmd/chassis/ack"]);
    clients.publish(
        "/root/sim/cmd/chassis/set",
        r#"{"messageId": 9, "timestamp": "x", "messageType": 100, "data": {"linear": 0.0, "angular": 0.0}}"#,
    );
    assert!(acks.next_on("/root/sim/cmd/chassis/ack", WAIT).is_some());
    daemon.stop();
}

#[test]
fn invented_topic_names_share_one_rate_limit_on_mosquitto() {
    let broker = Mosquitto::start();
    let daemon = Proc::start(&["sim", "--mqtt", &broker.address()]);
    invented_names_flood(daemon, broker.port, "mosquitto");
}

#[test]
fn invented_topic_names_share_one_rate_limit_on_the_embedded_broker() {
    let port = free_port();
    let daemon = Proc::start(&["sim", "--broker-port", &port.to_string()]);
    invented_names_flood(daemon, port, "embedded");
}
