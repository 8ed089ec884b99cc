//! Dialect `root` over a real mosquitto with real clients, the daemon running the simulated
//! vehicle: every command example of root-mqtt-api.rst sent as written gets an ack of the
//! documented shape with its messageId and the documented outcome; DRIVE moves the vehicle;
//! the reports arrive with the spec's keys; the heartbeat is answered and its loss stops the
//! vehicle; bad requests get error acks and change nothing.

use crate::common;

use std::time::{Duration, Instant};

use common::mqtt::{Mosquitto, Subscriber};
use common::process::Proc;
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(10);
const ID: &str = "sim";

fn daemon(broker: &Mosquitto) -> Proc {
    let mut p = Proc::start(&["sim", "--mqtt", &broker.address()]);
    p.wait_log(WAIT, "MQTT subscribed");
    p
}

fn json(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("not JSON ({e}): {text}"))
}

fn topic(rest: &str) -> String {
    format!("/root/{ID}/{rest}")
}

/// Publishes on `set_topic` and returns the ack (and the notify, when `notify`).
fn request(broker: &Mosquitto, acks: &Subscriber, set_topic: &str, payload: &str) -> Value {
    acks.clear();
    broker.publish(set_topic, payload);
    let ack_topic = sibling(set_topic, "ack");
    json(
        &acks
            .next_on(&ack_topic, WAIT)
            .unwrap_or_else(|| panic!("no ack on {ack_topic}")),
    )
}

/// `.../set` → `.../<suffix>`.
fn sibling(set_topic: &str, suffix: &str) -> String {
    let base = set_topic.strip_suffix("/set").expect("a set topic");
    format!("{base}/{suffix}")
}

fn is_timestamp(v: &Value) -> bool {
    v.as_str().is_some_and(|s| {
        s.len() == 19 && chrono::NaiveDateTime::parse_from_str(s, "%Y-%m-%d %H:%M:%S").is_ok()
    })
}

/// The spec's keys, at every level, are in ours (we may add keys); kinds match.
fn has_spec_keys(spec: &Value, ours: &Value, path: &str) {
    match (spec, ours) {
        (Value::Object(a), Value::Object(b)) => {
            for (k, v) in a {
                let o = b
                    .get(k)
                    .unwrap_or_else(|| panic!("{path}.{k} missing in {ours}"));
                has_spec_keys(v, o, &format!("{path}.{k}"));
            }
        }
        (Value::Array(_), Value::Array(_))
        | (Value::Number(_), Value::Number(_))
        | (Value::Bool(_), Value::Bool(_)) => {}
        (Value::String(s), v) if s.starts_with('%') => assert!(is_timestamp(v), "{path}: {v}"),
        (Value::String(_), Value::String(_)) => {}
        _ => panic!("{path}: spec has {spec}, chassisd sends {ours}"),
    }
}

fn wait_for_speed(status: &Subscriber, want: impl Fn(f64) -> bool, what: &str) {
    let deadline = Instant::now() + WAIT;
    while Instant::now() < deadline {
        if let Some(s) = status.next_on("base_status", WAIT)
            && want(json(&s)["robot"]["vx"].as_f64().unwrap_or(f64::NAN))
        {
            return;
        }
    }
    panic!("never {what}");
}

#[test]
fn every_command_example_gets_its_documented_ack() {
    let broker = Mosquitto::start();
    let acks = broker.subscribe(&[
        &topic("+/+/ack"),
        &topic("+/+/notify"),
        &topic("heartbeat/notify"),
    ]);
    let status = broker.subscribe(&["base_status"]);
    let _d = daemon(&broker);
    let spec = common::shared_spec("root-mqtt-api.rst");
    let examples = common::spec::rst_json_examples(&spec, ID);
    let ack_example = json(
        &examples
            .iter()
            .find(|e| e.topic.ends_with("/cmd/navigation/ack"))
            .expect("the ack example")
            .text,
    );
    let sets: Vec<_> = examples
        .iter()
        .filter(|e| e.topic.ends_with("/set"))
        .collect();
    let kinds: Vec<(String, Option<u64>)> = sets
        .iter()
        .map(|e| {
            let v: Value = serde_json::from_str(&e.text).unwrap_or(Value::Null);
            (e.topic.clone(), v["messageType"].as_u64())
        })
        .collect();
    assert_eq!(
        kinds.iter().map(|(_, k)| *k).collect::<Vec<_>>(),
        [
            Some(0),
            Some(1),
            Some(2),
            Some(3),
            Some(4),
            Some(5),
            Some(6),
            Some(100),
            Some(0),
            Some(100),
            None
        ],
        "{kinds:?}"
    );
    // What each example must get: (ack code, notify too).
    let expected = [
        (0, true),  // INIT_POSITION
        (0, false), // PAUSE: stops the vehicle
        (4, false), // CONTINUE: refused, no task is paused
        (3, false), // MAPPING_START: the navigation stack's job
        (3, false), // MAPPING_STOP
        (4, false), // MISSION: refused, PAUSE latched the operator's stop
        (0, false), // SWITCH_MODE 0: navigation mode
        (4, false), // DRIVE: refused in navigation mode
        (3, false), // SET_MAP
        (0, false), // SET_LNG_LAT
    ];
    wait_for_speed(&status, |v| v.is_finite(), "a status");
    for (example, (code, notify)) in sets.iter().zip(expected) {
        let sent: Value = json(&example.text);
        let ack = request(&broker, &acks, &example.topic, &example.text);
        has_spec_keys(&ack_example, &ack, &example.topic);
        assert_eq!(ack["messageId"], sent["messageId"], "{ack}");
        assert_eq!(ack["messageType"], sent["messageType"], "{ack}");
        assert_eq!(ack["data"]["code"], code, "{} → {ack}", example.topic);
        assert_eq!(ack["data"].get("message").is_some(), code != 0, "{ack}");
        if notify {
            let n = acks
                .next_on(&sibling(&example.topic, "notify"), WAIT)
                .expect("a notify");
            assert_eq!(json(&n)["data"]["code"], 0);
        }
    }
    // The heartbeat example (a trailing comma and all) is answered on notify.
    let heartbeat = sets.last().expect("heartbeat");
    acks.clear();
    broker.publish(&heartbeat.topic, &heartbeat.text);
    let beat = json(
        &acks
            .next_on(&topic("heartbeat/notify"), WAIT)
            .expect("heartbeat notify"),
    );
    assert!(is_timestamp(&beat["timestamp"]), "{beat}");
    // Back to manual: the DRIVE example now moves the vehicle.
    let manual =
        r#"{"messageId": 9, "timestamp": "2026-11-22 03:00:00", "messageType": 6, "data": 1}"#;
    assert_eq!(
        request(&broker, &acks, &topic("cmd/navigation/set"), manual)["data"]["code"],
        0
    );
    // PAUSE latched a stop: DRIVE is refused until the RESET extension (or a zero DRIVE).
    let drive = &sets[7];
    let refused = request(&broker, &acks, &drive.topic, &drive.text);
    assert_eq!(refused["data"]["code"], 4, "{refused}");
    assert!(
        refused["data"]["message"]
            .as_str()
            .is_some_and(|m| m.contains("stopped by the operator") && m.contains("reset")),
        "{refused}"
    );
    let reset =
        r#"{"messageId": 10, "timestamp": "2026-11-22 03:00:01", "messageType": 102, "data": {}}"#;
    assert_eq!(
        request(&broker, &acks, &topic("cmd/chassis/set"), reset)["data"]["code"],
        0
    );
    // Beyond the limits: refused as invalid, naming the limit and its key; nothing moves.
    let wild = r#"{"messageId": 11, "timestamp": "2026-11-22 03:00:02", "messageType": 100, "data": {"linear": 1e308, "angular": -1e308}}"#;
    let refused = request(&broker, &acks, &drive.topic, wild);
    assert_eq!(refused["data"]["code"], 1, "{refused}");
    assert!(
        refused["data"]["message"].as_str().is_some_and(|m| {
            m.contains("beyond the limit of 1.5 m/s") && m.contains("chassis.max_speed_mps")
        }),
        "{refused}"
    );
    for _ in 0..20 {
        broker.publish(&drive.topic, &drive.text);
        broker.publish(&heartbeat.topic, &heartbeat.text);
        std::thread::sleep(Duration::from_millis(100));
    }
    wait_for_speed(&status, |v| v > 0.3, "moving under DRIVE");
}

#[test]
fn reports_arrive_with_the_spec_keys() {
    let broker = Mosquitto::start();
    let reports = broker.subscribe(&[&topic("report/#")]);
    let _d = daemon(&broker);
    let spec = common::shared_spec("root-mqtt-api.rst");
    let examples = common::spec::rst_json_examples(&spec, ID);
    let mut seen = std::collections::BTreeMap::new();
    let deadline = Instant::now() + Duration::from_secs(4);
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        let Some((t, p)) = reports.next(left) else {
            break;
        };
        seen.entry(t).or_insert_with(Vec::new).push(json(&p));
    }
    for rest in [
        "report/navigation/localization",
        "report/navigation/obstacle",
        "report/navigation/usage",
        "report/chassis/general",
        "report/navigation/general",
    ] {
        let ours = seen
            .get(&topic(rest))
            .unwrap_or_else(|| panic!("no {rest}: {:?}", seen.keys()));
        // The spec's example for it; navigation general's example sits under the chassis
        // topic in the spec (documented).
        let example = examples
            .iter()
            .filter(|e| {
                e.topic
                    == topic(if rest == "report/navigation/general" {
                        "report/chassis/general"
                    } else {
                        rest
                    })
            })
            .map(|e| {
                common::spec::strip_json_comments(&e.text)
                    .replace(",\n}", "\n}")
                    .replace(",\n    }", "\n    }")
            })
            .filter_map(|t| serde_json::from_str::<Value>(&fix_trailing_commas(&t)).ok())
            .find(|v| rest != "report/navigation/general" || v["data"].get("mapping").is_some())
            .unwrap_or_else(|| panic!("no example for {rest}"));
        has_spec_keys(&example, &ours[0], rest);
    }
    // Rates: localization and chassis at 5 Hz, the others at 1 Hz (4 s observed; a report
    // delayed by a busy machine may fall on either side of the window's ends).
    let count = |rest: &str| seen.get(&topic(rest)).map_or(0, Vec::len);
    let localization = count("report/navigation/localization");
    assert!(
        (17..=22).contains(&localization),
        "{localization} localization reports"
    );
    let usage = count("report/navigation/usage");
    assert!((2..=6).contains(&usage), "{usage} usage reports");
    let usage = &seen[&topic("report/navigation/usage")][0]["data"];
    assert!(
        usage["cpu"]
            .as_f64()
            .is_some_and(|c| (0.0..=100.0).contains(&c))
    );
    assert!(
        usage["memory"]
            .as_f64()
            .is_some_and(|m| m > 0.0 && m <= 100.0)
    );
}

/// The spec's examples carry trailing commas (`"memory": 5.76,` before `}`); JSON does not.
fn fix_trailing_commas(text: &str) -> String {
    let mut out = String::new();
    let chars: Vec<char> = text.chars().collect();
    for (i, c) in chars.iter().enumerate() {
        if *c == ',' {
            let next = chars[i + 1..].iter().find(|c| !c.is_whitespace());
            if matches!(next, Some('}') | Some(']')) {
                continue;
            }
        }
        out.push(*c);
    }
    out
}

/// `n` rounds, 100 ms apart, of a heartbeat and the DRIVE request `drive`.
fn drive_with_heartbeats(broker: &Mosquitto, drive: &str, n: usize) {
    for _ in 0..n {
        broker.publish(&topic("heartbeat/set"), r#"{"timestamp": "x"}"#);
        broker.publish(&topic("cmd/chassis/set"), drive);
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_silent_heartbeat_stops_the_vehicle_until_it_beats_again() {
    let broker = Mosquitto::start();
    let acks = broker.subscribe(&[&topic("+/+/ack")]);
    let log = broker.subscribe(&[&topic("log/notify")]);
    let status = broker.subscribe(&["base_status"]);
    let _d = daemon(&broker);
    let drive = r#"{"messageId": 1, "timestamp": "x", "messageType": 100, "data": {"linear": 0.5, "angular": 0.0}}"#;
    drive_with_heartbeats(&broker, drive, 20);
    wait_for_speed(&status, |v| v > 0.3, "moving");
    // DRIVE goes on, heartbeats stop: after the 3 s timeout the vehicle stops, says why, and
    // refuses DRIVE.
    let silent_since = Instant::now();
    let mut refused = None;
    while silent_since.elapsed() < Duration::from_secs(5) {
        let ack = request(&broker, &acks, &topic("cmd/chassis/set"), drive);
        if ack["data"]["code"] == 4 {
            refused = Some(ack);
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let refused = refused.expect("DRIVE refused once the heartbeat stopped");
    assert!(
        refused["data"]["message"]
            .as_str()
            .unwrap()
            .contains("heartbeat")
    );
    let event = json(
        &log.next_on(&topic("log/notify"), WAIT)
            .expect("a log event"),
    );
    assert_eq!(event["data"]["key"], "CONTROL_LINK_LOST", "{event}");
    assert_eq!(event["data"]["code"], 402);
    wait_for_speed(&status, |v| v.abs() < 0.01, "stopped");
    // Heartbeats again: a DRIVE stream that never paused still does not move it...
    drive_with_heartbeats(&broker, drive, 10);
    let ack = request(&broker, &acks, &topic("cmd/chassis/set"), drive);
    assert_eq!(ack["data"]["code"], 4, "{ack}");
    assert!(
        ack["data"]["message"]
            .as_str()
            .is_some_and(|m| m.contains("zero velocity command or a reset")),
        "{ack}"
    );
    // ...a zero DRIVE re-arms, and then it moves.
    let zero = r#"{"messageId": 2, "timestamp": "x", "messageType": 100, "data": {"linear": 0.0, "angular": 0.0}}"#;
    broker.publish(&topic("heartbeat/set"), r#"{"timestamp": "x"}"#);
    assert_eq!(
        request(&broker, &acks, &topic("cmd/chassis/set"), zero)["data"]["code"],
        0
    );
    drive_with_heartbeats(&broker, drive, 20);
    wait_for_speed(&status, |v| v > 0.3, "moving again");
}

#[test]
fn the_software_estop_latches_and_release_alone_does_not_rearm() {
    let broker = Mosquitto::start();
    let acks = broker.subscribe(&[&topic("+/+/ack")]);
    let status = broker.subscribe(&["base_status"]);
    let log = broker.subscribe(&[&topic("log/notify")]);
    let _d = daemon(&broker);
    let drive = r#"{"messageId": 1, "timestamp": "x", "messageType": 100, "data": {"linear": 0.5, "angular": 0.0}}"#;
    let estop = |on: u8| {
        format!(r#"{{"messageId": 7, "timestamp": "x", "messageType": 101, "data": {on}}}"#)
    };
    drive_with_heartbeats(&broker, drive, 20);
    wait_for_speed(&status, |v| v > 0.3, "moving");
    let ack = request(&broker, &acks, &topic("cmd/chassis/set"), &estop(1));
    assert_eq!(ack["data"]["code"], 0, "{ack}");
    wait_for_speed(&status, |v| v.abs() < 0.01, "stopped by the e-stop");
    let s = json(&status.next_on("base_status", WAIT).expect("status"));
    let bits = s["robot"]["robot_status"].as_u64().unwrap();
    assert!(bits & (1 << 3) != 0, "robot_status bit 3 (e-stop): {s}");
    let event = json(&log.next_on(&topic("log/notify"), WAIT).expect("an event"));
    assert_eq!(event["data"]["key"], "EMERGENCY_STOP", "{event}");
    assert_eq!(event["data"]["code"], 404, "{event}");
    assert!(
        event["data"]["message"]
            .as_str()
            .unwrap()
            .contains("software emergency stop engaged"),
        "{event}"
    );
    // While engaged, neither a zero DRIVE nor a RESET re-arms.
    let reset = r#"{"messageId": 8, "timestamp": "x", "messageType": 102, "data": {}}"#;
    let ack = request(&broker, &acks, &topic("cmd/chassis/set"), reset);
    assert_eq!(ack["data"]["code"], 4, "{ack}");
    assert!(
        ack["data"]["message"]
            .as_str()
            .unwrap()
            .contains("emergency stop")
    );
    // Released: still stopped until the deliberate act.
    request(&broker, &acks, &topic("cmd/chassis/set"), &estop(0));
    let ack = request(&broker, &acks, &topic("cmd/chassis/set"), drive);
    assert_eq!(ack["data"]["code"], 4, "{ack}");
    let ack = request(&broker, &acks, &topic("cmd/chassis/set"), reset);
    assert_eq!(ack["data"]["code"], 0, "{ack}");
    drive_with_heartbeats(&broker, drive, 20);
    wait_for_speed(&status, |v| v > 0.3, "moving after release and reset");
}

#[test]
fn bad_requests_get_error_acks_and_change_nothing() {
    let broker = Mosquitto::start();
    let acks = broker.subscribe(&[&topic("+/+/ack")]);
    let _d = daemon(&broker);
    let cases = [
        ("cmd/chassis/set", "{oops", 1, "malformed"),
        ("cmd/chassis/set", "[1]", 1, "object"),
        (
            "cmd/chassis/set",
            r#"{"messageId":1,"messageType":"DRIVE","data":{}}"#,
            1,
            "messageType",
        ),
        (
            "cmd/chassis/set",
            r#"{"messageId":2,"messageType":100,"data":{"linear":"fast","angular":0}}"#,
            1,
            "linear",
        ),
        (
            "cmd/navigation/set",
            r#"{"messageId":3,"messageType":100,"data":{"linear":1,"angular":0}}"#,
            2,
            "messageType 100",
        ),
        (
            "cmd/navigation/set",
            r#"{"messageId":4,"messageType":42,"data":null}"#,
            2,
            "42",
        ),
        (
            "cmd/navigation/set",
            r#"{"messageId":5,"messageType":6,"data":7}"#,
            1,
            "manual",
        ),
        (
            "cmd/navigation/set",
            r#"{"messageId":6,"messageType":0,"data":[1,1,0]}"#,
            1,
            "quaternion",
        ),
        (
            "cmd/navigation/set",
            r#"{"messageId":7,"messageType":5,"data":[{"action":"FLY","parameters":{}}]}"#,
            1,
            "step 0",
        ),
        (
            "setting/navigation/set",
            r#"{"messageId":8,"messageType":100,"data":[123.0, 95.0, 0]}"#,
            1,
            "latitude",
        ),
    ];
    for (rest, payload, code, reason) in cases {
        let ack = request(&broker, &acks, &topic(rest), payload);
        assert_eq!(ack["data"]["code"], code, "{payload} → {ack}");
        let message = ack["data"]["message"].as_str().unwrap_or_default();
        assert!(message.contains(reason), "{payload} → {message}");
    }
    let big = format!(
        r#"{{"messageId":9,"messageType":100,"pad":"{}"}}"#,
        "x".repeat(2 << 20)
    );
    let file = common::tempdir("root-big").join("big.json");
    std::fs::write(&file, big).unwrap();
    acks.clear();
    broker.publish_file(&topic("cmd/chassis/set"), &file);
    let ack = json(
        &acks
            .next_on(&topic("cmd/chassis/ack"), WAIT)
            .expect("an ack"),
    );
    assert_eq!(ack["data"]["code"], 1);
    assert!(ack["data"]["message"].as_str().unwrap().contains("exceeds"));
}

/// `chassisd bench mqtt` on both brokers it starts (the embedded one, then mosquitto):
/// every DRIVE it sends is acknowledged and reaches the CAN bus, and the status period is
/// measured. Figures only; no timing is asserted.
#[test]
fn bench_mqtt_measures_every_drive_end_to_end_on_both_brokers() {
    let out = std::process::Command::new(common::chassisd())
        .args(["bench", "mqtt", "--seconds", "3", "--broker", "both"])
        .output()
        .expect("chassisd runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let report = json(stdout.lines().last().unwrap_or_default());
    assert!(report["skipped"].is_null(), "{report}");
    let runs = report["runs"].as_array().expect("runs");
    let brokers: Vec<&str> = runs.iter().filter_map(|r| r["broker"].as_str()).collect();
    assert_eq!(brokers, ["embedded", "mosquitto"], "{report}");
    for run in runs {
        let sent = run["drives"][0].as_u64().expect("drives sent");
        assert!(sent >= 5, "{run}");
        assert_eq!(run["drives"][1], sent, "every DRIVE acknowledged: {run}");
        assert_eq!(run["drive_round_trip_ms"]["n"], sent, "{run}");
        assert_eq!(
            run["command_to_rpdo_ms"]["n"], sent,
            "every DRIVE on the bus: {run}"
        );
        assert!(run["status_period_ms"]["n"].as_u64() >= Some(25), "{run}");
    }
    assert!(
        stdout.contains("broker: embedded")
            && stdout.contains("broker: mosquitto")
            && stdout.contains("DRIVE publish -> ack"),
        "{stdout}"
    );
}

/// The daemon alone loses the network (a relay between it and mosquitto is cut) while a
/// client drives it: the vehicle stops by itself, the CONTROL_LINK_LOST event raised during
/// the outage is kept and delivered once the link is back, and the telemetry that piled up
/// meanwhile is bounded by the queue (the oldest dropped).
#[test]
fn a_network_outage_stops_the_vehicle_keeps_events_and_drops_old_telemetry() {
    let broker = Mosquitto::start();
    let relay = common::netcut::Relay::to(broker.port);
    let log = broker.subscribe(&[&topic("log/notify")]);
    let status = broker.subscribe(&["base_status"]);
    let mut d = Proc::start(&["sim", "--mqtt", &format!("127.0.0.1:{}", relay.port)]);
    d.wait_log(WAIT, "MQTT subscribed");
    let drive = r#"{"messageId": 1, "timestamp": "x", "messageType": 100, "data": {"linear": 0.5, "angular": 0.0}}"#;
    drive_with_heartbeats(&broker, drive, 20);
    wait_for_speed(&status, |v| v > 0.3, "moving");

    relay.cut();
    let cut_at = Instant::now();
    d.wait_log(WAIT, "MQTT connection lost");
    // The client keeps commanding, but nothing reaches the daemon: it stops on its own (its
    // own stdout is the witness), and the heartbeat watchdog raises the event.
    drive_with_heartbeats(&broker, drive, 10);
    d.wait_out(WAIT, "stopped while cut off", |l| {
        serde_json::from_str::<Value>(l)
            .is_ok_and(|s| s["robot"]["vx"].as_f64().is_some_and(|v| v.abs() < 0.01))
    });
    d.wait_log(WAIT, "CONTROL_LINK_LOST");
    // Long enough for more telemetry than the queue holds (64): base_status alone is 10/s.
    std::thread::sleep(Duration::from_secs(8).saturating_sub(cut_at.elapsed()));
    let produced_during_cut = cut_at.elapsed().as_secs_f64() * 10.0;
    status.clear();

    relay.restore();
    let Some(event) = log.next_on(&topic("log/notify"), Duration::from_secs(10)) else {
        d.log.extend(d.stderr.try_iter());
        panic!("the event raised offline was not delivered: {:#?}", d.log);
    };
    let event = json(&event);
    assert_eq!(event["data"]["key"], "CONTROL_LINK_LOST", "{event}");
    // What arrives within a second of reconnecting: the queued burst plus about 10 live ones.
    let mut received = 0;
    let until = Instant::now() + Duration::from_secs(1);
    while let Some(left) = until.checked_duration_since(Instant::now()) {
        if status.next_on("base_status", left).is_none() {
            break;
        }
        received += 1;
    }
    eprintln!(
        "{received} base_status within 1 s of reconnecting; {produced_during_cut:.0} produced while cut off"
    );
    assert!(
        received > 0 && received <= 64 + 15,
        "{received} base_status after the outage ({produced_during_cut:.0} produced during it)"
    );
    assert!(
        (received as f64) < produced_during_cut,
        "old telemetry dropped: {received} of {produced_during_cut:.0}"
    );
}

/// A MISSION with every action over MQTT: acked at once, each step's start and end notified
/// with the request's messageId, and the end notified with code 0 once the vehicle charges on
/// the simulated dock.
#[test]
fn a_mission_with_every_action_is_notified_step_by_step_to_its_end() {
    let broker = Mosquitto::start();
    let notes = broker.subscribe(&[
        &topic("cmd/navigation/ack"),
        &topic("cmd/navigation/notify"),
    ]);
    let status = broker.subscribe(&["base_status"]);
    let _d = daemon(&broker);
    let deadline = Instant::now() + Duration::from_secs(30);
    let pose = loop {
        assert!(Instant::now() < deadline, "never located");
        let s = json(&status.next_on("base_status", WAIT).expect("base_status"));
        if s["nav"]["locate"] == "LOCATE_TRUE" {
            break s["pose"].clone();
        }
    };
    let (x, y, yaw) = (
        pose["x"].as_f64().unwrap(),
        pose["y"].as_f64().unwrap(),
        pose["yaw"].as_f64().unwrap(),
    );
    let (s, c) = yaw.sin_cos();
    let at = |ahead: f64, left: f64| {
        format!(
            "{:.3}, {:.3}",
            x + ahead * c - left * s,
            y + ahead * s + left * c
        )
    };
    let mission = format!(
        r#"{{"messageId": 77, "timestamp": "2026-11-23 10:00:00", "messageType": 5, "data": [
        {{"action": "MOVE_TO_POSITION", "parameters": {{"path": [{}, {}]}}}},
        {{"action": "WAIT", "parameters": {{"seconds": 1}}}},
        {{"action": "OPEN_CUTTER", "parameters": {{"cutter": true}}}},
        {{"action": "COVERAGE", "parameters": {{"path": [{}, {}, {}]}}}},
        {{"action": "CLOSE_CUTTER", "parameters": {{"cutter": false}}}},
        {{"action": "CHARGING", "parameters": {{"time": 0}}}}]}}"#,
        at(0.0, 0.0),
        at(0.8, 0.0),
        at(0.8, 0.0),
        at(2.0, 0.0),
        at(2.0, 0.5),
    );
    let ack = request(&broker, &notes, &topic("cmd/navigation/set"), &mission);
    assert_eq!(ack["data"]["code"], 0, "{ack}");
    let mut seen = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(120);
    let end = loop {
        assert!(Instant::now() < deadline, "no end; notified {seen:#?}");
        let Some(n) = notes.next_on(&topic("cmd/navigation/notify"), WAIT) else {
            continue;
        };
        let n = json(&n);
        assert_eq!(n["messageId"], 77, "{n}");
        assert_eq!(n["messageType"], 5, "{n}");
        assert!(is_timestamp(&n["timestamp"]), "{n}");
        if n["data"].get("state").is_none() {
            break n;
        }
        seen.push(format!(
            "{} {} {}",
            n["data"]["step"], n["data"]["action"], n["data"]["state"]
        ));
    };
    assert_eq!(
        end["data"],
        serde_json::json!({"code": 0}),
        "{end} after {seen:#?}"
    );
    let actions = [
        "MOVE_TO_POSITION",
        "WAIT",
        "OPEN_CUTTER",
        "COVERAGE",
        "CLOSE_CUTTER",
        "CHARGING",
    ];
    let want: Vec<String> = actions
        .iter()
        .enumerate()
        .flat_map(|(i, a)| {
            [
                format!("{i} \"{a}\" \"started\""),
                format!("{i} \"{a}\" \"done\""),
            ]
        })
        .collect();
    assert_eq!(seen, want);
    // The Daly BMS is polled one quantity at a time: the current is at most 2.5 s old.
    std::thread::sleep(Duration::from_secs(3));
    status.clear();
    let s = json(&status.next_on("base_status", WAIT).expect("base_status"));
    assert_eq!(s["nav"]["status"], "NAV_SUCCESS", "{s}");
    assert!(
        s["bms"]["current"].as_f64().unwrap() > 0.0,
        "charging on the dock: {s}"
    );
}
