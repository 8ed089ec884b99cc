//! Trajectories of the `rtk` dialect: their JSON, their checks, and where they are kept — a
//! folder of one file per trajectory, written atomically (temporary file, fsync, rename,
//! fsync of the folder), so a crash at any moment leaves the old file or the new one.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Longest trajectory name, bytes.
pub const MAX_NAME_BYTES: usize = 64;
/// Most points in one trajectory.
pub const MAX_POINTS: usize = 100_000;
/// Suffix of trajectory files.
const SUFFIX: &str = ".json";
/// Marks a temporary file of an atomic write (followed by the writer's process id).
const TEMP_MARK: &str = ".tmp-";

/// One point, as `save_trajectory` sends it and `trajectory_data` returns it.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Point {
    /// Heading, degrees (0 = north, clockwise).
    pub angle: f64,
    /// Latitude, degrees.
    pub latitude: f64,
    /// Longitude, degrees.
    pub longitude: f64,
    /// Local x, m.
    pub x: f64,
    /// Local y, m.
    pub y: f64,
    /// Local yaw, rad.
    pub yaw: f64,
    /// Local z, m (`trajectory_data` has it; `save_trajectory` may leave it out).
    #[serde(default)]
    pub z: f64,
}

/// A named trajectory.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Trajectory {
    /// Points in driving order.
    pub data: Vec<Point>,
    /// Name.
    pub name: String,
}

/// Why a trajectory or a store operation was refused.
#[derive(Debug, thiserror::Error)]
pub enum TrajectoryError {
    /// A bad name.
    #[error("trajectory name {0:?} is not allowed: {1}")]
    Name(String, &'static str),
    /// A bad point.
    #[error("point {index}: {problem}")]
    Point {
        /// Index in `data`.
        index: usize,
        /// What is wrong.
        problem: String,
    },
    /// Too many points.
    #[error("{0} points exceed the limit of {MAX_POINTS}")]
    TooManyPoints(usize),
    /// No points.
    #[error("a trajectory needs at least one point")]
    Empty,
    /// Not there.
    #[error("no trajectory named {0:?}")]
    NotFound(String),
    /// The storage failed.
    #[error("storage: {0}")]
    Io(#[from] std::io::Error),
    /// The storage queue is full.
    #[error("trajectory storage is busy writing earlier changes; try again")]
    Busy,
    /// The store holds its limit of points.
    #[error(
        "trajectory storage is full: {stored} points stored, limit {limit}; delete trajectories first"
    )]
    StoreFull {
        /// Points stored (besides the one being replaced).
        stored: usize,
        /// The limit.
        limit: usize,
    },
    /// The store holds its limit of trajectories.
    #[error("trajectory storage is full: {0} trajectories stored; delete some first")]
    TooManyTrajectories(usize),
    /// No storage is configured.
    #[error("trajectory storage is not configured (set mqtt.rtk.trajectory_dir)")]
    Unconfigured,
}

/// A name as stored: in Unicode NFC (the same letters typed on any system are one name),
/// then checked.
pub fn canonical_name(name: &str) -> Result<String, TrajectoryError> {
    use unicode_normalization::UnicodeNormalization;
    let nfc: String = name.nfc().collect();
    check_name(&nfc)?;
    Ok(nfc)
}

/// Checks a name: it becomes a file name, so no separators, no dot files, no control
/// characters, and a bounded length; and it reads as what it is: NFC, no invisible
/// characters, no white space at either end.
pub fn check_name(name: &str) -> Result<(), TrajectoryError> {
    let bad = |why| Err(TrajectoryError::Name(name.to_owned(), why));
    if name.is_empty() {
        return bad("it is empty");
    }
    if name.starts_with(char::is_whitespace) || name.ends_with(char::is_whitespace) {
        return bad("it begins or ends with white space");
    }
    if name.chars().any(is_invisible) {
        return bad(
            "it contains an invisible character (a zero-width space, a byte-order mark, a \
             joiner, a soft hyphen)",
        );
    }
    if !unicode_normalization::is_nfc(name) {
        return bad("it is not in Unicode NFC (write accented letters as single characters)");
    }
    if name.len() > MAX_NAME_BYTES {
        return bad("it is longer than 64 bytes");
    }
    if name.contains(['/', '\\']) || name.contains("..") {
        return bad("it contains a path separator or \"..\"");
    }
    if name.starts_with('.') || name.chars().any(char::is_control) {
        return bad("it starts with a dot or contains a control character");
    }
    if name.chars().any(is_bidi_control) {
        return bad(
            "it contains a bidirectional-text control character (U+202A-U+202E, U+2066-U+2069)",
        );
    }
    Ok(())
}

/// Unicode's default-ignorable code points: nothing shows where they stand, so two names
/// that differ by one look the same.
fn is_invisible(c: char) -> bool {
    matches!(c,
        '\u{00AD}' | '\u{034F}' | '\u{061C}' | '\u{115F}'..='\u{1160}' | '\u{17B4}'..='\u{17B5}'
        | '\u{180B}'..='\u{180F}' | '\u{200B}'..='\u{200F}' | '\u{2060}'..='\u{206F}'
        | '\u{3164}' | '\u{FE00}'..='\u{FE0F}' | '\u{FEFF}' | '\u{FFA0}' | '\u{FFF0}'..='\u{FFF8}'
        | '\u{1BCA0}'..='\u{1BCA3}' | '\u{1D173}'..='\u{1D17A}' | '\u{E0000}'..='\u{E0FFF}')
}

/// The bidirectional embedding, override and isolate controls: they make a name display
/// differently from what it is (a list or a log line that reads backwards).
fn is_bidi_control(c: char) -> bool {
    matches!(c, '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}')
}

impl Trajectory {
    /// Checks the name, the point count and every value.
    pub fn check(&self) -> Result<(), TrajectoryError> {
        check_name(&self.name)?;
        if self.data.is_empty() {
            return Err(TrajectoryError::Empty);
        }
        if self.data.len() > MAX_POINTS {
            return Err(TrajectoryError::TooManyPoints(self.data.len()));
        }
        for (index, p) in self.data.iter().enumerate() {
            let problem = if ![p.angle, p.latitude, p.longitude, p.x, p.y, p.yaw, p.z]
                .iter()
                .all(|v| v.is_finite())
            {
                Some("values must be finite numbers".to_owned())
            } else if !(-90.0..=90.0).contains(&p.latitude) {
                Some(format!("latitude {} is outside ±90°", p.latitude))
            } else if !(-180.0..=180.0).contains(&p.longitude) {
                Some(format!("longitude {} is outside ±180°", p.longitude))
            } else {
                None
            };
            if let Some(problem) = problem {
                return Err(TrajectoryError::Point { index, problem });
            }
        }
        Ok(())
    }
}

/// Where trajectories are kept.
pub trait TrajectoryStore: Send {
    /// Every readable trajectory, by name.
    fn all(&mut self) -> Result<Vec<Trajectory>, TrajectoryError>;
    /// The trajectory named `name`.
    fn get(&mut self, name: &str) -> Result<Trajectory, TrajectoryError> {
        self.all()?
            .into_iter()
            .find(|t| t.name == name)
            .ok_or_else(|| TrajectoryError::NotFound(name.to_owned()))
    }
    /// Saves (replaces) a checked trajectory.
    fn save(&mut self, trajectory: &Trajectory) -> Result<(), TrajectoryError>;
    /// Deletes one.
    fn delete(&mut self, name: &str) -> Result<(), TrajectoryError>;
    /// Deletes every one; returns how many.
    fn delete_all(&mut self) -> Result<usize, TrajectoryError>;
    /// Changes answered as done whose writing to storage failed since the last call (a
    /// store that writes later, off the control task, learns of a full disk after its
    /// answer): the dialect tells the client that asked.
    fn failed_writes(&mut self) -> Vec<FailedWrite> {
        Vec::new()
    }
}

/// A change whose success was answered, then failed to reach storage.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FailedWrite {
    /// The command that made it (`save_trajectory`, `delete_trajectory`,
    /// `delete_all_trajectory`).
    pub command: &'static str,
    /// What it changed: a trajectory's name, or every trajectory.
    pub what: String,
    /// Why the write failed.
    pub reason: String,
}

/// No storage configured: every operation is refused, saying how to configure it.
#[derive(Debug, Clone, Copy, Default)]
pub struct Unconfigured;

impl TrajectoryStore for Unconfigured {
    fn all(&mut self) -> Result<Vec<Trajectory>, TrajectoryError> {
        Err(TrajectoryError::Unconfigured)
    }

    fn save(&mut self, _: &Trajectory) -> Result<(), TrajectoryError> {
        Err(TrajectoryError::Unconfigured)
    }

    fn delete(&mut self, _: &str) -> Result<(), TrajectoryError> {
        Err(TrajectoryError::Unconfigured)
    }

    fn delete_all(&mut self) -> Result<usize, TrajectoryError> {
        Err(TrajectoryError::Unconfigured)
    }
}

/// Trajectories in memory (replay, tests).
#[derive(Debug, Clone, Default)]
pub struct MemoryStore {
    trajectories: BTreeMap<String, Trajectory>,
}

impl MemoryStore {
    /// A store holding `trajectories`.
    pub fn with(trajectories: Vec<Trajectory>) -> Self {
        Self {
            trajectories: trajectories
                .into_iter()
                .map(|t| (t.name.clone(), t))
                .collect(),
        }
    }

    /// The trajectory named `name`.
    pub fn get(&self, name: &str) -> Option<&Trajectory> {
        self.trajectories.get(name)
    }

    /// How many trajectories it holds.
    pub fn len(&self) -> usize {
        self.trajectories.len()
    }

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.trajectories.is_empty()
    }
}

impl TrajectoryStore for MemoryStore {
    fn all(&mut self) -> Result<Vec<Trajectory>, TrajectoryError> {
        Ok(self.trajectories.values().cloned().collect())
    }

    fn get(&mut self, name: &str) -> Result<Trajectory, TrajectoryError> {
        self.trajectories
            .get(name)
            .cloned()
            .ok_or_else(|| TrajectoryError::NotFound(name.to_owned()))
    }

    fn save(&mut self, trajectory: &Trajectory) -> Result<(), TrajectoryError> {
        self.trajectories
            .insert(trajectory.name.clone(), trajectory.clone());
        Ok(())
    }

    fn delete(&mut self, name: &str) -> Result<(), TrajectoryError> {
        self.trajectories
            .remove(name)
            .map(|_| ())
            .ok_or_else(|| TrajectoryError::NotFound(name.to_owned()))
    }

    fn delete_all(&mut self) -> Result<usize, TrajectoryError> {
        let n = self.trajectories.len();
        self.trajectories.clear();
        Ok(n)
    }
}

/// Trajectories in a folder, one `<name>.json` each.
#[derive(Debug, Clone)]
pub struct DirStore {
    dir: PathBuf,
    corrupt_reported: std::collections::BTreeSet<PathBuf>,
}

impl DirStore {
    /// A store in `dir`, created if missing. Temporary files a crash left behind are removed.
    pub fn open(dir: &Path) -> Result<Self, TrajectoryError> {
        std::fs::create_dir_all(dir)?;
        for entry in std::fs::read_dir(dir)?.filter_map(Result::ok) {
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if name.starts_with('.') && name.contains(TEMP_MARK) {
                tracing::info!(file = %name, "removing a trajectory write interrupted by a crash");
                std::fs::remove_file(entry.path())?;
            }
        }
        Ok(Self {
            dir: dir.to_owned(),
            corrupt_reported: Default::default(),
        })
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.join(format!("{name}{SUFFIX}"))
    }

    /// Reads every trajectory file; a corrupt one is reported once and skipped.
    fn read_all(&mut self) -> Result<Vec<Trajectory>, TrajectoryError> {
        let mut out = Vec::new();
        let mut entries: Vec<PathBuf> = std::fs::read_dir(&self.dir)?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.ends_with(SUFFIX) && !n.starts_with('.'))
            })
            .collect();
        entries.sort();
        for path in entries {
            let parsed = std::fs::read(&path)
                .map_err(|e| e.to_string())
                .and_then(|bytes| {
                    serde_json::from_slice::<Trajectory>(&bytes).map_err(|e| e.to_string())
                })
                .and_then(|t| t.check().map(|()| t).map_err(|e| e.to_string()));
            match parsed {
                Ok(t) => out.push(t),
                Err(e) => {
                    if self.corrupt_reported.insert(path.clone()) {
                        tracing::error!(file = %path.display(), error = %e, "trajectory file is corrupt; skipped");
                    }
                }
            }
        }
        Ok(out)
    }
}

impl TrajectoryStore for DirStore {
    fn all(&mut self) -> Result<Vec<Trajectory>, TrajectoryError> {
        self.read_all()
    }

    fn get(&mut self, name: &str) -> Result<Trajectory, TrajectoryError> {
        check_name(name)?;
        let path = self.path(name);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(TrajectoryError::NotFound(name.to_owned()));
            }
            Err(e) => return Err(e.into()),
        };
        let t: Trajectory = serde_json::from_slice(&bytes)
            .map_err(|e| std::io::Error::other(format!("{} is corrupt: {e}", path.display())))?;
        t.check()?;
        Ok(t)
    }

    fn save(&mut self, trajectory: &Trajectory) -> Result<(), TrajectoryError> {
        let bytes = serde_json::to_vec(trajectory).map_err(std::io::Error::other)?;
        write_atomically(&self.dir, &self.path(&trajectory.name), &bytes)?;
        Ok(())
    }

    fn delete(&mut self, name: &str) -> Result<(), TrajectoryError> {
        match std::fs::remove_file(self.path(name)) {
            Ok(()) => {
                sync_dir(&self.dir)?;
                Ok(())
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                Err(TrajectoryError::NotFound(name.to_owned()))
            }
            Err(e) => Err(e.into()),
        }
    }

    fn delete_all(&mut self) -> Result<usize, TrajectoryError> {
        let mut n = 0;
        for entry in std::fs::read_dir(&self.dir)? {
            let path = entry?.path();
            if path
                .file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.ends_with(SUFFIX) && !n.starts_with('.'))
            {
                std::fs::remove_file(&path)?;
                n += 1;
            }
        }
        sync_dir(&self.dir)?;
        Ok(n)
    }
}

/// Writes `bytes` to `path` so that a crash leaves either the old file or the new one:
/// a temporary file in the same folder, fsync, rename over `path`, fsync of the folder.
pub fn write_atomically(dir: &Path, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let temp = dir.join(format!(".{name}{TEMP_MARK}{}", std::process::id()));
    let result = (|| {
        let mut file = std::fs::File::create(&temp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&temp, path)?;
        sync_dir(dir)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&temp);
    }
    result
}

fn sync_dir(dir: &Path) -> std::io::Result<()> {
    std::fs::File::open(dir)?.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point() -> Point {
        Point {
            angle: 30.0,
            latitude: 23.04934955,
            longitude: 113.2222333,
            x: 1.0,
            y: 2.0,
            yaw: 0.5,
            z: 0.0,
        }
    }

    #[test]
    fn names_that_could_escape_the_folder_are_refused() {
        for bad in [
            "",
            "../x",
            "a/b",
            "a\\b",
            ".hidden",
            "x..y",
            "a\nb",
            &"n".repeat(65),
            "lawn\u{202E}1.txt",
            "\u{2066}north\u{2069}",
            "\u{200B}",
            "\u{FEFF}",
            " ",
            " lawn",
            "lawn ",
            "law\u{200D}n",
            "cafe\u{301}",
        ] {
            assert!(check_name(bad).is_err(), "{bad:?}");
        }
        // The same letters, composed or not, are one name.
        assert_eq!(canonical_name("cafe\u{301}").unwrap(), "caf\u{E9}");
        assert_eq!(canonical_name("caf\u{E9}").unwrap(), "caf\u{E9}");
        assert!(canonical_name("\u{200B}").is_err());
        for good in ["test5", "13", "北区", "lawn 1"] {
            assert!(check_name(good).is_ok(), "{good:?}");
        }
    }

    #[test]
    fn out_of_range_points_are_refused() {
        let mut t = Trajectory {
            name: "t".into(),
            data: vec![point()],
        };
        assert!(t.check().is_ok());
        t.data[0].longitude = 188.2222333;
        assert!(matches!(
            t.check(),
            Err(TrajectoryError::Point { index: 0, .. })
        ));
        t.data[0].longitude = f64::NAN;
        assert!(t.check().is_err());
        t.data.clear();
        assert!(matches!(t.check(), Err(TrajectoryError::Empty)));
    }

    #[test]
    fn a_folder_store_saves_lists_and_skips_corrupt_files() {
        let dir = std::env::temp_dir().join(format!("chassisd-traj-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut store = DirStore::open(&dir).expect("store");
        let t = Trajectory {
            name: "a".into(),
            data: vec![point(), point()],
        };
        store.save(&t).expect("save");
        std::fs::write(dir.join("broken.json"), b"{\"name\":").expect("write");
        assert_eq!(store.all().expect("list"), vec![t.clone()]);
        assert!(matches!(
            store.delete("zzz"),
            Err(TrajectoryError::NotFound(_))
        ));
        store.delete("a").expect("delete");
        assert_eq!(store.all().expect("list"), vec![]);
        // No temporary files are left behind.
        let left: Vec<_> = std::fs::read_dir(&dir)
            .expect("dir")
            .filter_map(Result::ok)
            .map(|e| e.file_name())
            .collect();
        assert_eq!(left, vec![std::ffi::OsString::from("broken.json")]);
        std::fs::remove_dir_all(&dir).ok();
    }
}
