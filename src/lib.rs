//! chassisd: the chassis daemon of an RTK ground robot.
//!
//! The logic is a sans-IO core ([`vehicle::Vehicle`]) fed through device decoders by the
//! [`engine::Engine`]; live mode ([`runtime`]) and replay ([`replay`]) are thin edges around
//! that one engine. docs/architecture.md describes the layers and their rules.

pub mod api;
pub mod bench;
pub mod broker;
pub mod calib;
pub mod config;
pub mod control;
pub mod devices;
pub mod engine;
pub mod fusion;
pub mod geodesy;
pub mod ntrip;
pub mod record;
pub mod replay;
pub mod runtime;
pub mod secret;
pub mod sim;
pub mod time;
pub mod vehicle;
pub mod zones;
