//! Localisation: geodesy, the `odom` frame's dead reckoning and the fusion filter.

pub mod ekf;
pub mod geodesy;
pub mod localizer;
pub mod map_filter;
pub mod odometry;
