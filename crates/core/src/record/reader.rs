//! Reads a recording folder (or in-memory records) back as one stream in time order.
//!
//! Each source file is read lazily and the sources are merged by time, ties going to the
//! source whose name sorts first and, within a source, to file order. A malformed line is
//! counted and skipped; the rest of the recording still plays. A record earlier than the one
//! before it in the same file is played but noted (a recording's files only ever go
//! forward). A recording without a clean end (chassisd was killed) plays up to the last
//! moment every file was flushed together ([`COVERED_FILE`]); what lies beyond is counted.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::Path;

use bytes::Bytes;
use socketcan::dump::{Direction, Reader as CandumpReader};

use super::envelope::{self, EnvelopeError};
use super::meta::{Meta, SourceKind};
use super::writer::COVERED_FILE;
use super::{Payload, Record, RecordError};
use crate::time::Timestamp;
use crate::vehicle::LinkState;

/// How many skipped lines are kept for the report; the rest are only counted.
const KEEP_SKIPPED: usize = 100;
/// The longest line a recording's own files hold, bytes: an MQTT message at its 1 MiB limit
/// as hex, with its topic and envelope. A longer line is counted and skipped as it is read,
/// so no file's size becomes memory.
pub const MAX_LINE: usize = 4 << 20;
/// A skipped line's reason is cut to this many characters (a reason may quote the line).
const MAX_REASON: usize = 200;
/// The flush mark is one time in microseconds.
const MAX_COVERED_BYTES: u64 = 64;

/// A line that was skipped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SkippedLine {
    /// File name inside the recording.
    pub file: String,
    /// One-based line number.
    pub line: u64,
    /// Why it was skipped.
    pub reason: String,
}

/// Merged, time-ordered reader over all sources of a recording.
pub struct RecordingReader {
    sources: Vec<SourceReader>,
    heads: Vec<Option<Record>>,
    /// Each source's last record time: a record before it is a step back in time.
    latest: Vec<Option<Timestamp>>,
    skipped: Noted,
    out_of_order: Noted,
    /// Records after this time are not played: what an unclean end left of every file.
    until: Option<Timestamp>,
    /// Records left out past `until`.
    beyond: u64,
}

/// Lines noted for the report: the first [`KEEP_SKIPPED`], and how many in all.
#[derive(Debug, Default)]
struct Noted {
    kept: Vec<SkippedLine>,
    count: u64,
}

impl Noted {
    fn note(&mut self, line: SkippedLine) {
        self.count += 1;
        if self.kept.len() < KEEP_SKIPPED {
            self.kept.push(line);
        }
    }
}

enum SourceReader {
    Envelope {
        file: String,
        kind: SourceKind,
        reader: BufReader<File>,
        line_no: u64,
        buf: Vec<u8>,
    },
    Candump {
        file: String,
        reader: CandumpReader<BufReader<File>>,
        line_no: u64,
    },
    Memory(std::vec::IntoIter<Record>),
}

impl RecordingReader {
    /// Opens the recording folder `dir` described by its `meta.toml`.
    pub fn open(dir: &Path) -> Result<(Meta, Self), RecordError> {
        let meta = Meta::load(dir)?;
        let mut sources = Vec::with_capacity(meta.sources.len());
        for source in &meta.sources {
            let file = super::open_regular(&dir.join(&source.file))?;
            if let Some(events) = &source.events {
                let file = super::open_regular(&dir.join(events))?;
                sources.push(SourceReader::Envelope {
                    file: events.clone(),
                    kind: source.kind,
                    reader: BufReader::new(file),
                    line_no: 0,
                    buf: Vec::with_capacity(64),
                });
            }
            sources.push(match source.kind {
                SourceKind::Can => SourceReader::Candump {
                    file: source.file.clone(),
                    reader: CandumpReader::from_reader(file),
                    line_no: 0,
                },
                kind => SourceReader::Envelope {
                    file: source.file.clone(),
                    kind,
                    reader: BufReader::new(file),
                    line_no: 0,
                    buf: Vec::with_capacity(256),
                },
            });
        }
        let mut reader = Self::from_sources(sources);
        if meta.end_us.is_none() {
            reader.until = read_covered(dir)?;
        }
        Ok((meta, reader))
    }

    /// A reader over records already in memory (an imported log). They are merged like file
    /// sources, so they need not be sorted.
    pub fn from_records(records: Vec<Record>) -> Self {
        Self::from_sources(vec![SourceReader::Memory(records.into_iter())])
    }

    fn from_sources(sources: Vec<SourceReader>) -> Self {
        let mut reader = Self {
            heads: Vec::with_capacity(sources.len()),
            latest: vec![None; sources.len()],
            sources,
            skipped: Noted::default(),
            out_of_order: Noted::default(),
            until: None,
            beyond: 0,
        };
        for i in 0..reader.sources.len() {
            let head = reader.pull(i);
            reader.heads.push(head);
        }
        reader
    }

    /// Lines skipped so far (the first [`KEEP_SKIPPED`]) and their total count.
    pub fn skipped(&self) -> (&[SkippedLine], u64) {
        (&self.skipped.kept, self.skipped.count)
    }

    /// Steps back in time so far: records earlier than the one before them in their file
    /// (the first [`KEEP_SKIPPED`], played all the same), and their total count.
    pub fn out_of_order(&self) -> (&[SkippedLine], u64) {
        (&self.out_of_order.kept, self.out_of_order.count)
    }

    /// For a recording without a clean end: the last moment every file covers, and how many
    /// records after it were left out.
    pub fn cut(&self) -> Option<(Timestamp, u64)> {
        self.until.map(|t| (t, self.beyond))
    }

    /// The next valid record of source `i`, skipping and noting malformed lines, and noting
    /// one earlier than the record before it.
    fn pull(&mut self, i: usize) -> Option<Record> {
        loop {
            match self.sources[i].next_line()? {
                Ok(record) => {
                    if let Some(latest) = self.latest[i]
                        && record.t < latest
                        && let Some((file, line)) = self.sources[i].position()
                    {
                        self.out_of_order.note(SkippedLine {
                            file: file.to_owned(),
                            line,
                            reason: format!("time ({}) goes back from ({latest})", record.t),
                        });
                    }
                    self.latest[i] = Some(record.t);
                    if self.until.is_some_and(|until| record.t > until) {
                        self.beyond += 1;
                        continue;
                    }
                    return Some(record);
                }
                Err(skip) => self.skipped.note(skip),
            }
        }
    }
}

impl Iterator for RecordingReader {
    type Item = Record;

    fn next(&mut self) -> Option<Record> {
        let mut best: Option<usize> = None;
        for (i, head) in self.heads.iter().enumerate() {
            let Some(r) = head else { continue };
            let better = match best.and_then(|b| self.heads[b].as_ref()) {
                None => true,
                Some(b) => (r.t, r.source.as_str()) < (b.t, b.source.as_str()),
            };
            if better {
                best = Some(i);
            }
        }
        let i = best?;
        let next = self.pull(i);
        std::mem::replace(&mut self.heads[i], next)
    }
}

impl SourceReader {
    /// The file and line number of the last line read (none for records in memory).
    fn position(&self) -> Option<(&str, u64)> {
        match self {
            SourceReader::Envelope { file, line_no, .. }
            | SourceReader::Candump { file, line_no, .. } => Some((file, *line_no)),
            SourceReader::Memory(_) => None,
        }
    }

    /// The next line's record, `Err` for a malformed line, `None` at the end.
    fn next_line(&mut self) -> Option<Result<Record, SkippedLine>> {
        match self {
            SourceReader::Memory(records) => records.next().map(Ok),
            SourceReader::Candump {
                file,
                reader,
                line_no,
            } => {
                *line_no += 1;
                match reader.next_record() {
                    Ok(None) => None,
                    Ok(Some(rec)) => Some(Ok(Record {
                        t: Timestamp::from_micros(rec.t_us),
                        source: rec.device,
                        payload: match rec.direction {
                            Some(Direction::Transmitted) => Payload::CanTx(rec.frame),
                            _ => Payload::Can(rec.frame),
                        },
                    })),
                    // A read error ends the source; a parse error skips one line.
                    Err(socketcan::dump::ParseError::Io(e)) => {
                        tracing::warn!(file = %file, line = *line_no, error = %e, "read error; source ends here");
                        None
                    }
                    Err(e) => Some(Err(SkippedLine {
                        file: file.clone(),
                        line: *line_no,
                        reason: bounded_reason(e.to_string()),
                    })),
                }
            }
            SourceReader::Envelope {
                file,
                kind,
                reader,
                line_no,
                buf,
            } => loop {
                let read = match read_bounded_line(reader, buf, MAX_LINE) {
                    Ok(read) => read,
                    Err(e) => {
                        tracing::warn!(file = %file, line = *line_no + 1, error = %e, "read error; source ends here");
                        return None;
                    }
                };
                *line_no += 1;
                let skip = |reason: String| SkippedLine {
                    file: file.clone(),
                    line: *line_no,
                    reason: bounded_reason(reason),
                };
                match read {
                    LineRead::End => return None,
                    LineRead::Line => {}
                    LineRead::TooLong(bytes) => {
                        return Some(Err(skip(format!(
                            "a line of {bytes} bytes, over the {MAX_LINE} a recording holds"
                        ))));
                    }
                }
                let Ok(line) = std::str::from_utf8(buf) else {
                    return Some(Err(skip("not UTF-8".into())));
                };
                if line.trim().is_empty() {
                    continue;
                }
                return Some(parse_line(*kind, line).map_err(|e| skip(e.to_string())));
            },
        }
    }
}

/// What [`read_bounded_line`] read.
#[derive(Debug, PartialEq, Eq)]
enum LineRead {
    /// The end of the file.
    End,
    /// A line, in the buffer.
    Line,
    /// A line of this many bytes, longer than the limit: read past, not kept.
    TooLong(u64),
}

/// Reads the next line (up to and with its newline) into `buf`, keeping at most `max` bytes:
/// a longer line is read to its end and dropped, so memory stays bounded by `max` whatever
/// the file holds.
fn read_bounded_line<R: BufRead>(
    reader: &mut R,
    buf: &mut Vec<u8>,
    max: usize,
) -> std::io::Result<LineRead> {
    buf.clear();
    let mut total: u64 = 0;
    loop {
        let available = match reader.fill_buf() {
            Ok(available) => available,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if available.is_empty() {
            break;
        }
        let (taken, ends) = match available.iter().position(|&b| b == b'\n') {
            Some(at) => (at + 1, true),
            None => (available.len(), false),
        };
        if total.saturating_add(taken as u64) <= max as u64 {
            buf.extend_from_slice(&available[..taken]);
        } else {
            buf.clear();
        }
        total = total.saturating_add(taken as u64);
        reader.consume(taken);
        if ends {
            break;
        }
    }
    Ok(match total {
        0 => LineRead::End,
        n if n > max as u64 => LineRead::TooLong(n),
        _ => LineRead::Line,
    })
}

/// `reason` cut to [`MAX_REASON`] characters, saying how long it was.
fn bounded_reason(reason: String) -> String {
    match reason.char_indices().nth(MAX_REASON) {
        Some((cut, _)) => format!("{}… ({} bytes)", &reason[..cut], reason.len()),
        None => reason,
    }
}

/// The time every file of a recording was flushed up to together, if it says. A file the
/// recorder never got to write (killed within its first flush period), or one that is not
/// a time, cuts nothing: the recording plays whole rather than not at all.
fn read_covered(dir: &Path) -> Result<Option<Timestamp>, RecordError> {
    let path = dir.join(COVERED_FILE);
    let text = match super::read_small(&path, MAX_COVERED_BYTES) {
        Ok(text) => text,
        Err(RecordError::Io { error, .. }) if error.kind() == std::io::ErrorKind::NotFound => {
            return Ok(None);
        }
        Err(e) => return Err(e),
    };
    let text = text.trim();
    if text.is_empty() {
        return Ok(None);
    }
    match text.parse::<u64>() {
        Ok(us) => Ok(Some(Timestamp::from_micros(us))),
        Err(_) => {
            tracing::warn!(file = %path.display(), found = %text.escape_debug(),
                "not a time in microseconds; the recording plays whole");
            Ok(None)
        }
    }
}

/// One line of an envelope file (serial, commands, or a CAN source's events) as a record.
pub fn parse_line(kind: SourceKind, line: &str) -> Result<Record, EnvelopeError> {
    let env = envelope::split(line)?;
    let payload = match kind {
        SourceKind::Serial => match env.payload {
            "!link-up" => Payload::Link(LinkState::Up),
            "!link-down" => Payload::Link(LinkState::Down),
            hex if hex.starts_with('!') => {
                return Err(EnvelopeError::Payload(format!("unknown event {hex:?}")));
            }
            "" => return Err(EnvelopeError::Payload("empty chunk".into())),
            hex => Payload::Serial(Bytes::from(envelope::from_hex(hex)?)),
        },
        SourceKind::Commands => match env.payload {
            "!link-up" => Payload::Link(LinkState::Up),
            "!link-down" => Payload::Link(LinkState::Down),
            command => {
                let (topic, hex) = command
                    .split_once('#')
                    .ok_or_else(|| EnvelopeError::Payload("expected topic#hex".into()))?;
                Payload::Command {
                    topic: envelope::unescape_topic(topic)?,
                    payload: Bytes::from(envelope::from_hex(hex)?),
                }
            }
        },
        // A CAN source's envelope file is its events file: link events only.
        SourceKind::Can => match env.payload {
            "!link-up" => Payload::Link(LinkState::Up),
            "!link-down" => Payload::Link(LinkState::Down),
            other => {
                return Err(EnvelopeError::Payload(format!(
                    "expected a link event, found {other:?}"
                )));
            }
        },
    };
    Ok(Record {
        t: env.t,
        source: env.source.to_owned(),
        payload,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_over_the_limit_is_read_past_and_not_kept() {
        let text = format!("short\n{}\nnext\nlast", "x".repeat(100));
        let mut reader = BufReader::with_capacity(16, text.as_bytes());
        let mut buf = Vec::new();
        let mut read = |buf: &mut Vec<u8>| read_bounded_line(&mut reader, buf, 50).unwrap();
        assert_eq!(read(&mut buf), LineRead::Line);
        assert_eq!(buf, b"short\n");
        assert_eq!(read(&mut buf), LineRead::TooLong(101));
        assert!(buf.capacity() <= 64, "kept {}", buf.capacity());
        assert_eq!(read(&mut buf), LineRead::Line);
        assert_eq!(buf, b"next\n");
        assert_eq!(read(&mut buf), LineRead::Line);
        assert_eq!(buf, b"last");
        assert_eq!(read(&mut buf), LineRead::End);
    }

    #[test]
    fn a_reason_is_cut_and_says_its_length() {
        let cut = bounded_reason(format!("bad timestamp {:?}", "\0".repeat(10_000)));
        assert!(cut.chars().count() < MAX_REASON + 20, "{cut}");
        assert!(cut.ends_with("bytes)"), "{cut}");
        assert_eq!(bounded_reason("short".into()), "short");
    }

    #[test]
    fn the_covered_time_cuts_only_when_it_is_one() {
        let dir = std::env::temp_dir().join(format!("chassisd-covered-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert_eq!(read_covered(&dir).unwrap(), None, "no file");
        for (text, want) in [
            ("00000000000000000042\n", Some(Timestamp::from_micros(42))),
            ("", None),
            ("\0\0\0", None),
            ("12ab", None),
        ] {
            std::fs::write(dir.join(COVERED_FILE), text).unwrap();
            assert_eq!(read_covered(&dir).unwrap(), want, "{text:?}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
