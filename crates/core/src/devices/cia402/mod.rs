//! CiA 402 motor drives: the power state machine, drive profiles and the per-node driver.

pub mod node;
pub mod profile;
pub mod state;

pub use profile::DriveProfile;
pub use state::DriveState;
