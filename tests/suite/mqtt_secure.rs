//! The MQTT link to a broker that wants TLS and a password: a real mosquitto with a
//! certificate made by openssl and a password file, the real daemon in live mode
//! (`chassisd run`), and real clients. With the right CA and credentials, status flows and
//! commands are answered; a wrong password or a CA that did not sign the broker is reported
//! in the log, never connects, and is retried.

use crate::common;

use std::path::{Path, PathBuf};
use std::time::Duration;

use common::mqtt::{Mosquitto, TestPki};
use common::process::Proc;
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(15);
const USER: &str = "chassisd";
const PASSWORD: &str = "s3cret";

/// A vehicle with the MQTT link and the rtk dialect, and a receiver on a port that is not
/// there (a run needs a device; an absent port is retried, and the link works regardless).
fn config(dir: &Path, name: &str, port: u16, password: &str, ca: &Path) -> PathBuf {
    let path = dir.join(format!("{name}.toml"));
    let text = format!(
        "[vehicle]\nname = \"{name}\"\n\n[gnss]\nport = \"{}\"\n\n[mqtt]\nhost = \"127.0.0.1\"\nport = {port}\n\
         username = \"{USER}\"\npassword = \"{password}\"\nreconnect_max_s = 0.5\n\n\
         [mqtt.tls]\nca_file = \"{}\"\n\n[mqtt.rtk]\n",
        dir.join("no-such-receiver").display(),
        ca.display()
    );
    std::fs::write(&path, text).expect("config written");
    path
}

fn run(config: &Path) -> Proc {
    Proc::start(&["run".as_ref(), "--config".as_ref(), config.as_os_str()])
}

#[test]
fn tls_and_a_password_carry_status_and_commands() {
    let dir = common::tempdir("mqtt-secure");
    let pki = TestPki::create(&dir, "good");
    let broker = Mosquitto::start_secured(&dir, &pki, USER, PASSWORD);
    let mut daemon = run(&config(&dir, "secure", broker.port, PASSWORD, &pki.ca));
    daemon.wait_log(WAIT, "MQTT subscribed");

    let sub = broker.subscribe(&["base_status", "feedback", "chassisd/secure/status"]);
    assert_eq!(
        sub.next_on("chassisd/secure/status", WAIT).as_deref(),
        Some("online")
    );
    let status: Value =
        serde_json::from_str(&sub.next_on("base_status", WAIT).expect("base_status"))
            .expect("JSON");
    assert!(
        status["rtk"].is_object() && status["sensor"].is_object(),
        "{status}"
    );

    broker.publish(
        "mqtt_control",
        r#"{"cmd": "cancel_task", "cmd_type": "task_control"}"#,
    );
    let feedback: Value =
        serde_json::from_str(&sub.next_on("feedback", WAIT).expect("feedback")).expect("JSON");
    assert_eq!(
        feedback,
        serde_json::json!({"cmd": "cancel_task_success", "cmd_type": "feedback"})
    );
    daemon.stop();
}

#[test]
fn a_wrong_password_or_an_unknown_ca_is_reported_and_retried() {
    let dir = common::tempdir("mqtt-secure-refused");
    let pki = TestPki::create(&dir, "good");
    let stranger = TestPki::create(&dir, "stranger");
    let broker = Mosquitto::start_secured(&dir, &pki, USER, PASSWORD);

    // The broker refuses the credentials: the reason is logged once, and the link retries.
    let mut daemon = run(&config(
        &dir,
        "wrong-password",
        broker.port,
        "nope",
        &pki.ca,
    ));
    daemon.wait_log(WAIT, "MQTT connect failed");
    let line = daemon.log.last().cloned().unwrap_or_default();
    assert!(
        line.contains("NotAuthorized") || line.contains("BadUserNamePassword"),
        "{line}"
    );
    std::thread::sleep(Duration::from_secs(2));
    daemon.log.extend(daemon.stderr.try_iter());
    assert!(
        daemon.child.try_wait().expect("status").is_none(),
        "still running"
    );
    assert!(
        !daemon.log.iter().any(|l| l.contains("MQTT connected")),
        "{:#?}",
        daemon.log
    );
    let reported = daemon
        .log
        .iter()
        .filter(|l| l.contains("MQTT connect failed"))
        .count();
    assert_eq!(reported, 1, "one report per cause: {:#?}", daemon.log);
    daemon.stop();

    // The broker's certificate is not signed by the configured CA: TLS fails, and says so.
    let mut daemon = run(&config(
        &dir,
        "unknown-ca",
        broker.port,
        PASSWORD,
        &stranger.ca,
    ));
    daemon.wait_log(WAIT, "MQTT connect failed");
    let line = daemon.log.last().cloned().unwrap_or_default();
    assert!(line.to_lowercase().contains("certificate"), "{line}");
    std::thread::sleep(Duration::from_secs(1));
    daemon.log.extend(daemon.stderr.try_iter());
    assert!(
        !daemon.log.iter().any(|l| l.contains("MQTT connected")),
        "{:#?}",
        daemon.log
    );
    daemon.stop();
}
