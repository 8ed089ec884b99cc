//! What can stop a runtime task from starting or going on: the runtime's one error type.
//! Each variant says what was being done; the messages read as they did when they were
//! `anyhow` contexts, `what: why`.

use crate::config::ConfigError;

/// Why a driver, link or mode could not start or go on.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    /// An operating-system call failed.
    #[error("{what}: {error}")]
    Io {
        /// What was being done.
        what: String,
        /// The operating system's word.
        error: std::io::Error,
    },
    /// A file's content (a certificate, a key, settings) was refused.
    #[error("{what}: {error}")]
    Invalid {
        /// What was being read.
        what: String,
        /// Why it was refused.
        error: String,
    },
    /// The configuration does not hold together (exit status 78).
    #[error("{0}")]
    Config(#[from] ConfigError),
    /// The trajectory folder could not be read.
    #[error("{0}")]
    Trajectories(#[from] crate::api::trajectory::TrajectoryError),
    /// A part could not start, or stopped: why, in full.
    #[error("{0}")]
    Failed(String),
}

/// The error of an operating-system call made while doing `what`.
pub fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> RuntimeError {
    let what = what.into();
    move |error| RuntimeError::Io { what, error }
}

/// The error of content refused while reading `what`.
pub fn invalid<E: std::fmt::Display>(what: impl Into<String>) -> impl FnOnce(E) -> RuntimeError {
    let what = what.into();
    move |error| RuntimeError::Invalid {
        what,
        error: error.to_string(),
    }
}

/// The result of the runtime's fallible steps.
pub type Result<T, E = RuntimeError> = std::result::Result<T, E>;
