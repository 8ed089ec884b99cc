//! One MCAP file being written: chunked, zstd-compressed and indexed, its channels added as
//! their first message comes, each with a JSON schema and a sequence of its own.

use std::collections::BTreeMap;
use std::collections::HashMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use super::InterchangeError;
use super::schemas::Schema;
use crate::time::Timestamp;

/// A chunk is closed once it holds this many bytes before compression: big enough for zstd to
/// do well, small enough that a reader seeking to a time decompresses little.
const CHUNK_BYTES: u64 = 1 << 20;

/// Channels a file may hold: MCAP's ids are 16 bits; a recording naming more sources than
/// this is refused by the writer rather than wrapped.
const MAX_CHANNELS: usize = 4096;

/// An MCAP file being written.
pub struct McapOut {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    /// Schema ids by name.
    schemas: HashMap<&'static str, u16>,
    /// Channel id and the next sequence number, by topic.
    channels: HashMap<String, (u16, u32)>,
    /// Messages written.
    messages: u64,
    /// Bytes of messages written (before compression).
    bytes: u64,
}

impl McapOut {
    /// Creates `path` (replacing a file there) and writes the header (`profile` empty: the
    /// messages are JSON, not a ROS profile).
    pub fn create(path: &Path) -> Result<Self, InterchangeError> {
        let file = File::create(path).map_err(|e| InterchangeError::io(path, e))?;
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(CHUNK_BYTES))
            .library(concat!("chassisd ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|e| InterchangeError::mcap(path, e))?;
        Ok(Self {
            path: path.to_owned(),
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            messages: 0,
            bytes: 0,
        })
    }

    /// Writes one JSON message on `topic`, logged at `t` (its channel, with `schema`, is
    /// added at its first message).
    pub fn write(
        &mut self,
        topic: &str,
        schema: &Schema,
        t: Timestamp,
        json: &[u8],
    ) -> Result<(), InterchangeError> {
        let (channel, sequence) = self.channel(topic, schema)?;
        let time = t.as_nanos();
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence,
                    log_time: time,
                    publish_time: time,
                },
                json,
            )
            .map_err(|e| InterchangeError::mcap(&self.path, e))?;
        self.messages += 1;
        self.bytes += json.len() as u64;
        Ok(())
    }

    /// The channel of `topic` and its next sequence number, the channel added when new.
    fn channel(&mut self, topic: &str, schema: &Schema) -> Result<(u16, u32), InterchangeError> {
        if let Some((id, next)) = self.channels.get_mut(topic) {
            let sequence = *next;
            *next = next.wrapping_add(1);
            return Ok((*id, sequence));
        }
        if self.channels.len() >= MAX_CHANNELS {
            return Err(InterchangeError::Refused(format!(
                "{}: more than {MAX_CHANNELS} channels ({topic} would be the next)",
                self.path.display()
            )));
        }
        let schema_id = match self.schemas.get(schema.name) {
            Some(id) => *id,
            None => {
                let id = self
                    .writer
                    .add_schema(schema.name, "jsonschema", schema.text.as_bytes())
                    .map_err(|e| InterchangeError::mcap(&self.path, e))?;
                self.schemas.insert(schema.name, id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, "json", &BTreeMap::new())
            .map_err(|e| InterchangeError::mcap(&self.path, e))?;
        self.channels.insert(topic.to_owned(), (id, 1));
        Ok((id, 0))
    }

    /// Closes the current chunk and puts it on disk: a reader streaming the file, or one
    /// reading it after the writer was killed, gets every message written so far.
    pub fn flush(&mut self) -> Result<(), InterchangeError> {
        self.writer
            .flush()
            .map_err(|e| InterchangeError::mcap(&self.path, e))?;
        Ok(())
    }

    /// Messages written so far, and their bytes before compression.
    pub fn written(&self) -> (u64, u64) {
        (self.messages, self.bytes)
    }

    /// Writes the summary (statistics, indexes) and the footer, and closes the file.
    pub fn finish(mut self) -> Result<(), InterchangeError> {
        self.writer
            .finish()
            .map_err(|e| InterchangeError::mcap(&self.path, e))?;
        let mut inner = self.writer.into_inner();
        std::io::Write::flush(&mut inner).map_err(|e| InterchangeError::io(&self.path, e))?;
        inner
            .get_ref()
            .sync_data()
            .map_err(|e| InterchangeError::io(&self.path, e))
    }
}
