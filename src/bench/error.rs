//! What can stop a benchmark before it has figures: the benchmarks' one error type. A step
//! that failed while doing something is the runtime's `what: why` error.

use crate::config::ConfigError;
use crate::runtime::error::RuntimeError;

/// Why a benchmark could not run to its figures.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A configuration or plant does not load.
    #[error("{0}")]
    Config(#[from] ConfigError),
    /// The simulated vehicle's runtime could not start or stopped.
    #[error("{0}")]
    Runtime(#[from] RuntimeError),
    /// The MQTT client refused a request (its queue closed).
    #[error("{0}")]
    Client(#[from] rumqttc::ClientError),
    /// A benchmark's own condition failed: why, in full.
    #[error("{0}")]
    Failed(String),
}

/// The error of an operating-system call made while doing `what` (the runtime's).
pub fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> BenchError {
    let error = crate::runtime::error::io(what);
    move |e| BenchError::Runtime(error(e))
}

/// The error of anything that failed while doing `what`, in its own words (the runtime's).
pub fn invalid<E: std::fmt::Display>(what: impl Into<String>) -> impl FnOnce(E) -> BenchError {
    let error = crate::runtime::error::invalid(what);
    move |e| BenchError::Runtime(error(e))
}

/// The result of the benchmarks' fallible steps.
pub type Result<T, E = BenchError> = std::result::Result<T, E>;

/// The error of something found missing: `what`, in full.
pub fn missing(what: impl Into<String>) -> impl FnOnce() -> BenchError {
    let what = what.into();
    move || BenchError::Failed(what)
}
