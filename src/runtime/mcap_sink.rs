//! `chassisd record --mcap`: beside each segment's recording files, the same records as an
//! MCAP file (`recording.mcap` in the segment's folder, so it rotates and is removed with
//! it), its chunks closed and put on disk at least every second: a recorder killed by a power
//! loss leaves a file a streaming reader reads whole up to its last second.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use crate::interchange::InterchangeError;
use crate::interchange::mcap_out::McapOut;
use crate::interchange::raw::{Message, RawChannels};
use crate::record::segments::{Progress, SegmentedWriter, segment_dir};
use crate::record::{Payload, Record, RecordError};
use crate::runtime::recorder::RecordSink;
use crate::time::Timestamp;
use crate::vehicle::LinkState;

/// The MCAP file's name in a segment's folder.
pub const MCAP_FILE: &str = "recording.mcap";
/// A chunk is closed and written at least this often.
const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// The segments, and the MCAP file of the current one.
pub struct WithMcap {
    segments: SegmentedWriter,
    progress: Arc<Progress>,
    root: PathBuf,
    nmea_sources: Vec<String>,
    /// The current segment's number, its file and channels (none while a file could not be
    /// created; the next segment tries again).
    number: u64,
    file: Option<McapOut>,
    raw: RawChannels,
    /// Each source's link state, repeated at the start of every file as the segments do.
    links: std::collections::BTreeMap<String, LinkState>,
    flushed: Instant,
    scratch: Vec<Message>,
}

impl WithMcap {
    /// `segments` (rooted at `root`) with an MCAP file per segment; `nmea_sources` are the
    /// serial sources whose sentences are also written as text.
    pub fn new(
        segments: SegmentedWriter,
        root: PathBuf,
        nmea_sources: Vec<String>,
    ) -> Result<Self, RecordError> {
        let progress = segments.progress();
        let number = progress.segment.load(Ordering::Relaxed).max(1);
        let mut sink = Self {
            segments,
            progress,
            root,
            nmea_sources,
            number,
            file: None,
            raw: RawChannels::default(),
            links: Default::default(),
            flushed: Instant::now(),
            scratch: Vec::new(),
        };
        sink.open()?;
        Ok(sink)
    }

    /// A new file for the current segment.
    fn open(&mut self) -> Result<(), RecordError> {
        let path = segment_dir(&self.root, self.number).join(MCAP_FILE);
        self.raw = RawChannels::new(self.nmea_sources.iter().map(String::as_str));
        self.file = Some(McapOut::create(&path).map_err(io_error)?);
        self.flushed = Instant::now();
        Ok(())
    }

    fn write_mcap(&mut self, record: &Record) -> Result<(), RecordError> {
        let Some(file) = self.file.as_mut() else {
            return Ok(());
        };
        self.raw.messages(record, &mut self.scratch);
        for m in self.scratch.drain(..) {
            file.write(&m.topic, &m.schema, record.t, &m.body)
                .map_err(io_error)?;
        }
        Ok(())
    }

    /// The segments rotated: the last file finished, the next begun with the links' states.
    fn rotated(&mut self, number: u64, t: Timestamp) -> Result<(), RecordError> {
        if let Some(done) = self.file.take() {
            done.finish().map_err(io_error)?;
        }
        self.number = number;
        self.open()?;
        let links: Vec<Record> = self
            .links
            .iter()
            .map(|(source, state)| Record {
                t,
                source: source.clone(),
                payload: Payload::Link(*state),
            })
            .collect();
        for link in &links {
            self.write_mcap(link)?;
        }
        Ok(())
    }
}

fn io_error(e: InterchangeError) -> RecordError {
    let path = match &e {
        InterchangeError::Io { path, .. } | InterchangeError::Mcap { path, .. } => path.clone(),
        InterchangeError::Refused(_) => PathBuf::from(MCAP_FILE),
    };
    RecordError::Io {
        path,
        error: std::io::Error::other(e.to_string()),
    }
}

impl RecordSink for WithMcap {
    fn write(&mut self, record: &Record) -> Result<(), RecordError> {
        let written = self.segments.write(record);
        let number = self.progress.segment.load(Ordering::Relaxed);
        if number != self.number {
            self.rotated(number, record.t)?;
        }
        if let Payload::Link(state) = record.payload {
            self.links.insert(record.source.clone(), state);
        }
        self.write_mcap(record)?;
        written
    }

    fn checkpoint(&mut self) -> Result<(), RecordError> {
        let segments = self.segments.checkpoint();
        if self.flushed.elapsed() >= FLUSH_EVERY {
            self.flushed = Instant::now();
            if let Some(file) = self.file.as_mut() {
                file.flush().map_err(io_error)?;
            }
        }
        segments
    }

    fn finish(self: Box<Self>, end: Timestamp) -> Result<(), RecordError> {
        let this = *self;
        let segments = this.segments.finish(end);
        if let Some(file) = this.file {
            file.finish().map_err(io_error)?;
        }
        segments
    }
}
