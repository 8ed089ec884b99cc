//! `chassisd record` against real parts: a receiver on a pseudo-terminal and a real
//! mosquitto with a real client sending a command. The recording rotates by time, keeps the
//! newest segments, each segment replays on its own to RTK-fixed base_status lines, the
//! command is in the recording, and the recorder sends nothing: not a byte to the port, not a
//! message to the broker. (CAN listen-only runs on vcan in the VM: tests/vcan.rs.)

use crate::common;

use std::io::Read;
use std::os::fd::AsRawFd;
use std::path::Path;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use common::mqtt::Mosquitto;
use common::process::Proc;
use common::pty::{Port, Talker};

/// The pty tests take turns so no child inherits another test's descriptors.
static SERIAL: Mutex<()> = Mutex::new(());

const SERIAL_NUMBER: &str = "REC0001";

fn config(dir: &Path, gnss: &Path, broker: &Mosquitto) -> std::path::PathBuf {
    let port = broker
        .address()
        .rsplit(':')
        .next()
        .expect("port")
        .to_owned();
    let text = format!(
        "[vehicle]\nname = \"recorder-test\"\n\n[gnss]\nport = \"{}\"\n\n\
         [mqtt]\nhost = \"127.0.0.1\"\nport = {port}\n\n[mqtt.device]\nserial_number = \"{SERIAL_NUMBER}\"\n",
        gnss.display()
    );
    let path = dir.join("vehicle.toml");
    std::fs::write(&path, text).expect("config");
    path
}

/// `chassisd record --config CONFIG --out OUT EXTRA...`.
fn record(config: &Path, out: &Path, extra: &[&str]) -> Proc {
    let mut args = vec![
        "record".into(),
        "--config".into(),
        config.as_os_str().to_owned(),
        "--out".into(),
        out.as_os_str().to_owned(),
    ];
    args.extend(extra.iter().map(std::ffi::OsString::from));
    Proc::start(&args)
}

/// Waits for the process to exit on its own; returns its exit code and its whole log.
fn exit(proc: &mut Proc, within: Duration) -> (Option<i32>, String) {
    let deadline = Instant::now() + within;
    let code = loop {
        if let Some(status) = proc.child.try_wait().expect("wait") {
            break status.code();
        }
        assert!(Instant::now() < deadline, "chassisd record did not stop");
        std::thread::sleep(Duration::from_millis(50));
    };
    // The pipe is closed: the rest of standard error arrives and ends.
    proc.log.extend(proc.stderr.iter());
    (code, proc.log.join("\n"))
}

/// The base_status lines of a replayed segment.
fn replay_lines(dir: &Path) -> Vec<serde_json::Value> {
    let out = common::replay(dir);
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect()
}

#[test]
fn record_rotates_keeps_the_newest_and_each_segment_replays_and_nothing_is_sent() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let dir = common::tempdir("record-listen");
    let link = dir.join("gnss-port");
    let port = Port::open_at(&link);
    let mut master = port.master.try_clone().expect("master");
    let _talker = Talker::start(port);
    let broker = Mosquitto::start();
    let everything = broker.subscribe(&["#"]);
    let config = config(&dir, &link, &broker);
    let out = dir.join("rec");
    let mut proc = record(
        &config,
        &out,
        &[
            "--segment-s",
            "2",
            "--keep",
            "3",
            "--duration",
            "7",
            "--mcap",
        ],
    );
    proc.wait_log(Duration::from_secs(10), "recording the vehicle's commands");
    // Into the second segment: the first is removed by the end.
    proc.wait_log(Duration::from_secs(10), "recording segment complete");
    let goal = format!("device/{SERIAL_NUMBER}/goal");
    let command = r#"{"msg_id":"rec-1","timestamp":1,"data":{"x":1.0,"y":2.0}}"#;
    broker.publish(&goal, command);
    // Not a byte went to the receiver's port (read while the recorder holds it open).
    nix::fcntl::fcntl(
        master.as_raw_fd(),
        nix::fcntl::FcntlArg::F_SETFL(nix::fcntl::OFlag::O_NONBLOCK),
    )
    .expect("non-blocking");
    let mut buf = [0u8; 64];
    match master.read(&mut buf) {
        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
        other => panic!("the recorder wrote to the port: {other:?}"),
    }
    let (code, log) = exit(&mut proc, Duration::from_secs(15));
    assert_eq!(code, Some(0), "{log}");
    assert!(log.contains("stopped by duration"), "{log}");

    // Seven seconds in segments of two: four segments, the oldest removed.
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .expect("the recording")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["0002", "0003", "0004"], "{log}");

    // A whole segment in the middle replays on its own: 2 s of a 10 Hz RTK-fixed receiver.
    let lines = replay_lines(&out.join("0003"));
    assert!((18..=22).contains(&lines.len()), "{} lines", lines.len());
    let fixed = lines.iter().filter(|l| l["rtk"]["status"] == 4).count();
    assert!(
        fixed >= lines.len() - 2,
        "{fixed} of {} RTK fixed",
        lines.len()
    );

    // The command is in the recording, byte for byte.
    let recorded: String = names
        .iter()
        .filter_map(|n| std::fs::read_to_string(out.join(n).join("mqtt.log")).ok())
        .collect();
    let hex: String = command.bytes().map(|b| format!("{b:02x}")).collect();
    assert!(
        recorded.contains(&goal) && recorded.to_lowercase().contains(&hex),
        "{recorded}"
    );

    // The broker carried our command and nothing from the recorder.
    let mut seen = Vec::new();
    while let Some((topic, _)) = everything.next(Duration::from_millis(300)) {
        seen.push(topic);
    }
    assert_eq!(seen, [goal], "only the test's command on the broker");

    // Each segment's MCAP file holds what its folder holds, as an independent reader reads
    // it (raw chunks and the command byte for byte, indexes and statistics).
    let empty = dir.join("no-statuses");
    std::fs::write(&empty, "").unwrap();
    for name in &names {
        let segment = out.join(name);
        let check = std::process::Command::new(common::venv_python())
            .arg(common::repo().join("tests/mcap/check_export.py"))
            .arg(segment.join("recording.mcap"))
            .arg(&segment)
            .arg(&empty)
            .output()
            .expect("check_export.py");
        assert!(
            check.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&check.stderr)
        );
    }
}

#[test]
fn a_killed_record_mcap_leaves_a_file_read_whole_up_to_its_last_second() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let dir = common::tempdir("record-mcap-kill");
    let link = dir.join("gnss-port");
    let _talker = Talker::start(Port::open_at(&link));
    let broker = Mosquitto::start();
    let config = config(&dir, &link, &broker);
    let out = dir.join("rec");
    let mut proc = record(&config, &out, &["--mcap"]);
    proc.wait_log(Duration::from_secs(10), "link up");
    std::thread::sleep(Duration::from_millis(3500));
    let killed_at = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    proc.child.kill().expect("SIGKILL");
    let _ = proc.child.wait();
    let segment = out.join("0001");
    let read = std::process::Command::new(common::venv_python())
        .arg(common::repo().join("tests/mcap/stream_read.py"))
        .arg(segment.join("recording.mcap"))
        .output()
        .expect("stream_read.py");
    assert!(
        read.status.success(),
        "{}",
        String::from_utf8_lossy(&read.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    // No summary: the writer never finished; every message before the cut reads whole.
    assert_ne!(report["ended"], "footer", "{report}");
    let chunks = report["messages"]["/raw/gnss"].as_u64().unwrap_or(0);
    assert!(chunks >= 20, "{report}");
    assert!(
        report["messages"]["/raw/gnss/nmea"].as_u64() >= Some(chunks),
        "{report}"
    );
    // Flushed at least every second: what was read reaches to within 1.5 s of the kill.
    let last = report["last_log_time"].as_u64().unwrap();
    assert!(
        killed_at.saturating_sub(last) < 1_500_000_000,
        "the file ends {} ms before the kill",
        killed_at.saturating_sub(last) / 1_000_000
    );
    // And what it holds is the receiver's bytes as the recording's files hold them.
    let gnss = std::fs::read_to_string(segment.join("gnss.log")).unwrap();
    let recorded: String = gnss
        .lines()
        .filter(|l| !l.contains('!'))
        .filter_map(|l| l.rsplit(' ').next())
        .collect::<String>()
        .to_lowercase();
    let in_mcap = report["serial_bytes"]["/raw/gnss"].as_str().unwrap();
    assert!(
        !in_mcap.is_empty() && recorded.starts_with(in_mcap),
        "the MCAP's bytes are not the recording's"
    );
}

#[test]
fn sigterm_ends_the_segment_cleanly_and_an_absent_port_is_recorded_as_down() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let dir = common::tempdir("record-sigterm");
    let link = dir.join("gnss-port");
    let broker = Mosquitto::start();
    let config = config(&dir, &link, &broker);
    let out = dir.join("rec");
    let mut proc = record(&config, &out, &[]);
    // No receiver yet: the port is missing, reported, and retried.
    proc.wait_log(Duration::from_secs(10), "cannot open port; retrying");
    let _talker = Talker::start(Port::open_at(&link));
    proc.wait_log(Duration::from_secs(10), "link up");
    std::thread::sleep(Duration::from_secs(1));
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(proc.child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .expect("SIGTERM");
    let (code, log) = exit(&mut proc, Duration::from_secs(10));
    assert_eq!(code, Some(0), "{log}");
    assert!(log.contains("stopped by SIGTERM"), "{log}");
    let meta = std::fs::read_to_string(out.join("0001").join("meta.toml")).expect("meta");
    assert!(meta.contains("end_us"), "a clean end is marked:\n{meta}");
    let gnss = std::fs::read_to_string(out.join("0001").join("gnss.log")).expect("gnss.log");
    assert!(gnss.contains("!link-up"), "{gnss}");
    let lines = replay_lines(&out.join("0001"));
    assert!(
        lines.iter().any(|l| l["rtk"]["status"] == 4),
        "the fixes after the port came up replay"
    );
}
