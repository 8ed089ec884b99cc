//! Writes a recording folder: `meta.toml`, a copy of the vehicle configuration, and one
//! file per source.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use socketcan::dump::{CanDumpRecord, Direction};

use super::envelope;
use super::meta::{FORMAT_VERSION, META_FILE, Meta, SourceKind, SourceMeta};
use super::{Payload, Record, RecordError};
use crate::time::Timestamp;
use crate::vehicle::LinkState;

/// File name of the vehicle configuration copy.
pub const VEHICLE_CONFIG_FILE: &str = "vehicle.toml";
/// The file holding the trajectories at a session's start.
pub const TRAJECTORIES_FILE: &str = "trajectories.json";
/// The file holding the time every file was last flushed up to together (microseconds):
/// how far a recording whose writer was killed can be trusted.
pub const COVERED_FILE: &str = "covered";

/// An open recording folder.
pub struct RecordingWriter {
    dir: PathBuf,
    meta: Meta,
    sources: BTreeMap<String, SourceFiles>,
    covered: File,
    /// The latest record time written.
    latest: Option<Timestamp>,
    /// Bytes of records written (before buffering).
    written: u64,
    /// The time last noted in `covered`.
    noted: Option<Timestamp>,
}

impl RecordingWriter {
    /// Creates `dir` (which must not exist, or be empty), and writes `meta.toml` and the
    /// configuration copy. `sources` lists every source that may be written.
    pub fn create(
        dir: &Path,
        vehicle: &str,
        start: Timestamp,
        vehicle_config_toml: Option<&str>,
        mut sources: Vec<SourceMeta>,
    ) -> Result<Self, RecordError> {
        for s in &mut sources {
            if s.events.is_none() {
                s.events = s.default_events_file();
            }
        }
        let io = |path: &Path| {
            let path = path.to_owned();
            move |source| RecordError::Io {
                path,
                error: source,
            }
        };
        if dir.exists() {
            let mut entries = std::fs::read_dir(dir).map_err(io(dir))?;
            if entries.next().is_some() {
                return Err(RecordError::Io {
                    path: dir.to_owned(),
                    error: std::io::Error::new(
                        std::io::ErrorKind::AlreadyExists,
                        "recording folder is not empty; choose a new one",
                    ),
                });
            }
        }
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let meta = Meta {
            format: FORMAT_VERSION,
            vehicle: vehicle.to_owned(),
            start_us: Some(start.as_micros()),
            end_us: None,
            vehicle_config: vehicle_config_toml.map(|_| VEHICLE_CONFIG_FILE.to_owned()),
            trajectories: None,
            sources: sources.clone(),
        };
        meta.check().map_err(|message| RecordError::Meta {
            path: dir.join(META_FILE),
            message,
        })?;
        if let Some(text) = vehicle_config_toml {
            let path = dir.join(VEHICLE_CONFIG_FILE);
            std::fs::write(&path, text).map_err(io(&path))?;
        }
        meta.store(dir).map_err(io(&dir.join(META_FILE)))?;
        let mut files = BTreeMap::new();
        for s in sources {
            let path = dir.join(&s.file);
            let file = File::create(&path).map_err(io(&path))?;
            let events = match &s.events {
                Some(name) => {
                    let path = dir.join(name);
                    Some(BufWriter::new(File::create(&path).map_err(io(&path))?))
                }
                None => None,
            };
            files.insert(
                s.name,
                SourceFiles {
                    kind: s.kind,
                    out: BufWriter::new(file),
                    events,
                },
            );
        }
        let path = dir.join(COVERED_FILE);
        let covered = File::create(&path).map_err(io(&path))?;
        Ok(Self {
            dir: dir.to_owned(),
            meta,
            sources: files,
            covered,
            latest: None,
            written: 0,
            noted: None,
        })
    }

    /// Stores the trajectories as they are at the session's start (a JSON array).
    pub fn attach_trajectories(&mut self, json: &[u8]) -> Result<(), RecordError> {
        let path = self.dir.join(TRAJECTORIES_FILE);
        std::fs::write(&path, json).map_err(|source| RecordError::Io {
            path: path.clone(),
            error: source,
        })?;
        self.meta.trajectories = Some(TRAJECTORIES_FILE.to_owned());
        let meta = self.dir.join(META_FILE);
        self.meta
            .store(&self.dir)
            .map_err(|source| RecordError::Io {
                path: meta,
                error: source,
            })
    }

    /// Appends one record to its source's file (a CAN source's link events to its events
    /// file).
    pub fn write(&mut self, record: &Record) -> Result<(), RecordError> {
        let Some(files) = self.sources.get_mut(&record.source) else {
            return Err(RecordError::Meta {
                path: self.dir.join(META_FILE),
                message: format!("source {:?} is not declared", record.source),
            });
        };
        let kind = files.kind;
        let (line, out) = match (&record.payload, kind) {
            (Payload::Serial(bytes), SourceKind::Serial) => (
                format!(
                    "({}) {} {}\n",
                    record.t,
                    record.source,
                    envelope::to_hex(bytes)
                ),
                &mut files.out,
            ),
            // A command channel's link (the MQTT connection) has events as a port does; a
            // CAN source keeps them beside its candump file.
            (Payload::Link(state), SourceKind::Serial | SourceKind::Commands) => {
                (link_line(record, *state), &mut files.out)
            }
            (Payload::Link(state), SourceKind::Can) => match files.events.as_mut() {
                Some(events) => (link_line(record, *state), events),
                None => {
                    return Err(RecordError::Meta {
                        path: self.dir.join(META_FILE),
                        message: format!("source {:?} has no events file", record.source),
                    });
                }
            },
            (Payload::Can(frame), SourceKind::Can) | (Payload::CanTx(frame), SourceKind::Can) => {
                let rec = CanDumpRecord {
                    t_us: record.t.as_micros(),
                    device: record.source.clone(),
                    frame: *frame,
                    // Only chassisd's own frames are marked, as `candump -x` marks them.
                    direction: matches!(record.payload, Payload::CanTx(_))
                        .then_some(Direction::Transmitted),
                };
                (format!("{rec}\n"), &mut files.out)
            }
            (Payload::Command { topic, payload }, SourceKind::Commands) => (
                format!(
                    "({}) {} {}#{}\n",
                    record.t,
                    record.source,
                    envelope::escape_topic(topic),
                    envelope::to_hex(payload)
                ),
                &mut files.out,
            ),
            (_, kind) => {
                return Err(RecordError::Meta {
                    path: self.dir.join(META_FILE),
                    message: format!(
                        "source {:?} is {kind:?}; it cannot hold this record",
                        record.source
                    ),
                });
            }
        };
        out.write_all(line.as_bytes())
            .map_err(|source| RecordError::Io {
                path: self.dir.clone(),
                error: source,
            })?;
        self.latest = self.latest.max(Some(record.t));
        self.written += line.len() as u64;
        Ok(())
    }

    /// Bytes of records written so far.
    pub fn bytes_written(&self) -> u64 {
        self.written
    }

    /// The folder written.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Flushes every file, then notes the time they all cover in [`COVERED_FILE`] (one
    /// fixed-width write in place, so the file never grows and a kill leaves it whole).
    pub fn checkpoint(&mut self) -> Result<(), RecordError> {
        use std::os::unix::fs::FileExt;
        self.flush()?;
        // Nothing new since the last note (an idle recording): no write.
        let Some(latest) = self.latest.filter(|&t| Some(t) != self.noted) else {
            return Ok(());
        };
        let line = format!("{:020}\n", latest.as_micros());
        self.covered
            .write_all_at(line.as_bytes(), 0)
            .map_err(|source| RecordError::Io {
                path: self.dir.join(COVERED_FILE),
                error: source,
            })?;
        self.noted = Some(latest);
        Ok(())
    }

    /// Flushes every file to the operating system.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        for files in self.sources.values_mut() {
            for out in files.all() {
                out.flush().map_err(|source| RecordError::Io {
                    path: self.dir.clone(),
                    error: source,
                })?;
            }
        }
        Ok(())
    }
}

impl RecordingWriter {
    /// Flushes everything and records the session's clean end in `meta.toml`.
    pub fn finish(mut self, end: Timestamp) -> Result<(), RecordError> {
        self.flush()?;
        for files in self.sources.values_mut() {
            for out in files.all() {
                out.get_ref().sync_all().map_err(|source| RecordError::Io {
                    path: self.dir.clone(),
                    error: source,
                })?;
            }
        }
        self.meta.end_us = Some(end.as_micros());
        self.meta
            .store(&self.dir)
            .map_err(|source| RecordError::Io {
                path: self.dir.join(META_FILE),
                error: source,
            })
    }
}

/// The open files of one source.
struct SourceFiles {
    kind: SourceKind,
    out: BufWriter<File>,
    /// A CAN source's link events.
    events: Option<BufWriter<File>>,
}

impl SourceFiles {
    fn all(&mut self) -> impl Iterator<Item = &mut BufWriter<File>> {
        std::iter::once(&mut self.out).chain(self.events.as_mut())
    }
}

/// `(t) source !link-up` or `!link-down`.
fn link_line(record: &Record, state: LinkState) -> String {
    let event = match state {
        LinkState::Up => "!link-up",
        LinkState::Down => "!link-down",
    };
    format!("({}) {} {event}\n", record.t, record.source)
}

impl Drop for RecordingWriter {
    fn drop(&mut self) {
        if let Err(e) = self.flush() {
            tracing::error!(error = %e, "recording: final flush failed");
        }
    }
}
