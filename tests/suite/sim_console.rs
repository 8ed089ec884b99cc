//! `chassisd sim` speaks to a person (issue 11, item 11): one line at start saying what runs,
//! where to watch and how to stop; the scenario's own commands kept out of the info log; a
//! summary at the end of a run or on Ctrl-C; `sim --help` lists the scenarios.

use crate::common;

use std::process::Command;
use std::time::{Duration, Instant};

use chassisd::sim::scenario::Scenario;
use common::process::Proc;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

#[test]
fn sim_help_lists_every_scenario_with_what_it_drives() {
    let out = Command::new(common::chassisd())
        .args(["sim", "--help"])
        .output()
        .expect("runs");
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    for s in Scenario::all() {
        assert!(
            help.lines()
                .any(|l| l.contains(&format!("{}:", s.name)) && l.contains(s.about)),
            "{} missing from:\n{help}",
            s.name
        );
    }
}

#[test]
fn a_scenario_run_says_what_runs_keeps_its_own_commands_quiet_and_sums_up() {
    let out = Command::new(common::chassisd())
        .args([
            "sim",
            "--no-mqtt",
            "--scenario",
            "straight",
            "--duration",
            "4",
        ])
        .env("RUST_LOG", "info")
        .output()
        .expect("runs");
    assert!(out.status.success());
    let log = String::from_utf8_lossy(&out.stderr);
    let first = log
        .lines()
        .find(|l| l.starts_with("chassisd sim:"))
        .expect("a start line");
    for part in [
        "scenario straight",
        "base_status JSON lines on stdout",
        "Ctrl-C stops",
    ] {
        assert!(first.contains(part), "{first}");
    }
    // The scenario commands from 1 s on, ten a second: none in the info log.
    assert!(!log.contains("command accepted"), "{log}");
    let last = log.lines().last().expect("a summary");
    assert!(
        last.starts_with("chassisd sim: duration reached after 4.0 s simulated"),
        "{last}"
    );
    assert!(last.contains("commands (0 refused)"), "{last}");
    assert!(last.contains("40 status lines"), "{last}");
}

#[test]
fn ctrl_c_ends_with_a_summary_too() {
    let mut sim = Proc::start(&["sim", "--no-mqtt", "--scenario", "turns"]);
    sim.wait_log(Duration::from_secs(10), "Ctrl-C stops");
    std::thread::sleep(Duration::from_millis(1500));
    kill(Pid::from_raw(sim.child.id() as i32), Signal::SIGINT).expect("signal");
    let deadline = Instant::now() + Duration::from_secs(10);
    while sim.child.try_wait().expect("status").is_none() {
        assert!(Instant::now() < deadline, "still running after Ctrl-C");
        std::thread::sleep(Duration::from_millis(20));
    }
    sim.wait_log(Duration::from_secs(5), "chassisd sim: stopped after");
}

/// The start line's `mosquitto_sub` and `mosquitto_pub` lines work when pasted into a shell:
/// base_status arrives at 10 Hz, and the goal drives the vehicle there. The simulator runs
/// as the README's first command starts it (on a free broker port), scenario and all: the
/// scenario yields to the goal.
#[test]
fn the_printed_mosquitto_lines_watch_and_drive_the_vehicle() {
    let port = common::mqtt::free_port().to_string();
    let mut args = readme_main_command();
    args.extend(["--broker-port".to_owned(), port]);
    let mut sim = Proc::start(&args);
    sim.wait_log(Duration::from_secs(10), "Ctrl-C stops");
    let start = sim
        .log
        .iter()
        .find(|l| l.contains("Ctrl-C stops"))
        .expect("the start line")
        .clone();
    let pasted = |tool: &str| -> String {
        let from = start
            .find(tool)
            .unwrap_or_else(|| panic!("{tool} in {start}"));
        start[from..]
            .split(';')
            .next()
            .expect("up to the next clause")
            .trim_end_matches(')')
            .to_owned()
    };
    let watch = pasted("mosquitto_sub");
    let drive = pasted("mosquitto_pub");
    // 30 messages: three seconds at 10 Hz, well within the wait.
    let began = Instant::now();
    let seen = Command::new("sh")
        .arg("-c")
        .arg(format!("{watch} -C 30 -W 10"))
        .output()
        .expect("sh runs");
    let took = began.elapsed().as_secs_f64();
    let lines = String::from_utf8_lossy(&seen.stdout);
    assert_eq!(lines.lines().count(), 30, "{watch}: {lines}");
    assert!((2.5..=4.5).contains(&took), "30 lines took {took:.2} s");
    assert!(lines.lines().all(|l| l.contains("\"pose\"")));
    sim.wait_out(Duration::from_secs(30), "located", |l| {
        l.contains("LOCATE_TRUE")
    });
    let sent = Command::new("sh")
        .arg("-c")
        .arg(&drive)
        .status()
        .expect("sh runs");
    assert!(sent.success(), "{drive}");
    sim.wait_log(Duration::from_secs(10), "scripted driving stops");
    sim.wait_out(Duration::from_secs(60), "the pose at the goal", |l| {
        serde_json::from_str::<serde_json::Value>(l).is_ok_and(|s| {
            let (x, y) = (s["pose"]["x"].as_f64(), s["pose"]["y"].as_f64());
            matches!((x, y), (Some(x), Some(y)) if (x - 2.0).hypot(y - 1.0) < 0.05)
        })
    });
    sim.stop();
}

/// The README's first command is `cargo run`: the package builds two binaries (the daemon,
/// and chassisd-bench beside it), so its manifest must say which one `cargo run` runs.
#[test]
fn cargo_run_runs_the_daemon() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml"))
        .expect("Cargo.toml");
    let manifest: toml::Table = toml::from_str(&text).expect("a TOML manifest");
    assert_eq!(
        manifest["package"]
            .get("default-run")
            .and_then(|v| v.as_str()),
        Some("chassisd"),
        "Cargo.toml's [package] needs default-run = \"chassisd\""
    );
}

/// The arguments of the README's first command, `cargo run --release -- ARGS`.
fn readme_main_command() -> Vec<String> {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md"))
        .expect("README.md");
    let line = readme
        .lines()
        .find(|l| l.starts_with("cargo run --release -- "))
        .expect("a `cargo run --release -- ...` line in the README");
    let args: Vec<String> = line
        .trim_start_matches("cargo run --release -- ")
        .split_whitespace()
        .map(str::to_owned)
        .collect();
    assert_eq!(args.first().map(String::as_str), Some("sim"), "{line}");
    args
}
