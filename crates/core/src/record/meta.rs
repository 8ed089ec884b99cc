//! `meta.toml`: names the sources of a recording and the configuration in force.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::RecordError;

/// Current recording format version.
pub const FORMAT_VERSION: u32 = 1;
/// Name of the metadata file in a recording folder.
pub const META_FILE: &str = "meta.toml";

/// How a source's file is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SourceKind {
    /// Serial chunks in the hex envelope.
    Serial,
    /// CAN frames in `candump -L` format.
    Can,
    /// Received commands.
    Commands,
}

/// One source of a recording.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceMeta {
    /// Source name as it appears in the lines (`gnss`, `can0`, `mqtt`).
    pub name: String,
    /// File format.
    pub kind: SourceKind,
    /// File name inside the recording folder.
    pub file: String,
    /// Wire protocol, e.g. `nmea0183`, so replay picks the right decoder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub protocol: Option<String>,
    /// File (inside the folder) of the source's link events (`!link-up`, `!link-down` in the
    /// envelope), for CAN sources: their `candump -L` file has no way to hold them. The
    /// writer names it when the source is created.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub events: Option<String>,
}

impl SourceMeta {
    /// A serial device's source, `<name>.log`, read with `protocol`.
    pub fn serial(name: &str, protocol: &str) -> Self {
        Self::in_file(
            name,
            SourceKind::Serial,
            format!("{name}.log"),
            Some(protocol),
        )
    }

    /// A CAN interface's source, `<name>.log` (its events file is named on creation).
    pub fn can(name: &str) -> Self {
        Self::in_file(name, SourceKind::Can, format!("{name}.log"), None)
    }

    /// A command channel's source, in `file`.
    pub fn commands(name: &str, file: &str) -> Self {
        Self::in_file(name, SourceKind::Commands, file.to_owned(), None)
    }

    fn in_file(name: &str, kind: SourceKind, file: String, protocol: Option<&str>) -> Self {
        Self {
            name: name.to_owned(),
            kind,
            file,
            protocol: protocol.map(str::to_owned),
            events: None,
        }
    }

    /// The events file a CAN source gets: `can0.log` → `can0.events.log`.
    pub fn default_events_file(&self) -> Option<String> {
        (self.kind == SourceKind::Can).then(|| {
            let stem = self.file.strip_suffix(".log").unwrap_or(&self.file);
            format!("{stem}.events.log")
        })
    }
}

/// The contents of `meta.toml`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Meta {
    /// Format version, [`FORMAT_VERSION`].
    pub format: u32,
    /// Vehicle name from the configuration.
    pub vehicle: String,
    /// Record-clock time when the session started, microseconds since the Unix epoch. Replay
    /// starts its status ticks here, as the live session did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_us: Option<u64>,
    /// Record-clock time when the session ended cleanly; replay ticks up to here. Absent
    /// after a crash, when replay stops at the last record.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end_us: Option<u64>,
    /// File (inside the folder) holding a copy of the vehicle configuration in force.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vehicle_config: Option<String>,
    /// File (inside the folder) holding the stored trajectories at the session's start, so
    /// a replay answers trajectory commands as the live session did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectories: Option<String>,
    /// The sources.
    #[serde(default, rename = "source")]
    pub sources: Vec<SourceMeta>,
}

/// The largest `meta.toml` read, bytes (a few sources' lines; a thousand sources fit).
const MAX_META_BYTES: u64 = 1 << 20;

impl Meta {
    /// Reads and checks `dir/meta.toml`.
    pub fn load(dir: &Path) -> Result<Self, RecordError> {
        let path = dir.join(META_FILE);
        let text = match super::read_small(&path, MAX_META_BYTES) {
            Err(RecordError::Io { error, .. })
                if error.kind() == std::io::ErrorKind::NotFound && dir.is_dir() =>
            {
                return Err(RecordError::Meta {
                    path: dir.to_path_buf(),
                    message: format!(
                        "not a recording: no {META_FILE} in this folder (`chassisd record` \
                         writes one; a plain receiver log is a file: give its path)"
                    ),
                });
            }
            other => other?,
        };
        let meta: Meta = toml::from_str(&text).map_err(|e| RecordError::Meta {
            path: path.clone(),
            message: e.to_string(),
        })?;
        meta.check()
            .map_err(|message| RecordError::Meta { path, message })?;
        Ok(meta)
    }

    /// Checks the version and that file names stay inside the folder.
    pub fn check(&self) -> Result<(), String> {
        if self.format != FORMAT_VERSION {
            return Err(format!(
                "key `format`: version {} is not supported (this build reads {FORMAT_VERSION})",
                self.format
            ));
        }
        let files = self
            .sources
            .iter()
            .map(|s| ("source.file", &s.file))
            .chain(
                self.sources
                    .iter()
                    .filter_map(|s| s.events.as_ref().map(|f| ("source.events", f))),
            )
            .chain(self.vehicle_config.iter().map(|f| ("vehicle_config", f)))
            .chain(self.trajectories.iter().map(|f| ("trajectories", f)));
        for (key, file) in files {
            if !is_plain_file_name(file) {
                return Err(format!(
                    "key `{key}`: {file:?} must be a plain file name inside the recording folder"
                ));
            }
        }
        for s in &self.sources {
            if s.name.is_empty() || s.name.contains(char::is_whitespace) {
                return Err(format!(
                    "key `source.name`: {:?} must be non-empty without spaces",
                    s.name
                ));
            }
        }
        Ok(())
    }

    /// The TOML text of this meta.
    pub fn to_toml(&self) -> String {
        // Plain strings, numbers and enums always serialise.
        toml::to_string(self).unwrap_or_default()
    }

    /// Writes `dir/meta.toml` atomically (temporary file, then rename), so a crash leaves
    /// the old or the new file, never a partial one.
    pub fn store(&self, dir: &Path) -> std::io::Result<()> {
        let tmp = dir.join(".meta.toml.tmp");
        std::fs::write(&tmp, self.to_toml())?;
        std::fs::File::open(&tmp)?.sync_all()?;
        std::fs::rename(&tmp, dir.join(META_FILE))
    }
}

fn is_plain_file_name(name: &str) -> bool {
    !name.is_empty() && name != "." && name != ".." && !name.contains(['/', '\\', '\0'])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta() -> Meta {
        Meta {
            format: FORMAT_VERSION,
            vehicle: "m1".into(),
            start_us: Some(1_700_000_000_000_000),
            end_us: None,
            vehicle_config: Some("vehicle.toml".into()),
            trajectories: None,
            sources: vec![SourceMeta {
                name: "gnss".into(),
                kind: SourceKind::Serial,
                file: "gnss.log".into(),
                protocol: Some("nmea0183".into()),
                events: None,
            }],
        }
    }

    #[test]
    fn round_trips_through_toml() {
        let m = meta();
        let back: Meta = toml::from_str(&m.to_toml()).unwrap();
        assert_eq!(back, m);
    }

    #[test]
    fn rejects_paths_outside_the_folder_and_other_versions() {
        let mut m = meta();
        m.sources[0].file = "../etc/passwd".into();
        assert!(m.check().unwrap_err().contains("source.file"));
        let mut m = meta();
        m.format = 99;
        assert!(m.check().unwrap_err().contains("format"));
    }
}
