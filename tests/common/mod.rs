//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses a different subset

pub mod canbus;
pub mod lockstep;
pub mod mqtt;
pub mod netcut;
pub mod process;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `chassisd replay PATH`, which must succeed.
pub fn replay(path: &Path) -> Output {
    let out = Command::new(chassisd())
        .arg("replay")
        .arg(path)
        .output()
        .expect("chassisd runs");
    assert!(
        out.status.success(),
        "replay failed: {}",
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

/// Every `*.log` with a gpsd `.log.chk` beside it.
pub fn shared_gnss_logs() -> Vec<PathBuf> {
    let dir = shared_gnss_dir();
    let mut logs: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("readable shared data folder")
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "log"))
        .collect();
    logs.sort();
    assert!(!logs.is_empty(), "no *.log files in {}", dir.display());
    logs
}

/// Path of the chassisd binary under test.
pub fn chassisd() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_chassisd"))
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
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

/// Replays a recording through the library's engine and returns the drive train's wheel
/// odometry at its end.
pub fn replay_odometry(dir: &std::path::Path) -> chassisd::core::chassis::WheelOdometry {
    use chassisd::config::VehicleConfig;
    use chassisd::engine::{Engine, EngineOutput};
    use chassisd::record::RecordingReader;
    use chassisd::time::Timestamp;

    let (meta, reader) = RecordingReader::open(dir).expect("recording opens");
    let file = meta
        .vehicle_config
        .as_deref()
        .expect("recording holds its configuration");
    let config = VehicleConfig::load(&dir.join(file)).expect("stored configuration loads");
    let mut engine = Engine::new(&config, &[]);
    engine.check_recorded_transmissions();
    if let Some(start) = meta.start_us {
        engine.start_at(Timestamp::from_micros(start));
    }
    let mut out = Vec::new();
    for record in reader {
        engine.handle(&record, &mut out);
    }
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

/// Removes `//` comments outside strings, so a spec's annotated JSON parses.
pub fn strip_json_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let mut in_string = false;
        let mut escaped = false;
        let mut cut = line.len();
        let bytes = line.as_bytes();
        for (i, &b) in bytes.iter().enumerate() {
            match b {
                _ if escaped => escaped = false,
                b'\\' if in_string => escaped = true,
                b'"' => in_string = !in_string,
                b'/' if !in_string && bytes.get(i + 1) == Some(&b'/') => {
                    cut = i;
                    break;
                }
                _ => {}
            }
        }
        out.push_str(&line[..cut]);
        out.push('\n');
    }
    out
}

/// Every ```json block of a Markdown spec, comments removed, with the heading above it.
pub fn markdown_json_examples(text: &str) -> Vec<(String, serde_json::Value)> {
    let mut out = Vec::new();
    let mut heading = String::new();
    let mut block: Option<String> = None;
    for line in text.lines() {
        let trimmed = line.trim();
        match &mut block {
            Some(b) if trimmed.starts_with("```") => {
                let json = strip_json_comments(b);
                let value = serde_json::from_str(&json).unwrap_or_else(|e| {
                    panic!("example under {heading:?} does not parse: {e}\n{json}")
                });
                out.push((heading.clone(), value));
                block = None;
            }
            Some(b) => {
                b.push_str(line);
                b.push('\n');
            }
            None if trimmed.starts_with("```json") => block = Some(String::new()),
            None if trimmed.starts_with('#') => {
                heading = trimmed.trim_start_matches('#').trim().to_owned()
            }
            None => {}
        }
    }
    out
}

/// A JSON example of a reStructuredText spec, with the topic named above it.
#[derive(Debug, Clone)]
pub struct RstExample {
    /// The last `Topic` line before it, `${vehicleId}` replaced.
    pub topic: String,
    /// The block as written.
    pub text: String,
}

/// Every `.. code-block:: json` of root-mqtt-api.rst with its topic (`${vehicleId}` →
/// `vehicle_id`).
pub fn rst_json_examples(text: &str, vehicle_id: &str) -> Vec<RstExample> {
    let mut out = Vec::new();
    let mut topic = String::new();
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i].trim();
        if line.starts_with("/root/") {
            topic = line.replace("**", "").replace("${vehicleId}", vehicle_id);
        }
        if line.starts_with(".. code-block:: json") {
            let mut block = Vec::new();
            i += 1;
            // Blank lines, then the indented block.
            while i < lines.len() && lines[i].trim().is_empty() {
                i += 1;
            }
            let indent = lines.get(i).map_or(0, |l| l.len() - l.trim_start().len());
            while i < lines.len()
                && (lines[i].trim().is_empty()
                    || lines[i].len() - lines[i].trim_start().len() >= indent)
            {
                block.push(lines[i].trim_end());
                i += 1;
            }
            out.push(RstExample {
                topic: topic.clone(),
                text: block.join("\n").trim().to_owned(),
            });
            continue;
        }
        i += 1;
    }
    out
}
