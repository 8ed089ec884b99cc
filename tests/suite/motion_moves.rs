//! Closed-loop moves (`set_navi_cmd`) and a trajectory task (`follow_path`, paused and
//! continued) end to end: `chassisd sim` takes them on its local command channel, the
//! published pose moves by what was asked, the end is logged with its result, and the
//! recording replays to the same bytes (the same wheel commands).

use crate::common;

use std::time::Duration;

use common::process::Proc;

fn status(line: &str) -> Option<serde_json::Value> {
    serde_json::from_str(line).ok()
}

fn pose(s: &serde_json::Value) -> (f64, f64, f64) {
    let p = &s["pose"];
    (
        p["x"].as_f64().unwrap_or(f64::NAN),
        p["y"].as_f64().unwrap_or(f64::NAN),
        p["yaw"].as_f64().unwrap_or(f64::NAN),
    )
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
}

/// The last status line printed so far.
fn last(sim: &mut Proc) -> serde_json::Value {
    sim.drain_out()
        .iter()
        .rev()
        .find_map(|l| status(l))
        .expect("a status line")
}

#[test]
fn moves_and_a_task_from_stdin_move_the_published_pose_and_replay() {
    let dir = common::tempdir("motion-stdin").join("rec");
    let mut sim = Proc::start(&[
        "sim".as_ref(),
        "--no-mqtt".as_ref(),
        "--commands-stdin".as_ref(),
        "--record".as_ref(),
        dir.as_os_str(),
    ]);
    sim.wait_log(Duration::from_secs(10), "drive right: running");
    // Located (dual antenna, RTK fixed): the turn closes on the map's yaw.
    sim.wait_out(Duration::from_secs(20), "LOCATE_TRUE", |l| {
        status(l).is_some_and(|s| s["nav"]["locate"] == "LOCATE_TRUE")
    });
    std::thread::sleep(Duration::from_millis(300));
    let before = pose(&last(&mut sim));

    sim.send(r#"set_navi_cmd {"cmd": "1", "distance": 100}"#);
    sim.wait_log(
        Duration::from_secs(10),
        "move 1 (forward 1.000 m): succeeded",
    );
    sim.wait_out(Duration::from_secs(5), "NAV_SUCCESS", |l| {
        status(l).is_some_and(|s| s["nav"]["status"] == "NAV_SUCCESS")
    });
    std::thread::sleep(Duration::from_millis(500));
    let after_move = pose(&last(&mut sim));
    let moved = (after_move.0 - before.0).hypot(after_move.1 - before.1);
    assert!(
        (moved - 1.0).abs() < 0.01,
        "the published pose moved {moved} m"
    );

    sim.send(r#"set_navi_cmd {"cmd": 3, "distance": 90}"#);
    sim.wait_log(
        Duration::from_secs(10),
        "move 2 (turn left 90.0°): succeeded",
    );
    std::thread::sleep(Duration::from_millis(500));
    let after_turn = pose(&last(&mut sim));
    let turned = wrap(after_turn.2 - after_move.2).to_degrees();
    assert!(
        (turned - 90.0).abs() < 0.5,
        "the published yaw turned {turned}°"
    );

    // A bad request is refused with the reason; the next move replaces the one under way,
    // and a stop request ends it without latching.
    sim.send(r#"set_navi_cmd {"cmd": "9", "distance": 10}"#);
    sim.wait_log(Duration::from_secs(5), "cmd must be");
    sim.send(r#"set_navi_cmd {"cmd": "1", "distance": 300}"#);
    std::thread::sleep(Duration::from_millis(300));
    sim.send(r#"set_navi_cmd {"cmd": "2", "distance": 300}"#);
    sim.wait_log(
        Duration::from_secs(5),
        "move 3 (forward 3.000 m): cancelled: replaced",
    );
    std::thread::sleep(Duration::from_millis(300));
    sim.send(r#"set_navi_cmd {"cmd": "5"}"#);
    sim.wait_log(
        Duration::from_secs(5),
        "move 4 (back 3.000 m): cancelled: stop requested",
    );
    sim.send(r#"set_navi_cmd {"cmd": "4", "distance": 10}"#);
    sim.wait_log(
        Duration::from_secs(10),
        "move 5 (turn right 10.0°): succeeded",
    );
    std::thread::sleep(Duration::from_millis(300));

    // A trajectory task: 1.5 m ahead, then 1 m to the left (a corner turned on the spot),
    // paused on the way and continued.
    let (x, y, yaw) = pose(&last(&mut sim));
    let (s, c) = yaw.sin_cos();
    let at = |ahead: f64, left: f64| (x + ahead * c - left * s, y + ahead * s + left * c);
    let points: Vec<String> = [at(0.0, 0.0), at(1.5, 0.0), at(1.5, 1.0)]
        .iter()
        .flat_map(|(px, py)| [format!("{px:.4}"), format!("{py:.4}")])
        .collect();
    sim.send(&format!(
        r#"follow_path {{"path": [{}], "speed": 0.5}}"#,
        points.join(", ")
    ));
    std::thread::sleep(Duration::from_millis(1500));
    sim.send("pause {}");
    std::thread::sleep(Duration::from_millis(1000));
    sim.send("continue {}");
    sim.wait_log(Duration::from_secs(30), "move 6 (path of");
    let ended = sim.log.last().cloned().unwrap_or_default();
    assert!(ended.contains("succeeded"), "{ended}");
    std::thread::sleep(Duration::from_millis(500));
    let end = pose(&last(&mut sim));
    let (ex, ey) = at(1.5, 1.0);
    let off = (end.0 - ex).hypot(end.1 - ey);
    assert!(off < 0.05, "the task ended {off} m from its end");

    let lines = sim.stop();
    let live: Vec<u8> = lines
        .iter()
        .flat_map(|l| format!("{l}\n").into_bytes())
        .collect();
    let out = common::replay(&dir);
    let summary = String::from_utf8_lossy(&out.stderr);
    assert!(out.stdout == live, "replay differs from the live output");
    // Every wheel command of the live run was sent again by the replay.
    assert!(summary.contains("0 differ"), "{summary}");
}
