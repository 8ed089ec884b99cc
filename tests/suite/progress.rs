//! Long commands draw a progress bar on a terminal, and nothing when piped: `replay` of a
//! recording (by its recorded time) and of a plain log (by its bytes), and `calibrate`
//! reading a recording. The terminal is a real pseudo-terminal holding the command's
//! stderr, as a person's shell would.

use crate::common;

use std::io::Read;
use std::os::fd::{AsFd, AsRawFd};
use std::path::Path;
use std::process::{Command, Stdio};

use nix::fcntl::{FcntlArg, FdFlag, fcntl};
use nix::pty::{Winsize, openpty};

/// Runs chassisd with `args`, its stderr on a pseudo-terminal of 120 columns (stdout
/// discarded): whether it succeeded, and what the terminal showed.
fn on_a_terminal(args: &[&std::ffi::OsStr]) -> (bool, String) {
    let size = Winsize {
        ws_row: 24,
        ws_col: 120,
        ws_xpixel: 0,
        ws_ypixel: 0,
    };
    let pty = openpty(Some(&size), None).expect("openpty");
    fcntl(
        pty.master.as_fd().as_raw_fd(),
        FcntlArg::F_SETFD(FdFlag::FD_CLOEXEC),
    )
    .expect("cloexec");
    let mut child = Command::new(common::chassisd())
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::from(pty.slave))
        .spawn()
        .expect("chassisd runs");
    let mut master = std::fs::File::from(pty.master);
    let reader = std::thread::spawn(move || {
        let mut seen = Vec::new();
        let mut buf = [0u8; 4096];
        // The read fails (EIO) once the child, the last holder of the slave, is gone.
        while let Ok(n) = master.read(&mut buf) {
            if n == 0 {
                break;
            }
            seen.extend_from_slice(&buf[..n]);
        }
        seen
    });
    let status = child.wait().expect("chassisd ends");
    let seen = reader.join().expect("the reader");
    (
        status.success(),
        String::from_utf8_lossy(&seen).into_owned(),
    )
}

/// The same, its stderr piped.
fn piped(args: &[&std::ffi::OsStr]) -> (bool, String) {
    let out = Command::new(common::chassisd())
        .args(args)
        .stdout(Stdio::null())
        .output()
        .expect("chassisd runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A bar was drawn for `what`: its text, a percentage and the bar's brackets.
fn drew_a_bar(seen: &str, what: &str) -> bool {
    seen.contains(what) && seen.contains('%') && seen.contains("[=")
}

/// A 95 s simulated recording, made with `sim --fast`.
fn recording(dir: &Path) -> std::path::PathBuf {
    let rec = dir.join("rec");
    let out = Command::new(common::chassisd())
        .args(["sim", "--fast", "--scenario", "straight", "--record"])
        .arg(&rec)
        .stdout(Stdio::null())
        .output()
        .expect("sim runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    rec
}

#[test]
fn replay_draws_a_bar_on_a_terminal_and_nothing_when_piped() {
    let dir = common::tempdir("progress-replay");
    let rec = recording(&dir);
    let args = ["replay".as_ref(), rec.as_os_str()];
    let (ok, seen) = on_a_terminal(&args);
    assert!(ok, "{seen}");
    assert!(drew_a_bar(&seen, "replaying"), "{seen:?}");
    // The summary still follows, on a clean line.
    assert!(seen.contains("status lines"), "{seen:?}");
    let (ok, log) = piped(&args);
    assert!(ok, "{log}");
    assert!(
        !log.contains("replaying") && !log.contains('\u{1b}'),
        "{log:?}"
    );

    // A plain log, by its bytes: a real receiver's log, ten times over.
    let real = std::fs::read(common::shared_gnss_dir().join("ublox-zed-f9r.log")).expect("log");
    let long = dir.join("long.log");
    std::fs::write(&long, real.repeat(10)).expect("write");
    let args = ["replay".as_ref(), "--lenient".as_ref(), long.as_os_str()];
    let (_, seen) = on_a_terminal(&args);
    assert!(drew_a_bar(&seen, "replaying"), "{seen:?}");
    let (_, log) = piped(&args);
    assert!(!log.contains("replaying"), "{log:?}");
}

#[test]
fn calibrate_draws_a_bar_while_it_reads_a_recording() {
    let dir = common::tempdir("progress-calibrate");
    let rec = recording(&dir);
    let out = dir.join("calib");
    let args = [
        "calibrate".as_ref(),
        "imu".as_ref(),
        "--from".as_ref(),
        rec.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ];
    let (_, seen) = on_a_terminal(&args);
    assert!(drew_a_bar(&seen, "replaying"), "{seen:?}");
    let (_, log) = piped(&args);
    assert!(!log.contains("replaying"), "{log:?}");
}
