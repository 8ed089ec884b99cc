//! Replay golden tests: a recording through the real binary, compared byte for byte with
//! the expected output, and the same bytes on every run.
//!
//! `CHASSISD_BLESS=1 cargo test --test suite -- replay_golden::` rewrites the expected files after an
//! intended change; review the diff before committing it.

use crate::common;

use std::process::Command;

use common::replay;

fn statuses(stdout: &[u8]) -> Vec<serde_json::Value> {
    String::from_utf8(stdout.to_vec())
        .expect("UTF-8 output")
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
        .collect()
}

#[test]
fn rtk_drive_matches_expected_and_is_deterministic() {
    let fixture = common::repo().join("fixtures/rtk-drive");
    let expected_path = fixture.join("expected/base_status.jsonl");
    let first = replay(&fixture);
    let second = replay(&fixture);
    assert!(first.stdout == second.stdout, "two replays differ");
    if std::env::var_os("CHASSISD_BLESS").is_some() {
        std::fs::create_dir_all(expected_path.parent().unwrap()).unwrap();
        std::fs::write(&expected_path, &first.stdout).unwrap();
    }
    let expected = std::fs::read(&expected_path).expect("expected output exists");
    assert!(
        first.stdout == expected,
        "replay output differs from {}",
        expected_path.display()
    );

    let stderr = String::from_utf8_lossy(&first.stderr);
    let summary = stderr.lines().last().unwrap_or_default();
    for part in [
        "2489 frames (can0 20, gnss 2468, mqtt 1)",
        "600 status lines",
        "GGA 279",
        "checksum errors 1",
        "20 frames without a decoder",
        "1 commands from channels without a dialect",
        "skipped lines 0",
    ] {
        assert!(summary.contains(part), "summary lacks {part:?}: {summary}");
    }
}

/// The fixture's script (see fixtures/rtk-drive/generate.py), checked on the output itself
/// so the expected file cannot silently drift from it. The session starts at 0 s
/// (`start_us` in meta.toml), so tick `i` is at 0.1·i s.
#[test]
fn rtk_drive_status_follows_the_script() {
    let out = replay(&common::repo().join("fixtures/rtk-drive"));
    let rows = statuses(&out.stdout);
    assert_eq!(rows.len(), 600);
    let at = |s: f64| &rows[(s * 10.0).round() as usize];
    let status = |s: f64| at(s)["rtk"]["status"].as_u64().unwrap();
    let gnss_ok = |s: f64| at(s)["sensor"]["gnss"].as_bool().unwrap();
    assert!(
        !gnss_ok(0.0) && status(0.0) == 0,
        "nothing received at the start tick"
    );
    assert_eq!(status(2.0), 1, "single at the start");
    assert_eq!(status(10.0), 5, "float");
    assert_eq!(status(25.0), 4, "fixed");
    assert!(gnss_ok(34.9));
    // Silent from 35 s: the last fix (34.8 s) is stale 2 s later.
    assert!(gnss_ok(36.7));
    assert!(!gnss_ok(37.0) && status(37.0) == 0);
    assert_eq!(status(38.5), 4, "fix again after the outage");
    assert_eq!(status(47.0), 2, "DGPS");
    assert!(!gnss_ok(50.5) && status(50.5) == 0, "link down at 50.3 s");
    assert_eq!(status(52.0), 4, "after the reconnect");
    // Dual-antenna heading while it is valid; course over ground while THS is invalid.
    let angle = |s: f64| at(s)["rtk"]["angle"].as_f64().unwrap();
    assert!((angle(12.0) - 30.0).abs() < 1.0, "heading {}", angle(12.0));
    assert!((angle(40.0) - 245.0).abs() < 8.0, "course {}", angle(40.0));
    // Fusion: no map pose before the first fix; the first (single) fix is the datum and
    // gives a pose, beyond the bound while single; localised in float with the dual-antenna
    // heading, whose yaw the pose agrees with; lost during the outage, found again after it.
    let locate = |s: f64| at(s)["nav"]["locate"].as_str().unwrap().to_owned();
    assert_eq!(locate(0.0), "LOCATE_UNINIT");
    assert_eq!(locate(5.0), "LOCATE_FALSE");
    assert_eq!(locate(10.0), "LOCATE_TRUE");
    assert_eq!(locate(25.0), "LOCATE_TRUE");
    let yaw_deg = at(25.0)["pose"]["yaw"].as_f64().unwrap().to_degrees();
    let heading_as_yaw = 90.0 - angle(25.0);
    assert!(
        ((yaw_deg - heading_as_yaw + 540.0) % 360.0 - 180.0).abs() < 2.0,
        "{yaw_deg} vs {heading_as_yaw}"
    );
    assert_eq!(locate(37.5), "LOCATE_FALSE");
    assert_eq!(locate(40.0), "LOCATE_TRUE");
    // Position near the script's origin (23.1496524965 N, 113.0196366456667 E).
    let lat = at(25.0)["rtk"]["latitude"].as_f64().unwrap();
    let lon = at(25.0)["rtk"]["longitude"].as_f64().unwrap();
    assert!((lat - 23.14965).abs() < 1e-3 && (lon - 113.01964).abs() < 1e-3);
}

/// `fixtures/sim-drive` was recorded by `chassisd sim --plant devices/plant.delivery.toml
/// --scenario turns --duration 25 --record ...`, and its expected output is what that live
/// simulation printed: the replay must reproduce the simulator's status bytes exactly. It
/// runs the WitMotion decoder, the generic drives over PDO and the fusion filter.
#[test]
fn sim_drive_replays_to_the_simulators_live_output() {
    let fixture = common::repo().join("fixtures/sim-drive");
    let out = replay(&fixture);
    let expected = std::fs::read(fixture.join("expected/base_status.jsonl")).expect("expected");
    assert!(
        out.stdout == expected,
        "replay differs from the live simulation"
    );
    let summary = String::from_utf8_lossy(&out.stderr);
    for part in [
        "250 status lines",
        "0 refused",
        "0 differ",
        "checksum errors 0",
    ] {
        assert!(summary.contains(part), "summary lacks {part:?}: {summary}");
    }
    let rows = statuses(&out.stdout);
    let last = &rows[rows.len() - 1];
    assert_eq!(last["sensor"]["imu"], true);
    assert_eq!(last["sensor"]["robot"], true);
    assert_eq!(last["nav"]["locate"], "LOCATE_TRUE");
    // The turns scenario: 10 s straight east from 5 s, then an 8 m leg and a left turn on
    // the spot; by 25 s the vehicle is well away from the origin.
    let x = last["pose"]["x"].as_f64().unwrap();
    assert!(x > 10.0, "{last}");
}

#[test]
fn shared_logs_replay_to_status_lines() {
    for log in common::shared_gnss_logs() {
        let out = replay(&log);
        let rows = statuses(&out.stdout);
        assert!(!rows.is_empty(), "{}: no status", log.display());
        let summary = String::from_utf8_lossy(&out.stderr);
        assert!(summary.contains("replay: "), "{summary}");
        // Real receivers' logs without a clock jump read as one segment.
        assert!(!summary.contains("clock jumps"), "{summary}");
        assert!(
            rows.iter().any(|r| r["sensor"]["gnss"] == true),
            "{}: never a valid fix",
            log.display()
        );
        assert_eq!(out.stdout, replay(&log).stdout, "{}", log.display());
    }
    // A receiver that sends only u-blox UBX replays from its NAV-PVT times.
    for log in common::shared_binary_gnss_logs() {
        let out = replay(&log);
        let rows = statuses(&out.stdout);
        assert!(
            rows.iter().any(|r| r["sensor"]["gnss"] == true),
            "{}: never a valid fix",
            log.display()
        );
        let summary = String::from_utf8_lossy(&out.stderr);
        assert!(summary.contains("NAV-PVT"), "{summary}");
    }
    // A log with no time at all is refused, saying why.
    let dir = common::tempdir("untimed-log");
    let untimed = dir.join("untimed.log");
    std::fs::write(
        &untimed,
        b"$GPGSA,A,3,04,09,,,,,,,,,,,1.21,0.94,0.76*01\r\n",
    )
    .unwrap();
    let stderr = replay_failing(&untimed);
    assert!(
        stderr.contains("no sentence, NAV-PVT or NAV-SOL with a UTC time"),
        "{stderr}"
    );
}

/// `chassisd replay PATH`, which must fail: what it says.
fn replay_failing(path: &std::path::Path) -> String {
    let out = Command::new(common::chassisd())
        .arg("replay")
        .arg(path)
        .output()
        .expect("chassisd runs");
    assert!(
        !out.status.success(),
        "replay of {} succeeded",
        path.display()
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn bad_input_paths_fail_clearly() {
    let stderr = replay_failing(std::path::Path::new("/nonexistent/recording"));
    assert!(stderr.contains("/nonexistent/recording"), "{stderr}");
    // The operating system's reason, once.
    assert_eq!(
        stderr.matches("No such file or directory").count(),
        1,
        "{stderr}"
    );
    // A folder without meta.toml is named for what it is not.
    let stderr = replay_failing(&common::tempdir("not-a-recording"));
    assert!(stderr.contains("not a recording: no meta.toml"), "{stderr}");
}

/// A CAN session recorded on vcan0 in the VM (tests/vm/record-can-fixture): two CiA 402
/// drives and a Daly BMS. Replay fills bms.*, robot.* and sensor.robot from the frames, and
/// regenerates every frame chassisd sent in the live session.
#[test]
fn can_drive_replays_drives_and_bms() {
    let fixture = common::repo().join("fixtures/can-drive");
    let out = replay(&fixture);
    let expected =
        std::fs::read(fixture.join("expected/base_status.jsonl")).expect("expected output exists");
    assert!(
        out.stdout == expected,
        "replay differs from expected/base_status.jsonl"
    );
    assert_eq!(out.stdout, replay(&fixture).stdout, "two replays differ");
    // Every frame the live session sent (marked ` T` in the candump file) is regenerated.
    let sent = std::fs::read_to_string(fixture.join("vcan0.log"))
        .expect("vcan0.log")
        .lines()
        .filter(|l| l.ends_with(" T"))
        .count();
    assert!(sent > 1000, "{sent} transmissions recorded");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&format!(
            "recorded transmissions: {sent} reproduced, 0 differ"
        )),
        "{stderr}"
    );

    let rows = statuses(&out.stdout);
    let bits = |r: &serde_json::Value| r["robot"]["robot_status"].as_u64().unwrap();
    // BMS: decoded from the Daly replies, fresh, discharging with both MOSFETs on.
    let last = rows.last().unwrap();
    assert_eq!(last["bms"]["voltage"], 52.8);
    assert_eq!(last["bms"]["soc"], 80.0);
    assert_eq!(last["robot"]["power"], 80.0);
    assert_eq!(last["bms"]["status"], 1 | 8 | 16 | 32);
    let capacity = last["bms"]["remaining_capacity"].as_f64().unwrap();
    assert!(
        (23.9..24.0).contains(&capacity),
        "remaining capacity {capacity} Ah"
    );
    // Drives: ready and enabled, then at 0.3 m/s, then turning at 0.4 rad/s.
    assert!(
        rows.iter()
            .any(|r| r["sensor"]["robot"] == true && bits(r) & 1 != 0)
    );
    let top = rows
        .iter()
        .map(|r| r["robot"]["vx"].as_f64().unwrap())
        .fold(0.0, f64::max);
    assert!((top - 0.3).abs() < 0.002, "top speed {top}");
    // Motor speeds arrive in whole r/min: 0.4 rad/s reads back as 0.398.
    assert!(
        rows.iter()
            .any(|r| (r["robot"]["vz"].as_f64().unwrap() - 0.4).abs() < 0.005)
    );
    // The injected over-current: a latched fault that waits for a command, then clears.
    let faulted = rows
        .iter()
        .position(|r| bits(r) & 2 != 0 && bits(r) & 64 != 0)
        .expect("fault");
    assert_eq!(rows[faulted]["sensor"]["robot"], false);
    assert!(
        rows[faulted..]
            .iter()
            .any(|r| bits(r) & 2 == 0 && r["robot"]["vx"].as_f64().unwrap() > 0.15)
    );
}

/// `fixtures/ros-legacy`: a simulated session (`chassisd sim --fast --duration 10 --plant
/// devices/plant.delivery.toml --record`) with ROS1 node and rosbridge requests written in
/// the form recordings held before the protocol adapters: the local channel's topics and
/// JSON under the sources `ros1` and `websocket`. Such a recording must replay to the bytes
/// it replayed to then, and each request must get the answer it got then
/// (`expected/answers.txt`). The requests drive the vehicle otherwise than the recorded
/// run, so its transmissions differ and the replay runs `--lenient`.
#[test]
fn ros_requests_recorded_before_the_adapters_replay_as_before() {
    let fixture = common::repo().join("fixtures/ros-legacy");
    let out = common::replay_lenient(&fixture);
    let answers = engine_answers(&fixture);
    let expected_status = fixture.join("expected/base_status.jsonl");
    let expected_answers = fixture.join("expected/answers.txt");
    if std::env::var_os("CHASSISD_BLESS").is_some() {
        std::fs::create_dir_all(expected_status.parent().unwrap()).unwrap();
        std::fs::write(&expected_status, &out.stdout).unwrap();
        std::fs::write(&expected_answers, &answers).unwrap();
    }
    assert!(
        out.stdout == std::fs::read(&expected_status).expect("expected status"),
        "replay differs from {}",
        expected_status.display()
    );
    assert_eq!(
        answers,
        std::fs::read_to_string(&expected_answers).expect("expected answers")
    );
    let summary = String::from_utf8_lossy(&out.stderr);
    for part in [
        "ros1 8, sim0 3525, websocket 5",
        "100 status lines",
        "13 commands (5 refused)",
        "recorded transmissions: 314 reproduced, 1338 differ",
    ] {
        assert!(summary.contains(part), "summary lacks {part:?}: {summary}");
    }
    for request in ["set_navi_cmd", "cmd_vel", "goal", "mission"] {
        assert!(answers.contains(request), "{request} unanswered: {answers}");
    }
}

/// What the engine answers and announces over a recording, one line per output, each with
/// the time of the record that caused it.
fn engine_answers(dir: &std::path::Path) -> String {
    use chassisd::engine::EngineOutput;
    use std::fmt::Write as _;

    let mut text = String::new();
    // Every record as a record, transmissions included, as when the answers were taken.
    common::through_engine(dir, false, |t, out| {
        for output in out.drain(..) {
            let line = match output {
                EngineOutput::CommandResult {
                    source,
                    topic,
                    result,
                    ..
                } => format!("{source} {topic} {result:?}"),
                EngineOutput::MotionEnded(r) => {
                    format!("ended {:?} {:?} {:?} {}", r.id, r.kind, r.tag, r.outcome)
                }
                EngineOutput::Mission { tag, event } => format!("mission {tag:?} {event:?}"),
                EngineOutput::Event(e) => format!("event {e}"),
                _ => continue,
            };
            writeln!(text, "{} {line}", t.as_micros()).unwrap();
        }
    });
    text
}
