//! chassisd: the chassis daemon of an RTK ground robot.
//!
//! The logic is a sans-IO core (the `chassisd-core` crate, [`vehicle::Vehicle`]) fed
//! through device decoders by the [`engine::Engine`]; live mode ([`runtime`]) and replay ([`replay`]) are thin edges around
//! that one engine. docs/architecture.md describes the layers and their rules.

// The core's layers, under the names the daemon's modules and its users have always used.
pub use chassisd_core::{
    api, broker, config, control, devices, engine, fusion, geodesy, ntrip, record, secret, sources,
    time, vehicle, zones,
};

pub mod bench;
pub mod calib;
pub mod interchange;
pub mod replay;
pub mod runtime;
pub mod sim;
