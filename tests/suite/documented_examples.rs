//! Every `mosquitto_pub` line the dialect pages of docs/protocols show works when pasted:
//! each page's lines run, in order, in a shell against a fresh `chassisd sim` (its port
//! swapped for a free one), and each request is answered with success in its dialect's own
//! reply, watched by a real `mosquitto_sub`.

use crate::common;

use std::process::{Child, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use common::process::{Proc, lines_of};
use serde_json::Value;

/// The `mosquitto_pub` commands of `page` (docs/protocols/PAGE), in order: one per line of
/// its shell blocks, cut out of a loop where one is written.
fn pasted(page: &str) -> Vec<String> {
    let text = std::fs::read_to_string(common::repo().join("docs/protocols").join(page))
        .expect("the page");
    let mut in_shell = false;
    let mut commands = Vec::new();
    for line in text.lines() {
        if line.starts_with("```") {
            in_shell = line == "```sh";
            continue;
        }
        if let Some(at) = line.find("mosquitto_pub").filter(|_| in_shell) {
            let command = line[at..].split("; sleep").next().unwrap_or_default();
            commands.push(command.to_owned());
        }
    }
    assert!(!commands.is_empty(), "{page} shows no mosquitto_pub line");
    commands
}

/// The value after `flag` in a pasted command (`-t TOPIC`, `-m 'JSON'`).
fn argument(command: &str, flag: &str) -> String {
    let rest = command
        .split_once(&format!(" {flag} "))
        .unwrap_or_else(|| panic!("{flag} in {command}"))
        .1;
    match rest.strip_prefix('\'') {
        Some(quoted) => quoted.split('\'').next().unwrap_or_default().to_owned(),
        None => rest
            .split_whitespace()
            .next()
            .unwrap_or_default()
            .to_owned(),
    }
}

/// Whether `line` (`TOPIC PAYLOAD`, from `mosquitto_sub -v`) answers `command` with success.
fn answers(command: &str, line: &str) -> Option<Result<(), String>> {
    let topic = argument(command, "-t");
    let request: Value = serde_json::from_str(&argument(command, "-m")).expect("JSON");
    let (answer_topic, payload) = line.split_once(' ')?;
    let answer: Value = serde_json::from_str(payload).ok()?;
    let verdict = |ok: bool| Some(if ok { Ok(()) } else { Err(line.to_owned()) });
    if let Some(command) = topic.strip_prefix("device/SIM0001/") {
        let mine = answer_topic == format!("device/SIM0001/{command}/ack")
            && answer["msg_id"] == request["msg_id"];
        return if mine {
            verdict(answer["success"] == true)
        } else {
            None
        };
    }
    if topic == "/root/sim/heartbeat/set" {
        return (answer_topic == "/root/sim/heartbeat/notify").then_some(Ok(()));
    }
    if let Some(base) = topic
        .strip_prefix("/root/sim/")
        .and_then(|t| t.strip_suffix("/set"))
    {
        let mine = answer_topic == format!("/root/sim/{base}/ack")
            && answer["messageId"] == request["messageId"];
        return if mine {
            verdict(answer["data"]["code"] == 0)
        } else {
            None
        };
    }
    assert_eq!(topic, "mqtt_control", "{command}");
    let cmd = request["cmd"].as_str().expect("cmd");
    if cmd == "get_all_trajectory" {
        return (answer_topic == "trajectory_data").then_some(Ok(()));
    }
    let said = answer["cmd"].as_str()?;
    match said.strip_prefix(cmd) {
        Some("_success") if answer_topic == "feedback" => Some(Ok(())),
        Some("_failse") if answer_topic == "feedback" => Some(Err(line.to_owned())),
        _ => None,
    }
}

/// Waits for the answer to `command` among `lines`.
fn answered(lines: &Receiver<String>, command: &str) -> Result<(), String> {
    let deadline = Instant::now() + Duration::from_secs(30);
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        let Ok(line) = lines.recv_timeout(left) else {
            break;
        };
        if let Some(verdict) = answers(command, &line) {
            return verdict;
        }
    }
    Err("no answer within 30 s".into())
}

/// A child process killed when the test ends, passed or not (a `mosquitto_sub` left behind
/// would hold the test's output open).
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A `mosquitto_sub -v` on every answer topic of the three dialects.
fn watch(port: &str) -> (Killed, Receiver<String>) {
    let mut child = Command::new("mosquitto_sub")
        .args(["-h", "127.0.0.1", "-p", port, "-v"])
        .args(["-t", "device/SIM0001/+/ack", "-t", "/root/sim/+/+/ack"])
        .args([
            "-t",
            "/root/sim/heartbeat/notify",
            "-t",
            "feedback",
            "-t",
            "trajectory_data",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .expect("mosquitto_sub runs");
    let lines = lines_of(child.stdout.take().expect("stdout"));
    (Killed(child), lines)
}

/// Pastes each `mosquitto_pub` line of `page` into a shell against a fresh simulator.
fn every_line_works(page: &str) {
    let port = common::mqtt::free_port().to_string();
    let mut sim = Proc::start(&["sim", "--broker-port", &port]);
    sim.wait_log(Duration::from_secs(10), "Ctrl-C stops");
    sim.wait_out(Duration::from_secs(30), "located", |l| {
        l.contains("LOCATE_TRUE")
    });
    let (_watcher, lines) = watch(&port);
    // mosquitto_sub subscribes within moments of starting.
    std::thread::sleep(Duration::from_millis(500));
    for command in pasted(page) {
        let here = command.replacen("-p 1883", &format!("-p {port}"), 1);
        let sent = Command::new("sh")
            .arg("-c")
            .arg(&here)
            .status()
            .expect("sh runs");
        assert!(sent.success(), "{here}");
        if let Err(why) = answered(&lines, &command) {
            panic!("{page}: {command}\nwas not answered with success: {why}");
        }
    }
    sim.stop();
}

#[test]
fn the_device_page_s_examples_work_when_pasted() {
    every_line_works("device.md");
}

#[test]
fn the_root_page_s_examples_work_when_pasted() {
    every_line_works("root.md");
}

#[test]
fn the_rtk_page_s_examples_work_when_pasted() {
    every_line_works("rtk.md");
}
