//! Recordings are data, never instructions: a copy of a real fixture edited as an attacker
//! (or a broken disk) would edit it, replayed by the real binary. A span its records do not
//! bear out is replaced by theirs (and memory stays bounded); a file named outside its
//! folder is refused unread; transmissions that differ make the replay fail.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// A copy of `fixtures/<name>` in a fresh folder.
fn copy_of(name: &str, test: &str) -> PathBuf {
    let from = common::repo().join("fixtures").join(name);
    let to = common::tempdir(test).join(name);
    std::fs::create_dir_all(&to).expect("folder");
    for entry in std::fs::read_dir(&from).expect("fixture") {
        let entry = entry.expect("entry");
        if entry.file_type().expect("type").is_file() {
            std::fs::copy(entry.path(), to.join(entry.file_name())).expect("copy");
        }
    }
    to
}

/// `key = N` of the fixture's meta.toml, as the line and its number.
fn meta_line(name: &str, key: &str) -> (String, u64) {
    let meta =
        std::fs::read_to_string(common::repo().join("fixtures").join(name).join("meta.toml"))
            .expect("meta.toml");
    let value = meta
        .lines()
        .find_map(|l| l.strip_prefix(&format!("{key} = ")))
        .and_then(|v| v.trim().parse::<u64>().ok())
        .unwrap_or_else(|| panic!("no {key} in {name}'s meta.toml"));
    (format!("{key} = {value}"), value)
}

fn edit(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).expect("read");
    assert!(text.contains(from), "{from:?} in {}", path.display());
    std::fs::write(path, text.replacen(from, to, 1)).expect("write");
}

/// `chassisd replay DIR [extra]`, killed after `limit`. Its output goes through files, so
/// that a long one never waits on a pipe nobody reads yet.
fn replay(dir: &Path, extra: &[&str], limit: Duration) -> Output {
    let out_dir = common::tempdir("hostile-replay-out");
    let (out_file, err_file) = (out_dir.join("stdout"), out_dir.join("stderr"));
    let mut child = Command::new(common::chassisd())
        .arg("replay")
        .arg(dir)
        .args(extra)
        .stdout(std::fs::File::create(&out_file).expect("stdout file"))
        .stderr(std::fs::File::create(&err_file).expect("stderr file"))
        .spawn()
        .expect("replay runs");
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("status") {
            break status;
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            panic!("the replay of {} ran past {limit:?}", dir.display());
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Output {
        status,
        stdout: std::fs::read(&out_file).expect("stdout"),
        stderr: std::fs::read(&err_file).expect("stderr"),
    }
}

/// The peak memory the replay's summary line reports, MB.
fn peak_mb(stderr: &str) -> f64 {
    stderr
        .split("peak memory ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no peak memory in {stderr}"))
}

#[test]
fn a_span_its_records_do_not_bear_out_is_replaced_by_theirs() {
    let honest = replay(
        &common::repo().join("fixtures/can-drive"),
        &[],
        Duration::from_secs(60),
    );
    assert!(honest.status.success());
    let (start, start_us) = meta_line("can-drive", "start_us");
    let (end, _) = meta_line("can-drive", "end_us");
    // A start after every record (86 s past the real one).
    let late = format!("start_us = {}", start_us + 86_833_188);
    for (key, lie) in [
        (&start, "start_us = 0"),
        (&end, "end_us = 99999999999999999"),
        (&start, late.as_str()),
    ] {
        let dir = copy_of("can-drive", "hostile-span");
        edit(&dir.join("meta.toml"), key, lie);
        // The session then starts at its first record, later than the drives' boot really
        // began (22 ms in this fixture): what chassisd sends is shifted, and may differ.
        let out = replay(&dir, &["--lenient"], Duration::from_secs(60));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{lie}: {stderr}");
        assert!(
            stderr.contains("meta.toml:") && stderr.contains("disagrees"),
            "{lie}: {stderr}"
        );
        assert!(peak_mb(&stderr) < 64.0, "{lie}: {stderr}");
        // The records' own span: the same lines as the honest recording, give or take the
        // ticks between the session's start and its first record.
        let lines = |o: &Output| String::from_utf8_lossy(&o.stdout).lines().count();
        assert!(
            lines(&out).abs_diff(lines(&honest)) <= 1,
            "{lie}: {} lines, honest {}",
            lines(&out),
            lines(&honest)
        );
    }
}

#[test]
fn a_long_quiet_lead_within_the_limit_is_ticked_through_in_bounded_memory() {
    // 58 minutes between the session's start and its first record: believable, ticked
    // through, and what the drives would have been sent meanwhile is not kept.
    let dir = copy_of("can-drive", "hostile-lead");
    let (start, start_us) = meta_line("can-drive", "start_us");
    edit(
        &dir.join("meta.toml"),
        &start,
        &format!("start_us = {}", start_us - 58 * 60_000_000),
    );
    let out = replay(&dir, &["--lenient"], Duration::from_secs(60));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!stderr.contains("disagrees"), "{stderr}");
    let lines = String::from_utf8_lossy(&out.stdout).lines().count();
    assert!(lines > 58 * 600, "{lines} status lines");
    assert!(peak_mb(&stderr) < 64.0, "{stderr}");
}

#[test]
fn an_ntrip_secret_file_named_outside_the_recording_is_refused_unread() {
    for key in ["password_file", "ca_file"] {
        let dir = copy_of("rtk-drive", &format!("hostile-ntrip-{key}"));
        let config = dir.join("vehicle.toml");
        let text = std::fs::read_to_string(&config).expect("vehicle.toml");
        std::fs::write(
            &config,
            format!(
                "{text}\n[ntrip]\nurl = \"ntrips://rover@127.0.0.1:2101/M\"\n{key} = \"/etc/passwd\"\n"
            ),
        )
        .expect("write");
        let out = replay(&dir, &[], Duration::from_secs(30));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{key}: {stderr}");
        assert!(
            stderr.contains("lies outside the recording's folder")
                && stderr.contains(&format!("ntrip.{key}")),
            "{key}: {stderr}"
        );
        assert!(!stderr.contains("root:x:0:0"), "{key}: {stderr}");
    }
}

#[test]
fn files_named_outside_the_recording_are_refused_unread() {
    for (name, target) in [
        ("absolute", "/etc/passwd"),
        ("relative", "../../../../../etc/hostname"),
    ] {
        let dir = copy_of("rtk-drive", &format!("hostile-profile-{name}"));
        let config = dir.join("vehicle.toml");
        let text = std::fs::read_to_string(&config).expect("vehicle.toml");
        std::fs::write(
            &config,
            format!(
                "{text}\n[[drive]]\nname = \"evil\"\nprofile = \"{target}\"\nbus = \"can0\"\n\
                 node = 9\nwheels = [\"left\"]\n"
            ),
        )
        .expect("write");
        let out = replay(&dir, &[], Duration::from_secs(30));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{target}: {stderr}");
        assert!(
            stderr.contains("lies outside the recording's folder") && stderr.contains("drive["),
            "{target}: {stderr}"
        );
        // Nothing of the file reached the output.
        let first = std::fs::read_to_string(target.trim_start_matches("../../../../.."))
            .ok()
            .and_then(|t| t.lines().next().map(str::to_owned))
            .unwrap_or_else(|| "root:x:0:0".into());
        assert!(!stderr.contains(&first), "{target}: {stderr}");
    }
}

#[test]
fn transmissions_that_differ_fail_the_replay_unless_lenient() {
    let dir = copy_of("can-drive", "hostile-transmissions");
    // The daemon's first heartbeat, as a drive would see a different master's.
    edit(&dir.join("vcan0.log"), "vcan0 77F#05 T", "vcan0 77F#7F T");
    let out = replay(&dir, &[], Duration::from_secs(60));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("transmissions differ"), "{stderr}");
    let lenient = replay(&dir, &["--lenient"], Duration::from_secs(60));
    assert!(lenient.status.success());
}
