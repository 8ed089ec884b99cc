//! The async edges of live mode: drivers that move bytes, and the task that owns the engine.

pub mod broker;
pub mod can;
pub mod can_sim;
pub mod clock;
pub mod host;
pub mod live;
pub mod mqtt;
pub mod recorder;
pub mod serial;
pub mod sim;
