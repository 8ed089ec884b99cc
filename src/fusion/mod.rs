//! Localisation: geodesy and the fusion filter.

pub mod ekf;
pub mod geodesy;
pub mod localizer;
