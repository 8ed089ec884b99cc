//! The ways of running: each wires the drivers it needs to the engine, with the links and the
//! recorder of a [`crate::runtime::session`] (or, for `record`, to the recorder alone).

pub mod can_sim;
pub mod check;
pub mod listen;
pub mod live;
pub mod sim;
pub mod sim_fast;
