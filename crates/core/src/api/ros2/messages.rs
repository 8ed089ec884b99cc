//! The ROS 2 node's messages that the rosbridge server does not have: `/fix`, `/imu/data`
//! and `/tf_static`, as JSON in ROS 2's shapes (the node's process checks each against its
//! type and serialises it). A value the vehicle does not know is `null`, sent as NaN.

use std::time::Duration;

use serde_json::{Value, json};

use crate::api::ros1::messages::{ImuNoise, diagonal, imu_fields, quaternion};
use crate::api::rosbridge::messages::BASE_FRAME;
use crate::api::rosbridge::parts::header;
use crate::devices::gnss::{FixQuality, GnssFix};
use crate::devices::imu::ImuSample;
use crate::time::Timestamp;

/// The frame of the GNSS antenna before `[ros2.frames]` renames it.
pub const GNSS_FRAME: &str = "gnss_link";
/// The frame of the IMU as mounted, before `[ros2.frames]` renames it.
pub const IMU_FRAME: &str = "imu_link";

/// sensor_msgs/NavSatStatus' `status`: no fix, a fix, SBAS-, ground-augmented.
const STATUS_NO_FIX: i8 = -1;
const STATUS_FIX: i8 = 0;
const STATUS_SBAS_FIX: i8 = 1;
const STATUS_GBAS_FIX: i8 = 2;
/// Its `service`: GPS (NMEA and UBX name no other constellation per fix).
const SERVICE_GPS: u16 = 1;
/// sensor_msgs/NavSatFix' `position_covariance_type`.
const COVARIANCE_UNKNOWN: u8 = 0;
const COVARIANCE_APPROXIMATED: u8 = 1;
const COVARIANCE_DIAGONAL_KNOWN: u8 = 2;
/// A GST epoch counts for a position received this close to it.
const GST_WITHIN: Duration = Duration::from_secs(1);

/// NavSatStatus' `status` of a fix quality: RTK (fixed and float) is ground-based
/// augmentation, DGPS and SBAS satellite-based; RTK fixed and float are told apart by the
/// covariance, as NavSatStatus has no word for each.
pub fn nav_sat_status(quality: FixQuality) -> i8 {
    match quality {
        FixQuality::RtkFixed | FixQuality::RtkFloat => STATUS_GBAS_FIX,
        FixQuality::Dgps => STATUS_SBAS_FIX,
        FixQuality::Single | FixQuality::Pps => STATUS_FIX,
        FixQuality::Invalid
        | FixQuality::DeadReckoning
        | FixQuality::Manual
        | FixQuality::Simulation => STATUS_NO_FIX,
    }
}

/// The covariance (ENU, m², row-major) of `fix`'s position and its type (NavSatFix's, which
/// Foxglove's LocationFix shares): the receiver's own GST figures for this epoch when it sent
/// them, else the quality's typical σ (vertical twice the horizontal).
pub fn position_covariance(fix: &GnssFix, rx: Timestamp) -> ([f64; 9], u8) {
    if !fix.quality.is_valid() {
        return ([0.0; 9], COVARIANCE_UNKNOWN);
    }
    let stated = fix.accuracy.filter(|a| {
        a.rx.saturating_since(rx) < GST_WITHIN && rx.saturating_since(a.rx) < GST_WITHIN
    });
    if let Some(a) = stated
        && let (Some(lat), Some(lon)) = (a.value.latitude_sd_m, a.value.longitude_sd_m)
    {
        let up = a.value.altitude_sd_m.unwrap_or(2.0 * lat.max(lon));
        let mut c = [0.0; 9];
        c[0] = lon * lon;
        c[4] = lat * lat;
        c[8] = up * up;
        return (c, COVARIANCE_DIAGONAL_KNOWN);
    }
    let sigma = fix.quality.typical_sigma_m();
    let mut c = diagonal(sigma * sigma);
    c[8] = (2.0 * sigma).powi(2);
    (c, COVARIANCE_APPROXIMATED)
}

/// `/fix` (sensor_msgs/NavSatFix) of the receiver's solution at `t`, in the antenna's
/// frame: the latest position report's position (height above the WGS 84 ellipsoid, as
/// NavSatFix says) with its covariance; without a valid fix, status -1 and no position.
pub fn fix(t: Timestamp, fix: &GnssFix) -> Value {
    let position = fix.position.filter(|_| fix.quality.is_valid());
    let (latitude, longitude, altitude) = match position {
        Some(p) => (
            json!(p.value.latitude_deg),
            json!(p.value.longitude_deg),
            json!(p.value.height_above_ellipsoid_m()),
        ),
        None => (Value::Null, Value::Null, Value::Null),
    };
    let (position_covariance, covariance_type) =
        position_covariance(fix, position.map_or(t, |p| p.rx));
    json!({
        "header": header(position.map_or(t, |p| p.rx), GNSS_FRAME),
        "status": {"status": nav_sat_status(fix.quality), "service": SERVICE_GPS},
        "latitude": latitude,
        "longitude": longitude,
        "altitude": altitude,
        "position_covariance": position_covariance,
        "position_covariance_type": covariance_type,
    })
}

/// `/imu/data` (sensor_msgs/Imu): a sample in the vehicle frame (the mounting applied, so
/// `base_link`), stamped when it was received.
pub fn imu(sample: &ImuSample, noise: &ImuNoise) -> Value {
    let mut msg = imu_fields(sample, noise);
    msg.insert("header".into(), header(sample.rx, BASE_FRAME));
    Value::Object(msg)
}

/// Where the sensors sit on the vehicle, for `/tf_static`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mounts {
    /// The GNSS antenna's phase centre in `base_link` (x forward, y left, z up), m.
    pub antenna: [f64; 3],
    /// The IMU's rotation to the vehicle frame (x, y, z, w), when there is an IMU.
    pub imu: Option<[f64; 4]>,
}

/// `/tf_static` (tf2_msgs/TFMessage): base_link→the GNSS antenna, and base_link→the IMU as
/// mounted when there is one.
pub fn tf_static(t: Timestamp, mounts: &Mounts) -> Value {
    let fixed = |child: &str, translation: [f64; 3], rotation: [f64; 4]| {
        json!({
            "header": header(t, BASE_FRAME),
            "child_frame_id": child,
            "transform": {
                "translation": {"x": translation[0], "y": translation[1], "z": translation[2]},
                "rotation": quaternion(rotation),
            },
        })
    };
    let mut transforms = vec![fixed(GNSS_FRAME, mounts.antenna, [0.0, 0.0, 0.0, 1.0])];
    if let Some(rotation) = mounts.imu {
        transforms.push(fixed(IMU_FRAME, [0.0; 3], rotation));
    }
    json!({ "transforms": transforms })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::gnss::decode::GstAccuracy;
    use crate::devices::gnss::{GeoPosition, Timed};

    fn fix_of(quality: FixQuality, gst: Option<(f64, f64)>) -> GnssFix {
        let rx = Timestamp::from_nanos(10_000_000_000);
        GnssFix {
            quality,
            position: Some(Timed {
                rx,
                value: GeoPosition {
                    latitude_deg: 47.5,
                    longitude_deg: 8.25,
                    altitude_msl_m: Some(400.0),
                    geoid_separation_m: Some(48.0),
                    ellipsoid_height_m: None,
                },
            }),
            accuracy: gst.map(|(lat, lon)| Timed {
                rx,
                value: GstAccuracy {
                    time: None,
                    rms_m: None,
                    semi_major_m: None,
                    semi_minor_m: None,
                    orientation_deg: None,
                    latitude_sd_m: Some(lat),
                    longitude_sd_m: Some(lon),
                    altitude_sd_m: Some(0.05),
                },
            }),
            ..Default::default()
        }
    }

    #[test]
    fn rtk_fixed_and_float_share_a_status_and_differ_in_covariance() {
        let t = Timestamp::from_nanos(10_000_000_000);
        let fixed = fix(t, &fix_of(FixQuality::RtkFixed, None));
        let float = fix(t, &fix_of(FixQuality::RtkFloat, None));
        assert_eq!(fixed["status"]["status"], STATUS_GBAS_FIX);
        assert_eq!(float["status"]["status"], STATUS_GBAS_FIX);
        let east = |m: &Value| m["position_covariance"][0].as_f64().unwrap();
        assert!((east(&fixed) - 0.02f64.powi(2)).abs() < 1e-12);
        assert!((east(&float) - 0.3f64.powi(2)).abs() < 1e-12);
        assert_eq!(fixed["position_covariance_type"], COVARIANCE_APPROXIMATED);
        // Height above the ellipsoid: MSL plus the geoid separation.
        assert_eq!(fixed["altitude"], 448.0);
        assert_eq!(fixed["header"]["frame_id"], GNSS_FRAME);
    }

    #[test]
    fn the_receivers_own_figures_are_a_known_diagonal_east_north_up() {
        let m = fix(
            Timestamp::from_nanos(10_000_000_000),
            &fix_of(FixQuality::RtkFixed, Some((0.01, 0.03))),
        );
        assert_eq!(m["position_covariance_type"], COVARIANCE_DIAGONAL_KNOWN);
        let c: Vec<f64> = serde_json::from_value(m["position_covariance"].clone()).unwrap();
        assert!((c[0] - 0.0009).abs() < 1e-12, "east is the longitude's σ");
        assert!((c[4] - 0.0001).abs() < 1e-12, "north is the latitude's σ");
        assert!((c[8] - 0.0025).abs() < 1e-12);
    }

    #[test]
    fn without_a_fix_the_position_is_unknown() {
        let m = fix(
            Timestamp::from_nanos(11_000_000_000),
            &fix_of(FixQuality::Invalid, None),
        );
        assert_eq!(m["status"]["status"], STATUS_NO_FIX);
        assert!(m["latitude"].is_null() && m["altitude"].is_null());
        assert_eq!(m["position_covariance_type"], COVARIANCE_UNKNOWN);
    }

    #[test]
    fn the_static_frames_place_the_antenna_and_the_imu() {
        let m = tf_static(
            Timestamp::from_nanos(1_000_000_000),
            &Mounts {
                antenna: [0.3, 0.0, 0.9],
                imu: Some([0.0, 0.0, 1.0, 0.0]),
            },
        );
        let transforms = m["transforms"].as_array().unwrap();
        assert_eq!(transforms.len(), 2);
        assert_eq!(transforms[0]["child_frame_id"], GNSS_FRAME);
        assert_eq!(transforms[0]["transform"]["translation"]["z"], 0.9);
        assert_eq!(transforms[1]["header"]["frame_id"], BASE_FRAME);
        assert_eq!(transforms[1]["transform"]["rotation"]["z"], 1.0);
    }
}
