//! The rosbridge v2 server against a real rosbridge client: roslibpy from PyPI (installed by
//! tests/install-deps into target/test-venv) talking to `chassisd sim --websocket`. The
//! client script, tests/websocket/client.py, prints what it saw as JSON; these tests judge
//! it. A second, raw client that subscribes and never reads checks that a slow client
//! delays no one. A jog over it towards a keep-out zone (`sim --zones`) stops short of the
//! zone, with the zones on `/zones` and the vehicle's margin on `/safety_envelope`. Each test has its own simulated vehicle on its own port, so they run side by side.

use crate::common;

use std::process::Command;
use std::time::Duration;

use common::mqtt::free_port;
use common::process::Proc;
use common::ws;
use serde_json::Value;

/// `chassisd sim --no-mqtt --websocket 127.0.0.1:PORT`, listening.
fn sim(port: u16) -> Proc {
    let bind = format!("127.0.0.1:{port}");
    let mut sim = Proc::start(&["sim", "--no-mqtt", "--websocket", &bind]);
    // The banner gives the page's address, which a browser opens.
    sim.wait_log(
        Duration::from_secs(10),
        &format!("live page: http://{bind}/"),
    );
    sim.wait_log_seen(Duration::from_secs(10), "rosbridge v2 server listening");
    sim
}

/// `chassisd sim --no-mqtt --websocket 127.0.0.1:PORT --zones` with the yard of
/// tests/common/zones.rs written in `dir` (the pond's west edge 4 m ahead), started.
fn sim_in_the_yard(port: u16, dir: &std::path::Path) -> Proc {
    let plant = chassisd::sim::plant::PlantConfig::builtin().expect("plant");
    let zones = common::zones::yard(&plant, dir);
    let bind = format!("127.0.0.1:{port}");
    Proc::start(&[
        "sim".as_ref(),
        "--no-mqtt".as_ref(),
        "--websocket".as_ref(),
        bind.as_ref(),
        "--zones".as_ref(),
        zones.as_os_str(),
    ])
}

/// `chassisd run` of a vehicle called `name` (in a fresh folder `dir_name`) with a receiver
/// on a pseudo-terminal, and the WebSocket server on `port` requiring `token`, with `extra`
/// lines in `[websocket]`; once the server listens. The receiver must outlive the daemon.
fn run_with_token(
    dir_name: &str,
    name: &str,
    port: u16,
    token: &str,
    extra: &str,
) -> (Proc, common::pty::Talker) {
    let dir = common::tempdir(dir_name);
    let link = dir.join("gnss-port");
    let receiver = common::pty::Talker::start(common::pty::Port::open_at(&link));
    let config = dir.join("vehicle.toml");
    std::fs::write(
        &config,
        format!(
            "[vehicle]\nname = \"{name}\"\n\n[gnss]\nport = \"{}\"\n\n\
             [websocket]\nbind = \"127.0.0.1:{port}\"\ntoken = \"{token}\"\n{extra}",
            link.display()
        ),
    )
    .expect("config");
    let mut daemon = Proc::start(&["run".as_ref(), "--config".as_ref(), config.as_os_str()]);
    daemon.wait_log(Duration::from_secs(10), "rosbridge v2 server listening");
    (daemon, receiver)
}

/// Runs one check of the client script against the server on `port`.
fn client(port: u16, check: &[&str]) -> Value {
    let out = Command::new(common::venv_python())
        .arg(common::repo().join("tests/websocket/client.py"))
        .arg(port.to_string())
        .args(check)
        .output()
        .expect("the client runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{check:?}: {}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let last = stdout.lines().last().unwrap_or_default();
    serde_json::from_str(last).unwrap_or_else(|e| panic!("{e}: {stdout}"))
}

fn number(v: &Value, pointer: &str) -> f64 {
    v.pointer(pointer)
        .and_then(Value::as_f64)
        .unwrap_or_else(|| panic!("{pointer} in {v}"))
}

#[test]
fn pose_odom_battery_and_diagnostics_arrive_at_their_rates() {
    let port = free_port();
    let sim = sim(port);
    let seen = client(port, &["rates", "4"]);
    let pose_hz = number(&seen, "/pose_hz");
    let odom_hz = number(&seen, "/odom_hz");
    assert!((9.0..=11.0).contains(&pose_hz), "{seen}");
    assert!((45.0..=55.0).contains(&odom_hz), "{seen}");
    assert_eq!(seen["pose_frame"], "map", "{seen}");
    assert_eq!(seen["pose_covariance"], 36, "{seen}");
    assert_eq!(seen["odom_frame"], "odom", "{seen}");
    assert_eq!(seen["odom_child"], "base_link", "{seen}");
    assert!(
        seen["stamp"]["sec"].as_u64().unwrap() > 1_700_000_000,
        "{seen}"
    );
    // The frame tree: both transforms at the status rate, and composed they are the pose.
    assert!((9.0..=11.0).contains(&number(&seen, "/tf_hz")), "{seen}");
    assert_eq!(
        seen["tf_frames"],
        serde_json::json!(["map>odom", "odom>base_link"]),
        "{seen}"
    );
    assert!(number(&seen, "/tf_compared") >= 20.0, "{seen}");
    assert!(number(&seen, "/tf_vs_pose") < 1e-6, "{seen}");
    drop(sim);
}

#[test]
fn wheel_speeds_arrive_left_then_right() {
    let port = free_port();
    let sim = sim(port);
    let seen = client(
        port,
        &["echo", "/wheel_speeds", "std_msgs/msg/Float64MultiArray"],
    );
    let message = &seen["message"];
    assert_eq!(message["layout"]["dim"][0]["label"], "left_right", "{seen}");
    assert_eq!(message["data"].as_array().map(Vec::len), Some(2), "{seen}");
    drop(sim);
}

#[test]
fn the_drive_mode_arrives_by_name() {
    let port = free_port();
    let sim = sim(port);
    let seen = client(port, &["echo", "/drive_mode", "std_msgs/msg/String"]);
    assert_eq!(seen["message"]["data"], "manual", "{seen}");
    drop(sim);
}

#[test]
fn a_goal_pose_drives_the_vehicle_there_along_its_plan() {
    let port = free_port();
    let sim = sim(port);
    let seen = client(port, &["goal", "2.0", "1.0", "90"]);
    let x = number(&seen, "/pose/x");
    let y = number(&seen, "/pose/y");
    let yaw = number(&seen, "/pose/yaw").to_degrees();
    assert!(
        (x - 2.0).hypot(y - 1.0) < 0.05,
        "arrived at ({x:.3}, {y:.3})"
    );
    assert!((yaw - 90.0).abs() < 3.0, "facing {yaw:.1}°");
    // /plan: empty at subscription, the goal's line while it drives, empty again at the end.
    let plans: Vec<&Vec<Value>> = seen["plans"]
        .as_array()
        .expect("plans")
        .iter()
        .filter_map(Value::as_array)
        .collect();
    let sizes: Vec<usize> = plans.iter().map(|p| p.len()).collect();
    assert_eq!(sizes, [0, 2, 0], "{seen}");
    let end = &plans[1][1];
    assert!(
        (number(end, "/0") - 2.0).abs() < 1e-9 && (number(end, "/1") - 1.0).abs() < 1e-9,
        "{seen}"
    );
    sim.stop();
}

#[test]
fn cmd_vel_moves_the_vehicle_it_stops_when_publishing_ends_and_the_session_replays() {
    let port = free_port();
    let dir = common::tempdir("websocket-record").join("rec");
    let bind = format!("127.0.0.1:{port}");
    let mut sim = Proc::start(&[
        "sim".as_ref(),
        "--no-mqtt".as_ref(),
        "--websocket".as_ref(),
        bind.as_ref(),
        "--record".as_ref(),
        dir.as_os_str(),
    ]);
    sim.wait_log(Duration::from_secs(10), "rosbridge v2 server listening");
    let seen = client(port, &["cmd_vel", "0.3", "2"]);
    assert!(number(&seen, "/max_during") > 0.25, "{seen}");
    assert!(number(&seen, "/after").abs() < 0.01, "{seen}");
    // The clients' commands are in the recording, which replays to the live output.
    let lines = sim.stop();
    let live: Vec<u8> = lines
        .iter()
        .flat_map(|l| format!("{l}\n").into_bytes())
        .collect();
    let replay = common::replay(&dir);
    assert!(replay.stdout == live, "replay differs from the live output");
    let commands = std::fs::read_to_string(dir.join("websocket.log")).expect("websocket.log");
    assert!(commands.lines().count() >= 15, "{commands}");
}

#[test]
fn a_jog_towards_a_keep_out_zone_over_the_websocket_stops_short_of_it() {
    let port = free_port();
    let dir = common::tempdir("websocket-zones");
    let mut sim = sim_in_the_yard(port, &dir);
    sim.wait_log(Duration::from_secs(40), "GNSS gate open");
    // 0.5 m/s for 12 s would take the mower 6 m east, through the pond 4 m ahead.
    let seen = client(port, &["zones_jog", "0.5", "12"]);
    assert!(number(&seen, "/jog/max_during") > 0.4, "{seen}");
    // /zones, latched: every zone of the file as a marker after a DELETEALL, in `map`.
    let markers = seen["markers"].as_array().expect("markers");
    assert_eq!(markers[0]["action"], 3, "{seen}");
    let named: Vec<(&str, &str)> = markers[1..]
        .iter()
        .map(|m| (m["ns"].as_str().unwrap(), m["text"].as_str().unwrap()))
        .collect();
    assert_eq!(
        named,
        [
            ("boundary", "lawn"),
            ("keep_out", "pond"),
            ("wall", "fence"),
            ("keep_out", "tree")
        ]
    );
    let pond_west = markers[2]["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["x"].as_f64().unwrap())
        .fold(f64::INFINITY, f64::min);
    assert!((pond_west - 4.0).abs() < 0.01, "{pond_west}");
    assert!(markers.iter().all(|m| m["frame"] == "map"));
    // /safety_envelope at 10 Hz: the gate open, the margin grows with the speed, and the
    // vehicle ends nearest the pond, outside it.
    assert!(number(&seen, "/envelope_count") > 100.0, "{seen}");
    assert_eq!(seen["first"]["gate"], "open", "{seen}");
    assert_eq!(seen["first"]["level"], 0, "{seen}");
    let at_rest: f64 = seen["first"]["margin_m"].as_str().unwrap().parse().unwrap();
    assert!(number(&seen, "/max_margin") > at_rest + 0.05, "{seen}");
    assert_eq!(seen["last"]["nearest_zone"], "pond", "{seen}");
    assert!(number(&seen, "/min_clearance") > 0.0, "{seen}");
    let log = sim.stop_log();
    assert!(
        log.iter()
            .any(|l| l.contains("stopping: the keep_out zone \"pond\"")),
        "{}",
        log.join("\n")
    );
    // The simulator's truth in its closing line: short of the pond's west edge (x = 4 m),
    // front edge 0.45 m ahead of the axle.
    let (x, _) = common::truth_end(&log);
    assert!(x + 0.45 < 4.0 && x > 2.5, "ended at x = {x}");
}

#[test]
fn map_scan_and_a_goal_in_the_wrong_frame_are_refused_with_a_status() {
    let port = free_port();
    let sim = sim(port);
    let seen = client(port, &["refusals"]);
    let statuses: Vec<&str> = seen["statuses"]
        .as_array()
        .expect("statuses")
        .iter()
        .filter_map(Value::as_str)
        .collect();
    let said = |text: &str| statuses.iter().any(|s| s.contains(text));
    assert!(said("/map") && said("mapping stack"), "{seen}");
    assert!(said("/scan") && said("lidar"), "{seen}");
    assert!(said("give it in \"map\""), "{seen}");
    assert!(
        seen["levels"]
            .as_array()
            .unwrap()
            .iter()
            .all(|l| l == "error"),
        "{seen}"
    );
    let topics: Vec<&str> = seen["topics"]
        .as_array()
        .expect("rosapi topics")
        .iter()
        .filter_map(Value::as_str)
        .collect();
    for topic in ["/pose", "/odom", "/cmd_vel", "/goal_pose", "/plan"] {
        assert!(topics.contains(&topic), "{seen}");
    }
    drop(sim);
}

#[test]
fn a_strict_client_is_let_in_and_a_page_request_is_answered_once() {
    use std::io::Write;
    use tokio_tungstenite::tungstenite::{self, Message};
    let port = free_port();
    let sim = sim(port);
    // tungstenite (as websocat and Rust clients) refuses an upgrade whose Connection header
    // is not `upgrade` alone: hyper's keep-alive off made it `upgrade, close`.
    let stream = std::net::TcpStream::connect(("127.0.0.1", port)).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    let (mut socket, response) =
        tungstenite::client(format!("ws://127.0.0.1:{port}/"), stream).expect("the handshake");
    assert_eq!(response.headers()["connection"], "upgrade");
    socket
        .send(Message::Text(
            r#"{"op": "subscribe", "topic": "/odom"}"#.into(),
        ))
        .expect("subscribe");
    let first: Value = match socket.read().expect("a message") {
        Message::Text(text) => serde_json::from_str(&text).expect("JSON"),
        other => panic!("{other:?}"),
    };
    assert_eq!(first["topic"], "/odom", "{first}");
    // Anything else is one request per connection: two sent at once get one answer, which
    // closes the connection.
    let mut s = ws::connect_from([127, 0, 0, 1], port);
    s.write_all(
        b"GET /connection HTTP/1.1\r\nHost: a\r\n\r\nGET /connection HTTP/1.1\r\nHost: a\r\n\r\n",
    )
    .expect("send");
    let all = answer(&mut s);
    assert_eq!(all.matches("HTTP/1.1 ").count(), 1, "{all}");
    assert!(all.to_lowercase().contains("connection: close"), "{all}");
    sim.stop();
}

#[test]
fn a_client_that_never_reads_delays_no_other_client() {
    let port = free_port();
    let mut sim = sim(port);
    let seen = client(port, &["slow", "10"]);
    assert!(number(&seen, "/pose_hz") >= 9.0, "{seen}");
    assert!(number(&seen, "/largest_gap_s") < 0.3, "{seen}");
    // The silent client's queue overflowed: its oldest messages were dropped and counted.
    let (stderr, log) = (&sim.stderr, &mut sim.log);
    common::process::wait_for(
        stderr,
        log,
        Duration::from_secs(10),
        "the silent client's drops",
        |l| l.contains("websocket: client gone") && !l.contains("dropped=0"),
    );
}

#[test]
fn with_a_token_nothing_is_served_before_it_is_presented() {
    let port = free_port();
    let token = "s3cret-token-1234";
    let (daemon, _receiver) = run_with_token("websocket-token", "ws-token", port, token, "");
    let seen = client(port, &["auth", token]);
    assert_eq!(seen["before"], 0, "{seen}");
    assert!(
        seen["refused"]
            .as_array()
            .unwrap()
            .iter()
            .any(|m| m.as_str().unwrap_or("").contains("authenticate first")),
        "{seen}"
    );
    assert!(seen["after"].as_u64().unwrap() >= 1, "{seen}");
    // The receiver sends RTK fixed: the GNSS diagnostic is OK (level 0).
    assert_eq!(seen["statuses"][0], 0, "{seen}");
    let seen = client(port, &["url_token", token]);
    assert_eq!(seen["with_token"], "publish", "{seen}");
    assert_eq!(seen["without"], "status", "{seen}");
    assert!(
        seen["without_msg"]
            .as_str()
            .unwrap()
            .contains("authenticate first"),
        "{seen}"
    );
    daemon.stop();
}

/// Drives the live page of the daemon on `port` in headless Chromium with
/// tests/websocket/page.py (`mode`: its extra arguments); what it saw.
fn live_page(port: u16, dir: &std::path::Path, mode: &[&str]) -> Value {
    let chromium = std::path::Path::new("/usr/bin/chromium");
    assert!(
        chromium.exists(),
        "tests/install-deps installs Debian's chromium"
    );
    let out = Command::new(common::venv_python())
        .arg(common::repo().join("tests/websocket/page.py"))
        .arg(chromium)
        .arg(port.to_string())
        .arg(dir)
        .args(mode)
        .output()
        .expect("the page driver runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(stdout.lines().last().unwrap_or_default())
        .unwrap_or_else(|e| panic!("{e}: {stdout}"))
}

#[test]
fn the_live_page_in_headless_chromium_shows_the_vehicle_jogs_it_and_sets_a_goal() {
    let port = free_port();
    let sim = sim(port);
    let dir = common::tempdir("websocket-page");
    let seen = live_page(port, &dir, &[]);
    // Nothing but the daemon: the page, roslibjs, the WebSocket.
    let requests: Vec<&str> = seen["requests"]
        .as_array()
        .expect("requests")
        .iter()
        .filter_map(Value::as_str)
        .collect();
    let own = [
        format!("http://127.0.0.1:{port}/"),
        format!("ws://127.0.0.1:{port}/"),
    ];
    assert!(
        requests
            .iter()
            .all(|r| own.iter().any(|o| r.starts_with(o.as_str()))),
        "{requests:?}"
    );
    assert!(
        requests.iter().any(|r| r.ends_with("/roslib.min.js"))
            && requests.iter().any(|r| r.starts_with("ws://")),
        "{requests:?}"
    );
    // Held for 2 s at 0.3 m/s the vehicle moved; released, it stopped at once.
    assert_eq!(seen["held"], true, "{seen}");
    let moved = number(&seen, "/jogged/x") - number(&seen, "/start/x");
    assert!(moved > 0.4, "jogged {moved:.3} m: {seen}");
    assert!(number(&seen, "/stop_s") < 1.0, "{seen}");
    // The screenshot shows it: the picture changed as the pose did.
    let picture = |name: &str| std::fs::read(dir.join(name)).expect("screenshot");
    assert_ne!(picture("page-start.png"), picture("page-jogged.png"));
    // A click on the plot set a goal 2 m to its left, and the vehicle reached it.
    let (tx, ty) = (number(&seen, "/target/0"), number(&seen, "/target/1"));
    let (ax, ay) = (number(&seen, "/arrived/x"), number(&seen, "/arrived/y"));
    assert!((ax - tx).hypot(ay - ty) < 0.05, "{seen}");
    assert!(
        seen["events"]
            .as_array()
            .unwrap()
            .iter()
            .any(|e| e.as_str().unwrap_or("").contains("succeeded")),
        "{seen}"
    );
    // A held button stops when the page loses the focus.
    assert!(number(&seen, "/blur_stop_s") < 1.5, "{seen}");
    assert_eq!(seen["gnss"], "fix", "{seen}");
    assert!(number(&seen, "/battery") > 40.0, "{seen}");
    // For a person: numbers on the axes and a scale bar; every panel in plain words, no
    // protocol or Rust enum names; green only where all is well.
    assert!(
        seen["axis"]["x"].as_array().is_some_and(|a| a.len() >= 3),
        "{seen}"
    );
    assert!(
        seen["axis"]["y"].as_array().is_some_and(|a| a.len() >= 3),
        "{seen}"
    );
    assert!(number(&seen, "/scale/metres") >= 1.0, "{seen}");
    let panels = &seen["panels"];
    assert_eq!(panels["gnss"], "fix: RTK fixed", "{seen}");
    assert_eq!(
        panels["nav"], "the last motion succeeded; located",
        "{seen}"
    );
    let drives = panels["drives"].as_str().unwrap_or_default();
    assert!(drives.starts_with("ready") || drives == "driving", "{seen}");
    for (name, text) in panels.as_object().expect("panels") {
        let text = text.as_str().unwrap_or_default();
        let enum_like = text
            .split(|c: char| !c.is_alphanumeric() && c != '_')
            .any(|w| {
                w.contains('_')
                    || w.chars().skip(1).any(char::is_uppercase)
                        && w.chars().any(char::is_lowercase)
            });
        assert!(!enum_like, "{name}: {text:?}");
    }
    let green = "rgb(42, 122, 59)";
    for part in ["gnss", "drives", "nav", "battery"] {
        assert_eq!(seen["colours"][part], green, "{part} is well: {seen}");
    }
    // The last minutes: a sample a second, the speed and the position's σ known.
    let history = &seen["history"];
    for series in ["speed", "sigma", "fix", "battery"] {
        let values = history[series].as_array().expect("a series");
        assert!(values.len() >= 5, "{series}: {history}");
        assert!(values.iter().any(Value::is_number), "{series}: {history}");
    }
    drop(sim);
}

/// A page that cannot connect says why, in chassisd's words (a wrong token, none, too many
/// clients), and connects by itself once it can.
#[test]
fn the_live_page_says_why_it_cannot_connect_and_connects_once_it_can() {
    let port = free_port();
    let token = "page-token-5678";
    let (daemon, _receiver) = run_with_token(
        "websocket-page-refused",
        "ws-page",
        port,
        token,
        "max_clients = 1\n",
    );
    let dir = common::tempdir("websocket-page-refused-out");
    let seen = live_page(port, &dir, &["refused", token]);
    let said = |key: &str| seen[key].as_str().unwrap_or_default().to_owned();
    assert!(
        said("wrong").starts_with("wrong token (websocket.token)"),
        "{seen}"
    );
    assert!(said("none").contains("wants its token"), "{seen}");
    assert!(
        said("full").contains("too many WebSocket clients (websocket.max_clients)"),
        "{seen}"
    );
    assert_eq!(said("after"), "connected", "{seen}");
    assert!(number(&seen, "/reconnect_s") < 12.0, "{seen}");
    daemon.stop();
}

#[test]
fn the_live_page_draws_the_zones_and_the_margin_and_a_jog_on_it_stops_short_of_the_pond() {
    let port = free_port();
    let dir = common::tempdir("websocket-page-zones");
    let mut sim = sim_in_the_yard(port, &dir);
    sim.wait_log(Duration::from_secs(10), "rosbridge v2 server listening");
    let seen = live_page(port, &dir, &["zones"]);
    let kinds: Vec<(&str, &str)> = seen["zones"]
        .as_array()
        .expect("zones")
        .iter()
        .map(|z| (z["kind"].as_str().unwrap(), z["name"].as_str().unwrap()))
        .collect();
    assert_eq!(
        kinds,
        [
            ("boundary", "lawn"),
            ("keep_out", "pond"),
            ("wall", "fence"),
            ("keep_out", "tree")
        ]
    );
    // The pond is filled red on the plot; beside it the plot is white.
    let rgba = |key: &str| -> Vec<u64> {
        seen[key]
            .as_array()
            .unwrap_or_else(|| panic!("{key}: {seen}"))
            .iter()
            .map(|c| c.as_u64().unwrap())
            .collect()
    };
    let (inside, beside) = (rgba("inside"), rgba("beside"));
    assert!(inside[0] > inside[1] + 20 && inside[3] > 0, "{inside:?}");
    assert!(beside[0] == beside[1] || beside[3] == 0, "{beside:?}");
    // The margin: σ at rest, more while moving; it stopped nearest the pond, outside it.
    let margin = |key: &str| number(&seen, &format!("/{key}/margin"));
    assert!(margin("moving") > margin("at_rest") + 0.03, "{seen}");
    assert_eq!(seen["stopped"]["nearest"], "pond", "{seen}");
    let clearance = number(&seen, "/stopped/clearance");
    assert!(clearance > 0.0 && clearance < 0.6, "{seen}");
    let panel = seen["panel"].as_str().unwrap_or_default();
    assert!(
        panel.contains("gate open") && panel.contains("\"pond\""),
        "{panel}"
    );
    assert!(
        seen["margin_text"]
            .as_str()
            .unwrap_or_default()
            .starts_with("margin "),
        "{seen}"
    );
    assert!(
        seen["drives"].as_str().unwrap_or_default().contains("pond"),
        "the stop's reason on the page: {seen}"
    );
    let log = sim.stop_log();
    let (x, _) = common::truth_end(&log);
    assert!(x + 0.45 < 4.0 && x > 2.5, "ended at x = {x}");
}

#[test]
fn a_handshake_from_another_web_page_is_refused() {
    let port = free_port();
    let sim = sim(port);
    let here = format!("127.0.0.1:{port}");
    // chassisd's own page, a native client without Origin, and the allowed ones: in.
    assert_eq!(
        ws::handshake(port, "/", &here, Some(&format!("http://{here}"))).1,
        101
    );
    assert_eq!(ws::handshake(port, "/", &here, None).1, 101);
    // A page elsewhere, and a name that only resolves here (DNS rebinding): out.
    assert_eq!(
        ws::handshake(port, "/", &here, Some("http://evil.example.com")).1,
        403
    );
    let rebound = format!("evil.example.com:{port}");
    assert_eq!(
        ws::handshake(port, "/", &rebound, Some(&format!("http://{rebound}"))).1,
        403
    );
    drop(sim);
}

#[test]
fn a_publish_without_a_message_or_over_the_size_limit_is_refused_with_a_status() {
    let port = free_port();
    let mut sim = sim(port);
    let here = format!("127.0.0.1:{port}");
    let (mut s, code) = ws::handshake(port, "/", &here, None);
    assert_eq!(code, 101);
    let status_of = |s: &mut std::net::TcpStream| loop {
        let v = ws::next_json(s).expect("a message");
        if v["op"] == "status" {
            return v["msg"].as_str().unwrap_or_default().to_owned();
        }
    };
    ws::send_text(&mut s, r#"{"op": "publish", "topic": "/cmd_vel"}"#).unwrap();
    assert!(status_of(&mut s).contains("no `msg` object"));
    ws::send_text(
        &mut s,
        r#"{"op": "publish", "topic": "/cmd_vel", "msg": {}}"#,
    )
    .unwrap();
    assert!(status_of(&mut s).contains("linear.x and angular.z"));
    // Over 256 KiB: a status saying why, then the close.
    let big = format!(
        r#"{{"op": "publish", "topic": "/cmd_vel", "msg": {{"pad": "{}"}}}}"#,
        "x".repeat(300 << 10)
    );
    ws::send_text(&mut s, &big).unwrap();
    let said = status_of(&mut s);
    assert!(said.contains("262144"), "{said}");
    assert_eq!(
        ws::read_frame(&mut s).map(|f| f.0),
        Some(8),
        "a Close frame"
    );
    // None of it moved the vehicle, nor re-armed it.
    sim.wait_log(Duration::from_secs(5), "websocket: client gone");
    assert!(
        !sim.log.iter().any(|l| l.contains("command accepted")),
        "{:#?}",
        sim.log
    );
}

#[test]
fn wrong_tokens_are_delayed_and_the_fifth_closes_the_connection() {
    let port = free_port();
    let (mut daemon, _receiver) = run_with_token(
        "websocket-wrong-token",
        "ws-guess",
        port,
        "s3cret-token-1234",
        "",
    );
    let (mut s, code) = ws::handshake(port, "/", &format!("127.0.0.1:{port}"), None);
    assert_eq!(code, 101);
    let started = std::time::Instant::now();
    let guess = r#"{"op": "auth", "mac": "wrong-guess"}"#;
    let status = |s: &mut std::net::TcpStream| {
        ws::next_json(s).expect("a status")["msg"]
            .as_str()
            .unwrap_or_default()
            .to_owned()
    };
    // 5,000 guesses, as fast as the answers are read (in rounds of 100, within the
    // client's queue): a guess is checked only once the wait after the last wrong one is
    // over (1, 2, 4, 8 s); every other one is refused unchecked.
    let mut failed = 0u32;
    let mut waited = 0;
    for _ in 0..50 {
        for _ in 0..100 {
            ws::send_text(&mut s, guess).unwrap();
        }
        for _ in 0..100 {
            let said = status(&mut s);
            if said.contains("authentication failed") {
                failed += 1;
            } else if said.contains("wait") {
                waited += 1;
            }
        }
    }
    assert!(
        failed <= 2 && waited >= 4998,
        "{failed} checked, {waited} waited"
    );
    // Then a guess each time the wait is over, until the fifth wrong one closes.
    while failed < 5 {
        std::thread::sleep(Duration::from_secs(1 << (failed - 1)) + Duration::from_millis(200));
        ws::send_text(&mut s, guess).unwrap();
        let said = status(&mut s);
        if said.contains("authentication failed") {
            failed += 1;
            assert_eq!(
                said.contains("connection closes"),
                failed == 5,
                "{failed}: {said}"
            );
        }
    }
    assert_eq!(ws::next_json(&mut s), None, "the connection is closed");
    assert!(
        started.elapsed() >= Duration::from_secs(15),
        "{:?}",
        started.elapsed()
    );
    // Summed up every 5 s, never a line per try or per client.
    wait_summed(&mut daemon, "wrong_token", 5);
    assert_eq!(daemon.log_count("wrong token"), 0, "{:#?}", daemon.log);
    daemon.stop();
}

/// Descriptors `pid` has open.
fn descriptors(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count())
}

/// Whether the server closed `s` (end of stream or reset) within `wait`.
fn closed_within(s: &mut std::net::TcpStream, wait: Duration) -> bool {
    use std::io::Read;
    s.set_read_timeout(Some(wait)).expect("timeout");
    let mut buf = [0u8; 1024];
    loop {
        match s.read(&mut buf) {
            Ok(0) => return true,
            Ok(_) => {}
            Err(e) => {
                return !matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                );
            }
        }
    }
}

#[test]
fn half_sent_requests_are_closed_within_the_header_timeout_while_a_client_connects() {
    use std::io::Write;
    let port = free_port();
    let mut sim = sim(port);
    let pid = sim.child.id();
    let before = descriptors(pid);
    let here = format!("127.0.0.1:{port}");
    // 200 connections from one host (127.0.0.2) that never finish their request's head.
    let started = std::time::Instant::now();
    let mut half: Vec<std::net::TcpStream> = (0..200)
        .map(|_| {
            let mut s = ws::connect_from([127, 0, 0, 2], port);
            let _ = s.write_all(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n");
            s
        })
        .collect();
    // Meanwhile a rosbridge client from another host connects and is served.
    let (mut client, code) = ws::handshake(port, "/", &here, None);
    assert_eq!(code, 101);
    ws::send_text(
        &mut client,
        r#"{"op": "subscribe", "topic": "/diagnostics"}"#,
    )
    .unwrap();
    let first = ws::next_json(&mut client).expect("a message");
    assert_eq!(first["topic"], "/diagnostics", "{first}");
    // Every half-sent one is closed: beyond the per-address cap at once, the others at the
    // header timeout (5 s), all well within the 10 s deadline.
    for (i, s) in half.iter_mut().enumerate() {
        let left = Duration::from_secs(9).saturating_sub(started.elapsed());
        assert!(closed_within(s, left), "connection {i} still open");
    }
    drop(half);
    // Then 8 from each of nine hosts: 64 may be in their exchange at once in all, and the
    // newest take the oldest ones' places.
    let started = std::time::Instant::now();
    let mut half: Vec<std::net::TcpStream> = (3..12)
        .flat_map(|host| (0..8).map(move |_| host))
        .map(|host| {
            let mut s = ws::connect_from([127, 0, 0, host], port);
            let _ = s.write_all(b"GET / HTTP/1.1\r\n");
            s
        })
        .collect();
    for (i, s) in half.iter_mut().enumerate() {
        let left = Duration::from_secs(9).saturating_sub(started.elapsed());
        assert!(closed_within(s, left), "connection {i} still open");
    }
    drop(half);
    // A head over 8 KiB is refused; a page request is answered and the connection closed.
    let mut big = ws::connect_from([127, 0, 0, 1], port);
    let head = format!(
        "GET / HTTP/1.1\r\nHost: {here}\r\nX-Pad: {}\r\n\r\n",
        "x".repeat(10_000)
    );
    let _ = big.write_all(head.as_bytes());
    assert!(answer(&mut big).starts_with("HTTP/1.1 431"));
    let mut page = ws::connect_from([127, 0, 0, 1], port);
    page.write_all(format!("GET / HTTP/1.1\r\nHost: {here}\r\n\r\n").as_bytes())
        .unwrap();
    assert!(answer(&mut page).starts_with("HTTP/1.1 200"));
    std::thread::sleep(Duration::from_millis(300));
    let after = descriptors(pid);
    assert!(
        after <= before + 2,
        "descriptors: {before} before, {after} after"
    );
    // Summed up in the log, not one line per connection: 8 of the first 200 in their
    // exchange (one host), 64 of the next 72 (nine hosts), 8 of which lost their places.
    let lines = |sim: &mut Proc| sim.log_count("websocket: clients refused or closed");
    wait_summed(&mut sim, "header_timeout", 72);
    assert_eq!(summed(&sim.log, "over_address"), 192, "{:#?}", sim.log);
    assert_eq!(summed(&sim.log, "handshake_evicted"), 8, "{:#?}", sim.log);
    // A flood from 64 hosts, 8 each: a client that comes after it still connects.
    let started = std::time::Instant::now();
    let mut half: Vec<std::net::TcpStream> = (20..84)
        .flat_map(|host| (0..8).map(move |_| host))
        .map(|host| {
            let mut s = ws::connect_from([127, 0, 1, host], port);
            let _ = s.write_all(b"GET / HTTP/1.1\r\n");
            s
        })
        .collect();
    let (mut late, code) = ws::handshake(port, "/", &here, None);
    assert_eq!(code, 101);
    ws::send_text(&mut late, r#"{"op": "subscribe", "topic": "/diagnostics"}"#).unwrap();
    assert_eq!(
        ws::next_json(&mut late).expect("a message")["topic"],
        "/diagnostics"
    );
    for (i, s) in half.iter_mut().enumerate() {
        let left = Duration::from_secs(9).saturating_sub(started.elapsed());
        assert!(closed_within(s, left), "flood connection {i} still open");
    }
    drop(half);
    let n = lines(&mut sim);
    assert!((1..=8).contains(&n), "{n}: {:#?}", sim.log);
    drop(client);
}

/// Everything the server sends on `s` until it closes it (10 s at most).
fn answer(s: &mut std::net::TcpStream) -> String {
    use std::io::Read;
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut all = Vec::new();
    let _ = s.read_to_end(&mut all);
    String::from_utf8_lossy(&all).into_owned()
}

/// Waits for the server's summaries in `p`'s log to count `n` of `key` (they come every
/// 5 s, and a burst may be split between two), and checks there are no more.
fn wait_summed(p: &mut Proc, key: &str, n: u64) {
    let deadline = std::time::Instant::now() + Duration::from_secs(11);
    while summed(&p.log, key) < n && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(200));
        p.log_count("");
    }
    assert_eq!(summed(&p.log, key), n, "{key}: {:#?}", p.log);
}

/// The sum of `key=N` over the server's summary lines in `log`.
fn summed(log: &[String], key: &str) -> u64 {
    let key = format!("{key}=");
    log.iter()
        .filter(|l| l.contains("websocket: clients refused or closed"))
        .flat_map(|l| l.split_whitespace())
        .filter_map(|w| w.strip_prefix(key.as_str()))
        .filter_map(|n| {
            n.trim_end_matches(|c: char| !c.is_ascii_digit())
                .parse::<u64>()
                .ok()
        })
        .sum()
}

#[test]
fn clients_without_the_token_lock_no_operator_out_and_are_closed_within_20_s() {
    let port = free_port();
    let token = "s3cret-token-1234";
    let (mut daemon, _receiver) = run_with_token("websocket-idle", "ws-idle", port, token, "");
    let here = format!("127.0.0.1:{port}");
    let idle_from =
        |host: u8| ws::handshake_on(ws::connect_from([127, 0, 0, host], port), "/", &here, None);
    // 16 idle clients without the token (websocket.max_clients) from four hosts: all in,
    // waiting to authenticate. A fifth from one host, and a 17th from a new one, are not.
    let started = std::time::Instant::now();
    let mut idle = Vec::new();
    for host in 2..6 {
        for _ in 0..4 {
            let (s, code) = idle_from(host);
            assert_eq!(code, 101);
            idle.push(s);
        }
    }
    assert_eq!(idle_from(2).1, 503, "four per host");
    assert_eq!(idle_from(9).1, 503, "max_clients waiting at once");
    // A wrong token in the URL takes no place at all.
    let wrong = ws::handshake(port, "/?token=not-the-token", &here, None).1;
    assert_eq!(wrong, 401);
    // The operator, with the token, has places of its own and is served.
    let (mut operator, code) = ws::handshake(port, &format!("/?token={token}"), &here, None);
    assert_eq!(code, 101);
    ws::send_text(
        &mut operator,
        r#"{"op": "subscribe", "topic": "/diagnostics"}"#,
    )
    .unwrap();
    let first = ws::next_json(&mut operator).expect("a message");
    assert_eq!(first["topic"], "/diagnostics", "{first}");
    // The idle ones are told and closed 20 s after their handshake.
    for s in &mut idle {
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        let said = ws::next_json(s).expect("a status");
        assert!(
            said["msg"]
                .as_str()
                .unwrap_or("")
                .contains("not done within 20 s"),
            "{said}"
        );
        assert_eq!(ws::next_json(s), None, "closed");
    }
    let waited = started.elapsed();
    assert!(waited >= Duration::from_secs(19), "{waited:?}");
    // Their places are back.
    drop(idle);
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(idle_from(2).1, 101);
    wait_summed(&mut daemon, "auth_timeout", 16);
    assert_eq!(
        daemon.log_count("websocket: client connected"),
        1,
        "only the operator is logged: {:#?}",
        daemon.log
    );
    drop(operator);
    daemon.stop();
}

#[test]
fn a_client_that_authenticates_with_every_place_taken_is_closed_with_a_status() {
    let port = free_port();
    let token = "s3cret-token-1234";
    let (mut daemon, _receiver) = run_with_token(
        "websocket-full",
        "ws-full",
        port,
        token,
        "max_clients = 1\n",
    );
    let here = format!("127.0.0.1:{port}");
    // The one place is taken by an operator; a second client waits without the token.
    let (_operator, code) = ws::handshake(port, &format!("/?token={token}"), &here, None);
    assert_eq!(code, 101);
    let (mut late, code) = ws::handshake(port, "/", &here, None);
    assert_eq!(code, 101);
    ws::send_text(&mut late, &format!(r#"{{"op": "auth", "mac": "{token}"}}"#)).unwrap();
    let mut said = Vec::new();
    while let Some(v) = ws::next_json(&mut late) {
        said.push(v["msg"].as_str().unwrap_or_default().to_owned());
    }
    assert!(
        said.iter().any(|m| m.contains("websocket.max_clients")),
        "{said:?}"
    );
    wait_summed(&mut daemon, "full", 1);
    daemon.stop();
}
