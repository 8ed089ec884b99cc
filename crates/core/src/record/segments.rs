//! A long recording as a series of recording folders, `DIR/0001`, `DIR/0002`, …: a new one
//! starts when the current one reaches its size or its span, and the oldest are removed
//! beyond a count, so a recorder left running for months has a bounded footprint. Each
//! segment is a complete recording that replays on its own: it starts with the link state
//! every source had when it began.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use super::{Payload, Record, RecordError, RecordingWriter, SourceMeta};
use crate::time::Timestamp;
use crate::vehicle::LinkState;

/// When a segment ends, and how many are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rotation {
    /// A segment ends once it holds this many bytes of records.
    pub max_bytes: u64,
    /// A segment ends once it spans this long.
    pub max_span: Duration,
    /// At most this many segments are kept; the oldest go first. `None` keeps them all.
    pub keep: Option<usize>,
}

/// Counters shared with whoever shows the progress.
#[derive(Debug, Default)]
pub struct Progress {
    /// Records written, over every segment.
    pub records: AtomicU64,
    /// Bytes of records written, over every segment.
    pub bytes: AtomicU64,
    /// The number of the segment being written.
    pub segment: AtomicU64,
    /// Segments removed to stay within `keep`.
    pub removed: AtomicU64,
}

/// Writes records into the current segment and starts the next when it is due.
pub struct SegmentedWriter {
    root: PathBuf,
    vehicle: String,
    config_toml: Option<String>,
    sources: Vec<SourceMeta>,
    rotation: Rotation,
    current: RecordingWriter,
    number: u64,
    segment_start: Timestamp,
    /// The last link state of each source, repeated at the start of every segment.
    links: BTreeMap<String, LinkState>,
    /// A failed rotation is tried again only from this time on.
    retry_at: Option<Timestamp>,
    progress: Arc<Progress>,
}

/// How long after a failed rotation (a full disk) the next attempt waits.
const RETRY_AFTER: Duration = Duration::from_secs(10);

/// The folder of segment `number` under `root`.
pub fn segment_dir(root: &Path, number: u64) -> PathBuf {
    root.join(format!("{number:04}"))
}

impl SegmentedWriter {
    /// Creates `root` (which must not exist, or be empty) and its first segment.
    pub fn create(
        root: &Path,
        vehicle: &str,
        start: Timestamp,
        config_toml: Option<&str>,
        sources: Vec<SourceMeta>,
        rotation: Rotation,
    ) -> Result<Self, RecordError> {
        let not_empty = std::fs::read_dir(root).is_ok_and(|mut d| d.next().is_some());
        if not_empty {
            return Err(RecordError::Io {
                path: root.to_owned(),
                error: std::io::Error::new(
                    std::io::ErrorKind::AlreadyExists,
                    "recording folder is not empty; choose a new one",
                ),
            });
        }
        let first = segment_dir(root, 1);
        let current =
            RecordingWriter::create(&first, vehicle, start, config_toml, sources.clone())?;
        let progress = Arc::new(Progress::default());
        progress.segment.store(1, Ordering::Relaxed);
        Ok(Self {
            root: root.to_owned(),
            vehicle: vehicle.to_owned(),
            config_toml: config_toml.map(str::to_owned),
            sources,
            rotation,
            current,
            number: 1,
            segment_start: start,
            links: BTreeMap::new(),
            retry_at: None,
            progress,
        })
    }

    /// The counters this writer keeps up to date.
    pub fn progress(&self) -> Arc<Progress> {
        self.progress.clone()
    }

    /// Appends `record`, first starting a new segment if the current one is full or long
    /// enough. When the next segment cannot be started, the record still goes into the
    /// current one, the error is returned, and the next attempt waits [`RETRY_AFTER`].
    pub fn write(&mut self, record: &Record) -> Result<(), RecordError> {
        let mut rotation_failed = None;
        if self.due(record.t)
            && let Err(e) = self.rotate(record.t)
        {
            self.retry_at = Some(record.t.saturating_add(RETRY_AFTER));
            rotation_failed = Some(e);
        }
        if let Payload::Link(state) = record.payload {
            self.links.insert(record.source.clone(), state);
        }
        let before = self.current.bytes_written();
        self.current.write(record)?;
        self.progress.records.fetch_add(1, Ordering::Relaxed);
        self.progress
            .bytes
            .fetch_add(self.current.bytes_written() - before, Ordering::Relaxed);
        rotation_failed.map_or(Ok(()), Err)
    }

    /// Flushes the current segment and notes how far it reaches.
    pub fn checkpoint(&mut self) -> Result<(), RecordError> {
        self.current.checkpoint()
    }

    /// Ends the current segment cleanly at `end`.
    pub fn finish(self, end: Timestamp) -> Result<(), RecordError> {
        self.current.finish(end)
    }

    fn due(&self, t: Timestamp) -> bool {
        let full = self.current.bytes_written() >= self.rotation.max_bytes
            || t.saturating_since(self.segment_start) >= self.rotation.max_span;
        full && self.retry_at.is_none_or(|at| t >= at)
    }

    /// Ends the current segment at `t` and starts the next one there.
    fn rotate(&mut self, t: Timestamp) -> Result<(), RecordError> {
        let number = self.number + 1;
        let dir = segment_dir(&self.root, number);
        // What a failed attempt left (a full disk) is no recording: start it afresh.
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|source| RecordError::Io {
                path: dir.clone(),
                error: source,
            })?;
        }
        let next = RecordingWriter::create(
            &dir,
            &self.vehicle,
            t,
            self.config_toml.as_deref(),
            self.sources.clone(),
        )?;
        let done = std::mem::replace(&mut self.current, next);
        self.number = number;
        self.segment_start = t;
        self.retry_at = None;
        self.progress.segment.store(number, Ordering::Relaxed);
        let dir = done.dir().to_owned();
        done.finish(t)?;
        tracing::info!(folder = %dir.display(), "recording segment complete");
        for (source, state) in &self.links {
            self.current.write(&Record {
                t,
                source: source.clone(),
                payload: Payload::Link(*state),
            })?;
        }
        self.remove_oldest();
        Ok(())
    }

    /// Removes the oldest segments beyond `keep`.
    fn remove_oldest(&mut self) {
        let Some(keep) = self.rotation.keep else {
            return;
        };
        let keep = keep.max(1) as u64;
        let first_kept = self.number.saturating_sub(keep) + 1;
        // Segments are numbered from 1 with no gaps; those already removed are gone.
        for number in (1..first_kept).rev() {
            let dir = segment_dir(&self.root, number);
            if !dir.exists() {
                break;
            }
            match std::fs::remove_dir_all(&dir) {
                Ok(()) => {
                    self.progress.removed.fetch_add(1, Ordering::Relaxed);
                    tracing::info!(folder = %dir.display(), keep, "oldest recording segment removed");
                }
                Err(e) => {
                    tracing::error!(folder = %dir.display(), error = %e, "cannot remove an old recording segment");
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{RecordingReader, SourceKind};
    use bytes::Bytes;

    /// A fresh scratch folder for one test.
    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("chassisd-segments-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn serial(t_ms: u64, text: &str) -> Record {
        Record {
            t: Timestamp::from_micros(t_ms * 1000),
            source: "gnss".into(),
            payload: Payload::Serial(Bytes::copy_from_slice(text.as_bytes())),
        }
    }

    fn writer(root: &Path, rotation: Rotation) -> SegmentedWriter {
        SegmentedWriter::create(
            root,
            "test",
            Timestamp::from_micros(0),
            Some("[vehicle]\nname = \"test\"\n"),
            vec![SourceMeta::serial("gnss", "nmea0183")],
            rotation,
        )
        .unwrap()
    }

    fn segments(root: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(root)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    /// Every record of a segment, read back as a replay reads it.
    fn read(dir: &Path) -> Vec<Record> {
        let (meta, reader) = RecordingReader::open(dir).unwrap();
        assert_eq!(meta.sources[0].kind, SourceKind::Serial);
        assert!(meta.end_us.is_some(), "{} has no clean end", dir.display());
        reader.collect()
    }

    #[test]
    fn a_segment_ends_at_its_span_and_each_replays_on_its_own_with_the_link_state() {
        let root = scratch("span").join("rec");
        let mut w = writer(
            &root,
            Rotation {
                max_bytes: u64::MAX,
                max_span: Duration::from_secs(1),
                keep: None,
            },
        );
        w.write(&Record {
            t: Timestamp::from_micros(0),
            source: "gnss".into(),
            payload: Payload::Link(LinkState::Up),
        })
        .unwrap();
        for i in 0..25 {
            w.write(&serial(i * 100, "$GPGGA\r\n")).unwrap();
        }
        w.finish(Timestamp::from_micros(2_500_000)).unwrap();
        assert_eq!(segments(&root), ["0001", "0002", "0003"]);
        let second = read(&segment_dir(&root, 2));
        // The link state first, at the segment's start, then its ten chunks.
        assert!(matches!(second[0].payload, Payload::Link(LinkState::Up)));
        assert_eq!(second[0].t, Timestamp::from_micros(1_000_000));
        let chunks: Vec<u64> = second[1..].iter().map(|r| r.t.as_micros()).collect();
        assert_eq!(chunks, (10..20).map(|i| i * 100_000).collect::<Vec<_>>());
        // Nothing lost or repeated across the three.
        let all: usize = (1..=3)
            .map(|n| {
                read(&segment_dir(&root, n))
                    .iter()
                    .filter(|r| matches!(r.payload, Payload::Serial(_)))
                    .count()
            })
            .sum();
        assert_eq!(all, 25);
    }

    #[test]
    fn a_segment_ends_at_its_size_and_the_oldest_beyond_keep_are_removed() {
        let root = scratch("size").join("rec");
        let mut w = writer(
            &root,
            Rotation {
                max_bytes: 1000,
                max_span: Duration::from_secs(3600),
                keep: Some(2),
            },
        );
        let progress = w.progress();
        let text = "x".repeat(100);
        for i in 0..60 {
            w.write(&serial(i, &text)).unwrap();
        }
        w.finish(Timestamp::from_micros(60_000)).unwrap();
        let segment = progress.segment.load(Ordering::Relaxed);
        assert!(
            segment >= 6,
            "only {segment} segments for 60 lines of 200+ bytes"
        );
        let kept = segments(&root);
        assert_eq!(
            kept,
            [format!("{:04}", segment - 1), format!("{segment:04}")],
            "the last two segments are kept"
        );
        assert_eq!(progress.removed.load(Ordering::Relaxed), segment - 2);
        assert_eq!(progress.records.load(Ordering::Relaxed), 60);
        for name in kept {
            let size: u64 = std::fs::metadata(root.join(&name).join("gnss.log"))
                .unwrap()
                .len();
            // The check comes before each write, so a segment passes its size by one line.
            assert!(size < 1000 + 300, "segment {name} holds {size} bytes");
        }
    }

    #[test]
    fn a_folder_with_something_in_it_is_refused() {
        let dir = scratch("full");
        std::fs::write(dir.join("old"), "x").unwrap();
        let rotation = Rotation {
            max_bytes: 1,
            max_span: Duration::from_secs(1),
            keep: None,
        };
        let result = SegmentedWriter::create(
            &dir,
            "test",
            Timestamp::from_micros(0),
            None,
            vec![SourceMeta::serial("gnss", "nmea0183")],
            rotation,
        );
        assert!(result.is_err());
    }
}
