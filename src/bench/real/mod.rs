//! `chassisd bench real`: every real vehicle's recording in the shared data (`ekf/`) turned
//! into a chassisd recording and replayed through the whole core, each figure beside its
//! target and the naive dead reckoning's. The test of every change to the fusion filter: a
//! change holds only when it holds on every vehicle at once.
//!
//! - `husky-test1`: a Husky's SBAS fixes at 2.5 Hz, wheels and gyro, 395 s; once as
//!   recorded (GGA only) and once with a course and speed in RMC made from the fixes, as a
//!   receiver without Doppler makes them (noisy at 1 m/s).
//! - `comma2k19-rav4`: a car's u-blox single fixes at 10 Hz with the receiver's own speed
//!   and course, rear wheel speeds and a gyro, 60 s at 8–20 m/s, scored against the
//!   dataset's reference pose.
//! - `jackal-test2`: a Jackal's wheels and gyro without GNSS, against the upstream filter's
//!   final position.

pub mod comma2k19;
pub mod data;
pub mod husky_test1;
pub mod jackal_test2;
pub mod recording;

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::bench::error::{BenchError, Result, invalid};

/// One figure of one vehicle, beside its target.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Figure {
    /// The vehicle (the data's folder, and the variant).
    pub vehicle: String,
    /// What is measured.
    pub name: String,
    /// chassisd's figure.
    pub value: f64,
    /// The largest value that passes.
    pub target: f64,
    /// The naive dead reckoning's figure, where there is one.
    pub naive: Option<f64>,
    /// The unit.
    pub unit: &'static str,
}

impl Figure {
    /// Whether it meets its target.
    pub fn pass(&self) -> bool {
        self.value <= self.target
    }
}

/// Every vehicle's figures.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Table {
    /// The figures, vehicle by vehicle.
    pub figures: Vec<Figure>,
}

impl Table {
    /// Whether every figure meets its target.
    pub fn pass(&self) -> bool {
        !self.figures.is_empty() && self.figures.iter().all(Figure::pass)
    }
}

impl std::fmt::Display for Table {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "| vehicle | figure | chassisd | target | naive | |")?;
        writeln!(f, "|---|---|---|---|---|---|")?;
        for x in &self.figures {
            let value = |v: f64| match x.unit {
                "m" | "rad" if v.abs() < 0.01 && v != 0.0 => format!("{v:.1e} {}", x.unit),
                "m" => format!("{v:.3} m"),
                unit => format!("{v:.1} {unit}"),
            };
            writeln!(
                f,
                "| {} | {} | {} | ≤ {} | {} | {} |",
                x.vehicle,
                x.name,
                value(x.value),
                value(x.target),
                x.naive.map_or("".into(), value),
                if x.pass() { "ok" } else { "MISSED" }
            )?;
        }
        Ok(())
    }
}

/// A folder of its own for one replay's recording, removed when dropped.
pub struct Scratch(PathBuf);

impl Scratch {
    /// A new empty folder under the system's temporary one.
    pub fn new(name: &str) -> Result<Self> {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let dir = std::env::temp_dir().join(format!(
            "chassisd-real-{name}-{}-{nanos}",
            std::process::id()
        ));
        std::fs::create_dir_all(&dir).map_err(invalid(format!("creating {}", dir.display())))?;
        Ok(Self(dir))
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Runs `jobs` on up to `workers` threads; their results in order.
pub fn parallel<T: Send>(workers: usize, jobs: Vec<Box<dyn FnOnce() -> T + Send + '_>>) -> Vec<T> {
    let next = std::sync::Mutex::new(jobs.into_iter().enumerate());
    let results = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..workers.max(1) {
            scope.spawn(|| {
                loop {
                    let job = next.lock().map(|mut j| j.next());
                    let Ok(Some((i, job))) = job else { return };
                    let out = job();
                    if let Ok(mut r) = results.lock() {
                        r.push((i, out));
                    }
                }
            });
        }
    });
    let mut results = results.into_inner().unwrap_or_default();
    results.sort_by_key(|(i, _)| *i);
    results.into_iter().map(|(_, r)| r).collect()
}

/// How `bench real` runs.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// Replays run on this many threads.
    pub workers: usize,
    /// Each vehicle's whole run is written here as CSV (`<vehicle>.csv`), when given.
    pub trace: Option<PathBuf>,
}

impl Options {
    /// Where the trace of `name` goes, if traces are wanted.
    pub fn trace_file(&self, name: &str) -> Option<PathBuf> {
        self.trace
            .as_ref()
            .map(|dir| dir.join(format!("{}.csv", name.replace([' ', ','], "_"))))
    }
}

/// Every vehicle of `data` (the shared data's `ekf/` folder).
pub fn run(data: &Path, options: &Options) -> Result<Table> {
    let folder = |name: &str| {
        let dir = data.join(name);
        if dir.is_dir() {
            Ok(dir)
        } else {
            Err(BenchError::Failed(format!(
                "{} is missing: bench real needs the shared data's ekf/ folder (--data)",
                dir.display()
            )))
        }
    };
    let mut table = Table::default();
    if let Some(dir) = &options.trace {
        std::fs::create_dir_all(dir).map_err(invalid(format!("creating {}", dir.display())))?;
    }
    table.figures.extend(husky_test1::figures(
        &folder("husky-test1")?,
        husky_test1::Course::None,
        options,
    )?);
    table.figures.extend(husky_test1::figures(
        &folder("husky-test1")?,
        husky_test1::Course::FromFixes,
        options,
    )?);
    table
        .figures
        .extend(comma2k19::figures(&folder("comma2k19-rav4")?, options)?);
    table
        .figures
        .extend(jackal_test2::figures(&folder("jackal-test2")?)?);
    Ok(table)
}
