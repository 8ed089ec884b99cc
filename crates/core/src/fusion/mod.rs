//! Localisation: geodesy, the `odom` frame's dead reckoning, the map filter over it and its
//! estimators.

pub mod course;
pub mod epoch_clock;
pub mod gnss_only;
pub mod gyro_drift;
pub mod localizer;
pub mod map_filter;
pub mod odometry;
pub mod planar;
pub mod wheel_scale;
