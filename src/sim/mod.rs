//! Simulated devices that speak the real protocols, for tests and for `chassisd can-sim`:
//! the frames they exchange are the frames real hardware would.

pub mod bms;
pub mod can_devices;
pub mod cia402_drive;
pub mod cutter_switch;
pub mod estop;
pub mod gnss_error;
pub mod lockstep;
pub mod nmea_out;
pub mod plant;
pub mod receiver_corrections;
pub mod scenario;
