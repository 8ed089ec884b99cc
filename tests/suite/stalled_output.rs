//! A stalled standard output (a pipe nobody reads) must not hold up the control loop or the
//! command watchdog: the simulated vehicle runs with its stdout never read, long enough to
//! fill the pipe many times over, and its recording shows the drive commands kept their
//! rhythm and the watchdog stopped the wheels on time.

use crate::common;

use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The simulator's command timeout (src/sim/lockstep.rs).
const CMD_TIMEOUT_MS: u64 = 500;

/// `(seconds) sim0 201#DATA T` lines of node 1's RPDO: time in µs and data.
fn rpdo1(log: &str) -> Vec<(u64, String)> {
    log.lines()
        .filter(|l| l.ends_with(" T") && l.contains(" 201#"))
        .filter_map(|l| {
            let (stamp, rest) = l.strip_prefix('(')?.split_once(')')?;
            let (s, us) = stamp.split_once('.')?;
            let t = s.parse::<u64>().ok()? * 1_000_000 + us.parse::<u64>().ok()?;
            let data = rest.split('#').nth(1)?.trim_end_matches(" T").to_owned();
            Some((t, data))
        })
        .collect()
}

#[test]
fn a_pipe_nobody_reads_delays_neither_the_control_loop_nor_the_watchdog() {
    let dir = common::tempdir("stalled-output");
    let session = dir.join("session");
    let mut child = Command::new(common::chassisd())
        .args(["sim", "--no-mqtt", "--commands-stdin", "--duration", "16"])
        .arg("--record")
        .arg(&session)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("chassisd sim starts");
    // Never read while it runs: after some 6 s of base_status the pipe is full.
    let mut stdout = child.stdout.take().expect("stdout");
    let stderr = common::process::lines_of(child.stderr.take().expect("stderr"));
    let mut stdin = child.stdin.take().expect("stdin");
    let started = Instant::now();
    while started.elapsed() < Duration::from_secs(12) {
        let _ = writeln!(
            stdin,
            r#"cmd_vel {{"linear":{{"x":0.3}},"angular":{{"z":0}}}}"#
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // Commands stop; the watchdog must stop the wheels while stdout stays stalled.
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        assert!(Instant::now() < deadline, "sim did not end");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(status.success(), "{status:?}");
    drop(stderr);
    // The pipe (64 KiB) held only part of the 160 lines of the run: the writer really was
    // stalled.
    let mut held = String::new();
    std::io::Read::read_to_string(&mut stdout, &mut held).expect("pipe");
    let lines = held.lines().count();
    assert!(
        lines <= 140,
        "{lines} of 160 status lines got through: the output never stalled"
    );

    let frames = rpdo1(&std::fs::read_to_string(session.join("sim0.log")).expect("sim0.log"));
    assert!(frames.len() > 500, "{} RPDOs", frames.len());
    // The drive commands kept their rhythm (RPDO at least every 20 ms, on changes more often).
    // A stalled writer would hold the loop for seconds; 60 ms leaves room for a busy 2-core
    // machine running the other tests beside this one.
    let worst = frames
        .windows(2)
        .map(|w| w[1].0 - w[0].0)
        .max()
        .unwrap_or(0);
    assert!(worst <= 60_000, "a {worst} µs gap in the drive commands");
    // The last command, from the recording; within the timeout and one period after it the
    // target is zero.
    let commands = std::fs::read_to_string(session.join("commands.log")).expect("commands.log");
    let last_command = commands
        .lines()
        .filter_map(|l| {
            let stamp = l.strip_prefix('(')?.split_once(')')?.0;
            let (s, us) = stamp.split_once('.')?;
            Some(s.parse::<u64>().ok()? * 1_000_000 + us.parse::<u64>().ok()?)
        })
        .max()
        .expect("commands recorded");
    let due = last_command + (CMD_TIMEOUT_MS + 10) * 1000;
    let after: Vec<&(u64, String)> = frames.iter().filter(|(t, _)| *t >= due).collect();
    assert!(!after.is_empty(), "the loop ran past the timeout");
    for (t, data) in after {
        // Controlword (2 bytes), then the i32 target: zero.
        assert_eq!(&data[4..], "00000000", "target at {t} µs: {data}");
    }
    let moving_before = frames
        .iter()
        .any(|(t, data)| *t < last_command && &data[4..] != "00000000");
    assert!(moving_before, "the vehicle was driving before");
}
