//! Crash safety of stored trajectories: the daemon is killed (SIGKILL) while trajectories are
//! being saved over MQTT, many times over — at random wall-clock moments, and (since a save
//! spends most of its time parsing, not writing) by strace at a random fsync or rename of a
//! save, the moments an unsafe write would be caught half done. Every trajectory file left is
//! complete and one of the versions sent; none is ever partly written.

use crate::common;

use std::process::{Command, Stdio};
use std::time::Duration;

use common::mqtt::Mosquitto;
use common::process::Proc;

const ROUNDS: u64 = 40;
const POINTS: usize = 4000;

/// The system Python, which has Debian's python3-paho-mqtt.
const PYTHON: &str = "/usr/bin/python3";

/// Publishes saves of "field" and "edge" (alternately) with increasing versions: every point
/// of version v has x = round·1000 + v. Arguments: port, round, --points N.
const PUBLISHER: &str = r#"
import sys, paho.mqtt.client as mqtt
port, rnd, points = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[4])
c = mqtt.Client()
c.connect("127.0.0.1", port)
c.loop_start()
for v in range(1000):
    version = rnd * 1000 + v
    name = "field" if v % 2 == 0 else "edge"
    p = '{"longitude":113.2,"latitude":23.1,"angle":%d,"x":%d,"y":0,"yaw":0}' % (version, version)
    msg = '{"cmd_type":"trajectory_control","cmd":"save_trajectory","data":{"name":"%s","data":[%s]}}' % (name, ",".join([p] * points))
    c.publish("mqtt_control", msg, qos=1).wait_for_publish()
"#;

#[test]
fn killed_while_saving_no_trajectory_is_ever_corrupt() {
    let broker = Mosquitto::start();
    let dir = common::tempdir("traj-crash");
    let mut seed: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut random = move |n: u64| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed % n
    };
    let mut saved_files = 0;
    let mut interrupted = 0;
    let mut killed_by_strace = 0;
    let mut newest_round = 0;
    for round in 0..ROUNDS {
        let address = broker.address();
        let args = [
            "sim".as_ref(),
            "--mqtt".as_ref(),
            address.as_ref(),
            "--trajectory-dir".as_ref(),
            dir.as_os_str(),
        ];
        // Every third round is killed by the clock; the others by strace, at the k-th fsync
        // (the temporary file is written, the rename not done) or the k-th rename.
        let injection: Option<String> = match round % 3 {
            0 => None,
            1 => Some(format!("inject=fsync:signal=KILL:when={}", 2 + random(12))),
            _ => Some(format!(
                "inject=rename,renameat,renameat2:signal=KILL:when={}",
                1 + random(6)
            )),
        };
        let mut daemon = match &injection {
            None => Proc::start(&args),
            Some(inject) => Proc::start_under(
                &[
                    "strace",
                    "-f",
                    "-qq",
                    "-o",
                    "/dev/null",
                    "-e",
                    "trace=fsync,rename,renameat,renameat2",
                    "-e",
                    inject,
                ],
                &args,
            ),
        };
        daemon.wait_log(Duration::from_secs(10), "MQTT subscribed");
        // A stream of saves as fast as paho can send them, each a new version of one of two
        // trajectories.
        let mut publisher = Command::new(PYTHON)
            .args([
                "-c",
                PUBLISHER,
                &broker.port.to_string(),
                &round.to_string(),
            ])
            .args(["--points", &POINTS.to_string()])
            .stdin(Stdio::null())
            .spawn()
            .expect("python3 with paho-mqtt (apt-get install python3-paho-mqtt)");
        if injection.is_some() {
            // strace kills it at the chosen system call; the clock is only a backstop.
            let deadline = std::time::Instant::now() + Duration::from_secs(20);
            while daemon.child.try_wait().expect("status").is_none()
                && std::time::Instant::now() < deadline
            {
                std::thread::sleep(Duration::from_millis(20));
            }
            killed_by_strace += u32::from(daemon.child.try_wait().expect("status").is_some());
        } else {
            std::thread::sleep(Duration::from_millis(200 + random(600)));
        }
        let _ = daemon.child.kill();
        let _ = daemon.child.wait();
        let _ = publisher.kill();
        let _ = publisher.wait();
        // Every trajectory file is whole: all its points from one version.
        for entry in std::fs::read_dir(&dir).expect("dir") {
            let path = entry.expect("entry").path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if name.starts_with('.') {
                interrupted += 1; // a temporary file of a write the kill interrupted
                continue;
            }
            let bytes = std::fs::read(&path).expect("read");
            let t: serde_json::Value = serde_json::from_slice(&bytes)
                .unwrap_or_else(|e| panic!("round {round}: {name} is corrupt: {e}"));
            let points = t["data"].as_array().expect("points");
            assert_eq!(points.len(), POINTS, "round {round}: {name}");
            let version = &points[0]["x"];
            assert!(
                points.iter().all(|p| &p["x"] == version),
                "round {round}: {name} mixes versions"
            );
            saved_files += 1;
            newest_round = newest_round.max(version.as_f64().unwrap_or(0.0) as u64 / 1000);
        }
    }
    assert!(saved_files > 0, "no save completed in {ROUNDS} rounds");
    // A restart cleans up what the last crash left, and lists what is stored.
    let mut daemon = Proc::start(&[
        "sim".as_ref(),
        "--mqtt".as_ref(),
        broker.address().as_ref(),
        "--trajectory-dir".as_ref(),
        dir.as_os_str(),
    ]);
    daemon.wait_log(Duration::from_secs(10), "MQTT subscribed");
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .expect("dir")
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    let answers = broker.subscribe(&["trajectory_data"]);
    broker.publish(
        "mqtt_control",
        r#"{"cmd_type":"trajectory_control","cmd":"get_all_trajectory"}"#,
    );
    let list = answers
        .next_on("trajectory_data", Duration::from_secs(10))
        .expect("listing");
    let list: serde_json::Value = serde_json::from_str(&list).expect("JSON");
    assert!(!list.as_array().expect("array").is_empty());
    eprintln!(
        "{saved_files} whole trajectory files checked over {ROUNDS} crashes ({killed_by_strace} \
         at an fsync or rename); {interrupted} temporary files left mid-write; newest version \
         from round {newest_round}"
    );
    // The injected kills really struck inside saves, leaving their temporary files.
    assert!(
        killed_by_strace >= ROUNDS as u32 / 2,
        "strace killed {killed_by_strace}"
    );
    assert!(interrupted > 0, "no kill caught a save mid-write");
    // Saves went on until late rounds, so the kills fell among them.
    assert!(
        newest_round >= ROUNDS / 2,
        "saves stopped early: round {newest_round}"
    );
}
