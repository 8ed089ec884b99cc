//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses a different subset

pub mod canbus;
pub mod caster;
pub mod lockstep;
pub mod mqtt;
pub mod netcut;
pub mod netns;
pub mod process;
pub mod pty;
pub mod spec;
pub mod ws;
pub mod zones;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `chassisd replay PATH`, which must succeed.
pub fn replay(path: &Path) -> Output {
    replay_with(&[], path)
}

/// `chassisd check --config DIR/vehicle.toml ARGS` with `config` written there: the exit
/// status, and stdout and stderr together.
pub fn check(config: &str, dir: &Path, args: &[&str]) -> (Option<i32>, String) {
    let path = dir.join("vehicle.toml");
    std::fs::write(&path, config).expect("config");
    let out = Command::new(chassisd())
        .args(["check", "--config"])
        .arg(&path)
        .args(args)
        .output()
        .expect("chassisd runs");
    (
        out.status.code(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ),
    )
}

/// `chassisd replay OPTIONS PATH`, which must succeed.
fn replay_with(options: &[&str], path: &Path) -> Output {
    let out = Command::new(chassisd())
        .arg("replay")
        .args(options)
        .arg(path)
        .output()
        .expect("chassisd runs");
    assert!(
        out.status.success(),
        "replay {options:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A folder of the shared data (`../shared/data/SUB` beside the checkout, or
/// `$CHASSISD_SHARED_DATA/SUB`). Panics when missing: CI must fail, not skip.
pub fn shared_data(sub: &str) -> PathBuf {
    let base = std::env::var_os("CHASSISD_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let dir = base.join(sub);
    assert!(
        dir.is_dir(),
        "{} is missing: the tests need the shared data (set CHASSISD_SHARED_DATA)",
        dir.display()
    );
    dir
}

/// The shared receiver logs (`../shared/data/gnss` beside the checkout, or
/// `$CHASSISD_SHARED_DATA/gnss`). Panics when missing: CI must fail, not skip.
pub fn shared_gnss_dir() -> PathBuf {
    let base = std::env::var_os("CHASSISD_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let dir = base.join("gnss");
    assert!(
        dir.is_dir(),
        "{} is missing: the GNSS tests need the shared receiver logs (set CHASSISD_SHARED_DATA)",
        dir.display()
    );
    dir
}

/// The shared receiver logs with gpsd's decoding beside them (`X.log` with `X.log.chk`),
/// sorted; `nmea` picks those whose receiver sends NMEA positions (a GGA, RMC or GNS
/// sentence), or those that hold none (binary protocols only: u-blox UBX, which issue 49
/// brings). The Unicore capture, one sentence of each kind rather than a log, has no `.chk`.
fn shared_logs_with_chk(nmea: bool) -> Vec<PathBuf> {
    let dir = shared_gnss_dir();
    let mut logs: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("readable shared data folder")
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "log"))
        .filter(|p| p.with_extension("log.chk").is_file())
        .filter(|p| {
            let bytes = std::fs::read(p).expect("readable log");
            chassisd::bench::replay::sends_nmea_positions(&bytes) == nmea
        })
        .collect();
    logs.sort();
    assert!(!logs.is_empty(), "no such *.log files in {}", dir.display());
    logs
}

/// The shared receiver logs whose receivers send NMEA, with gpsd's decoding beside them.
pub fn shared_gnss_logs() -> Vec<PathBuf> {
    shared_logs_with_chk(true)
}

/// The shared receiver logs in binary protocols only, with gpsd's decoding beside them.
pub fn shared_binary_gnss_logs() -> Vec<PathBuf> {
    shared_logs_with_chk(false)
}

/// Path of the chassisd binary under test.
pub fn chassisd() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_chassisd"))
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The Python of the test environment, with the PyPI packages tests/install-deps pins there
/// (roslibpy, cyclonedds, rosbags, mcap, ...).
pub fn venv_python() -> PathBuf {
    let python = repo().join("target/test-venv/bin/python");
    assert!(
        python.exists(),
        "{} is missing: tests/install-deps builds the test environment there",
        python.display()
    );
    python
}

/// A new empty folder under the system temp dir, unique to this process and call.
pub fn tempdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "chassisd-{name}-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .expect("clock after 1970")
            .as_nanos()
    ));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// `chassisd replay --lenient PATH`, which must succeed (transmissions may differ).
pub fn replay_lenient(path: &Path) -> Output {
    replay_with(&["--lenient"], path)
}

/// A recording's records through the library's engine, built from the configuration the
/// recording holds and started where it starts; with `check_transmissions` the recorded
/// transmissions are compared with the engine's, as `chassisd replay` does, instead of being
/// taken as records. `each` sees the time the engine used for each record and the outputs
/// it caused. Returns the engine after the records.
pub fn through_engine(
    dir: &Path,
    check_transmissions: bool,
    each: impl FnMut(chassisd::time::Timestamp, &mut Vec<chassisd::engine::EngineOutput>),
) -> (chassisd::engine::Engine, chassisd::record::Meta) {
    records_through_engine(dir, check_transmissions, false, each)
}

/// A recording through the library's engine as `chassisd replay` takes it: its serial
/// sources decoded by their recorded protocol, its transmissions compared. `each` sees the
/// time of each record and the outputs it caused.
pub fn as_replayed(
    dir: &Path,
    each: impl FnMut(chassisd::time::Timestamp, &mut Vec<chassisd::engine::EngineOutput>),
) -> (chassisd::engine::Engine, chassisd::record::Meta) {
    records_through_engine(dir, true, true, each)
}

fn records_through_engine(
    dir: &Path,
    check_transmissions: bool,
    decode_serial: bool,
    mut each: impl FnMut(chassisd::time::Timestamp, &mut Vec<chassisd::engine::EngineOutput>),
) -> (chassisd::engine::Engine, chassisd::record::Meta) {
    use chassisd::config::VehicleConfig;
    use chassisd::engine::{Decoder, Engine};
    use chassisd::record::RecordingReader;
    use chassisd::time::Timestamp;

    let (meta, reader) = RecordingReader::open(dir).expect("recording opens");
    let file = meta
        .vehicle_config
        .as_deref()
        .expect("recording holds its configuration");
    let config = VehicleConfig::load(&dir.join(file)).expect("stored configuration loads");
    let decoders = if decode_serial {
        Decoder::of_recording(&meta)
    } else {
        Vec::new()
    };
    let mut engine = Engine::new(&config, &decoders);
    if check_transmissions {
        engine.check_recorded_transmissions();
    }
    if let Some(start) = meta.start_us {
        engine.start_at(Timestamp::from_micros(start));
    }
    let mut out = Vec::new();
    for record in reader {
        let t = engine.handle(&record, &mut out);
        each(t, &mut out);
    }
    (engine, meta)
}

/// Replays a recording through the library's engine and returns the drive train's wheel
/// odometry at its end.
pub fn replay_odometry(dir: &Path) -> chassisd::vehicle::chassis::WheelOdometry {
    use chassisd::engine::EngineOutput;
    use chassisd::time::Timestamp;

    let mut out = Vec::new();
    let (mut engine, meta) = through_engine(dir, true, |_, outputs| out.append(outputs));
    if let Some(end) = meta.end_us {
        engine.advance_to(Timestamp::from_micros(end), &mut out);
    }
    out.iter()
        .rev()
        .find_map(|o| match o {
            EngineOutput::Status(s) => s.chassis.as_ref().map(|c| c.odometry),
            _ => None,
        })
        .expect("a status with the drive train")
}

/// A protocol document of `../shared/spec/` (or `$CHASSISD_SHARED_SPEC`).
pub fn shared_spec(file: &str) -> String {
    let base = std::env::var_os("CHASSISD_SHARED_SPEC")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/spec"));
    let path = base.join(file);
    std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e}; the protocol tests need the shared specs (set CHASSISD_SHARED_SPEC)",
            path.display()
        )
    })
}

/// Resident memory of `pid` and its children (the embedded broker), kB.
pub fn rss_with_children_kb(pid: u32) -> u64 {
    let rss = |pid: u32| -> u64 {
        std::fs::read_to_string(format!("/proc/{pid}/status"))
            .ok()
            .and_then(|s| {
                s.lines()
                    .find_map(|l| l.strip_prefix("VmRSS:"))
                    .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            })
            .unwrap_or(0)
    };
    let children = std::process::Command::new("pgrep")
        .args(["-P", &pid.to_string()])
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default();
    rss(pid)
        + children
            .split_whitespace()
            .filter_map(|p| p.parse().ok())
            .map(rss)
            .sum::<u64>()
}

/// Runs `chassisd ARGS` (a `bench`), checks that its last line is JSON with `"pass": true`
/// and that it exited 0 (else fails naming `what`, with its output); that JSON.
pub fn passing_bench<S: AsRef<std::ffi::OsStr>>(args: &[S], what: &str) -> serde_json::Value {
    let out = std::process::Command::new(chassisd())
        .args(args)
        .output()
        .expect("chassisd runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last = stdout.lines().last().unwrap_or_default();
    let summary: serde_json::Value = serde_json::from_str(last).expect("last line is JSON");
    assert!(
        summary["pass"] == true && out.status.success(),
        "targets missed on {what}:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    summary
}

/// The connects in each second after `bench fleet`'s node kill, from its JSON summary.
pub fn connects_per_second(summary: &serde_json::Value) -> Vec<u64> {
    summary["failover"]["connects_per_second"]
        .as_array()
        .expect("the curve")
        .iter()
        .filter_map(serde_json::Value::as_u64)
        .collect()
}

/// How far the simulated vehicle went forward by random wheel slip alone (m), from `chassisd
/// sim`'s closing log line: motion no odometry sees, so no controller answers for it.
pub fn unseen_slip(log: &[String]) -> f64 {
    let summary = log
        .iter()
        .find(|l| l.contains("from the start"))
        .unwrap_or_else(|| panic!("no summary in {log:?}"));
    summary
        .split("heading ")
        .nth(1)
        .and_then(|s| s.split(", ").nth(1))
        .and_then(|s| s.split(" m of it random wheel slip").next())
        .unwrap_or_else(|| panic!("no unseen slip in {summary}"))
        .parse()
        .expect("a number")
}

/// Where the simulated vehicle truly ended (x, y, m), from `chassisd sim`'s closing log line.
pub fn truth_end(log: &[String]) -> (f64, f64) {
    let summary = log
        .iter()
        .find(|l| l.contains("from the start"))
        .unwrap_or_else(|| panic!("no summary in {log:?}"));
    let xy: Vec<f64> = summary
        .split("ending (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .unwrap_or_else(|| panic!("no ending (x, y) in {summary}"))
        .split(',')
        .map(|v| v.trim().parse().expect("a number"))
        .collect();
    (xy[0], xy[1])
}
