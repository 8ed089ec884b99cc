//! The native ROS 2 node against a DDS implementation that is not ours: the Eclipse Cyclone
//! DDS Python binding (PyPI, pinned) as `tests/ros2/peer.py`, which builds its message
//! classes from PyPI rosbags' definitions and checks every sample's CDR bytes against
//! rosbags' serialiser. chassisd runs as `chassisd sim --no-mqtt --ros2`, as a newcomer
//! would run it. Everything runs inside a network namespace of its own
//! (`common::netns`): DDS discovery multicasts, and no packet may leave the test.

use std::process::Output;
use std::time::Duration;

use serde_json::Value;

use crate::common::netns::NetNs;
use crate::common::process::Proc;

/// `peer.py ARGS` inside `ns`, on domain `domain`; its output (checked to be a success).
fn peer(ns: &NetNs, domain: u16, args: &[&str]) -> Vec<Value> {
    let out = peer_output(ns, domain, args);
    assert!(
        out.status.success(),
        "peer.py {args:?}: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    events(&out)
}

fn peer_output(ns: &NetNs, domain: u16, args: &[&str]) -> Output {
    ns.command(crate::common::venv_python().to_str().expect("UTF-8 path"))
        .arg(crate::common::repo().join("tests/ros2/peer.py"))
        .args(args)
        .env("ROS_DOMAIN_ID", domain.to_string())
        .output()
        .expect("peer.py runs")
}

/// Each line of `out` as JSON.
fn events(out: &Output) -> Vec<Value> {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

/// The samples among a listener's events, each checked byte for byte against rosbags.
fn samples(events: &[Value]) -> Vec<&Value> {
    let samples: Vec<&Value> = events.iter().filter(|e| e.get("msg").is_some()).collect();
    for s in &samples {
        assert_eq!(
            s["bytes_match_rosbags"], true,
            "{}: CDR differs from rosbags' serialisation: {s}",
            s["topic"]
        );
    }
    samples
}

/// `chassisd sim --no-mqtt --ros2 [MORE]` inside `ns` on `domain`, once its node is on the
/// domain, framing the action's services as rmw_cyclonedds does.
fn sim(ns: &NetNs, domain: u16, more: &[&str]) -> Proc {
    // The peer frames the action's services as rmw_cyclonedds does; chassisd learns that
    // from ROS 2's own variable, as it would on a vehicle.
    sim_on(ns, domain, "rmw_cyclonedds_cpp", more)
}

/// [`sim`] with `RMW_IMPLEMENTATION=rmw`.
fn sim_on(ns: &NetNs, domain: u16, rmw: &str, more: &[&str]) -> Proc {
    let mut args = vec!["sim", "--no-mqtt", "--ros2"];
    args.extend_from_slice(more);
    let wrapper = ns.wrapper();
    let wrapper: Vec<&str> = wrapper.iter().map(String::as_str).collect();
    let domain = format!("ROS_DOMAIN_ID={domain}");
    let rmw = format!("RMW_IMPLEMENTATION={rmw}");
    let env = ["env", domain.as_str(), rmw.as_str()];
    let full: Vec<&str> = wrapper.iter().copied().chain(env).collect();
    let mut p = Proc::start_under(&full, &args);
    p.wait_log(Duration::from_secs(30), "ROS 2 node on its domain");
    p
}

/// The vehicle's forward speed in a base_status line.
fn vx(line: &str) -> f64 {
    let v: Value = serde_json::from_str(line).expect("base_status JSON");
    v["robot"]["vx"].as_f64().expect("robot.vx")
}

/// A listener on `topic` of `msg_type`: at most `count` samples within `seconds`.
fn listen(
    ns: &NetNs,
    domain: u16,
    topic: &str,
    msg_type: &str,
    count: u32,
    more: &[&str],
) -> Vec<Value> {
    let count = count.to_string();
    let mut args = vec![
        "listen",
        "--topic",
        topic,
        "--type",
        msg_type,
        "--seconds",
        "15",
        "--count",
        &count,
    ];
    args.extend_from_slice(more);
    peer(ns, domain, &args)
}

#[test]
fn odometry_frames_the_fix_and_the_latched_topics_arrive_in_ros2s_types() {
    let ns = NetNs::new();
    let _sim = sim(&ns, 11, &[]);
    let odom_events = listen(&ns, 11, "/odom", "nav_msgs/msg/Odometry", 40, &[]);
    let odom = samples(&odom_events);
    assert_eq!(odom.len(), 40, "{odom_events:?}");
    let first = &odom[0]["msg"];
    assert_eq!(first["header"]["frame_id"], "odom");
    assert_eq!(first["child_frame_id"], "base_link");
    // 50 Hz: 39 periods of 20 ms (the receiver's own timing adds a little).
    let span = odom[39]["t_rx"].as_f64().unwrap() - odom[0]["t_rx"].as_f64().unwrap();
    let rate = 39.0 / span;
    assert!((35.0..=65.0).contains(&rate), "/odom at {rate:.1} Hz");

    let tf = listen(&ns, 11, "/tf", "tf2_msgs/msg/TFMessage", 3, &[]);
    let tf = samples(&tf);
    assert_eq!(tf.len(), 3);
    let children: Vec<&str> = tf[2]["msg"]["transforms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["child_frame_id"].as_str().unwrap())
        .collect();
    assert!(children.contains(&"base_link"), "{children:?}");

    // Published once, long before this reader joined: transient local keeps it.
    let fixed = listen(
        &ns,
        11,
        "/tf_static",
        "tf2_msgs/msg/TFMessage",
        1,
        &["--transient-local", "--depth", "1"],
    );
    let fixed = samples(&fixed);
    assert_eq!(fixed.len(), 1, "a late joiner gets /tf_static");
    assert_eq!(
        fixed[0]["msg"]["transforms"][0]["child_frame_id"],
        "gnss_link"
    );

    let fix = listen(&ns, 11, "/fix", "sensor_msgs/msg/NavSatFix", 2, &[]);
    let fix = samples(&fix);
    assert_eq!(fix.len(), 2);
    let f = &fix[1]["msg"];
    assert_eq!(f["header"]["frame_id"], "gnss_link");
    assert!(
        f["latitude"].as_f64().is_some_and(|l| l.abs() <= 90.0),
        "{f}"
    );
    assert!(f["position_covariance_type"].as_u64().unwrap() >= 1, "{f}");

    let zones = listen(
        &ns,
        11,
        "/zones",
        "visualization_msgs/msg/MarkerArray",
        1,
        &["--transient-local", "--depth", "1"],
    );
    assert_eq!(samples(&zones).len(), 1, "a late joiner gets /zones");
    let plan = listen(
        &ns,
        11,
        "/plan",
        "nav_msgs/msg/Path",
        1,
        &["--transient-local", "--depth", "1"],
    );
    assert_eq!(samples(&plan).len(), 1, "a late joiner gets /plan");
    let imu = listen(
        &ns,
        11,
        "/imu/data",
        "sensor_msgs/msg/Imu",
        5,
        &["--best-effort"],
    );
    assert_eq!(samples(&imu).len(), 5);
    let battery = listen(
        &ns,
        11,
        "/battery_state",
        "sensor_msgs/msg/BatteryState",
        1,
        &[],
    );
    assert_eq!(samples(&battery).len(), 1);
    let diagnostics = listen(
        &ns,
        11,
        "/diagnostics",
        "diagnostic_msgs/msg/DiagnosticArray",
        1,
        &[],
    );
    assert_eq!(samples(&diagnostics).len(), 1);
}

#[test]
fn cmd_vel_of_either_type_drives_and_stops_when_publishing_ends() {
    let ns = NetNs::new();
    let dir = crate::common::tempdir("ros2-cmd-vel");
    let record = dir.join("rec");
    let mut p = sim(&ns, 12, &["--record", record.to_str().expect("UTF-8 path")]);
    peer(
        &ns,
        12,
        &[
            "publish",
            "--topic",
            "/cmd_vel",
            "--type",
            "geometry_msgs/msg/Twist",
            "--json",
            r#"{"linear": {"x": 0.4}, "angular": {"z": 0.0}}"#,
            "--rate",
            "10",
            "--seconds",
            "3",
            "--wait-match",
            "10",
            "--best-effort",
        ],
    );
    let lines: Vec<String> = p.drain_out().to_vec();
    let fastest = lines.iter().map(|l| vx(l)).fold(0.0, f64::max);
    assert!(fastest > 0.3, "never drove: fastest {fastest} m/s");
    // The command watchdog (0.5 s) and the deceleration bring it to rest by itself.
    p.wait_out(Duration::from_secs(3), "the vehicle at rest", |l| {
        vx(l).abs() < 0.01
    });

    // Jazzy's diff_drive_controller and nav2 send TwistStamped on the same topic.
    peer(
        &ns,
        12,
        &[
            "publish",
            "--topic",
            "/cmd_vel",
            "--type",
            "geometry_msgs/msg/TwistStamped",
            "--json",
            r#"{"header": {"frame_id": "base_link"}, "twist": {"linear": {"x": -0.3}}}"#,
            "--rate",
            "10",
            "--seconds",
            "3",
            "--wait-match",
            "10",
            "--stamp-now",
        ],
    );
    let lines: Vec<String> = p.drain_out().to_vec();
    let backwards = lines.iter().map(|l| vx(l)).fold(0.0, f64::min);
    assert!(backwards < -0.2, "never reversed: slowest {backwards} m/s");
    p.wait_out(Duration::from_secs(3), "the vehicle at rest", |l| {
        vx(l).abs() < 0.01
    });
    // Every message went through the arbiter, none refused (a TwistStamped is not taken
    // for a Twist, nor the other way round).
    assert_eq!(p.log_count("command refused"), 0, "{:?}", p.log);
    // Recorded as they came: the recording replays to the live output, without DDS.
    let lines = p.stop();
    let live: Vec<u8> = lines
        .iter()
        .flat_map(|l| format!("{l}\n").into_bytes())
        .collect();
    let replay = crate::common::replay(&record);
    assert!(replay.stdout == live, "replay differs from the live output");
    let commands = std::fs::read_to_string(record.join("ros2.log")).expect("ros2.log");
    assert!(commands.lines().count() >= 40, "{commands}");
    // The payloads' hex: the stamped ones' `"twist"`, as they came.
    assert!(commands.contains("22747769737422"), "{commands}");
}

#[test]
fn a_navigate_to_pose_goal_gives_feedback_and_a_result_and_a_cancel_ends_one() {
    let ns = NetNs::new();
    let mut p = sim(&ns, 13, &[]);
    p.wait_log_seen(Duration::from_secs(30), "localisation started");
    let events = peer(
        &ns,
        13,
        &[
            "navigate",
            "--x",
            "1.0",
            "--y",
            "0.0",
            "--seconds",
            "40",
            "--mapping",
            "cyclone",
        ],
    );
    assert!(events.iter().any(|e| e["goal"] == "accepted"), "{events:?}");
    let feedback: Vec<&Value> = events.iter().filter_map(|e| e.get("feedback")).collect();
    assert!(feedback.len() >= 2, "{events:?}");
    let distance = |f: &Value| f["distance_remaining"].as_f64().unwrap();
    assert!(
        distance(feedback[feedback.len() - 1]) < distance(feedback[0]),
        "{feedback:?}"
    );
    let result = events
        .iter()
        .find_map(|e| e.get("result"))
        .expect("a result");
    assert_eq!(result["status"], 4, "succeeded: {result}");
    assert_eq!(result["error_code"], 0);

    let events = peer(
        &ns,
        13,
        &[
            "navigate",
            "--x",
            "8.0",
            "--y",
            "0.0",
            "--cancel-after",
            "1.5",
            "--seconds",
            "30",
            "--mapping",
            "cyclone",
        ],
    );
    assert!(
        events.iter().any(|e| e.get("cancel").is_some()),
        "{events:?}"
    );
    let result = events
        .iter()
        .find_map(|e| e.get("result"))
        .expect("a result");
    assert_eq!(result["status"], 5, "cancelled: {result}");
    p.wait_log_seen(Duration::from_secs(5), "cancelled");

    // A goal the vehicle cannot take is rejected; the reason goes to /rosout and the log.
    let events = peer(
        &ns,
        13,
        &[
            "navigate",
            "--x",
            "1.0",
            "--y",
            "0.0",
            "--frame",
            "odom",
            "--seconds",
            "20",
            "--mapping",
            "cyclone",
        ],
    );
    assert!(events.iter().any(|e| e["goal"] == "rejected"), "{events:?}");
    p.wait_log_seen(Duration::from_secs(5), "goal rejected");
}

/// examples/ros2_navigate (an action client of ours, on ros2-client) inside `ns` on
/// `domain`: its events, and whether it got a result.
fn navigate_ours(ns: &NetNs, domain: u16, mapping: &str, seconds: &str) -> (Vec<Value>, bool) {
    // Beside chassisd: target/release/examples.
    let example = crate::common::chassisd().with_file_name("examples/ros2_navigate");
    assert!(
        example.exists(),
        "{} is missing: `cargo test` builds the examples (or `cargo build --release --examples`)",
        example.display()
    );
    let out = ns
        .command(example.to_str().expect("UTF-8 path"))
        .args([
            "--mapping",
            mapping,
            "--x",
            "1.0",
            "--y",
            "0.0",
            "--seconds",
            seconds,
        ])
        .args(["--domain", &domain.to_string()])
        .output()
        .expect("ros2_navigate runs");
    (events(&out), out.status.success())
}

#[test]
fn fast_ddss_framing_of_the_action_is_served_when_configured() {
    // Fast DDS, ROS 2's default middleware, carries a request's identity in the RTPS message
    // rather than in a header of the request: with RMW_IMPLEMENTATION naming it (or unset),
    // the node frames the action's services so.
    let ns = NetNs::new();
    let mut p = sim_on(&ns, 16, "rmw_fastrtps_cpp", &[]);
    p.wait_log_seen(Duration::from_secs(30), "localisation started");
    let (events, ended) = navigate_ours(&ns, 16, "enhanced", "40");
    assert!(ended, "{events:?}");
    assert!(
        events
            .iter()
            .any(|e| e["event"] == "accepted" && e["accepted"] == true),
        "{events:?}"
    );
    assert!(
        events.iter().any(|e| e["event"] == "feedback"),
        "{events:?}"
    );
    let result = events
        .iter()
        .find(|e| e["event"] == "result")
        .expect("a result");
    assert_eq!(result["status"], "Succeeded", "{result}");
    assert_eq!(result["error_code"], 0, "{result}");
    // The two framings do not mix: a client framing as Cyclone DDS does is not understood.
    let (events, ended) = navigate_ours(&ns, 16, "cyclone", "6");
    assert!(!ended, "a result across framings: {events:?}");
}

#[test]
fn rviz2s_goal_pose_drives_the_vehicle_there() {
    let ns = NetNs::new();
    let mut p = sim(&ns, 14, &[]);
    p.wait_log_seen(Duration::from_secs(30), "localisation started");
    peer(
        &ns,
        14,
        &[
            "publish",
            "--topic",
            "/goal_pose",
            "--type",
            "geometry_msgs/msg/PoseStamped",
            "--json",
            r#"{"header": {"frame_id": "map"}, "pose": {"position": {"x": 1.5, "y": 0.0}, "orientation": {"w": 1.0}}}"#,
            "--count",
            "1",
            "--rate",
            "1",
            "--seconds",
            "5",
            "--wait-match",
            "10",
        ],
    );
    p.wait_log_seen(Duration::from_secs(30), "succeeded");
}

#[test]
fn a_configuration_that_names_a_missing_interface_is_refused_with_the_fix() {
    let dir = crate::common::tempdir("ros2-interface");
    let config = "[vehicle]\nname = \"t\"\n[ros2]\ninterface = \"nosuch0\"\n";
    let file = dir.join("v.toml");
    std::fs::write(&file, config).expect("write");
    let out = std::process::Command::new(crate::common::chassisd())
        .args(["run", "--config"])
        .arg(&file)
        .output()
        .expect("chassisd runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(78), "{err}");
    assert!(
        err.contains("ros2.interface") && err.contains("nosuch0") && err.contains("lo"),
        "{err}"
    );
}

/// `hostile.py ARGS` inside `ns`, on `domain`; its output.
fn hostile(ns: &NetNs, domain: u16, args: &[&str]) -> std::process::Child {
    script_running(ns, domain, "hostile.py", args, std::process::Stdio::piped())
}

/// `tests/ros2/SCRIPT ARGS` inside `ns` on `domain`, started and left running with its
/// standard output to `stdout`.
fn script_running(
    ns: &NetNs,
    domain: u16,
    script: &str,
    args: &[&str],
    stdout: std::process::Stdio,
) -> std::process::Child {
    ns.command(crate::common::venv_python().to_str().expect("UTF-8 path"))
        .arg(crate::common::repo().join("tests/ros2").join(script))
        .args(args)
        .env("ROS_DOMAIN_ID", domain.to_string())
        .stdout(stdout)
        .spawn()
        .unwrap_or_else(|e| panic!("{script} runs: {e}"))
}

#[test]
fn hundreds_of_participants_and_malformed_rtps_cost_the_nodes_process_alone() {
    let ns = NetNs::new();
    let mut p = sim(&ns, 15, &[]);
    let started = std::time::Instant::now();
    let pid = p.child.id();
    let node = || {
        crate::common::process::children_of(pid)
            .into_iter()
            .max_by_key(|&child| crate::common::process::rss_mb(child) as u64)
            .expect("the node's process")
    };
    let (rss_before, fds_before) = (
        crate::common::process::rss_mb(pid),
        crate::common::process::descriptors(pid),
    );
    // 300 participants join the domain, each with a reader and a writer, and stay 8 s.
    let mut crowd = hostile(&ns, 15, &["participants", "300", "--seconds", "8"]);
    std::thread::sleep(Duration::from_secs(7));
    let node_rss = crate::common::process::rss_mb(node());
    assert!(
        node_rss < 200.0,
        "the node's process holds {node_rss:.0} MB"
    );
    assert!(crowd.wait().expect("hostile.py ends").success());
    // 3000 malformed datagrams on every port of the domain (random bytes, random
    // submessages, fragments announcing samples of up to 4 GiB).
    let garbage = hostile(&ns, 15, &["garbage", "3000"])
        .wait_with_output()
        .expect("hostile.py ends");
    assert!(garbage.status.success());
    // The vehicle's process did not notice: its memory and descriptors, and its status
    // lines at 10 Hz throughout.
    let rss_after = crate::common::process::rss_mb(pid);
    assert!(
        rss_after < rss_before + 5.0,
        "{rss_before:.1} -> {rss_after:.1} MB"
    );
    assert_eq!(crate::common::process::descriptors(pid), fds_before);
    // 10 Hz throughout: at least 9 a second of the time since the start, a second spared
    // for the first line.
    let lines = p.drain_out().len();
    let span = started.elapsed().as_secs_f64();
    assert!(
        lines as f64 >= (span - 1.0) * 9.0,
        "{lines} status lines over {span:.1} s"
    );
    // The node publishes still (its process restarted or not).
    let odom = listen(&ns, 15, "/odom", "nav_msgs/msg/Odometry", 5, &[]);
    assert_eq!(samples(&odom).len(), 5);
    // What RustDDS says of it is held to the log's budget, never a line a datagram.
    let warnings = p.log_count("rustdds");
    assert!(warnings < 50, "{warnings} RustDDS lines");
}

/// `peer.py ARGS` inside `ns` on `domain`, started and left running.
fn peer_running(ns: &NetNs, domain: u16, args: &[&str]) -> std::process::Child {
    // Its output unread: nothing to fill a pipe and stop it before the test does.
    script_running(ns, domain, "peer.py", args, std::process::Stdio::null())
}

#[test]
fn stalled_and_vanished_subscribers_delay_nobody_and_oversized_samples_are_dropped() {
    let ns = NetNs::new();
    let mut p = sim(&ns, 17, &[]);
    p.wait_log_seen(Duration::from_secs(30), "localisation started");
    let pid = p.child.id();
    let node = crate::common::process::children_of(pid)[0];
    let odom = [
        "listen",
        "--topic",
        "/odom",
        "--type",
        "nav_msgs/msg/Odometry",
    ];
    // A reliable subscriber that stops (SIGSTOP: no more acknowledgements, its buffers
    // full), and one that vanishes without a goodbye (SIGKILL), once both are matched.
    let mut stalled = peer_running(&ns, 17, &[&odom[..], &["--seconds", "60"]].concat());
    let mut vanished = peer_running(&ns, 17, &[&odom[..], &["--seconds", "60"]].concat());
    std::thread::sleep(Duration::from_secs(3));
    // SAFETY: kill on a child of ours, still running.
    unsafe { libc::kill(stalled.id() as libc::pid_t, libc::SIGSTOP) };
    vanished.kill().expect("SIGKILL");
    let _ = vanished.wait();
    p.drain_out();
    // Another subscriber gets /odom at its rate without a gap, and the vehicle's status
    // lines keep their 10 Hz.
    let heard = listen(&ns, 17, "/odom", "nav_msgs/msg/Odometry", 250, &[]);
    let heard = samples(&heard);
    assert_eq!(heard.len(), 250);
    let t: Vec<f64> = heard.iter().map(|s| s["t_rx"].as_f64().unwrap()).collect();
    let rate = 249.0 / (t[249] - t[0]);
    let gap = t.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    assert!((40.0..=60.0).contains(&rate), "/odom at {rate:.1} Hz");
    assert!(gap < 0.1, "a gap of {gap:.3} s");
    let lines = p.drain_out().len();
    assert!(lines >= 45, "{lines} status lines over some 5 s");
    let _ = stalled.kill();
    let _ = stalled.wait();

    // Goals of 4 MB: dropped by the node's process and counted, never handed over; its
    // memory stays bounded and it is the same process.
    let goal = r#"{"header": {"frame_id": "map"},
                   "pose": {"position": {"x": 2.0}, "orientation": {"w": 1.0}}}"#;
    let publish = [
        "publish",
        "--topic",
        "/goal_pose",
        "--type",
        "geometry_msgs/msg/PoseStamped",
        "--json",
        goal,
        "--rate",
        "4",
    ];
    let big = [&publish[..], &["--pad-frame-id", "4000000", "--count", "4"]].concat();
    peer(&ns, 17, &big);
    p.wait_log(
        Duration::from_secs(10),
        "a sample larger than any request dropped",
    );
    let rss = crate::common::process::rss_mb(node);
    assert!(rss < 200.0, "the node's process holds {rss:.0} MB");
    assert_eq!(crate::common::process::children_of(pid), vec![node]);
    assert_eq!(p.log_count("command accepted"), 0, "{:#?}", p.log);

    // RViz2's "2D Pose Estimate": /initialpose places the vehicle, and /pose shows it there.
    let estimate = r#"{"header": {"frame_id": "map"},
                       "pose": {"pose": {"position": {"x": 10.0, "y": -5.0},
                                         "orientation": {"z": 0.479425538604203,
                                                         "w": 0.8775825618903728}}}}"#;
    peer(
        &ns,
        17,
        &[
            "publish",
            "--topic",
            "/initialpose",
            "--type",
            "geometry_msgs/msg/PoseWithCovarianceStamped",
            "--json",
            estimate,
            "--count",
            "1",
        ],
    );
    p.wait_log(Duration::from_secs(10), "command accepted");
    std::thread::sleep(Duration::from_millis(500));
    let pose = listen(
        &ns,
        17,
        "/pose",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        1,
        &[],
    );
    let at = &samples(&pose)[0]["msg"]["pose"]["pose"]["position"];
    let (x, y) = (at["x"].as_f64().unwrap(), at["y"].as_f64().unwrap());
    assert!(
        (x - 10.0).abs() < 0.2 && (y + 5.0).abs() < 0.2,
        "/pose at ({x}, {y})"
    );
}

#[test]
fn the_configurations_namespace_and_frame_names_are_what_peers_see() {
    // `chassisd run` of a vehicle with a receiver on a pseudo-terminal, its node under
    // /robot_1 with frames of its own, as a fleet's second robot would be set up.
    let ns = NetNs::new();
    let dir = crate::common::tempdir("ros2-namespace");
    let link = dir.join("gnss-port");
    let _receiver = crate::common::pty::Talker::start(crate::common::pty::Port::open_at(&link));
    let config = dir.join("vehicle.toml");
    std::fs::write(
        &config,
        format!(
            "[vehicle]\nname = \"robot-1\"\n\n[gnss]\nport = \"{}\"\n\n\
             [ros2]\ndomain_id = 19\nnamespace = \"/robot_1\"\nnode_name = \"chassis\"\n\n\
             [ros2.frames]\nbase = \"robot_1/base_link\"\ngnss = \"robot_1/gps\"\n",
            link.display()
        ),
    )
    .expect("config");
    let wrapper = ns.wrapper();
    let wrapper: Vec<&str> = wrapper.iter().map(String::as_str).collect();
    let mut p = Proc::start_under(
        &wrapper,
        &["run".as_ref(), "--config".as_ref(), config.as_os_str()],
    );
    p.wait_log(Duration::from_secs(30), "ROS 2 node on its domain");
    let fix = listen(&ns, 19, "/robot_1/fix", "sensor_msgs/msg/NavSatFix", 2, &[]);
    let fix = samples(&fix);
    assert_eq!(fix.len(), 2);
    assert_eq!(fix[1]["msg"]["header"]["frame_id"], "robot_1/gps");
    let mounts = listen(
        &ns,
        19,
        "/robot_1/tf_static",
        "tf2_msgs/msg/TFMessage",
        1,
        &["--transient-local", "--depth", "1"],
    );
    let mounts = samples(&mounts);
    let antenna = &mounts[0]["msg"]["transforms"][0];
    assert_eq!(antenna["header"]["frame_id"], "robot_1/base_link");
    assert_eq!(antenna["child_frame_id"], "robot_1/gps");
    // Nothing under the bare name.
    let bare = peer_output(
        &ns,
        19,
        &[
            "listen",
            "--topic",
            "/fix",
            "--type",
            "sensor_msgs/msg/NavSatFix",
            "--seconds",
            "2",
            "--count",
            "1",
        ],
    );
    assert_eq!(bare.status.code(), Some(3), "{:?}", events(&bare));
}

#[test]
fn the_benchmark_gives_odom_to_every_subscriber_of_both_routes() {
    // A short run: the figures are the benchmark's; here, that every subscriber of both
    // routes gets /odom at the rate asked and each message's latency is measured. The
    // benchmark runs itself in a network namespace of its own.
    let out = std::process::Command::new(crate::common::chassisd())
        .args(["bench", "ros2", "--seconds", "1", "--subscribers", "2"])
        .output()
        .expect("chassisd bench ros2 runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let summary: Value = serde_json::from_str(stdout.lines().last().unwrap_or_default())
        .unwrap_or_else(|e| panic!("{e}: no JSON summary\n{stdout}\n{stderr}"));
    let runs = summary["runs"].as_array().expect("runs");
    let routes: Vec<&str> = runs.iter().filter_map(|r| r["route"].as_str()).collect();
    assert_eq!(routes, ["baseline", "ros2", "rosbridge"], "{summary}");
    assert!(runs[0]["cpu_percent"].as_f64().unwrap() > 0.0, "{summary}");
    for run in &runs[1..] {
        let expected = run["expected"].as_u64().unwrap();
        assert_eq!(expected, 100, "{run}");
        let received: Vec<u64> = run["received"]
            .as_array()
            .expect("received")
            .iter()
            .filter_map(Value::as_u64)
            .collect();
        assert_eq!(received.len(), 2, "{run}");
        assert!(received.iter().all(|n| (90..=102).contains(n)), "{run}");
        assert_eq!(
            run["latency_ms"]["n"].as_u64(),
            Some(received.iter().sum()),
            "{run}"
        );
        let median = run["latency_ms"]["median"].as_f64().unwrap();
        assert!(median > 0.0 && median < 100.0, "{run}");
        assert!(run["added_cpu_percent"].is_f64(), "{run}");
    }
}
