//! Recordings whose files lie (issue 48): replay reads a data file of any size in bounded
//! memory, reports an over-long line by its length and never quotes it whole, and refuses
//! a FIFO instead of waiting on it.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A copy of `fixtures/sim-drive` (a live simulation's recording) to spoil.
fn sim_drive_copy(name: &str) -> PathBuf {
    let from = common::repo().join("fixtures/sim-drive");
    let to = common::tempdir(name);
    for entry in std::fs::read_dir(&from).expect("fixture") {
        let entry = entry.expect("entry");
        if entry.file_type().expect("type").is_file() {
            std::fs::copy(entry.path(), to.join(entry.file_name())).expect("copy");
        }
    }
    to
}

/// Runs `chassisd replay --lenient DIR` to its end (at most `limit`), sampling its memory;
/// its exit status, stderr and peak resident memory (kB).
fn replay_sampled(dir: &Path, limit: Duration) -> (bool, String, u64) {
    let stderr_file = dir.with_extension("stderr");
    let mut child = Command::new(common::chassisd())
        .args(["replay", "--lenient"])
        .arg(dir)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&stderr_file).expect("stderr file"))
        .spawn()
        .expect("chassisd runs");
    let started = Instant::now();
    let mut peak = 0;
    let status = loop {
        peak = peak.max(common::rss_with_children_kb(child.id()));
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("replay still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let stderr = std::fs::read(&stderr_file).expect("stderr");
    (
        status.success(),
        String::from_utf8_lossy(&stderr).into_owned(),
        peak,
    )
}

#[test]
fn a_data_file_with_a_256_mb_line_replays_in_bounded_memory() {
    let dir = sim_drive_copy("replay-huge-line");
    // The GNSS log's records, then 256 MB of zeros without a newline (a sparse file: the
    // disk holds none of it).
    let gnss = std::fs::OpenOptions::new()
        .append(true)
        .open(dir.join("gnss.log"))
        .expect("gnss.log");
    let len = gnss.metadata().expect("metadata").len();
    gnss.set_len(len + (256 << 20)).expect("sparse tail");
    let (ok, stderr, peak_kb) = replay_sampled(&dir, Duration::from_secs(60));
    assert!(ok, "{}", &stderr[..stderr.len().min(2000)]);
    assert!(
        stderr.contains("a line of 268435456 bytes, over the 4194304 a recording holds"),
        "{}",
        &stderr[..stderr.len().min(2000)]
    );
    // The line is neither held nor quoted: a few MB of buffers, a short report.
    assert!(peak_kb < 100_000, "peak resident memory {peak_kb} kB");
    assert!(stderr.len() < 20_000, "stderr of {} bytes", stderr.len());
    // The records before it still played.
    assert!(stderr.contains("250 status lines"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_fifo_as_a_data_file_is_refused_with_the_reason() {
    let dir = sim_drive_copy("replay-fifo");
    let gnss = dir.join("gnss.log");
    std::fs::remove_file(&gnss).expect("remove gnss.log");
    nix::unistd::mkfifo(
        &gnss,
        nix::sys::stat::Mode::S_IRUSR | nix::sys::stat::Mode::S_IWUSR,
    )
    .expect("mkfifo");
    // Nobody writes the FIFO: a reader that opened it would wait for ever.
    let (ok, stderr, _) = replay_sampled(&dir, Duration::from_secs(30));
    assert!(!ok, "{stderr}");
    assert!(
        stderr.contains("gnss.log") && stderr.contains("not a regular file"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_oversized_trajectories_file_is_refused_before_it_is_read() {
    let dir = sim_drive_copy("replay-huge-trajectories");
    // 300 MB claimed, none of it on the disk, and named in meta.toml.
    let meta = dir.join("meta.toml");
    let text = std::fs::read_to_string(&meta).expect("meta.toml");
    let text = text.replacen(
        "vehicle_config = ",
        "trajectories = \"trajectories.json\"\nvehicle_config = ",
        1,
    );
    std::fs::write(&meta, text).expect("meta.toml written");
    let trajectories = std::fs::File::create(dir.join("trajectories.json")).expect("create");
    trajectories.set_len(300 << 20).expect("sparse");
    let (ok, stderr, peak_kb) = replay_sampled(&dir, Duration::from_secs(30));
    assert!(!ok, "{stderr}");
    assert!(
        stderr.contains("trajectories.json") && stderr.contains("more than such a file holds"),
        "{stderr}"
    );
    assert!(peak_kb < 100_000, "peak resident memory {peak_kb} kB");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_fifo_given_as_an_nmea_log_is_refused_with_the_reason() {
    let dir = common::tempdir("replay-nmea-fifo");
    let log = dir.join("receiver.nmea");
    nix::unistd::mkfifo(
        &log,
        nix::sys::stat::Mode::S_IRUSR | nix::sys::stat::Mode::S_IWUSR,
    )
    .expect("mkfifo");
    let out = Command::new(common::chassisd())
        .arg("replay")
        .arg(&log)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("chassisd runs");
    let started = Instant::now();
    let mut out = out;
    let status = loop {
        if let Some(status) = out.try_wait().expect("wait") {
            break status;
        }
        if started.elapsed() > Duration::from_secs(30) {
            let _ = out.kill();
            panic!("replay waited on the FIFO");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut out.stderr.take().expect("stderr"), &mut stderr)
        .expect("stderr");
    assert!(!status.success(), "{stderr}");
    assert!(stderr.contains("not a regular file"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
