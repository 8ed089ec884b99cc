//! A slow disk must not hold up the control loop: the simulated vehicle saves trajectories
//! over MQTT (mosquitto, mosquitto_pub) while strace makes every fsync take half a second.
//! The saves are answered at once, the drive commands in the recording keep their 20 ms
//! rhythm, and every trajectory reaches the folder whole.

use crate::common;

use std::time::{Duration, Instant};

use common::mqtt::Mosquitto;
use common::process::Proc;
use serde_json::Value;

const SAVES: usize = 6;

/// `(seconds) sim0 201#DATA T` lines of node 1's RPDO: their times in µs.
fn rpdo1_times(log: &str) -> Vec<u64> {
    log.lines()
        .filter(|l| l.ends_with(" T") && l.contains(" 201#"))
        .filter_map(|l| {
            let stamp = l.strip_prefix('(')?.split_once(')')?.0;
            let (s, us) = stamp.split_once('.')?;
            Some(s.parse::<u64>().ok()? * 1_000_000 + us.parse::<u64>().ok()?)
        })
        .collect()
}

#[test]
fn trajectory_saves_on_a_slow_disk_delay_neither_the_replies_nor_the_control_loop() {
    let broker = Mosquitto::start();
    let dir = common::tempdir("slow-disk");
    let folder = dir.join("trajectories");
    let session = dir.join("session");
    let address = broker.address();
    let mut daemon = Proc::start_under(
        &[
            "strace",
            "-f",
            "-qq",
            "--seccomp-bpf",
            "-o",
            "/dev/null",
            "-e",
            "trace=fsync,fdatasync",
            "-e",
            "inject=fsync,fdatasync:delay_enter=500000",
        ],
        &[
            "sim".as_ref(),
            "--mqtt".as_ref(),
            address.as_ref(),
            "--duration".as_ref(),
            "12".as_ref(),
            "--trajectory-dir".as_ref(),
            folder.as_os_str(),
            "--record".as_ref(),
            session.as_os_str(),
        ],
    );
    daemon.wait_log(Duration::from_secs(20), "MQTT subscribed");
    let answers = broker.subscribe(&["feedback"]);
    let mut slowest = Duration::ZERO;
    for i in 0..SAVES {
        answers.clear();
        let sent = Instant::now();
        broker.publish(
            "mqtt_control",
            &format!(
                r#"{{"cmd_type":"trajectory_control","cmd":"save_trajectory","data":{{"name":"slow{i}","data":[{{"longitude":113.2,"latitude":23.0,"angle":0,"x":{i},"y":0,"yaw":0}}]}}}}"#
            ),
        );
        let answer = answers
            .next_on("feedback", Duration::from_secs(10))
            .expect("an answer");
        slowest = slowest.max(sent.elapsed());
        let answer: Value = serde_json::from_str(&answer).expect("JSON");
        assert_eq!(answer["cmd"], "save_trajectory_success", "{answer}");
    }
    eprintln!("slowest save answer {slowest:?} with every fsync taking 500 ms");
    // Each save is two fsyncs (file, folder): written in the control task, every answer
    // would wait a second. mosquitto_pub's own start-up is the rest.
    assert!(slowest < Duration::from_millis(900), "{slowest:?}");

    let deadline = Instant::now() + Duration::from_secs(60);
    while daemon.child.try_wait().expect("status").is_none() {
        assert!(Instant::now() < deadline, "sim did not end");
        std::thread::sleep(Duration::from_millis(100));
    }
    let log: Vec<String> = daemon.stderr.try_iter().collect();
    assert!(
        daemon.child.wait().expect("exit").success(),
        "{:#?}",
        &log[log.len().saturating_sub(10)..]
    );

    let times = rpdo1_times(&std::fs::read_to_string(session.join("sim0.log")).expect("sim0.log"));
    assert!(times.len() > 400, "{} RPDOs", times.len());
    let worst = times.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
    eprintln!("worst gap between drive commands {worst} µs");
    assert!(worst <= 25_000, "a {worst} µs gap in the drive commands");

    for i in 0..SAVES {
        let file = folder.join(format!("slow{i}.json"));
        let text = std::fs::read_to_string(&file).expect("trajectory written");
        let saved: Value = serde_json::from_str(&text).expect("whole JSON");
        assert_eq!(saved["name"], format!("slow{i}"));
    }
}
