//! Benchmarks that print figures (`chassisd bench ...`), as opposed to the criterion
//! micro-benchmarks under `benches/`.

pub mod control;
pub mod fusion;
pub mod mosquitto;
pub mod mqtt;
pub mod replay;
pub mod soak;
