//! Device protocols: pure decoders from raw bytes or frames to typed measurements.

pub mod bms;
pub mod can;
pub mod canopen;
pub mod cia402;
pub mod estop;
pub mod gnss;
pub mod imu;
pub mod profile;
