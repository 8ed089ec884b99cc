//! Dialect `device` over a real mosquitto with real clients, the daemon running the simulated
//! vehicle: every request example of device-mqtt-api.md sent as written gets an ack of the
//! documented shape on `<topic>/ack` with its msg_id; bad requests get error acks.

mod common;

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
    let examples = common::markdown_json_examples(&common::shared_spec("device-mqtt-api.md"));
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
    for (command, example) in requests {
        let ack = ask(&broker, &acks, command, &example.to_string());
        for key in failure_example.as_object().unwrap().keys() {
            assert!(ack.get(key).is_some(), "{command}: {key} missing in {ack}");
        }
        assert_eq!(ack["msg_id"], example["msg_id"]);
        assert_eq!(ack["success"], false);
        let expected = if command == "goal" { 3002 } else { 3003 };
        assert_eq!(ack["code"], expected, "{command} → {ack}");
        assert!(
            ack["message"].as_str().unwrap().contains("not available"),
            "{ack}"
        );
        assert!(ack["timestamp"].as_u64().is_some_and(|t| t > 1_700_000_000));
    }
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
