//! Panics by what they hit: one in an auxiliary task (here the MQTT link) is contained,
//! logged once with its place, and the task restarted, while the vehicle goes on; one in
//! the control loop ends the process (status 101) after the drives' stop frames. The panics
//! are injected on purpose (`CHASSISD_INJECT_PANIC`). The CAN side of the safety-relevant
//! case, the stop frames on a real bus, is `tests/vcan.rs`'s.

use crate::common;

use std::time::{Duration, Instant};

use common::mqtt::{Mosquitto, free_port};
use common::process::Proc;
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(15);

/// A root DRIVE command through `clients`; its ack's code.
fn drive(clients: &Mosquitto, id: u32) -> Option<i64> {
    let acks = clients.subscribe(&["/root/sim/cmd/chassis/ack"]);
    clients.publish(
        "/root/sim/cmd/chassis/set",
        &format!(
            r#"{{"messageId": {id}, "timestamp": "x", "messageType": 100, "data": {{"linear": 0.3, "angular": 0.0}}}}"#
        ),
    );
    let ack: Value =
        serde_json::from_str(&acks.next_on("/root/sim/cmd/chassis/ack", WAIT)?).ok()?;
    ack["data"]["code"].as_i64()
}

#[test]
fn a_panic_in_the_mqtt_link_is_contained_and_the_link_restarts() {
    let port = free_port();
    let mut daemon = Proc::start_with_env(
        &["sim", "--broker-port", &port.to_string()],
        &[("CHASSISD_INJECT_PANIC", "mqtt")],
    );
    daemon.wait_log(WAIT, "MQTT subscribed");
    let clients = Mosquitto::clients_for(port);
    // The first command meets the injected panic: no answer to it.
    let status = clients.subscribe(&["base_status"]);
    assert_eq!(drive(&clients, 1), None);
    daemon.wait_log(
        WAIT,
        "an auxiliary task panicked at src/runtime/links/mqtt.rs",
    );
    daemon.wait_log(WAIT, "MQTT link restarted after a panic");
    daemon.wait_log(WAIT, "MQTT subscribed");
    // The link is back, and the vehicle takes commands; it never stopped reporting.
    assert_eq!(drive(&clients, 2), Some(0));
    status.clear();
    let first = Instant::now();
    for _ in 0..10 {
        assert!(status.next_on("base_status", WAIT).is_some());
    }
    assert!(
        first.elapsed() < Duration::from_secs(3),
        "10 statuses at 10 Hz"
    );
    let reports = daemon.log_count("an auxiliary task panicked");
    assert_eq!(reports, 1, "logged once: {:#?}", daemon.log);
    assert!(
        daemon.child.try_wait().expect("status").is_none(),
        "still running"
    );
    daemon.stop();
}

#[test]
fn a_panic_in_the_control_loop_ends_the_process() {
    let mut daemon = Proc::start_with_env(
        &["sim", "--no-mqtt", "--commands-stdin"],
        &[("CHASSISD_INJECT_PANIC", "control")],
    );
    daemon.wait_out(WAIT, "a status line", |l| l.starts_with('{'));
    daemon.send(r#"cmd_vel {"linear":{"x":0.2},"angular":{"z":0}}"#);
    let exit = daemon.wait_exit(WAIT, "still running after the panic");
    assert_eq!(exit.code(), Some(101));
    daemon.log.extend(daemon.stderr.iter());
    assert!(
        daemon
            .log
            .iter()
            .any(|l| l.contains("panic in the control loop or a CAN driver")),
        "{:#?}",
        daemon.log
    );
}
