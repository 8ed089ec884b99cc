//! The embedded broker of the no-hardware default (rumqttd inside `chassisd sim`): real
//! clients use it like any broker; a port someone else holds is a loud start-up failure.

mod common;

use std::time::{Duration, Instant};

use common::mqtt::{Mosquitto, free_port};
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
    let deadline = Instant::now() + WAIT;
    let exit = loop {
        if let Some(exit) = daemon.child.try_wait().expect("status") {
            break exit;
        }
        assert!(Instant::now() < deadline, "chassisd kept running");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(!exit.success(), "{exit}");
    daemon.log.extend(daemon.stderr.iter());
    let log = daemon.log.join("\n");
    assert!(
        log.contains(&format!("127.0.0.1:{}", other.port)) && log.contains("another broker"),
        "{log}"
    );
}
