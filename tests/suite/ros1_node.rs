//! The ROS1 node (issue 12) against a real rosmaster and the real ROS tools (`rostopic`,
//! `rosservice`) as the client, on `chassisd sim --no-mqtt --ros-master URI`, exactly as a
//! person would run it. The Python tools call the spec's services through classes genpy
//! generates from the repository's own `map_msgs` files.

#![cfg(feature = "ros1")]

use crate::common;

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use common::process::{Proc, children_of, descriptors, lines_of, rss_mb};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// A rosmaster on its own port (the tests run side by side).
struct Master {
    port: u16,
    child: Child,
}

impl Master {
    fn start() -> Master {
        Self::start_on(common::mqtt::free_port())
    }

    fn start_on(port: u16) -> Master {
        let child = Command::new("rosmaster")
            .args(["--core", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("rosmaster runs (Debian's ros-core; tests/install-deps installs it)");
        let deadline = Instant::now() + Duration::from_secs(20);
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(
                Instant::now() < deadline,
                "rosmaster did not listen on {port}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        Master { port, child }
    }

    fn uri(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// Kills it (no goodbye to anyone) and waits for it to be gone.
    fn kill(mut self) -> u16 {
        let _ = self.child.kill();
        let _ = self.child.wait();
        self.port
    }
}

impl Drop for Master {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The Python classes of the spec's services, generated once from the repository's files.
fn python_classes() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = common::tempdir("ros1-python");
        let interfaces = common::repo().join("crates/core/src/api/ros1/interfaces");
        let include = |package: &str| {
            format!(
                "-I{package}:{}",
                interfaces.join(package).join("msg").display()
            )
        };
        for kind in ["srv", "msg"] {
            let out = dir.join("map_msgs").join(kind);
            std::fs::create_dir_all(&out).expect("folder");
            let generator = if kind == "srv" {
                "/usr/lib/genpy/gensrv_py.py"
            } else {
                "/usr/lib/genpy/genmsg_py.py"
            };
            let files: Vec<PathBuf> = std::fs::read_dir(interfaces.join("map_msgs").join(kind))
                .expect("map_msgs definitions")
                .map(|e| e.expect("entry").path())
                .collect();
            let status = Command::new("/usr/bin/python3")
                .arg(generator)
                .args(["-p", "map_msgs"])
                .args([
                    include("map_msgs"),
                    include("geometry_msgs"),
                    include("std_msgs"),
                ])
                .arg("-o")
                .arg(&out)
                .args(&files)
                .status()
                .expect("genpy runs (Debian's python3-genpy)");
            assert!(status.success(), "genpy failed on {files:?}");
            let status = Command::new("/usr/bin/python3")
                .arg(generator)
                .args(["--initpy", "-p", "map_msgs", "-o"])
                .arg(&out)
                .status()
                .expect("genpy runs");
            assert!(status.success());
        }
        std::fs::write(dir.join("map_msgs/__init__.py"), "").expect("package");
        dir
    })
}

/// Runs a ROS tool (`rostopic ...`, `rosservice ...`) against `master`, stopped with SIGINT
/// after `limit` (as a person stops `rostopic hz`).
fn ros(master: &Master, args: &[&str], limit: Duration) -> Output {
    Command::new("timeout")
        .args(["-s", "INT", "-k", "3", &format!("{}", limit.as_secs_f64())])
        .args(args)
        .env("ROS_MASTER_URI", master.uri())
        .env("PYTHONPATH", python_classes())
        .env("ROS_HOME", common::tempdir("ros-home"))
        .output()
        .expect("the ROS tools run (Debian's ros-core)")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `rostopic echo -n 1 TOPIC`, retried until `want` holds or `wait` passes.
fn echo_until(master: &Master, topic: &str, wait: Duration, want: impl Fn(&str) -> bool) -> String {
    let deadline = Instant::now() + wait;
    loop {
        let out = text(&ros(
            master,
            &["rostopic", "echo", "-n", "1", topic],
            Duration::from_secs(5),
        ));
        if want(&out) {
            return out;
        }
        assert!(
            Instant::now() < deadline,
            "{topic} never showed what was wanted; last:\n{out}"
        );
        std::thread::sleep(Duration::from_millis(300));
    }
}

/// `chassisd sim --no-mqtt --ros-master URI [MORE]`, once the node is registered.
fn sim_with(master: &Master, more: &[&str]) -> Proc {
    let uri = master.uri();
    let mut args = vec!["sim", "--ros-master", uri.as_str()];
    if !more.contains(&"--mqtt") {
        args.push("--no-mqtt");
    }
    args.extend_from_slice(more);
    let mut p = Proc::start(&args);
    p.wait_log(Duration::from_secs(30), "ROS1 node registered");
    p
}

fn sim(master: &Master) -> Proc {
    sim_with(master, &[])
}

/// Stops `p` with SIGINT; every stdout line and its stderr (the summary line last).
fn interrupt(mut p: Proc) -> (Vec<String>, Vec<String>) {
    kill(Pid::from_raw(p.child.id() as i32), Signal::SIGINT).expect("signal");
    let deadline = Instant::now() + Duration::from_secs(10);
    while p.child.try_wait().expect("status").is_none() {
        assert!(Instant::now() < deadline, "no exit within 10 s of SIGINT");
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut log = std::mem::take(&mut p.log);
    log.extend(p.stderr.iter());
    let mut out = std::mem::take(&mut p.out);
    out.extend(p.stdout.iter());
    (out, log)
}

/// The last "average rate" `rostopic hz` printed.
fn average_rate(out: &str) -> f64 {
    out.lines()
        .filter_map(|l| l.trim().strip_prefix("average rate:"))
        .filter_map(|v| v.trim().parse().ok())
        .next_back()
        .unwrap_or_else(|| panic!("no rate in:\n{out}"))
}

/// The vehicle's forward speed in a base_status line.
fn vx(line: &str) -> f64 {
    let v: serde_json::Value = serde_json::from_str(line).expect("base_status JSON");
    v["robot"]["vx"].as_f64().expect("robot.vx")
}

#[test]
fn the_node_publishes_its_topics_and_answers_its_services() {
    // On ROS's own port, exactly as the README runs it by hand.
    assert!(
        TcpStream::connect(("127.0.0.1", 11311)).is_err(),
        "port 11311 is taken: stop the ROS master running on this machine"
    );
    let master = Master::start_on(11311);
    assert_eq!(master.uri(), "http://127.0.0.1:11311");
    let recording = common::tempdir("ros1-services").join("rec");
    let mut p = sim_with(
        &master,
        &["--record", recording.to_str().expect("UTF-8 path")],
    );

    let hz = text(&ros(
        &master,
        &["rostopic", "hz", "-w", "300", "/raw_odom"],
        Duration::from_secs(7),
    ));
    let rate = average_rate(&hz);
    assert!((95.0..=105.0).contains(&rate), "/raw_odom at {rate} Hz");
    let odom = echo_until(&master, "/raw_odom", Duration::from_secs(5), |o| {
        o.contains("frame_id: \"odom\"")
    });
    assert!(odom.contains("child_frame_id: \"base_link\""), "{odom}");
    assert!(
        odom.contains("1000000.0"),
        "z, roll, pitch unmeasured:\n{odom}"
    );

    let located = echo_until(
        &master,
        "/androidmsg_locationstatus",
        Duration::from_secs(20),
        |o| o.contains("data: 10"),
    );
    assert!(located.contains("data: 10"));
    let pose = echo_until(&master, "/tracked_pose", Duration::from_secs(5), |o| {
        o.contains("frame_id: \"map\"")
    });
    assert!(
        pose.contains("position:") && pose.contains("orientation:"),
        "{pose}"
    );
    let tracked = text(&ros(
        &master,
        &["rostopic", "hz", "-w", "50", "/tracked_pose"],
        Duration::from_secs(5),
    ));
    let rate = average_rate(&tracked);
    assert!((14.0..=16.0).contains(&rate), "/tracked_pose at {rate} Hz");
    // The frame tree (REP-105): map→odom and odom→base_link in one message, at 15 Hz.
    let tf = echo_until(&master, "/tf", Duration::from_secs(5), |o| {
        o.contains("child_frame_id: \"odom\"")
    });
    assert!(
        tf.contains("frame_id: \"map\"")
            && tf.contains("frame_id: \"odom\"")
            && tf.contains("child_frame_id: \"base_link\"")
            && tf.contains("translation:")
            && tf.contains("rotation:"),
        "{tf}"
    );
    let rate = average_rate(&text(&ros(
        &master,
        &["rostopic", "hz", "-w", "50", "/tf"],
        Duration::from_secs(5),
    )));
    assert!((14.0..=16.0).contains(&rate), "/tf at {rate} Hz");
    let imu = echo_until(&master, "/imu/data", Duration::from_secs(5), |o| {
        o.contains("angular_velocity_covariance")
    });
    assert!(imu.contains("frame_id: \"base_link\""), "{imu}");
    // A topic published from the status (api::ros1::topics): the wheels, left then right.
    let wheels = echo_until(&master, "/wheel_speeds", Duration::from_secs(5), |o| {
        o.contains("label: \"left_right\"")
    });
    assert!(
        wheels.contains("size: 2") && wheels.contains("data: ["),
        "{wheels}"
    );
    // Another, of a type added with it (std_msgs/String): who may drive, at 1 Hz.
    let mode = echo_until(&master, "/drive_mode", Duration::from_secs(5), |o| {
        o.contains("data: ")
    });
    assert!(mode.contains("data: \"manual\""), "{mode}");

    for (topic, code) in [
        ("/androidmsg_initstatus", "data: 12"),
        ("/androidmsg_emergencystatus", "data: 32"),
        ("/androidmsg_chargestatus", "data: 41"),
        ("/power_report", "data: 80"),
    ] {
        echo_until(&master, topic, Duration::from_secs(10), |o| {
            o.contains(code)
        });
    }

    let info = text(&ros(
        &master,
        &["rosservice", "call", "/navi_info"],
        Duration::from_secs(10),
    ));
    assert!(info.contains("status: 0"), "{info}");
    assert!(info.contains(env!("CARGO_PKG_VERSION")), "{info}");
    let position = text(&ros(
        &master,
        &["rosservice", "call", "/get_position"],
        Duration::from_secs(10),
    ));
    assert!(
        position.contains("pose:") && position.contains("x:"),
        "{position}"
    );

    let ssh = ros(
        &master,
        &["rosservice", "call", "/robot_ssh", "instruction: 'reboot'"],
        Duration::from_secs(10),
    );
    let answer = text(&ssh);
    assert!(answer.contains("status: 1"), "{answer}");
    assert!(answer.contains("disabled for security"), "{answer}");
    p.wait_log(Duration::from_secs(5), "topic=/robot_ssh");
    let wifi = ros(
        &master,
        &[
            "rosservice",
            "call",
            "/set_wifi",
            "{wifi_name: 'yard-net', wifi_pass: 'secret-pass'}",
        ],
        Duration::from_secs(10),
    );
    assert!(!wifi.status.success());
    assert!(
        text(&wifi).contains("disabled for security"),
        "{}",
        text(&wifi)
    );

    // The services went through the engine: recorded (a Wi-Fi password never), and a
    // replay of the recording answers them as the vehicle did.
    drop(interrupt(p));
    let (_, records) = chassisd::record::RecordingReader::open(&recording).expect("recording");
    let requests: String = records
        .filter(|r| r.source == "ros1")
        .filter_map(|r| match r.payload {
            chassisd::record::Payload::Command { topic, payload } => {
                Some(format!("{topic} {}\n", String::from_utf8_lossy(&payload)))
            }
            _ => None,
        })
        .collect();
    for service in ["/navi_info", "/get_position", "/robot_ssh", "/set_wifi"] {
        assert!(
            requests.contains(service),
            "{service} not recorded:\n{requests}"
        );
    }
    assert!(requests.contains("yard-net"), "{requests}");
    assert!(!requests.contains("secret-pass"), "{requests}");
    let mut answers = Vec::new();
    common::as_replayed(&recording, |_, outputs| {
        for output in outputs.drain(..) {
            if let chassisd::engine::EngineOutput::CommandResult {
                topic,
                result,
                data,
                ..
            } = output
            {
                answers.push((topic, result, data));
            }
        }
    });
    let answered = |service: &str| {
        answers
            .iter()
            .find(|(topic, ..)| topic == service)
            .unwrap_or_else(|| panic!("{service} not answered on replay: {answers:?}"))
            .clone()
    };
    let (_, result, data) = answered("/get_position");
    let at = data.unwrap_or_else(|| panic!("the position: {result:?}"));
    assert!(
        result.is_ok() && at["x"].is_f64() && at["y"].is_f64(),
        "{at}"
    );
    // The caller got the same position (as float32, the service's type).
    let got = |key: &str| -> f32 {
        position
            .lines()
            .find_map(|l| l.trim().strip_prefix(&format!("{key}: ")))
            .and_then(|v| v.trim().parse::<f64>().ok())
            .unwrap_or_else(|| panic!("no {key} in:\n{position}")) as f32
    };
    for key in ["x", "y"] {
        assert_eq!(
            got(key),
            at[key].as_f64().unwrap() as f32,
            "{key}: the replay answers {at}, the caller got:\n{position}"
        );
    }
    let (_, _, about) = answered("/navi_info");
    assert!(about.is_some_and(|a| {
        a.as_str()
            .is_some_and(|a| a.contains(env!("CARGO_PKG_VERSION")))
    }));
    for refused in ["/robot_ssh", "/set_wifi"] {
        let (_, result, _) = answered(refused);
        assert!(result.is_err_and(|why| why.contains("disabled for security")));
    }
}

/// The zones on the WebSocket server at `port` as a new `/zones` subscriber gets them:
/// each marker's kind, id and name (the DELETEALL left out).
fn zone_markers(port: u16) -> Vec<(String, u64, String)> {
    let (mut ws, code) = common::ws::handshake(port, "/", "127.0.0.1", None);
    assert_eq!(code, 101);
    common::ws::send_text(&mut ws, r#"{"op": "subscribe", "topic": "/zones"}"#).expect("subscribe");
    let message = common::ws::next_json(&mut ws).expect("the latched zones");
    message["msg"]["markers"]
        .as_array()
        .expect("markers")
        .iter()
        .filter(|m| m["action"] == 0)
        .map(|m| {
            let text = |k: &str| m[k].as_str().unwrap_or_default().to_owned();
            (
                text("ns"),
                m["id"].as_u64().unwrap_or(u64::MAX),
                text("text"),
            )
        })
        .collect()
}

#[test]
fn set_shape_adds_a_wall_that_refuses_a_task_and_a_move_through_it_the_file_keeps_it_and_websocket_clients_see_it()
 {
    let master = Master::start();
    let dir = common::tempdir("ros1-zones");
    let plant = chassisd::sim::plant::PlantConfig::builtin().expect("plant");
    let zones = common::zones::yard(&plant, &dir);
    let port = common::mqtt::free_port();
    let bind = format!("127.0.0.1:{port}");
    let broker = common::mqtt::Mosquitto::start();
    let feedback = broker.subscribe(&["feedback"]);
    let mut p = sim_with(
        &master,
        &[
            "--zones",
            zones.to_str().expect("UTF-8 path"),
            "--websocket",
            &bind,
            "--mqtt",
            &broker.address(),
        ],
    );
    p.wait_log(Duration::from_secs(40), "GNSS gate open");
    let call = |request: &[&str]| {
        let mut args = vec!["rosservice", "call"];
        args.extend_from_slice(request);
        ros(&master, &args, Duration::from_secs(10))
    };
    // An edit's answer (`success: True` or `False`) and its code on the status topic.
    let edit = |service: &str, request: &str, answer: &str, code: &str| {
        let out = call(&[service, request]);
        assert!(text(&out).contains(answer), "{}", text(&out));
        echo_until(
            &master,
            "/androidmsg_virtualmapstatus",
            Duration::from_secs(10),
            |o| o.contains(code),
        );
    };
    // A wall across the way 2 m ahead: made (62), written to the zones file.
    edit(
        "/set_shape",
        "{type: 'lines', points: [{x: 2, y: -2, z: 0}, {x: 2, y: 2, z: 0}], radius: 0, closed: false}",
        "success: True",
        "data: 62",
    );
    p.wait_log(Duration::from_secs(5), "zones written");
    let written = std::fs::read_to_string(&zones).expect("zones file");
    assert!(written.contains("virtual wall"), "{written}");
    // The id it took is the next after the yard's four.
    let set = chassisd::zones::ZoneSet::from_geojson(&written).expect("the file reads back");
    assert_eq!(set.zones().len(), 5);
    let wall = set
        .zones()
        .iter()
        .find(|z| z.name == "virtual wall")
        .expect("the wall");
    assert_eq!(wall.id, 5);
    // A WebSocket client sees it on /zones, as a wall with its id and name.
    let drawn = zone_markers(port);
    assert!(
        drawn.contains(&("wall".to_owned(), 5, "virtual wall".to_owned())),
        "{drawn:?}"
    );

    // A task through it, started over MQTT (rtk dialect), is refused naming it: a path
    // from 0.5 m to 2.8 m east (short of the pond), saved first.
    let frame = chassisd::geodesy::Enu::new(plant.datum());
    let points: Vec<serde_json::Value> = (5..=28)
        .map(|i| {
            let x = f64::from(i) * 0.1;
            let g = frame.to_geodetic(&nalgebra::Vector3::new(x, 0.0, 0.0));
            serde_json::json!({"longitude": g.lon_deg, "latitude": g.lat_deg, "angle": 0,
                               "x": x, "y": 0, "yaw": 0})
        })
        .collect();
    let save = serde_json::json!({"cmd_type": "trajectory_control", "cmd": "save_trajectory",
                                  "data": {"name": "across", "data": points}});
    let ask = |payload: &str| {
        feedback.clear();
        broker.publish("mqtt_control", payload);
        let (_, body) = feedback
            .next(Duration::from_secs(10))
            .unwrap_or_else(|| panic!("no answer to {payload}"));
        serde_json::from_str::<serde_json::Value>(&body).expect("JSON")
    };
    assert_eq!(ask(&save.to_string())["cmd"], "save_trajectory_success");
    let start =
        r#"{"cmd_type":"task_control","cmd":"start_task","name":"across","id":0,"speed":0.3}"#;
    let refused = ask(start);
    assert_eq!(refused["cmd"], "start_task_failse", "{refused}");
    assert!(
        refused["message"]
            .as_str()
            .unwrap_or_default()
            .contains("wall zone \"virtual wall\""),
        "{refused}"
    );

    // A move through it is refused, naming it.
    let refused = call(&["/set_navi_cmd", "{cmd: '1', distance: 300}"]);
    assert!(!refused.status.success());
    assert!(
        text(&refused).contains("wall zone \"virtual wall\""),
        "{}",
        text(&refused)
    );
    // A region that is not closed is refused (63), and changes nothing.
    edit(
        "/set_region",
        "{type: 'lines', points: [{x: 8, y: 3, z: 0}, {x: 9, y: 3, z: 0}, {x: 9, y: 4, z: 0}], closed: false}",
        "success: False",
        "data: 63",
    );
    // Removed by its id: the way is clear again, and the file no longer holds it.
    let removed = call(&["/set_shape", "{shapeId: 5}"]);
    assert!(
        text(&removed).contains("success: True"),
        "{}",
        text(&removed)
    );
    let started = ask(start);
    assert_eq!(started["cmd"], "start_task_success", "{started}");
    assert_eq!(
        ask(r#"{"cmd_type":"task_control","cmd":"cancel_task"}"#)["cmd"],
        "cancel_task_success"
    );
    let moved = call(&["/set_navi_cmd", "{cmd: '1', distance: 50}"]);
    assert!(moved.status.success(), "{}", text(&moved));
    let drawn = zone_markers(port);
    assert!(drawn.iter().all(|(_, id, _)| *id != 5), "{drawn:?}");
    assert_eq!(drawn.len(), 4, "{drawn:?}");
    let (_, log) = interrupt(p);
    let written = std::fs::read_to_string(&zones).expect("zones file");
    assert!(
        !written.contains("virtual wall"),
        "{written}\n{}",
        log.join("\n")
    );
    assert!(written.contains("pond"), "{written}");
}

#[test]
fn set_navi_cmd_drives_50_cm_and_reports_its_start_and_end() {
    let master = Master::start();
    let recording = common::tempdir("ros1-move").join("rec");
    let p = sim_with(
        &master,
        &["--record", recording.to_str().expect("UTF-8 path")],
    );
    echo_until(
        &master,
        "/androidmsg_locationstatus",
        Duration::from_secs(20),
        |o| o.contains("data: 10"),
    );
    // The navigation codes, as a client listening all along sees them.
    let mut listener = Command::new("rostopic")
        .args(["echo", "/androidmsg_navigationstatus"])
        .env("ROS_MASTER_URI", master.uri())
        .env("ROS_HOME", common::tempdir("ros-home"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("rostopic runs");
    let codes: Receiver<String> = lines_of(listener.stdout.take().expect("piped"));
    std::thread::sleep(Duration::from_secs(2));

    let call = ros(
        &master,
        &[
            "rosservice",
            "call",
            "/set_navi_cmd",
            "{cmd: '1', distance: 50}",
        ],
        Duration::from_secs(10),
    );
    assert!(call.status.success(), "{}", text(&call));
    let mut seen = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(15);
    while !seen.iter().any(|l: &String| l == "data: 2") {
        let left = deadline
            .checked_duration_since(Instant::now())
            .unwrap_or_else(|| panic!("no success on the navigation topic: {seen:?}"));
        if let Ok(line) = codes.recv_timeout(left) {
            seen.push(line);
        }
    }
    let started = seen.iter().position(|l| l == "data: 1");
    let ended = seen.iter().position(|l| l == "data: 2");
    assert!(started < ended && started.is_some(), "{seen:?}");

    let refused = ros(
        &master,
        &[
            "rosservice",
            "call",
            "/set_navi_cmd",
            "{cmd: '9', distance: 50}",
        ],
        Duration::from_secs(10),
    );
    assert!(!refused.status.success());
    assert!(text(&refused).contains("cmd must be"), "{}", text(&refused));
    let _ = listener.kill();
    let _ = listener.wait();

    // The simulator's truth, in the closing line: the move against the target of
    // `bench control` (5 mm + 0.5 % of the distance), less the random wheel slip that no
    // odometry sees, as that bench scores it.
    let (live, log) = interrupt(p);
    let (x, y) = common::truth_end(&log);
    let slip = common::unseen_slip(&log);
    let moved = x.hypot(y);
    assert!(
        (moved - slip - 0.5).abs() <= 0.005 + 0.005 * 0.5,
        "drove {moved} m for 50 cm ({slip} m of it unseen slip), ending at ({x}, {y})"
    );

    // The node's requests are in the recording, which replays to the live output, move and
    // refusal included, without ROS.
    let requests = std::fs::read_to_string(recording.join("ros1.log")).expect("ros1.log");
    assert_eq!(requests.matches("set_navi_cmd").count(), 2, "{requests}");
    let replayed = common::replay(&recording);
    let replayed: Vec<&str> = std::str::from_utf8(&replayed.stdout)
        .expect("UTF-8")
        .lines()
        .collect();
    assert_eq!(replayed.len(), live.len());
    assert!(replayed == live, "the replay differs from the live output");
}

#[test]
fn cmd_vel_drives_through_the_watchdog_and_navi_stop_ends_a_move() {
    let master = Master::start();
    let mut p = sim(&master);
    let publishing = ros(
        &master,
        &[
            "rostopic",
            "pub",
            "-r",
            "10",
            "/cmd_vel",
            "geometry_msgs/Twist",
            "{linear: {x: 0.4}, angular: {z: 0.0}}",
        ],
        Duration::from_secs(4),
    );
    // rostopic pub ends on SIGINT with a non-zero status; what it did is in the log.
    drop(publishing);
    let lines: Vec<String> = p.drain_out().to_vec();
    let fastest = lines.iter().map(|l| vx(l)).fold(0.0, f64::max);
    assert!(fastest > 0.3, "never drove: fastest {fastest} m/s");
    // The command watchdog (0.5 s) and the deceleration bring it to rest by itself.
    p.wait_out(Duration::from_secs(3), "the vehicle at rest", |l| {
        vx(l).abs() < 0.01
    });

    // A long move, ended by /navi_stop 5: the navigation topic says "stopped" (7).
    let call = ros(
        &master,
        &[
            "rosservice",
            "call",
            "/set_navi_cmd",
            "{cmd: '1', distance: 500}",
        ],
        Duration::from_secs(10),
    );
    assert!(call.status.success(), "{}", text(&call));
    std::thread::sleep(Duration::from_secs(1));
    let stop = ros(
        &master,
        &[
            "rostopic",
            "pub",
            "-1",
            "/navi_stop",
            "std_msgs/Int16",
            "data: 5",
        ],
        Duration::from_secs(10),
    );
    assert!(stop.status.success(), "{}", text(&stop));
    p.wait_log(Duration::from_secs(5), "cancelled: stop requested");
    echo_until(
        &master,
        "/androidmsg_navigationstatus",
        Duration::from_secs(5),
        |o| o.contains("data: 7"),
    );
    p.wait_out(Duration::from_secs(3), "the vehicle at rest", |l| {
        vx(l).abs() < 0.01
    });
}

#[test]
fn a_master_restart_and_a_node_restart_are_both_survived() {
    // chassisd first: it keeps trying until the master comes.
    let port = common::mqtt::free_port();
    let mut p = Proc::start(&[
        "sim",
        "--no-mqtt",
        "--ros-master",
        &format!("http://127.0.0.1:{port}"),
    ]);
    p.wait_log(Duration::from_secs(10), "ROS master unreachable; retrying");
    let master = Master::start_on(port);
    p.wait_log(Duration::from_secs(20), "ROS1 node registered");
    assert!(
        !p.log.iter().any(|l| l.contains("poses dropped")),
        "the feed piled up while the master was away"
    );
    let port = master.kill();
    p.wait_log(Duration::from_secs(10), "ROS master unreachable");
    let master = Master::start_on(port);
    p.wait_log(Duration::from_secs(20), "registering again");
    p.wait_log(Duration::from_secs(20), "ROS1 node registered");
    let hz = text(&ros(
        &master,
        &["rostopic", "hz", "-w", "200", "/raw_odom"],
        Duration::from_secs(5),
    ));
    assert!(average_rate(&hz) > 90.0, "{hz}");
    let moved = ros(
        &master,
        &[
            "rosservice",
            "call",
            "/set_navi_cmd",
            "{cmd: '3', distance: 90}",
        ],
        Duration::from_secs(10),
    );
    assert!(moved.status.success(), "{}", text(&moved));
    p.wait_log(Duration::from_secs(10), "succeeded");

    // chassisd itself restarts: the new node takes the name, and clients find it.
    drop(p);
    let _p = sim(&master);
    echo_until(&master, "/raw_odom", Duration::from_secs(10), |o| {
        o.contains("frame_id: \"odom\"")
    });
    let info = text(&ros(
        &master,
        &["rosservice", "call", "/navi_info"],
        Duration::from_secs(10),
    ));
    assert!(info.contains("status: 0"), "{info}");
}

#[test]
fn run_joins_the_graph_from_its_configuration() {
    let master = Master::start();
    let dir = common::tempdir("ros1-run");
    let config = dir.join("vehicle.toml");
    // A receiver that is not plugged in (retried, not fatal), and the node.
    std::fs::write(
        &config,
        format!(
            "[vehicle]\nname = \"yard-7\"\n\n[gnss]\nport = \"{}\"\n\n[ros1]\nmaster_uri = \"{}\"\nnode_name = \"/yard7/chassisd\"\n",
            dir.join("absent-tty").display(),
            master.uri()
        ),
    )
    .expect("config");
    let mut p = Proc::start(&["run", "--config", config.to_str().expect("UTF-8")]);
    p.wait_log(Duration::from_secs(30), "ROS1 node registered");
    let nodes = text(&ros(&master, &["rosnode", "list"], Duration::from_secs(10)));
    assert!(nodes.contains("/yard7/chassisd"), "{nodes}");
    let info = text(&ros(
        &master,
        &["rosservice", "call", "/navi_info"],
        Duration::from_secs(10),
    ));
    assert!(info.contains("yard-7"), "{info}");
    let position = ros(
        &master,
        &["rosservice", "call", "/get_position"],
        Duration::from_secs(10),
    );
    assert!(!position.status.success());
    assert!(
        text(&position).contains("not located"),
        "{}",
        text(&position)
    );
    // SIGTERM still ends it cleanly.
    p.stop();
}

#[test]
fn the_md5sums_are_what_ros_clients_compute_from_the_same_files() {
    use chassisd::runtime::links::ros1::messages::{
        geometry_msgs, map_msgs, nav_msgs, sensor_msgs, std_msgs, tf2_msgs,
    };
    use roslibrust::{RosMessageType, RosServiceType};
    fn message<T: RosMessageType>() -> (String, &'static str) {
        let name = T::DESCRIPTION.ros_type_name.replacen('/', ".msg.", 1);
        (name, T::DESCRIPTION.md5sum)
    }
    fn service<T: RosServiceType>() -> (String, &'static str) {
        (T::ROS_SERVICE_NAME.replacen('/', ".srv.", 1), T::MD5SUM)
    }
    let ours = [
        message::<std_msgs::Header>(),
        message::<std_msgs::Int16>(),
        message::<std_msgs::Float64MultiArray>(),
        message::<std_msgs::String>(),
        message::<geometry_msgs::Twist>(),
        message::<geometry_msgs::PoseStamped>(),
        message::<geometry_msgs::Transform>(),
        message::<geometry_msgs::TransformStamped>(),
        message::<tf2_msgs::TFMessage>(),
        message::<nav_msgs::Odometry>(),
        message::<sensor_msgs::Imu>(),
        message::<map_msgs::TargetGoal>(),
        service::<map_msgs::SetNaviCmd>(),
        service::<map_msgs::GetPosition>(),
        service::<map_msgs::AboutRobot>(),
        service::<map_msgs::RobotSsh>(),
        service::<map_msgs::SetWifi>(),
        service::<map_msgs::SetShape>(),
        service::<map_msgs::SetRegion>(),
    ];
    // Debian's classes for the standard types; genpy's from the repository's map_msgs.
    let script = "import importlib, sys\n\
        for name in sys.argv[1:]:\n\
        \x20   module, kind = name.rsplit('.', 1)\n\
        \x20   print(name, getattr(importlib.import_module(module), kind)._md5sum)\n";
    let out = Command::new("/usr/bin/python3")
        .args(["-c", script])
        .args(ours.iter().map(|(name, _)| name.as_str()))
        .env("PYTHONPATH", python_classes())
        .output()
        .expect("python3 runs");
    let printed = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for (name, md5) in ours {
        assert!(
            printed.lines().any(|l| l == format!("{name} {md5}")),
            "{name}: ours {md5}, ROS's:\n{printed}"
        );
    }
}

/// The port of a `scheme://host:port[/]` address.
fn port_of(address: &str) -> u16 {
    address
        .trim()
        .trim_end_matches('/')
        .rsplit(':')
        .next()
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("no port in {address:?}"))
}

#[test]
fn with_ros_ip_the_nodes_ports_answer_on_that_address_only() {
    use std::net::SocketAddr;
    let master = Master::start();
    let uri = master.uri();
    let mut p = Proc::start_with_env(
        &["sim", "--no-mqtt", "--ros-master", &uri],
        &[("ROS_IP", "127.0.0.1")],
    );
    p.wait_log(Duration::from_secs(30), "ROS1 node registered");
    p.wait_log_seen(
        Duration::from_secs(5),
        "its ports take connections to these addresses only",
    );
    let registered = p
        .log
        .iter()
        .find(|l| l.contains("ROS1 node registered"))
        .expect("the line");
    let xmlrpc = port_of(
        registered
            .split_whitespace()
            .find_map(|w| w.strip_prefix("uri="))
            .expect("the node's URI"),
    );
    // A service's TCPROS port, as the master gives it to clients.
    let service = text(&ros(
        &master,
        &["rosservice", "uri", "/navi_info"],
        Duration::from_secs(10),
    ));
    let tcpros = port_of(service.lines().next().unwrap_or_default());
    // roslibrust listens on 0.0.0.0: the ports answer on ROS_IP, and on nothing else.
    for port in [xmlrpc, tcpros] {
        let to = |ip: [u8; 4]| {
            TcpStream::connect_timeout(&SocketAddr::from((ip, port)), Duration::from_secs(1))
        };
        assert!(to([127, 0, 0, 1]).is_ok(), "{port} on ROS_IP");
        assert!(to([127, 0, 0, 2]).is_err(), "{port} elsewhere");
    }
    // The graph works as before.
    let info = text(&ros(
        &master,
        &["rosservice", "call", "/navi_info"],
        Duration::from_secs(10),
    ));
    assert!(info.contains("name"), "{info}");
    interrupt(p);
}

/// Waits until `/navi_info` answers (the node registered and serving).
fn serves(master: &Master, wait: Duration) {
    let deadline = Instant::now() + wait;
    loop {
        let info = text(&ros(
            master,
            &["rosservice", "call", "/navi_info"],
            Duration::from_secs(10),
        ));
        if info.contains("status: 0") {
            return;
        }
        assert!(Instant::now() < deadline, "the node does not serve: {info}");
        std::thread::sleep(Duration::from_millis(300));
    }
}

/// The TCPROS port of `/navi_info`'s server, as the master gives it now.
fn service_port(master: &Master) -> u16 {
    let uri = text(&ros(
        master,
        &["rosservice", "uri", "/navi_info"],
        Duration::from_secs(10),
    ));
    port_of(uri.lines().next().unwrap_or_default())
}

/// Sends a TCPROS connection header that announces `told` bytes, then up to `sent` bytes of
/// it, while chassisd's own memory is watched; the most chassisd held, MB.
fn lie_about_a_length(port: u16, told: u32, sent: usize, chassisd: u32) -> f64 {
    use std::io::Write;
    let mut most = rss_mb(chassisd);
    let Ok(mut peer) = TcpStream::connect(("127.0.0.1", port)) else {
        return most;
    };
    let _ = peer.set_write_timeout(Some(Duration::from_secs(5)));
    let chunk = vec![b'x'; 1 << 20];
    let mut written = peer.write_all(&told.to_le_bytes()).map(|()| 0).ok();
    while let Some(n) = written.filter(|&n| n < sent) {
        written = peer.write_all(&chunk).ok().map(|()| n + chunk.len());
        if n % (16 << 20) == 0 {
            most = most.max(rss_mb(chassisd));
        }
    }
    most.max(rss_mb(chassisd))
}

/// Item 8 of issue 48: a raw TCPROS peer that announces a gigabyte, one that sends 200 MB,
/// and one that opens connections without end. Each costs the node's own process at most
/// its limits (ended and started again past them); chassisd's memory and descriptors stay
/// where they were, its status keeps its rate, and the node serves again afterwards.
#[test]
fn hostile_tcpros_peers_cost_the_nodes_process_never_chassisd() {
    let master = Master::start();
    // Backtraces asked for, as a developer's shell often does: the node's ends must still
    // cost one line each, not a backtrace read from the program's debug information.
    let uri = master.uri();
    let mut p = Proc::start_with_env(
        &["sim", "--ros-master", uri.as_str(), "--no-mqtt"],
        &[("RUST_BACKTRACE", "full")],
    );
    p.wait_log(Duration::from_secs(30), "ROS1 node registered");
    let pid = p.child.id();
    p.wait_out(Duration::from_secs(10), "a status", |_| true);
    let (rss_before, fds_before) = (rss_mb(pid), descriptors(pid));
    let attack_start = Instant::now();
    p.drain_out();

    // A header of 1 GiB: the allocation fails in the node's process, which ends.
    let most = lie_about_a_length(service_port(&master), 1 << 30, 64 << 20, pid);
    eprintln!("1 GiB told: {:?}", attack_start.elapsed());
    p.wait_log(Duration::from_secs(10), "ROS1 node's process ended");
    serves(&master, Duration::from_secs(30));
    // 200 MB announced and sent: the node's process holds it, within its limit.
    let most = most.max(lie_about_a_length(
        service_port(&master),
        200 << 20,
        200 << 20,
        pid,
    ));
    eprintln!("200 MB sent: {:?}", attack_start.elapsed());
    // roslibrust then reads the bytes sent as the header's first field length (2 GB): the
    // node's process ends again, maybe after answering a call or two.
    p.wait_log(Duration::from_secs(10), "ROS1 node's process ended");
    serves(&master, Duration::from_secs(30));
    eprintln!("serving: {:?}", attack_start.elapsed());
    // Connections without end: the node's process runs out of descriptors, chassisd not;
    // held, they make the node's process end (roslibrust would retry its accept without end).
    let port = service_port(&master);
    let mut held = Vec::new();
    let mut node_fds = Vec::new();
    let mut fds_during = 0;
    let flood_until = Instant::now() + Duration::from_secs(15);
    while p.log_count("held all its descriptors") == 0 {
        assert!(
            Instant::now() < flood_until,
            "{} connections held, the node's process holds {node_fds:?} descriptors, and it did not end",
            held.len()
        );
        for _ in 0..50 {
            if let Ok(s) = TcpStream::connect_timeout(
                &std::net::SocketAddr::from(([127, 0, 0, 1], port)),
                Duration::from_millis(200),
            ) {
                held.push(s);
            }
        }
        fds_during = fds_during.max(descriptors(pid));
        node_fds = children_of(pid).into_iter().map(descriptors).collect();
    }
    let connected = held.len();
    drop(held);
    let most = most.max(rss_mb(pid));
    let attacked = attack_start.elapsed().as_secs_f64();
    let statuses = p.drain_out().len() as f64;
    eprintln!(
        "chassisd: {rss_before:.1} MB before, {most:.1} MB at most; descriptors {fds_before} before, {fds_during} with {connected} peers connected (the node's process: {node_fds:?}); {statuses} statuses in {attacked:.1} s"
    );
    assert!(connected >= 200, "{connected} connections made");
    assert!(
        most < rss_before + 30.0,
        "chassisd grew from {rss_before:.1} to {most:.1} MB"
    );
    assert!(
        fds_during < fds_before + 16,
        "chassisd's descriptors {fds_before} → {fds_during}"
    );
    assert!(
        statuses >= 0.9 * 10.0 * (attacked - 0.5),
        "{statuses} statuses in {attacked:.1} s"
    );
    // The node serves again.
    serves(&master, Duration::from_secs(30));
    let log = interrupt(p).1;
    for line in log
        .iter()
        .filter(|l| l.contains("ROS1 node's process") || l.contains("left out"))
    {
        eprintln!("{line}");
    }
    assert!(
        log.iter().filter(|l| l.contains("roslibrust")).count() <= 40,
        "roslibrust's lines were not held to their budget"
    );
    assert!(
        !log.iter().any(|l| l.contains("stack backtrace")),
        "the node's process printed a backtrace as it ended"
    );
}

/// Service calls have a rate per service, as topics' messages do: a client polling
/// `/get_position` as fast as rospy can is refused beyond `ros1.command_rate_hz` (with a reason
/// that says so, and one log line), and another service still answers.
#[test]
fn a_service_polled_beyond_its_rate_is_refused_and_the_others_still_answer() {
    let master = Master::start();
    let dir = common::tempdir("ros1-service-rate");
    let config = dir.join("vehicle.toml");
    std::fs::write(
        &config,
        format!(
            "[vehicle]\nname = \"poll-1\"\n\n[gnss]\nport = \"{}\"\n\n[ros1]\nmaster_uri = \"{}\"\ncommand_rate_hz = 5.0\ncommand_burst = 5\n",
            dir.join("absent-tty").display(),
            master.uri()
        ),
    )
    .expect("config");
    let mut p = Proc::start(&["run", "--config", config.to_str().expect("UTF-8")]);
    p.wait_log(Duration::from_secs(30), "ROS1 node registered");
    let poll = r#"
import time, rospy
from map_msgs.srv import GetPosition, AboutRobot
rospy.wait_for_service('/get_position', 10)
position = rospy.ServiceProxy('/get_position', GetPosition)
answered = over_rate = 0
start = time.monotonic()
for _ in range(100):
    try:
        position()
        answered += 1
    except rospy.ServiceException as e:
        if 'command_rate_hz' in str(e):
            over_rate += 1
        else:
            answered += 1
print('answered', answered, 'over_rate', over_rate, 'seconds', time.monotonic() - start)
print('navi_info status', rospy.ServiceProxy('/navi_info', AboutRobot)().status)
"#;
    let out = text(&ros(
        &master,
        &["/usr/bin/python3", "-c", poll],
        Duration::from_secs(60),
    ));
    let figure = |key: &str| -> f64 {
        let words: Vec<&str> = out.split_whitespace().collect();
        words
            .iter()
            .position(|w| *w == key)
            .and_then(|i| words.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no {key} in:\n{out}"))
    };
    let (answered, over_rate, seconds) =
        (figure("answered"), figure("over_rate"), figure("seconds"));
    assert_eq!(answered + over_rate, 100.0, "{out}");
    // The burst, then 5 a second (one more for a token refilled while the loop began).
    assert!(
        answered <= 5.0 + 5.0 * seconds + 1.0,
        "{answered} answered in {seconds} s: {out}"
    );
    assert!(over_rate > 0.0, "{out}");
    assert!(out.contains("navi_info status 0"), "{out}");
    p.wait_log(
        Duration::from_secs(10),
        "ROS1 service calls over the rate limit are refused",
    );
    p.stop();
}
