//! `chassisd sim`: the simulated vehicle in real time through the live engine. Its recording
//! replays to exactly the status bytes it printed, whether a scenario or standard input
//! drove it, and it stops cleanly on SIGTERM.

use crate::common;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use common::process::Proc;

/// The replay's stdout and its stderr summary.
fn replay(dir: &Path) -> (Vec<u8>, String) {
    let out = common::replay(dir);
    let summary = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.stdout, summary)
}

fn last_status(stdout: &[u8]) -> serde_json::Value {
    let text = String::from_utf8_lossy(stdout);
    serde_json::from_str(text.lines().last().expect("status lines")).expect("JSON")
}

#[test]
fn a_scripted_session_replays_to_the_same_bytes() {
    let dir = common::tempdir("sim-scenario").join("rec");
    let out = Command::new(common::chassisd())
        .args([
            "sim",
            "--no-mqtt",
            "--scenario",
            "turns",
            "--duration",
            "15",
            "--record",
        ])
        .arg(&dir)
        .output()
        .expect("chassisd runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 150);
    let (replayed, summary) = replay(&dir);
    assert!(
        replayed == out.stdout,
        "replay differs from the live output"
    );
    assert!(summary.contains("0 differ"), "{summary}");
    assert!(summary.contains("0 refused"), "{summary}");
    // The whole path ran: drives up and moving, IMU and RTK fixed, localised.
    let status = last_status(&out.stdout);
    assert_eq!(status["sensor"]["robot"], true, "{status}");
    assert_eq!(status["sensor"]["imu"], true, "{status}");
    assert_eq!(status["sensor"]["gnss"], true, "{status}");
    assert_eq!(status["rtk"]["status"], 4, "{status}");
    assert_eq!(status["nav"]["locate"], "LOCATE_TRUE", "{status}");
    assert!(status["robot"]["vx"].as_f64() > Some(0.5), "{status}");
}

#[test]
fn a_session_driven_from_stdin_replays_to_the_same_bytes() {
    let dir = common::tempdir("sim-stdin").join("rec");
    let mut sim = Proc::start(&[
        "sim".as_ref(),
        "--no-mqtt".as_ref(),
        "--plant".as_ref(),
        common::repo()
            .join("devices/plant.delivery.toml")
            .as_os_str(),
        "--commands-stdin".as_ref(),
        "--record".as_ref(),
        dir.as_os_str(),
    ]);
    sim.wait_log(Duration::from_secs(10), "drive right: running");
    for _ in 0..20 {
        sim.send(r#"cmd_vel {"linear":{"x":0.5},"angular":{"z":0.2}}"#);
        std::thread::sleep(Duration::from_millis(100));
    }
    sim.send(r#"cmd_vel {"linear":{"y":1.0}}"#);
    sim.wait_log(Duration::from_secs(5), "command refused");
    std::thread::sleep(Duration::from_millis(1500));
    let lines = sim.stop();
    let live: Vec<u8> = lines
        .iter()
        .flat_map(|l| format!("{l}\n").into_bytes())
        .collect();
    let (replayed, summary) = replay(&dir);
    assert!(replayed == live, "replay differs from the live output");
    assert!(summary.contains("1 refused"), "{summary}");
    // It moved while commanded, and the watchdog stopped it after the last command.
    let moved = lines.iter().any(|l| {
        serde_json::from_str::<serde_json::Value>(l)
            .is_ok_and(|s| s["robot"]["vx"].as_f64() > Some(0.4))
    });
    assert!(moved, "never moved");
    assert_eq!(last_status(&replayed)["robot"]["vx"].as_f64(), Some(0.0));
}

#[test]
fn a_bad_plant_file_is_refused_with_the_key() {
    let dir = common::tempdir("sim-bad-plant");
    let plant = dir.join("plant.toml");
    let text = std::fs::read_to_string(common::repo().join("devices/plant.mower.toml"))
        .expect("plant file")
        .replace("track_m = 0.42", "track_m = -1.0");
    std::fs::write(&plant, text).expect("write");
    let out = Command::new(common::chassisd())
        .args(["sim", "--no-mqtt", "--duration", "1", "--plant"])
        .arg(&plant)
        .output()
        .expect("chassisd runs");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("geometry.track_m"), "{stderr}");
}

#[test]
fn durations_that_are_not_a_span_of_seconds_are_refused_without_a_panic() {
    for bad in ["1e300", "nan", "inf", "0", "-3", "ten"] {
        let out = Command::new(common::chassisd())
            .args(["sim", "--no-mqtt", &format!("--duration={bad}")])
            .output()
            .expect("chassisd runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{bad}: {stderr}");
        assert!(stderr.contains("seconds"), "{bad}: {stderr}");
        assert!(!stderr.contains("panicked"), "{bad}: {stderr}");
    }
}

/// Killed (SIGKILL) while recording: every file of the recording was flushed on one
/// schedule, so the replay plays to the last moment they all cover, says so, and prints the
/// live output up to there exactly.
#[test]
fn a_killed_recording_replays_to_the_last_moment_every_file_covers() {
    let dir = common::tempdir("sim-killed").join("rec");
    let mut sim = Proc::start(&[
        "sim".as_ref(),
        "--no-mqtt".as_ref(),
        "--scenario".as_ref(),
        "turns".as_ref(),
        "--duration".as_ref(),
        "60".as_ref(),
        "--record".as_ref(),
        dir.as_os_str(),
    ]);
    // Past the scenario's first commands (it turns after a few seconds).
    let seen = std::cell::Cell::new(0);
    sim.wait_out(Duration::from_secs(20), "40 status lines", |_| {
        seen.set(seen.get() + 1);
        seen.get() >= 40
    });
    sim.child.kill().expect("SIGKILL");
    sim.child.wait().expect("exit status");
    std::thread::sleep(Duration::from_millis(200));
    sim.drain_out();
    let live: Vec<String> = sim.out.clone();
    let (replayed, summary) = replay(&dir);
    assert!(summary.contains("no clean end"), "{summary}");
    let replayed: Vec<&str> = std::str::from_utf8(&replayed)
        .expect("UTF-8")
        .lines()
        .collect();
    // The files end within a flush period (100 ms) of each other and of the kill; the live
    // pipe may hold a line or two more.
    assert!(
        replayed.len() + 3 >= live.len() && replayed.len() <= live.len(),
        "replayed {} status lines of {} live; {summary}",
        replayed.len(),
        live.len()
    );
    for (i, (r, l)) in replayed.iter().zip(&live).enumerate() {
        assert_eq!(r, l, "status line {} differs; {summary}", i + 1);
    }
    let commands = std::fs::read_to_string(dir.join("commands.log")).expect("commands.log");
    assert!(commands.lines().count() > 0, "no command reached the disk");
}

/// A recording whose file goes back in time is reported with the file and line, and the
/// replay exits 1 unless `--lenient` is given.
#[test]
fn records_out_of_time_order_are_reported_and_fail_the_replay() {
    let dir = common::tempdir("sim-out-of-order").join("rec");
    let out = Command::new(common::chassisd())
        .args(["sim", "--no-mqtt", "--scenario", "turns", "--duration", "3"])
        .arg("--record")
        .arg(&dir)
        .output()
        .expect("chassisd runs");
    assert!(out.status.success());
    common::replay(&dir);
    // Move the last 20 lines of the IMU file to its start.
    let imu = dir.join("imu.log");
    let text = std::fs::read_to_string(&imu).expect("imu.log");
    let lines: Vec<&str> = text.lines().collect();
    let (head, tail) = lines.split_at(lines.len() - 20);
    let edited: Vec<&str> = tail.iter().chain(head).copied().collect();
    std::fs::write(&imu, edited.join("\n") + "\n").expect("write imu.log");

    let strict = Command::new(common::chassisd())
        .arg("replay")
        .arg(&dir)
        .output()
        .expect("chassisd runs");
    let stderr = String::from_utf8_lossy(&strict.stderr);
    assert_eq!(strict.status.code(), Some(1), "{stderr}");
    // The first record after the moved block goes back: line 21.
    assert!(stderr.contains("out of time order imu.log:21:"), "{stderr}");
    assert!(stderr.contains("records out of time order 1"), "{stderr}");
    assert!(stderr.contains("--lenient"), "{stderr}");
    common::replay_lenient(&dir);
}
