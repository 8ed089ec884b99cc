//! The clients' protocols: each link carries one protocol's connections to and from the
//! engine.

pub mod backoff;
pub mod broker;
pub mod child_pipes;
pub mod command_rate;
pub mod input_lines;
pub mod mqtt;
pub mod mqtt_echo;
pub mod mqtt_losses;
pub mod mqtt_observe;
pub mod ntrip;
pub mod per_address;
pub mod ros1;
pub mod ros2;
pub mod websocket;
