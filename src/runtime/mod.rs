//! The async edges of live mode: drivers that move bytes, and the task that owns the engine.

pub mod can;
pub mod can_sim;
pub mod clock;
pub mod live;
pub mod recorder;
pub mod serial;
pub mod sim;
