//! Replay across time: plain logs whose receiver clock jumps (set after boot, a week
//! rollover, a step back) replay in segments, and memory does not grow with the span or
//! the length of what is replayed.

use crate::common;

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

/// The bound on replay's peak memory, bytes.
const RSS_LIMIT: u64 = 50 * 1024 * 1024;

fn sentence(body: &str) -> String {
    let sum = body.bytes().fold(0u8, |a, b| a ^ b);
    format!("${body}*{sum:02X}\r\n")
}

/// One receiver epoch at `secs` after midnight of `date` (ddmmyy): GGA, RMC and GST, a
/// standing vehicle with a DGPS fix.
fn epoch(log: &mut String, date: &str, secs: f64) {
    let whole = secs as u64;
    let time = format!(
        "{:02}{:02}{:02}.{:02}",
        whole / 3600 % 24,
        whole / 60 % 60,
        whole % 60,
        ((secs - whole as f64) * 100.0).round() as u64
    );
    log.push_str(&sentence(&format!(
        "GPGGA,{time},4723.8645,N,00832.7356,E,2,12,0.8,488.0,M,47.0,M,1.0,0000"
    )));
    log.push_str(&sentence(&format!(
        "GPRMC,{time},A,4723.8645,N,00832.7356,E,0.0,,{date},,,D"
    )));
    log.push_str(&sentence(&format!(
        "GPGST,{time},0.9,0.6,0.5,0.0,0.6,0.5,1.1"
    )));
}

/// What a replay left: exit code, summary, peak memory (bytes, from its summary), output.
struct Replayed {
    code: Option<i32>,
    stderr: String,
    peak_rss: u64,
}

fn replay_measured(log: &Path, extra: &[&str]) -> (Replayed, String) {
    let out = Command::new(common::chassisd())
        .arg("replay")
        .arg(log)
        .args(extra)
        .output()
        .expect("chassisd runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    // The process reports its own peak (VmHWM): a spawner's rusage would count the test's
    // memory too.
    let peak_rss = stderr
        .split("peak memory ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|mb| mb.parse::<f64>().ok())
        .map_or(u64::MAX, |mb| (mb * 1e6) as u64);
    let stdout = String::from_utf8(out.stdout).expect("UTF-8 output");
    (
        Replayed {
            code: out.status.code(),
            stderr,
            peak_rss,
        },
        stdout,
    )
}

#[test]
fn a_log_spanning_years_replays_in_segments_in_bounded_memory() {
    let dir = common::tempdir("years");
    let log = dir.join("jumps.log");
    let mut text = String::from("# boots on its default date, then sets its clock twice\n");
    // 2008-01-01 00:00:39 for three epochs, 2010-07-09 07:36:58 for 60 s, back to
    // 1980-01-05 (a week rollover) for 20 s, then 2008-08-23 for 20 s.
    for i in 0..3 {
        epoch(&mut text, "010108", 39.0 + f64::from(i));
    }
    for i in 0..600 {
        epoch(
            &mut text,
            "090710",
            7.0 * 3600.0 + 36.0 * 60.0 + 58.0 + f64::from(i) * 0.1,
        );
    }
    for i in 0..200 {
        epoch(&mut text, "050180", 3600.0 + f64::from(i) * 0.1);
    }
    for i in 0..200 {
        epoch(&mut text, "230808", 43200.0 + f64::from(i) * 0.1);
    }
    std::fs::write(&log, &text).expect("log written");

    let (m, stdout) = replay_measured(&log, &["--stamped"]);
    assert_eq!(m.code, Some(0), "{}", m.stderr);
    println!(
        "a log over 2008-2010 and 1980: peak RSS {:.1} MB, {} lines; {}",
        m.peak_rss as f64 / 1e6,
        stdout.lines().count(),
        m.stderr.trim()
    );
    assert!(m.peak_rss < RSS_LIMIT, "peak RSS {} bytes", m.peak_rss);
    // Three jumps, each named by its line (line 1 is the comment, three lines per epoch).
    for part in [
        "3 clock jumps",
        "line 11: 2008-01-01 00:00:41 to 2010-07-09 07:36:58",
        "line 1811: 2010-07-09 07:37:57.900 to 1980-01-05 01:00:00",
        "line 2411: 1980-01-05 01:00:19.900 to 2008-08-23 12:00:00",
    ] {
        assert!(
            m.stderr.contains(part),
            "summary lacks {part:?}: {}",
            m.stderr
        );
    }
    // About 3 + 60 + 20 + 20 s of ticks, not years of them.
    let rows: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect();
    assert!(
        (1000..1060).contains(&rows.len()),
        "{} status lines",
        rows.len()
    );
    // Stamps show the log's own time in each segment.
    let stamps: Vec<f64> = rows.iter().map(|r| r["stamp"].as_f64().unwrap()).collect();
    let in_segment = |from: f64, to: f64| stamps.iter().filter(|s| **s >= from && **s < to).count();
    // 2008-01-01, 2010-07-09, 1980-01-05 and 2008-08-23 (Unix seconds).
    assert!(in_segment(1_199_145_600.0, 1_199_145_700.0) >= 20);
    assert!(in_segment(1_278_661_018.0, 1_278_661_080.0) >= 590);
    assert!(in_segment(315_882_000.0, 315_882_021.0) >= 190);
    assert!(in_segment(1_219_492_800.0, 1_219_492_821.0) >= 190);
    assert_eq!(
        rows[0]
            .as_object()
            .unwrap()
            .keys()
            .next()
            .map(String::as_str),
        Some("stamp")
    );

    // Without --stamped the lines keep the protocol's schema.
    let (plain, stdout) = replay_measured(&log, &[]);
    assert_eq!(plain.code, Some(0));
    assert!(!stdout.contains("\"stamp\""));
    assert_eq!(stdout.lines().count(), rows.len());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_hour_long_log_replays_in_bounded_memory() {
    let dir = common::tempdir("hour");
    let log = dir.join("hour.log");
    let mut text = String::with_capacity(40_000 * 200);
    for i in 0..36_000 {
        epoch(&mut text, "010126", 36_000.0 + f64::from(i) * 0.1);
    }
    let mut file_text = String::new();
    let _ = writeln!(file_text, "# one hour at 10 Hz");
    file_text.push_str(&text);
    std::fs::write(&log, &file_text).expect("log written");
    let (m, stdout) = replay_measured(&log, &[]);
    assert_eq!(m.code, Some(0), "{}", m.stderr);
    let lines = stdout.lines().count();
    println!(
        "a 1-hour 10 Hz log ({:.1} MB): peak RSS {:.1} MB, {lines} lines",
        file_text.len() as f64 / 1e6,
        m.peak_rss as f64 / 1e6,
    );
    assert!((35_990..=36_010).contains(&lines), "{lines} lines");
    assert!(m.peak_rss < RSS_LIMIT, "peak RSS {} bytes", m.peak_rss);
    assert!(!m.stderr.contains("clock jumps"), "{}", m.stderr);
    std::fs::remove_dir_all(&dir).ok();
}

/// `chassisd bench replay` on the shared receiver logs, kept small: every input (the
/// concatenation, then each receiver) is replayed and compared with gpsdecode, and peak
/// memory does not grow with the log's length. Figures only; no speed is asserted here
/// (the README reports the 70 MB run).
#[test]
fn bench_replay_compares_every_receiver_with_gpsdecode() {
    let out = Command::new(common::chassisd())
        .args([
            "bench",
            "replay",
            "--megabytes",
            "3",
            "--runs",
            "1",
            "--data",
        ])
        .arg(common::shared_gnss_dir())
        .output()
        .expect("chassisd runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let report: serde_json::Value =
        serde_json::from_str(stdout.lines().last().unwrap_or_default()).expect("JSON last line");
    println!("{stdout}");
    let inputs = report["inputs"].as_array().expect("inputs");
    // Every log with gpsd's decode: NMEA, UBX only, or both.
    assert_eq!(
        inputs.len(),
        common::shared_gnss_logs().len() + common::shared_binary_gnss_logs().len() + 1,
        "{report}"
    );
    assert_eq!(inputs[0]["input"], "all");
    assert!(report["gpsdecode_missing"].is_null(), "{report}");
    for input in inputs {
        assert!(input["bytes"].as_u64() >= Some(3_000_000), "{input}");
        assert!(
            input["speedup"].as_f64().is_some_and(|s| s > 0.0),
            "{input}"
        );
        assert!(input["chassisd_peak_bytes"].as_u64().is_some(), "{input}");
    }
    let full = inputs[0]["chassisd_peak_bytes"].as_u64().unwrap();
    let tenth = report["tenth_peak_bytes"].as_u64().expect("tenth's peak");
    assert!(
        full <= tenth + 2_000_000,
        "peak {full} vs {tenth} on a tenth"
    );
}
