//! The recorded-frame layer: every raw frame with its time, written as a recording folder
//! and read back in time order (docs/recording.md).

pub mod envelope;
pub mod meta;
pub mod nmea_import;
pub mod reader;
pub mod segments;
pub mod writer;

use bytes::Bytes;
use socketcan::CanAnyFrame;

use crate::time::Timestamp;
use crate::vehicle::LinkState;

pub use meta::{Meta, SourceKind, SourceMeta};
pub use reader::{RecordingReader, SkippedLine};
pub use writer::RecordingWriter;

/// One recorded event.
#[derive(Debug, Clone)]
pub struct Record {
    /// When it happened (host time).
    pub t: Timestamp,
    /// The source: serial device name, CAN interface or command channel.
    pub source: String,
    /// What happened.
    pub payload: Payload,
}

/// What a record holds.
#[derive(Debug, Clone)]
pub enum Payload {
    /// A chunk of bytes read from a serial port, exactly as it arrived.
    Serial(Bytes),
    /// A driver's link state changed.
    Link(LinkState),
    /// A CAN frame received from the bus.
    Can(CanAnyFrame),
    /// A CAN frame chassisd transmitted (`T` direction in the candump file).
    CanTx(CanAnyFrame),
    /// A command received over MQTT.
    Command {
        /// Topic it arrived on.
        topic: String,
        /// Raw payload.
        payload: Bytes,
    },
}

/// Opens a recording's file for reading, refusing what is not a regular file: a FIFO would
/// block the reader until someone writes, a device would stream without end.
pub fn open_regular(path: &std::path::Path) -> Result<std::fs::File, RecordError> {
    let io = |source| RecordError::Io {
        path: path.to_path_buf(),
        error: source,
    };
    let kind = std::fs::metadata(path).map_err(io)?.file_type();
    if !kind.is_file() {
        return Err(io(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file (a FIFO, device or folder); a recording holds plain files",
        )));
    }
    std::fs::File::open(path).map_err(io)
}

/// Reads a small file of a recording (its description, its flush mark) whole, refusing one
/// over `limit` bytes or not a regular file.
pub fn read_small(path: &std::path::Path, limit: u64) -> Result<String, RecordError> {
    use std::io::Read as _;
    let io = |source| RecordError::Io {
        path: path.to_path_buf(),
        error: source,
    };
    let too_big = || {
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("over {limit} bytes, more than such a file holds"),
        ))
    };
    let file = open_regular(path)?;
    // Its size says when it is too large before a byte is read (a sparse file costs nothing
    // to claim); the read's own bound catches one that grows meanwhile.
    if file.metadata().map_err(io)?.len() > limit {
        return Err(too_big());
    }
    let mut text = String::new();
    file.take(limit + 1).read_to_string(&mut text).map_err(io)?;
    if text.len() as u64 > limit {
        return Err(too_big());
    }
    Ok(text)
}

/// A recording that could not be opened, read or written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// File system trouble.
    /// (The reason is in the message, not a source too: a chain of causes would print it
    /// twice.)
    #[error("{path}: {error}")]
    Io {
        /// The file or folder.
        path: std::path::PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// `meta.toml` is missing or invalid.
    #[error("{path}: {message}")]
    Meta {
        /// The meta file.
        path: std::path::PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A plain log could not be imported.
    #[error("{0}")]
    Import(String),
}
