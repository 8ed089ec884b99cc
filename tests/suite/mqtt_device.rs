//! Dialect `device` over a real mosquitto with real clients, the daemon running the simulated
//! vehicle: every request example of device-mqtt-api.md sent as written gets an ack of the
//! documented shape on `<topic>/ack` with its msg_id; the goal example drives the vehicle
//! there; bad requests get error acks.

use crate::common;

use std::time::Duration;

use common::mqtt::{Mosquitto, Subscriber};
use common::process::Proc;
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(10);
const SN: &str = "SIM0001";

fn json(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("not JSON ({e}): {text}"))
}

fn ask(broker: &Mosquitto, acks: &Subscriber, command: &str, payload: &str) -> Value {
    acks.clear();
    broker.publish(&format!("device/{SN}/{command}"), payload);
    let ack = acks
        .next_on(&format!("device/{SN}/{command}/ack"), WAIT)
        .unwrap_or_else(|| panic!("no ack for {command}"));
    json(&ack)
}

#[test]
fn every_request_example_gets_a_documented_ack() {
    let broker = Mosquitto::start();
    let acks = broker.subscribe(&[&format!("device/{SN}/+/ack")]);
    let mut d = Proc::start(&["sim", "--mqtt", &broker.address()]);
    d.wait_log(WAIT, "MQTT subscribed");
    let examples = common::spec::markdown_json_examples(&common::shared_spec("device-mqtt-api.md"));
    let failure_example = &examples
        .iter()
        .find(|(h, v)| h.contains("ACK") && v["success"] == false)
        .expect("a failure ack example")
        .1;
    let requests: Vec<(&str, &Value)> = examples
        .iter()
        .filter(|(h, _)| !h.contains("ACK"))
        .map(|(h, v)| {
            let command = match h.as_str() {
                "开始建图" => "start_mapping",
                "结束建图" => "stop_mapping",
                "使用地图" => "use_map",
                "导航到目标点" => "goal",
                other => panic!("unexpected request example {other:?}"),
            };
            (command, v)
        })
        .collect();
    assert_eq!(requests.len(), 4);
    // The goal is driven (see below); the mapping requests belong to a navigation stack.
    for (command, example) in requests.into_iter().filter(|(c, _)| *c != "goal") {
        let ack = ask(&broker, &acks, command, &example.to_string());
        for key in failure_example.as_object().unwrap().keys() {
            assert!(ack.get(key).is_some(), "{command}: {key} missing in {ack}");
        }
        assert_eq!(ack["msg_id"], example["msg_id"]);
        assert_eq!(ack["success"], false);
        assert_eq!(ack["code"], 3003, "{command} → {ack}");
        assert!(
            ack["message"].as_str().unwrap().contains("not available"),
            "{ack}"
        );
        assert!(ack["timestamp"].as_u64().is_some_and(|t| t > 1_700_000_000));
    }
}

/// The status lines' pose: x, y (m) and yaw (rad), map frame.
fn last_pose(d: &mut Proc) -> (f64, f64, f64) {
    let s = d
        .drain_out()
        .iter()
        .rev()
        .find_map(|l| serde_json::from_str::<Value>(l).ok())
        .expect("a status line");
    let p = &s["pose"];
    let get = |k: &str| p[k].as_f64().unwrap_or(f64::NAN);
    (get("x"), get("y"), get("yaw"))
}

#[test]
fn the_goal_example_drives_there_and_a_replaced_goal_is_cancelled() {
    let broker = Mosquitto::start();
    let acks = broker.subscribe(&[&format!("device/{SN}/goal/ack")]);
    let mut d = Proc::start(&["sim", "--mqtt", &broker.address()]);
    d.wait_log(WAIT, "MQTT subscribed");
    d.wait_out(Duration::from_secs(30), "LOCATE_TRUE", |l| {
        serde_json::from_str::<Value>(l).is_ok_and(|s| s["nav"]["locate"] == "LOCATE_TRUE")
    });
    let example = common::spec::markdown_json_examples(&common::shared_spec("device-mqtt-api.md"))
        .into_iter()
        .find(|(h, _)| h == "导航到目标点")
        .expect("the goal example")
        .1;
    let topic = format!("device/{SN}/goal");
    // A far goal first: the example replaces it, so it is answered as cancelled.
    broker.publish(
        &topic,
        r#"{"msg_id": "far", "timestamp": 1757403776, "data": {"x": 40, "y": 0, "z": 0}}"#,
    );
    std::thread::sleep(Duration::from_secs(1));
    broker.publish(&topic, &example.to_string());
    let first = json(
        &acks
            .next_on(&format!("{topic}/ack"), WAIT)
            .expect("the far goal's ack"),
    );
    assert_eq!(first["msg_id"], "far");
    assert_eq!(first["success"], false);
    assert_eq!(first["code"], 3001, "{first}");
    assert!(
        first["message"]
            .as_str()
            .is_some_and(|m| m.contains("replaced")),
        "{first}"
    );
    let done = json(
        &acks
            .next_on(&format!("{topic}/ack"), Duration::from_secs(60))
            .expect("the example goal's ack"),
    );
    assert_eq!(done["msg_id"], example["msg_id"]);
    assert_eq!(done["success"], true, "{done}");
    // The spec's success ack: msg_id, timestamp, success, nothing else.
    assert_eq!(done.as_object().map(|o| o.len()), Some(3), "{done}");
    std::thread::sleep(Duration::from_millis(500));
    let (x, y, yaw) = last_pose(&mut d);
    let off = (x - 1.23).hypot(y - 4.56);
    assert!(off <= 0.05, "the published pose is {off} m from the goal");
    let heading = (yaw - std::f64::consts::FRAC_PI_2).to_degrees();
    assert!(heading.abs() <= 2.0, "the heading is {heading}° off 90°");
}

/// `cancel` ends the goal under way without latching: acked at once, the goal answered 3001,
/// the vehicle at rest, and the next goal taken without a reset.
#[test]
fn cancel_ends_the_goal_under_way_and_the_next_goal_is_taken() {
    let broker = Mosquitto::start();
    let goal_acks = broker.subscribe(&[&format!("device/{SN}/goal/ack")]);
    let cancel_acks = broker.subscribe(&[&format!("device/{SN}/cancel/ack")]);
    let mut d = Proc::start(&["sim", "--mqtt", &broker.address()]);
    d.wait_log(WAIT, "MQTT subscribed");
    d.wait_out(Duration::from_secs(30), "LOCATE_TRUE", |l| {
        serde_json::from_str::<Value>(l).is_ok_and(|s| s["nav"]["locate"] == "LOCATE_TRUE")
    });
    let goal = format!("device/{SN}/goal");
    broker.publish(
        &goal,
        r#"{"msg_id": "far", "timestamp": 1757403776, "data": {"x": 40, "y": 0, "z": 0}}"#,
    );
    std::thread::sleep(Duration::from_secs(2));
    broker.publish(
        &format!("device/{SN}/cancel"),
        r#"{"msg_id": "cancel-1", "timestamp": 1757403778, "data": {}}"#,
    );
    let cancelled = json(
        &goal_acks
            .next_on(&format!("{goal}/ack"), WAIT)
            .expect("the far goal's ack"),
    );
    assert_eq!(cancelled["msg_id"], "far");
    assert_eq!(cancelled["code"], 3001, "{cancelled}");
    let ack = json(
        &cancel_acks
            .next_on(&format!("device/{SN}/cancel/ack"), WAIT)
            .expect("the cancel's ack"),
    );
    assert_eq!(ack["msg_id"], "cancel-1");
    assert_eq!(ack["success"], true, "{ack}");
    // At rest within a second, and not latched: the next goal drives without a reset.
    std::thread::sleep(Duration::from_secs(1));
    let (x0, y0, _) = last_pose(&mut d);
    std::thread::sleep(Duration::from_secs(1));
    let (x1, y1, _) = last_pose(&mut d);
    assert!((x1 - x0).hypot(y1 - y0) < 0.01, "still moving after cancel");
    let next = ask(
        &broker,
        &goal_acks,
        "goal",
        &format!(
            r#"{{"msg_id": "near", "timestamp": 1757403790, "data": {{"x": {}, "y": {}, "z": 0}}}}"#,
            x1 + 0.5,
            y1
        ),
    );
    assert_eq!(next["msg_id"], "near");
    assert_eq!(next["success"], true, "{next}");
}

#[test]
fn bad_requests_get_error_acks() {
    let broker = Mosquitto::start();
    let acks = broker.subscribe(&[&format!("device/{SN}/+/ack")]);
    let mut d = Proc::start(&["sim", "--mqtt", &broker.address()]);
    d.wait_log(WAIT, "MQTT subscribed");
    let cases = [
        ("goal", "{not json", 4000),
        (
            "goal",
            r#"{"msg_id": 7, "timestamp": 1, "data": {"x": 1, "y": 2, "z": 0}}"#,
            4000,
        ),
        (
            "goal",
            r#"{"msg_id": "a", "timestamp": 1, "data": {"x": "one", "y": 2, "z": 0}}"#,
            4000,
        ),
        // z is the heading's quaternion z, never radians.
        (
            "goal",
            r#"{"msg_id": "r", "timestamp": 1, "data": {"x": 1, "y": 2, "z": 1.57}}"#,
            4000,
        ),
        (
            "fly",
            r#"{"msg_id": "b", "timestamp": 1, "data": {}}"#,
            4004,
        ),
    ];
    for (command, payload, code) in cases {
        let ack = ask(&broker, &acks, command, payload);
        assert_eq!(ack["success"], false);
        assert_eq!(ack["code"], code, "{payload} → {ack}");
    }
}

#[test]
fn a_goal_across_a_keep_out_zone_is_refused_with_an_error_ack() {
    let broker = Mosquitto::start();
    let acks = broker.subscribe(&[&format!("device/{SN}/goal/ack")]);
    let dir = common::tempdir("mqtt-device-zones");
    let plant = chassisd::sim::plant::PlantConfig::builtin().expect("plant");
    let zones = common::zones::yard(&plant, &dir);
    let mut d = Proc::start(&[
        "sim",
        "--mqtt",
        &broker.address(),
        "--zones",
        &zones.to_string_lossy(),
    ]);
    d.wait_log(WAIT, "MQTT subscribed");
    d.wait_out(Duration::from_secs(30), "LOCATE_TRUE", |l| {
        serde_json::from_str::<Value>(l).is_ok_and(|s| s["nav"]["locate"] == "LOCATE_TRUE")
    });
    // Straight across the pond 4 m ahead: refused before the vehicle moves.
    let ack = ask(
        &broker,
        &acks,
        "goal",
        r#"{"msg_id": "pond", "timestamp": 1757403776, "data": {"x": 10, "y": 0, "z": 0}}"#,
    );
    assert_eq!(ack["msg_id"], "pond");
    assert_eq!(ack["success"], false, "{ack}");
    let message = ack["message"].as_str().unwrap_or_default();
    assert!(message.contains("keep_out zone \"pond\""), "{ack}");
    std::thread::sleep(Duration::from_millis(500));
    let (x, y, _) = last_pose(&mut d);
    assert!(x.hypot(y) < 0.1, "the vehicle stayed: ({x}, {y})");
}
