//! The live serial driver against real pseudo-terminals: the real `chassisd run` reads a
//! pty through a udev-style symlink, decodes fixes, sees the port vanish (the pty closes, as
//! a USB adapter does when unplugged), reconnects when it reappears, and records everything.
//! The replay of that recording must print exactly the status lines the live run printed.

use crate::common;

use std::io::Write;
use std::path::Path;
use std::process::Command;
use std::sync::Mutex;
use std::time::Duration;

use common::process::Proc;
use common::pty::Port;

const WAIT: Duration = Duration::from_secs(10);

/// The tests open ptys and spawn processes; they take turns so no child inherits another
/// test's descriptors.
static SERIAL: Mutex<()> = Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    SERIAL
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn status(line: &str) -> Option<serde_json::Value> {
    serde_json::from_str(line).ok()
}

fn is_status(line: &str, rtk_status: u64, latitude: f64) -> bool {
    status(line).is_some_and(|s| {
        s["rtk"]["status"] == rtk_status
            && s["sensor"]["gnss"] == true
            && (s["rtk"]["latitude"].as_f64().unwrap_or(0.0) - latitude).abs() < 1e-9
    })
}

/// A running `chassisd run` on a config whose GNSS port is `link`.
struct Daemon(Proc);

impl Daemon {
    fn start(dir: &Path, link: &Path, extra_args: &[&std::ffi::OsStr]) -> Daemon {
        let config = format!(
            "[gnss]\nport = \"{}\"\nbaud = 115200\nreconnect_max_s = 0.2\n",
            link.display()
        );
        Daemon::with_config(dir, &config, extra_args)
    }

    fn with_config(dir: &Path, config_text: &str, extra_args: &[&std::ffi::OsStr]) -> Daemon {
        let config = dir.join("vehicle.toml");
        std::fs::write(&config, config_text).unwrap();
        let mut args: Vec<&std::ffi::OsStr> =
            vec!["run".as_ref(), "--config".as_ref(), config.as_os_str()];
        args.extend_from_slice(extra_args);
        Daemon(Proc::start(&args))
    }

    fn wait_status(&mut self, what: &str, want: impl Fn(&str) -> bool) {
        self.0.wait_out(WAIT, what, want);
    }

    fn wait_log(&mut self, _what: &str, text: &str) {
        self.0.wait_log(WAIT, text);
    }

    fn stop(self) -> Vec<String> {
        self.0.stop()
    }
}

fn gga(quality: u8, lat_minutes: &str) -> String {
    format!(
        "GNGGA,120000.00,23{lat_minutes},N,11301.17918515,E,{quality},20,0.6,12.3,M,-6.1,M,1.0,0123"
    )
}

#[test]
fn decodes_reconnects_and_records_for_an_identical_replay() {
    let _turn = one_at_a_time();
    let dir = common::tempdir("pty");
    let link = dir.join("gnss-port");
    let record = dir.join("recording");

    let mut port = Port::open_at(&link);
    let mut daemon = Daemon::start(&dir, &link, &["--record".as_ref(), record.as_os_str()]);
    daemon.wait_log("link up", "link up");
    // RTK fixed at 23°08.98071170'.
    let lat_fixed = 23.0 + 8.98071170 / 60.0;
    for _ in 0..3 {
        port.send(&gga(4, "08.98071170"));
        std::thread::sleep(Duration::from_millis(100));
    }
    daemon.wait_status("an RTK fixed status", |l| is_status(l, 4, lat_fixed));

    // Unplug: the pty closes and the link disappears.
    drop(port);
    std::fs::remove_file(&link).unwrap();
    daemon.wait_log("link down", "link down");
    daemon.wait_status("a status without GNSS", |l| {
        status(l).is_some_and(|s| s["sensor"]["gnss"] == false && s["rtk"]["status"] == 0)
    });

    // Plug back in: a new pty at the same link; the driver finds it by itself.
    std::thread::sleep(Duration::from_millis(500));
    let mut port = Port::open_at(&link);
    daemon.wait_log("link up again", "link up");
    let lat_float = 23.0 + 8.5 / 60.0;
    for _ in 0..3 {
        port.send(&gga(5, "08.50000000"));
        std::thread::sleep(Duration::from_millis(100));
    }
    daemon.wait_status("an RTK float status", |l| is_status(l, 5, lat_float));
    let out = daemon.stop();
    drop(port);

    // Status lines are 10 Hz and every line is a complete status.
    assert!(out.len() >= 10, "{} lines", out.len());
    assert!(
        out.iter().all(|l| status(l).is_some()),
        "non-JSON on stdout"
    );

    let replayed = common::replay(&record);
    let live = out.join("\n") + "\n";
    assert!(
        String::from_utf8_lossy(&replayed.stdout) == live,
        "the replay of the recording differs from the live output ({} vs {} lines)",
        String::from_utf8_lossy(&replayed.stdout).lines().count(),
        out.len()
    );
    let summary = String::from_utf8_lossy(&replayed.stderr);
    assert!(summary.contains("GGA 6"), "{summary}");
    let recorded = std::fs::read_to_string(record.join("gnss.log")).unwrap();
    assert_eq!(recorded.matches("!link-up").count(), 2);
    assert_eq!(recorded.matches("!link-down").count(), 1);
}

#[test]
fn a_missing_port_is_retried_not_fatal() {
    let _turn = one_at_a_time();
    let dir = common::tempdir("pty");
    let link = dir.join("not-yet");
    let mut daemon = Daemon::start(&dir, &link, &[]);
    daemon.wait_log("the open failure", "cannot open port");
    // Status keeps flowing while the receiver is absent.
    for _ in 0..3 {
        daemon.wait_status("a status", |l| {
            status(l).is_some_and(|s| s["sensor"]["gnss"] == false)
        });
    }
    // A reminder a second into the outage (then at 10 s, then every minute), not silence.
    daemon.wait_log("the 1 s reminder", "port still unavailable");
    let mut port = Port::open_at(&link);
    daemon.wait_log("link up", "link up");
    port.send(&gga(4, "08.98071170"));
    daemon.wait_status("a fix", |l| is_status(l, 4, 23.0 + 8.98071170 / 60.0));
}

/// `check` while a running chassisd holds the receiver's port says so, and does not send
/// the person to the cable or the dialout group.
#[test]
fn check_names_a_running_chassisd_holding_the_port() {
    let _turn = one_at_a_time();
    let dir = common::tempdir("pty-held");
    let link = dir.join("gnss-port");
    let _port = Port::open_at(&link);
    let mut daemon = Daemon::start(&dir, &link, &[]);
    daemon.wait_log("link up", "link up");
    let checking = dir.join("check");
    std::fs::create_dir_all(&checking).unwrap();
    let config = format!("[gnss]\nport = \"{}\"\nbaud = 115200\n", link.display());
    let (code, table) = common::check(&config, &checking, &[]);
    assert_eq!(code, Some(1), "{table}");
    assert!(table.contains("another program holds"), "{table}");
    assert!(table.contains("systemctl stop chassisd"), "{table}");
    assert!(
        !table.contains("dialout") && !table.contains("cable"),
        "{table}"
    );
    daemon.stop();
}

#[test]
fn imu_over_pty_reports_health() {
    let _turn = one_at_a_time();
    let dir = common::tempdir("pty");
    let link = dir.join("imu-port");
    let config = format!(
        "[imu]\nport = \"{}\"\nprotocol = \"hipnuc\"\ntimeout_s = 0.3\nreconnect_max_s = 0.2\n",
        link.display()
    );
    let mut port = Port::open_at(&link);
    let mut daemon = Daemon::with_config(&dir, &config, &[]);
    daemon.wait_log("link up", "link up");
    let imu_ok = |l: &str| status(l).is_some_and(|s| s["sensor"]["imu"] == true);
    let imu_bad = |l: &str| status(l).is_some_and(|s| s["sensor"]["imu"] == false);
    let frame = chassisd::devices::imu::hipnuc::frame(&chassisd::devices::imu::hipnuc::packet_91(
        0,
        [0.0, 0.0, 1.0],
        [0.0, 0.0, 10.0],
        [1.0, 0.0, 0.0, 0.0],
    ));
    let dead = chassisd::devices::imu::hipnuc::frame(&chassisd::devices::imu::hipnuc::packet_91(
        0,
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0, 0.0],
    ));
    for _ in 0..30 {
        port.master.write_all(&[0x00, 0x5A]).unwrap(); // garbage between frames
        port.master.write_all(&frame).unwrap();
        std::thread::sleep(Duration::from_millis(10));
    }
    daemon.wait_status("IMU ok", imu_ok);
    // Frames keep coming but say the accelerometer feels no gravity: not ok.
    for _ in 0..60 {
        port.master.write_all(&dead).unwrap();
        std::thread::sleep(Duration::from_millis(10));
    }
    daemon.wait_status("IMU implausible", imu_bad);
    for _ in 0..30 {
        port.master.write_all(&frame).unwrap();
        std::thread::sleep(Duration::from_millis(10));
    }
    daemon.wait_status("IMU ok again", imu_ok);
    // Silence: stale after the 0.3 s timeout.
    daemon.wait_status("IMU silent", imu_bad);
    drop(port);
}

/// `chassisd run` on a configuration of `text`, which must be refused as a configuration
/// error (exit status 78, which systemd does not restart): its stderr and stdout.
fn refused_run(dir_name: &str, text: &str) -> (String, Vec<u8>) {
    let dir = common::tempdir(dir_name);
    let config = dir.join("vehicle.toml");
    std::fs::write(&config, text).unwrap();
    let out = Command::new(common::chassisd())
        .args(["run", "--config"])
        .arg(&config)
        .output()
        .expect("chassisd runs");
    assert_eq!(
        out.status.code(),
        Some(78),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (
        String::from_utf8_lossy(&out.stderr).into_owned(),
        out.stdout,
    )
}

#[test]
fn invalid_config_names_the_key() {
    let _turn = one_at_a_time();
    let (stderr, _) = refused_run("pty", "[gnss]\nport = \"/dev/null\"\nbaud = 1234\n");
    assert!(
        stderr.contains("`gnss.baud`") && stderr.contains("vehicle.toml"),
        "{stderr}"
    );
}

#[test]
fn a_run_without_devices_is_refused_with_the_smallest_configuration() {
    let (stderr, stdout) = refused_run("pty-empty", "[vehicle]\nname = \"empty\"\n");
    assert!(
        stderr.contains("names no device") && stderr.contains("[gnss] port = \"/dev/ttyUSB0\""),
        "{stderr}"
    );
    assert!(stdout.is_empty(), "no status without devices");
}
