//! Dialect `rtk` over a real mosquitto with real clients (mosquitto_pub / mosquitto_sub), the
//! daemon running the simulated vehicle: every example of rtk-mqtt-protocol.md sent as written
//! gets its documented answer, base_status matches the spec key by key, bad messages get
//! `_failse` answers and change nothing, and a broker restart is survived without executing a
//! command published while chassisd was away.

use crate::common;

use std::time::{Duration, Instant};

use common::mqtt::{Mosquitto, Subscriber};
use common::process::Proc;
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(10);
const STATUS_TOPIC: &str = "chassisd/sim-mower/status";

fn daemon(broker: &Mosquitto) -> Proc {
    let mut p = Proc::start(&["sim", "--mqtt", &broker.address()]);
    p.wait_log(WAIT, "MQTT subscribed");
    p
}

fn json(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("not JSON ({e}): {text}"))
}

/// Waits until base_status says the vehicle is localised (init_rtk_data needs a position).
fn wait_localised(status: &Subscriber) {
    let deadline = Instant::now() + WAIT;
    while Instant::now() < deadline {
        if let Some(s) = status.next_on("base_status", WAIT)
            && json(&s)["nav"]["locate"] == "LOCATE_TRUE"
        {
            return;
        }
    }
    panic!("never localised");
}

/// Sends `payload` on mqtt_control and returns the answer (topic, JSON).
fn ask(broker: &Mosquitto, answers: &Subscriber, payload: &str) -> (String, Value) {
    answers.clear();
    broker.publish("mqtt_control", payload);
    let (topic, body) = answers
        .next(WAIT)
        .unwrap_or_else(|| panic!("no answer to {payload}"));
    (topic, json(&body))
}

fn feedback(broker: &Mosquitto, answers: &Subscriber, payload: &str) -> Value {
    let (topic, body) = ask(broker, answers, payload);
    assert_eq!(topic, "feedback", "{body}");
    assert_eq!(body["cmd_type"], "feedback");
    body
}

/// Same keys at every level, the same JSON kind of value (numbers as numbers).
fn same_shape(spec: &Value, ours: &Value, path: &str) {
    match (spec, ours) {
        (Value::Object(a), Value::Object(b)) => {
            let ka: Vec<_> = a.keys().collect();
            let kb: Vec<_> = b
                .keys()
                .filter(|k| *k != "gnss" || path != ".sensor")
                .collect();
            assert_eq!(ka, kb, "keys of {path}");
            for (k, v) in a {
                same_shape(v, &b[k], &format!("{path}.{k}"));
            }
        }
        (Value::Array(a), Value::Array(b)) => {
            assert!(!b.is_empty() || a.is_empty(), "{path}: empty");
            if let (Some(x), Some(y)) = (a.first(), b.first()) {
                same_shape(x, y, &format!("{path}[0]"));
            }
        }
        (Value::Number(_), Value::Number(_))
        | (Value::Bool(_), Value::Bool(_))
        | (Value::String(_), Value::String(_)) => {}
        _ => panic!("{path}: spec has {spec}, chassisd sends {ours}"),
    }
}

#[test]
fn base_status_matches_the_spec_key_by_key() {
    let broker = Mosquitto::start();
    let status = broker.subscribe(&["base_status"]);
    let _d = daemon(&broker);
    let spec = common::spec::markdown_json_examples(&common::shared_spec("rtk-mqtt-protocol.md"));
    let example = &spec
        .iter()
        .find(|(h, _)| h.contains("base_status"))
        .expect("the base_status example")
        .1;
    let sample = json(&status.next_on("base_status", WAIT).expect("a base_status"));
    same_shape(example, &sample, "");
    // The one addition, documented in the README.
    assert!(sample["sensor"]["gnss"].is_boolean());
    let locate = sample["nav"]["locate"].as_str().unwrap_or_default();
    assert!(["LOCATE_UNINIT", "LOCATE_TRUE", "LOCATE_FALSE"].contains(&locate));
    assert!([0, 1, 2, 4, 5].contains(&sample["rtk"]["status"].as_u64().unwrap_or(9)));
    // 10 Hz: 20 messages take about 2 s.
    let started = Instant::now();
    for _ in 0..20 {
        status.next_on("base_status", WAIT).expect("base_status");
    }
    let took = started.elapsed();
    assert!(
        took > Duration::from_millis(1700) && took < Duration::from_millis(2600),
        "{took:?}"
    );
}

#[test]
fn every_spec_example_gets_its_documented_answer() {
    let broker = Mosquitto::start();
    let status = broker.subscribe(&["base_status"]);
    let answers = broker.subscribe(&["feedback", "trajectory_data"]);
    let _d = daemon(&broker);
    wait_localised(&status);
    let examples: Vec<(String, Value)> =
        common::spec::markdown_json_examples(&common::shared_spec("rtk-mqtt-protocol.md"))
            .into_iter()
            .filter(|(_, v)| {
                ["trajectory_control", "task_control"]
                    .contains(&v["cmd_type"].as_str().unwrap_or(""))
            })
            .collect();
    let cmds: Vec<&str> = examples
        .iter()
        .map(|(_, v)| v["cmd"].as_str().unwrap())
        .collect();
    assert_eq!(
        cmds,
        [
            "get_all_trajectory",
            "save_trajectory",
            "delete_trajectory",
            "delete_all_trajectory",
            "start_task",
            "cancel_task",
            "init_rtk_data"
        ]
    );
    for (heading, example) in &examples {
        let cmd = example["cmd"].as_str().unwrap();
        let (topic, answer) = ask(&broker, &answers, &example.to_string());
        match cmd {
            "get_all_trajectory" => {
                assert_eq!(topic, "trajectory_data", "{heading}");
                assert_eq!(answer, Value::Array(vec![]), "nothing saved yet");
            }
            // The example's longitude, 188.2222333°, is not a longitude.
            "save_trajectory" => {
                assert_eq!(answer["cmd"], "save_trajectory_failse", "{answer}");
                assert!(
                    answer["message"].as_str().unwrap().contains("longitude"),
                    "{answer}"
                );
            }
            "delete_trajectory" => {
                assert_eq!(answer["cmd"], "delete_trajectory_failse", "{answer}");
                assert!(
                    answer["message"].as_str().unwrap().contains("test5"),
                    "{answer}"
                );
            }
            // Nothing named "13" is saved.
            "start_task" => {
                assert_eq!(answer["cmd"], "start_task_failse", "{answer}");
                assert!(
                    answer["message"]
                        .as_str()
                        .unwrap()
                        .contains("no trajectory named \"13\""),
                    "{answer}"
                );
            }
            _ => {
                assert_eq!(topic, "feedback");
                assert_eq!(answer["cmd"], format!("{cmd}_success"), "{answer}");
                assert!(answer.get("message").is_none(), "{answer}");
            }
        }
    }
    // The save example with a real longitude is stored, listed in the documented shape and
    // deleted again.
    let mut save = examples[1].1.clone();
    for p in save["data"]["data"].as_array_mut().unwrap() {
        p["longitude"] = 113.2222333.into();
    }
    let answer = feedback(&broker, &answers, &save.to_string());
    assert_eq!(answer["cmd"], "save_trajectory_success", "{answer}");
    let (topic, list) = ask(&broker, &answers, &examples[0].1.to_string());
    assert_eq!(topic, "trajectory_data");
    let spec_listing =
        &common::spec::markdown_json_examples(&common::shared_spec("rtk-mqtt-protocol.md"))
            .into_iter()
            .find(|(h, _)| h.contains("trajectory_data"))
            .expect("the trajectory_data example")
            .1;
    same_shape(spec_listing, &list, "trajectory_data");
    assert_eq!(list[0]["name"], "test1");
    assert_eq!(list[0]["data"][0]["longitude"], 113.2222333);
    let delete = r#"{"cmd_type":"trajectory_control","cmd":"delete_trajectory","name":"test1"}"#;
    assert_eq!(
        feedback(&broker, &answers, delete)["cmd"],
        "delete_trajectory_success"
    );
}

/// The latitude and longitude `east` and `north` metres from `(lat, lon)` (degrees).
fn offset(lat: f64, lon: f64, east: f64, north: f64) -> (f64, f64) {
    let phi = lat.to_radians();
    let per_deg_lat = 111_132.954 - 559.822 * (2.0 * phi).cos() + 1.175 * (4.0 * phi).cos();
    let per_deg_lon = 111_412.84 * phi.cos() - 93.5 * (3.0 * phi).cos();
    (lat + north / per_deg_lat, lon + east / per_deg_lon)
}

/// The simulated mower's GNSS antenna in the vehicle frame (x forward, y left), m.
fn antenna() -> (f64, f64) {
    let plant: toml::Value = toml::from_str(
        &std::fs::read_to_string(common::repo().join("devices/plant.mower.toml")).unwrap(),
    )
    .unwrap();
    let a = &plant["geometry"]["antenna"];
    (a[0].as_float().unwrap(), a[1].as_float().unwrap())
}

/// The next base_status.
fn next_status(status: &Subscriber) -> Value {
    json(&status.next_on("base_status", WAIT).expect("base_status"))
}

/// A base_status published from now on.
fn fresh_status(status: &Subscriber) -> Value {
    status.clear();
    next_status(status)
}

#[test]
fn start_task_follows_a_saved_trajectory_to_its_end_and_cancel_task_stops_one() {
    let broker = Mosquitto::start();
    let status = broker.subscribe(&["base_status"]);
    let answers = broker.subscribe(&["feedback"]);
    let _d = daemon(&broker);
    wait_localised(&status);
    let s = fresh_status(&status);
    let (lat, lon) = (
        s["rtk"]["latitude"].as_f64().unwrap(),
        s["rtk"]["longitude"].as_f64().unwrap(),
    );
    let (x0, y0, yaw0) = (
        s["pose"]["x"].as_f64().unwrap(),
        s["pose"]["y"].as_f64().unwrap(),
        s["pose"]["yaw"].as_f64().unwrap(),
    );
    // Recorded as a client would: from 0.5 m ahead of the antenna, 4 m straight, then a
    // quarter circle of 2 m to the left; points every 0.1 m.
    let mut local: Vec<(f64, f64)> = (5..45).map(|i| (f64::from(i) * 0.1, 0.0)).collect();
    for i in 0..=31 {
        let a = -std::f64::consts::FRAC_PI_2 + std::f64::consts::FRAC_PI_2 * f64::from(i) / 31.0;
        local.push((4.5 + 2.0 * a.cos(), 2.0 + 2.0 * a.sin()));
    }
    let (sin, cos) = yaw0.sin_cos();
    let rotate = |(fx, fy): (f64, f64)| (fx * cos - fy * sin, fx * sin + fy * cos);
    let points: Vec<Value> = local
        .iter()
        .map(|&p| {
            let (e, n) = rotate(p);
            let (plat, plon) = offset(lat, lon, e, n);
            serde_json::json!({"longitude": plon, "latitude": plat, "angle": 0, "x": e, "y": n, "yaw": 0})
        })
        .collect();
    let save = serde_json::json!({
        "cmd_type": "trajectory_control",
        "cmd": "save_trajectory",
        "data": {"name": "lap", "data": points}
    });
    assert_eq!(
        feedback(&broker, &answers, &save.to_string())["cmd"],
        "save_trajectory_success"
    );
    let start = |id: u32| {
        format!(
            r#"{{"cmd_type":"task_control","cmd":"start_task","name":"lap","id":{id},"speed":0.5}}"#
        )
    };
    let answer = feedback(&broker, &answers, &start(0));
    assert_eq!(answer["cmd"], "start_task_success", "{answer}");
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut seen_run = false;
    let last = loop {
        assert!(Instant::now() < deadline, "the task never ended");
        let s = next_status(&status);
        match s["nav"]["status"].as_str() {
            Some("NAV_RUN") => seen_run = true,
            Some("NAV_SUCCESS") if seen_run => break s,
            Some("NAV_ERROR") => panic!("the task failed: {s}"),
            _ => {}
        }
    };
    std::thread::sleep(Duration::from_millis(500));
    let end = fresh_status(&status);
    assert_eq!(end["nav"]["status"], "NAV_SUCCESS", "{last}");
    // The antenna was 0.5 m behind the path's start; the path ends where it was recorded.
    let (ax, ay) = rotate(antenna());
    let (ex, ey) = rotate(*local.last().unwrap());
    let (want_x, want_y) = (x0 + ax + ex, y0 + ay + ey);
    let (x, y, yaw) = (
        end["pose"]["x"].as_f64().unwrap(),
        end["pose"]["y"].as_f64().unwrap(),
        end["pose"]["yaw"].as_f64().unwrap(),
    );
    let off = (x - want_x).hypot(y - want_y);
    assert!(off <= 0.05, "ended {off} m from the trajectory's end");
    let turned = (yaw - yaw0 - std::f64::consts::FRAC_PI_2)
        .sin()
        .asin()
        .to_degrees();
    assert!(
        turned.abs() <= 3.0,
        "heading {turned}° off the trajectory's last direction"
    );
    // From there the start is more than motion.task_max_approach_m away.
    let far = feedback(&broker, &answers, &start(0));
    assert_eq!(far["cmd"], "start_task_failse", "{far}");
    assert!(
        far["message"]
            .as_str()
            .unwrap()
            .contains("task_max_approach_m"),
        "{far}"
    );
    // From point 30 (3.5 m along) it is near enough; cancel_task stops it on the way.
    assert_eq!(
        feedback(&broker, &answers, &start(30))["cmd"],
        "start_task_success"
    );
    std::thread::sleep(Duration::from_secs(3));
    let cancel = r#"{"cmd_type":"task_control","cmd":"cancel_task"}"#;
    assert_eq!(
        feedback(&broker, &answers, cancel)["cmd"],
        "cancel_task_success"
    );
    std::thread::sleep(Duration::from_secs(2));
    let s = fresh_status(&status);
    assert_eq!(s["nav"]["status"], "NAV_FREE", "{s}");
    assert!(s["robot"]["vx"].as_f64().unwrap().abs() < 0.01, "{s}");
}

#[test]
fn bad_messages_get_failse_answers_and_change_nothing() {
    let broker = Mosquitto::start();
    // A retained command left on the broker is stale by definition: chassisd, subscribing,
    // receives it flagged retained and ignores it.
    broker.publish_with(
        "mqtt_control",
        r#"{"cmd_type":"trajectory_control","cmd":"save_trajectory","data":{"name":"stale","data":[{"longitude":1,"latitude":1,"angle":0,"x":0,"y":0,"yaw":0}]}}"#,
        &["-r"],
    );
    let answers = broker.subscribe(&["feedback", "trajectory_data"]);
    answers.clear();
    let mut d = daemon(&broker);
    assert!(
        answers.next(Duration::from_secs(1)).is_none(),
        "the retained command was answered"
    );
    d.wait_log(WAIT, "retained command ignored");
    // Clearing it is an empty message, which reaches chassisd live: refused as malformed.
    broker.publish_with("mqtt_control", "", &["-r"]);
    let (_, cleared) = answers.next(WAIT).expect("an answer to the empty message");
    assert_eq!(json(&cleared)["cmd"], "mqtt_control_failse");
    let cases = [
        ("{not json", "mqtt_control_failse", "malformed JSON"),
        ("[1, 2]", "mqtt_control_failse", "cmd"),
        (
            r#"{"cmd_type":"task_control","cmd":"fly"}"#,
            "fly_failse",
            "unknown command",
        ),
        (
            r#"{"cmd_type":"task_control","cmd":"save_trajectory","data":{}}"#,
            "save_trajectory_failse",
            "cmd_type",
        ),
        (
            r#"{"cmd_type":"trajectory_control","cmd":"save_trajectory","data":{"name":"x","data":"many"}}"#,
            "save_trajectory_failse",
            "data",
        ),
        (
            r#"{"cmd_type":"trajectory_control","cmd":"save_trajectory","data":{"name":"../etc/passwd","data":[{"longitude":1,"latitude":1,"angle":0,"x":0,"y":0,"yaw":0}]}}"#,
            "save_trajectory_failse",
            "not allowed",
        ),
        (
            r#"{"cmd_type":"trajectory_control","cmd":"delete_trajectory","name":5}"#,
            "delete_trajectory_failse",
            "name",
        ),
    ];
    for (payload, cmd, reason) in cases {
        let answer = feedback(&broker, &answers, payload);
        assert_eq!(answer["cmd"], cmd, "{payload} → {answer}");
        let message = answer["message"].as_str().unwrap_or_default();
        assert!(message.contains(reason), "{payload} → {message}");
    }
    // Oversized: 2 MiB of JSON.
    let big = format!(
        r#"{{"cmd_type":"trajectory_control","cmd":"save_trajectory","pad":"{}"}}"#,
        "x".repeat(2 << 20)
    );
    let file = common::tempdir("mqtt-big").join("big.json");
    std::fs::write(&file, big).unwrap();
    answers.clear();
    broker.publish_file("mqtt_control", &file);
    let (_, body) = answers
        .next(WAIT)
        .expect("an answer to the oversized message");
    let answer = json(&body);
    assert_eq!(answer["cmd"], "mqtt_control_failse");
    assert!(
        answer["message"].as_str().unwrap().contains("exceeds"),
        "{answer}"
    );
    // Nothing was stored by any of it.
    let (_, list) = ask(
        &broker,
        &answers,
        r#"{"cmd_type":"trajectory_control","cmd":"get_all_trajectory"}"#,
    );
    assert_eq!(list, Value::Array(vec![]));
}

#[test]
fn a_broker_restart_is_survived_and_commands_sent_meanwhile_are_not_run() {
    let mut broker = Mosquitto::start();
    // chassisd reaches the broker through a relay the test can hold shut: its reconnects
    // are jittered, so only a closed way keeps it out while the command is sent.
    let relay = common::netcut::Relay::to(broker.port);
    let mut d = Proc::start(&["sim", "--mqtt", &format!("127.0.0.1:{}", relay.port)]);
    d.wait_log(WAIT, "MQTT subscribed");
    {
        let status = broker.subscribe(&["base_status"]);
        status
            .next_on("base_status", WAIT)
            .expect("status before the outage");
    }
    relay.cut();
    broker.kill();
    // Long enough for the daemon's reconnect back-off to reach its 2 s bound.
    std::thread::sleep(Duration::from_secs(4));
    broker.restart();
    let online = broker.subscribe(&[STATUS_TOPIC]);
    // Published while chassisd cannot reach the restarted broker: with a clean session the
    // broker keeps nothing for it.
    broker.publish(
        "mqtt_control",
        r#"{"cmd_type":"trajectory_control","cmd":"save_trajectory","data":{"name":"outage","data":[{"longitude":113.2,"latitude":23.1,"angle":0,"x":0,"y":0,"yaw":0}]}}"#,
    );
    assert!(
        online.next(Duration::from_millis(0)).is_none(),
        "chassisd reached the broker through a cut relay"
    );
    relay.restore();
    let restored = Instant::now();
    let back = online.next_on(STATUS_TOPIC, WAIT).expect("online again");
    assert_eq!(back, "online");
    let status = broker.subscribe(&["base_status"]);
    status
        .next_on("base_status", WAIT)
        .expect("status after the restart");
    // The back-off's bound is 2 s: the next attempt comes within it.
    assert!(
        restored.elapsed() < Duration::from_secs(5),
        "{:?}",
        restored.elapsed()
    );
    // Subscriptions work again, and the command from the outage was never executed.
    let answers = broker.subscribe(&["feedback", "trajectory_data"]);
    let (topic, list) = ask(
        &broker,
        &answers,
        r#"{"cmd_type":"trajectory_control","cmd":"get_all_trajectory"}"#,
    );
    assert_eq!(topic, "trajectory_data");
    assert_eq!(list, Value::Array(vec![]), "the outage command ran: {list}");
}

#[test]
fn the_last_will_says_offline_when_chassisd_dies() {
    let broker = Mosquitto::start();
    let online = broker.subscribe(&[STATUS_TOPIC]);
    let mut d = daemon(&broker);
    assert_eq!(
        online.next_on(STATUS_TOPIC, WAIT).as_deref(),
        Some("online")
    );
    let _ = d.child.kill();
    // The broker notices the dropped connection at once (socket closed) and sends the will.
    assert_eq!(
        online.next_on(STATUS_TOPIC, WAIT).as_deref(),
        Some("offline")
    );
}

#[test]
fn names_that_look_alike_are_one_trajectory_and_invisible_ones_are_refused() {
    let broker = Mosquitto::start();
    let answers = broker.subscribe(&["feedback", "trajectory_data"]);
    let _d = daemon(&broker);
    let save = |name: &str| {
        let payload = serde_json::json!({
            "cmd_type": "trajectory_control",
            "cmd": "save_trajectory",
            "data": {"name": name, "data": [
                {"longitude": 113.0, "latitude": 22.0, "angle": 0, "x": 0, "y": 0, "yaw": 0}
            ]}
        });
        feedback(&broker, &answers, &payload.to_string())
    };
    // "café" composed, then decomposed (e and a combining accent): one trajectory.
    assert_eq!(save("caf\u{e9}")["cmd"], "save_trajectory_success");
    assert_eq!(save("cafe\u{301}")["cmd"], "save_trajectory_success");
    let (_, list) = ask(
        &broker,
        &answers,
        r#"{"cmd_type":"trajectory_control","cmd":"get_all_trajectory"}"#,
    );
    let names: Vec<&str> = list
        .as_array()
        .expect("a list")
        .iter()
        .filter_map(|t| t["name"].as_str())
        .collect();
    assert_eq!(names, ["caf\u{e9}"], "{list}");
    // Names that show nothing, or hide something, are refused with the reason.
    for name in ["\u{200B}", "\u{FEFF}", " ", "law\u{200D}n", "lawn "] {
        let answer = save(name);
        assert_eq!(
            answer["cmd"], "save_trajectory_failse",
            "{name:?}: {answer}"
        );
    }
    // Deleting by the other spelling deletes it.
    let delete = serde_json::json!({
        "cmd_type": "trajectory_control", "cmd": "delete_trajectory", "name": "cafe\u{301}"
    });
    assert_eq!(
        feedback(&broker, &answers, &delete.to_string())["cmd"],
        "delete_trajectory_success"
    );
}

/// A `save_trajectory` of `name`: points every 0.1 m from 0.5 m to 3 m straight ahead of the
/// antenna, as base_status `s` places it.
fn straight_ahead(s: &Value, name: &str) -> String {
    let (lat, lon) = (
        s["rtk"]["latitude"].as_f64().unwrap(),
        s["rtk"]["longitude"].as_f64().unwrap(),
    );
    let (sin, cos) = s["pose"]["yaw"].as_f64().unwrap().sin_cos();
    let points: Vec<Value> = (5..=30)
        .map(|i| {
            let along = f64::from(i) * 0.1;
            let (plat, plon) = offset(lat, lon, along * cos, along * sin);
            serde_json::json!({"longitude": plon, "latitude": plat, "angle": 0, "x": 0, "y": 0, "yaw": 0})
        })
        .collect();
    serde_json::json!({"cmd_type": "trajectory_control", "cmd": "save_trajectory",
        "data": {"name": name, "data": points}})
    .to_string()
}

#[test]
fn after_an_emergency_stop_cancel_task_re_arms_and_each_refusal_says_what_to_do() {
    let broker = Mosquitto::start();
    let status = broker.subscribe(&["base_status"]);
    let answers = broker.subscribe(&["feedback"]);
    let _d = daemon(&broker);
    wait_localised(&status);
    let save = straight_ahead(&fresh_status(&status), "ahead");
    assert_eq!(
        feedback(&broker, &answers, &save)["cmd"],
        "save_trajectory_success"
    );
    let start =
        r#"{"cmd_type":"task_control","cmd":"start_task","name":"ahead","id":0,"speed":0.3}"#;
    let cancel = r#"{"cmd_type":"task_control","cmd":"cancel_task"}"#;
    // The site's e-stop (root's, as rtk has none) is engaged: start_task names it.
    assert_eq!(broker.sim_estop(1), 0);
    let refused = feedback(&broker, &answers, start);
    let reason = refused["message"].as_str().unwrap_or_default().to_owned();
    assert_eq!(refused["cmd"], "start_task_failse", "{refused}");
    assert!(
        reason.contains("release the software emergency stop")
            && reason.ends_with("send cancel_task to re-arm, then start_task again"),
        "{reason}"
    );
    // cancel_task while it holds cancels, but cannot re-arm.
    assert_eq!(
        feedback(&broker, &answers, cancel)["cmd"],
        "cancel_task_success"
    );
    assert_eq!(
        feedback(&broker, &answers, start)["cmd"],
        "start_task_failse"
    );
    // Released: the advice is rtk's own act, and following it works.
    assert_eq!(broker.sim_estop(0), 0);
    let refused = feedback(&broker, &answers, start);
    assert_eq!(
        refused["message"],
        "stopped (software emergency stop engaged): send cancel_task to re-arm, then start_task again",
        "{refused}"
    );
    assert_eq!(
        feedback(&broker, &answers, cancel)["cmd"],
        "cancel_task_success"
    );
    let answer = feedback(&broker, &answers, start);
    assert_eq!(answer["cmd"], "start_task_success", "{answer}");
    let deadline = Instant::now() + WAIT;
    while next_status(&status)["nav"]["status"] != "NAV_RUN" {
        assert!(Instant::now() < deadline, "the task never ran");
    }
    assert_eq!(
        feedback(&broker, &answers, cancel)["cmd"],
        "cancel_task_success"
    );
}
