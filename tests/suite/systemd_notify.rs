//! `chassisd run` as a `Type=notify` service, against a real notify socket (a Unix datagram
//! socket, as systemd gives `NOTIFY_SOCKET`): READY once its receiver (a real pty) is up,
//! WATCHDOG pings a quarter of `WATCHDOG_USEC` apart while the core runs, none while the
//! process is stopped or its control loop alone is stalled (an injected block), again when
//! it resumes; SIGTERM brings STOPPING and exit 0. Under journald
//! (`JOURNAL_STREAM`) log lines carry their syslog priority. The unit file passes
//! `systemd-analyze verify`.

use crate::common;

use std::os::unix::net::UnixDatagram;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::process::lines_of;
use common::pty::Port;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// The watchdog period the test sets: pings every 100 ms.
const WATCHDOG_US: u64 = 400_000;

/// Every datagram that arrives within `span`, with its arrival time.
fn messages(socket: &UnixDatagram, span: Duration) -> Vec<(Instant, String)> {
    let end = Instant::now() + span;
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        socket
            .set_read_timeout(Some(left.max(Duration::from_millis(1))))
            .expect("timeout");
        if let Ok(n) = socket.recv(&mut buf) {
            got.push((
                Instant::now(),
                String::from_utf8_lossy(&buf[..n]).into_owned(),
            ));
        }
    }
    got
}

fn pings(got: &[(Instant, String)]) -> Vec<Instant> {
    got.iter()
        .filter(|(_, m)| m.lines().any(|l| l == "WATCHDOG=1"))
        .map(|(t, _)| *t)
        .collect()
}

/// `chassisd run` on a pty receiver as systemd starts it: a notify socket, the watchdog on,
/// and one more environment variable.
struct Service {
    _port: Port,
    socket: UnixDatagram,
    daemon: std::process::Child,
    log: std::sync::mpsc::Receiver<String>,
}

impl Service {
    fn start(name: &str, env: (&str, &str)) -> Service {
        let dir = common::tempdir(name);
        let link = dir.join("gnss-port");
        let port = Port::open_at(&link);
        let config = dir.join("vehicle.toml");
        std::fs::write(&config, format!("[gnss]\nport = \"{}\"\n", link.display()))
            .expect("config");
        let socket_path = dir.join("notify.sock");
        let socket = UnixDatagram::bind(&socket_path).expect("notify socket");
        let mut daemon = Command::new(common::chassisd())
            .args(["run", "--config"])
            .arg(&config)
            .env("NOTIFY_SOCKET", &socket_path)
            .env("WATCHDOG_USEC", WATCHDOG_US.to_string())
            .env("RUST_LOG", "info")
            .env(env.0, env.1)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("chassisd starts");
        let log = lines_of(daemon.stderr.take().expect("stderr"));
        Service {
            _port: port,
            socket,
            daemon,
            log,
        }
    }
}

#[test]
fn ready_watchdog_from_the_control_loop_and_stopping() {
    let Service {
        _port,
        socket,
        mut daemon,
        log,
    } = Service::start("systemd-notify", ("JOURNAL_STREAM", "8:12345"));
    let pid = Pid::from_raw(daemon.id() as i32);

    let first = messages(&socket, Duration::from_secs(3));
    let ready = first
        .iter()
        .find(|(_, m)| m.lines().any(|l| l == "READY=1"))
        .unwrap_or_else(|| panic!("READY within 3 s: {first:?}"));
    assert!(
        ready
            .1
            .contains("STATUS=running: every device and the broker are up"),
        "{ready:?}"
    );
    let running = pings(&first);
    assert!(running.len() >= 15, "about 10 pings a second: {first:?}");
    // Never a gap that would let systemd's watchdog fire.
    for pair in running.windows(2) {
        let gap = pair[1].duration_since(pair[0]);
        assert!(gap < Duration::from_micros(WATCHDOG_US), "a gap of {gap:?}");
    }

    // A stalled core feeds nothing; once it runs again, it does.
    kill(pid, Signal::SIGSTOP).expect("SIGSTOP");
    let _ = messages(&socket, Duration::from_millis(50));
    let stalled = messages(&socket, Duration::from_secs(1));
    assert!(pings(&stalled).is_empty(), "fed while stalled: {stalled:?}");
    kill(pid, Signal::SIGCONT).expect("SIGCONT");
    let resumed = messages(&socket, Duration::from_secs(1));
    assert!(pings(&resumed).len() >= 5, "{resumed:?}");

    kill(pid, Signal::SIGTERM).expect("SIGTERM");
    let last = messages(&socket, Duration::from_secs(2));
    assert!(
        last.iter()
            .any(|(_, m)| m.lines().any(|l| l == "STOPPING=1")),
        "{last:?}"
    );
    let status = daemon.wait().expect("exits");
    assert!(status.success(), "{status:?}");

    // Journald lines: the priority first, no timestamp of their own.
    let lines: Vec<String> = log.try_iter().collect();
    let ready_line = lines
        .iter()
        .find(|l| l.contains("ready"))
        .unwrap_or_else(|| panic!("{lines:?}"));
    assert!(
        ready_line.starts_with("<6> INFO") || ready_line.starts_with("<6>INFO"),
        "{ready_line}"
    );
    assert!(lines.iter().all(|l| !l.starts_with("20")), "{lines:?}");
}

#[test]
fn a_configuration_error_exits_78_so_systemd_does_not_restart() {
    let dir = common::tempdir("systemd-config-error");
    let config = dir.join("vehicle.toml");
    std::fs::write(&config, "[gnss]\nport = \"\"\n").expect("config");
    let out = Command::new(common::chassisd())
        .args(["run", "--config"])
        .arg(&config)
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(78));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("gnss.port") && err.contains("fix:"), "{err}");
}

#[test]
fn the_unit_file_verifies() {
    let Some(analyze) = ["/usr/bin/systemd-analyze", "/bin/systemd-analyze"]
        .into_iter()
        .find(|p| Path::new(p).exists())
    else {
        panic!("systemd-analyze is needed (the systemd package): tests/install-deps installs it");
    };
    let dir = common::tempdir("systemd-unit");
    let unit =
        std::fs::read_to_string(common::repo().join("debian/chassisd.service")).expect("the unit");
    assert!(unit.contains("Type=notify") && unit.contains("WatchdogSec="));
    // The installed path is /usr/bin/chassisd; here the built binary stands in for it.
    let local = unit.replace(
        "/usr/bin/chassisd",
        &common::chassisd().display().to_string(),
    );
    let path = dir.join("chassisd.service");
    std::fs::write(&path, local).expect("unit copy");
    let out = Command::new(analyze)
        .arg("verify")
        .arg(&path)
        .output()
        .expect("systemd-analyze runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        !text.contains("chassisd.service:"),
        "systemd-analyze verify: {text}"
    );
}

/// The core's own loop stalled (an injected 1 s block of the control loop, the process
/// otherwise running): the pings stop for that second and come back after it.
#[test]
fn a_stalled_control_loop_stops_feeding_the_watchdog() {
    let Service {
        _port,
        socket,
        mut daemon,
        log,
    } = Service::start("systemd-stall", ("CHASSISD_INJECT_CORE_STALL", "1@2"));
    let got = messages(&socket, Duration::from_secs(5));
    let fed = pings(&got);
    assert!(fed.len() >= 20, "{got:?}");
    let gaps: Vec<Duration> = fed.windows(2).map(|p| p[1].duration_since(p[0])).collect();
    let longest = gaps.iter().max().copied().unwrap_or_default();
    assert!(
        (Duration::from_millis(900)..Duration::from_millis(1500)).contains(&longest),
        "the stall's gap: {longest:?} in {gaps:?}"
    );
    // Apart from the stall, no gap would let the watchdog fire.
    assert_eq!(
        gaps.iter()
            .filter(|g| **g >= Duration::from_micros(WATCHDOG_US))
            .count(),
        1,
        "{gaps:?}"
    );
    kill(Pid::from_raw(daemon.id() as i32), Signal::SIGTERM).expect("SIGTERM");
    assert!(daemon.wait().expect("exits").success());
    let lines: Vec<String> = log.try_iter().collect();
    assert!(
        lines
            .iter()
            .any(|l| l.contains("injected control-loop stall")),
        "{lines:?}"
    );
}
