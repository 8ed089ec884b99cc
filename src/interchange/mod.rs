//! Recordings in the tools robotics people already use: MCAP files for Foxglove (the raw
//! inputs and what chassisd made of them) and ROS bags turned into chassisd recordings.
//!
//! - [`mcap_out`]: one MCAP file being written (chunked, zstd, indexed; JSON channels);
//! - [`schemas`]: the channels' JSON schemas, Foxglove's well-known ones among them;
//! - [`raw`]: the recorded inputs as messages, one channel per source;
//! - [`derived`]: the engine's outputs as messages;
//! - [`vehicle_recording`]: a vehicle's motion and fixes as a chassisd recording.

pub mod bag;
pub mod derived;
pub mod import;
pub mod mcap_out;
pub mod raw;
pub mod schemas;
pub mod vehicle_recording;

use std::path::{Path, PathBuf};

/// Why a file could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum InterchangeError {
    /// The file system refused.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What happened.
        error: std::io::Error,
    },
    /// The MCAP library refused (a malformed file, a write that failed).
    #[error("{path}: {message}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// What it said.
        message: String,
    },
    /// What the input holds cannot be taken, and why.
    #[error("{0}")]
    Refused(String),
}

impl InterchangeError {
    /// An I/O error on `path`.
    pub fn io(path: &Path, error: std::io::Error) -> Self {
        Self::Io {
            path: path.to_owned(),
            error,
        }
    }

    /// An MCAP error on `path`.
    pub fn mcap(path: &Path, error: mcap::McapError) -> Self {
        Self::Mcap {
            path: path.to_owned(),
            message: error.to_string(),
        }
    }
}
