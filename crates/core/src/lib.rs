//! chassisd's sans-IO core: device decoders and encoders, fusion, control, zones, the
//! configuration, the vehicle, the recording format, the protocol dialects and the engine
//! that feeds them. Nothing here opens a socket, spawns a task or reads a clock: the daemon
//! (`chassisd`'s runtime) moves the bytes and the time in, and the outputs out.
//! docs/architecture.md describes the layers and their rules.

pub mod api;
pub mod broker;
pub mod config;
pub mod control;
pub mod devices;
pub mod engine;
pub mod fusion;
pub mod geodesy;
pub mod ntrip;
pub mod record;
pub mod secret;
pub mod sources;
pub mod time;
pub mod vehicle;
pub mod zones;
