//! What the vehicle's parts' unit tests build their inputs from.

use super::chassis::{ChassisFeedback, DriveSummary, WheelFeedback};
use crate::config::chassis::ChassisConfig;
use crate::devices::gnss::{FixQuality, GeoPosition, GnssFix, Timed};
use crate::time::Timestamp;

/// `ms` milliseconds after the epoch.
pub fn at(ms: u64) -> Timestamp {
    Timestamp::from_micros(ms * 1_000)
}

/// A small differential drive: 0.1 m wheels, 0.5 m apart, the rest defaults.
pub fn chassis() -> ChassisConfig {
    toml::from_str("wheel_radius_m = 0.1\ntrack_m = 0.5").expect("a minimal [chassis]")
}

/// An RTK fixed position received at `ms`.
pub fn fixed_at(ms: u64) -> GnssFix {
    GnssFix {
        quality: FixQuality::RtkFixed,
        position: Some(Timed {
            value: GeoPosition {
                latitude_deg: 23.1,
                longitude_deg: 113.0,
                altitude_msl_m: None,
                geoid_separation_m: None,
                ellipsoid_height_m: None,
            },
            rx: at(ms),
        }),
        ..GnssFix::default()
    }
}

/// Two drives, ready and enabled, wheels at rest, read at `ms`.
pub fn drives_at_rest(ms: u64) -> ChassisFeedback {
    let drive = |name: &str| DriveSummary {
        name: name.into(),
        ready: true,
        running: true,
        enabled: true,
        fault: None,
        heartbeat_lost: false,
        resetting: false,
    };
    let wheel = WheelFeedback {
        velocity_rad_s: Some(0.0),
        angle_rad: Some(0.0),
        received: Some(at(ms)),
        velocity_received: Some(at(ms)),
    };
    ChassisFeedback {
        left: wheel,
        right: wheel,
        drives: vec![drive("left"), drive("right")],
        ..ChassisFeedback::default()
    }
}
