//! The ROS 2 types generated from `crates/core/src/api/ros2/interfaces` (build.rs), and the
//! CDR form of a message given as JSON (`api::ros2` builds them), checked by its type; and
//! back, a CDR message the node takes as JSON.
//!
//! Both take the type by any of ROS 2's spellings (`nav_msgs/msg/Odometry`,
//! `nav_msgs/Odometry`, `nav_msgs::msg::dds_::Odometry_`). The bytes are the payload only:
//! little-endian plain CDR (XCDR1, as ROS 2's middlewares send it) **without** the 4-byte
//! encapsulation header (`00 01 00 00`) in front, which the DDS layer writes and strips.

use byteorder::LittleEndian;
use serde::ser::{SerializeMap, SerializeSeq};

include!(concat!(env!("OUT_DIR"), "/ros2_interfaces.rs"));

/// Bytes past the end of a message that [`decode`] lets pass: the zeros some writers add to
/// fill the last 4-byte word (RTPS serialized payloads are padded to a multiple of 4).
const PADDING: usize = 3;

/// `msg` (JSON, fields as `type_name`'s definition names them) checked against that type and
/// serialised as its CDR payload: little-endian, without the encapsulation header. A `null`
/// stands for NaN (JSON has no NaN: `api::ros2` writes an unknown float as `null`), so it is
/// accepted where the type has a float and refused elsewhere.
pub fn cdr(type_name: &str, msg: &serde_json::Value) -> Result<Vec<u8>, String> {
    let descriptor = MESSAGE_REGISTRY
        .get(type_name)
        .ok_or_else(|| format!("no ROS 2 type {type_name}"))?;
    let message = descriptor
        .message_from(&NullIsNan(msg))
        .map_err(|e| e.to_string())?;
    let mut bytes = Vec::new();
    message
        .serialize_with(&mut cdr_encoding::CdrSerializer::<_, LittleEndian>::new(
            &mut bytes,
        ))
        .map_err(|e| e.to_string())?;
    Ok(bytes)
}

/// The CDR payload `cdr` (little-endian, without the encapsulation header) of a
/// `type_name` as JSON, in the field order of its definition; a NaN is `null`. An error for
/// bytes that are not such a message: too short, a length past the end, a string that is
/// not UTF-8, a bool that is neither 0 nor 1, or more than [`PADDING`] zeros left over.
/// Never panics, and allocates in proportion to `cdr`'s length, whatever a length in it says.
pub fn decode(type_name: &str, cdr: &[u8]) -> Result<serde_json::Value, String> {
    let descriptor = MESSAGE_REGISTRY
        .get(type_name)
        .ok_or_else(|| format!("no ROS 2 type {type_name}"))?;
    let mut deserializer = cdr_encoding::CdrDeserializer::<LittleEndian>::new(cdr);
    let message = descriptor
        .deserialize_with(&mut deserializer)
        .map_err(|e| e.to_string())?;
    let rest = &cdr[deserializer.bytes_consumed().min(cdr.len())..];
    if rest.len() > PADDING || rest.iter().any(|&b| b != 0) {
        return Err(format!(
            "{} bytes after the end of a {type_name}",
            rest.len()
        ));
    }
    serde_json::to_value(message.value()).map_err(|e| e.to_string())
}

/// A JSON value whose `null`s serialise as NaN.
struct NullIsNan<'a>(&'a serde_json::Value);

impl serde::Serialize for NullIsNan<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde_json::Value;
        match self.0 {
            Value::Null => serializer.serialize_f64(f64::NAN),
            Value::Array(items) => {
                let mut seq = serializer.serialize_seq(Some(items.len()))?;
                for item in items {
                    seq.serialize_element(&NullIsNan(item))?;
                }
                seq.end()
            }
            Value::Object(fields) => {
                let mut map = serializer.serialize_map(Some(fields.len()))?;
                for (name, value) in fields {
                    map.serialize_entry(name, &NullIsNan(value))?;
                }
                map.end()
            }
            other => other.serialize(serializer),
        }
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use serde_json::{Value, json};

    use super::*;

    fn header(frame: &str) -> Value {
        json!({"stamp": {"sec": 1_795_000_000, "nanosec": 123_456_789}, "frame_id": frame})
    }

    fn typed_header(frame: &str) -> std_msgs::Header {
        std_msgs::Header {
            stamp: builtin_interfaces::Time {
                sec: 1_795_000_000,
                nanosec: 123_456_789,
            },
            frame_id: frame.into(),
        }
    }

    fn le<T: serde::Serialize>(typed: &T) -> Vec<u8> {
        cdr_encoding::to_vec::<_, LittleEndian>(typed).unwrap()
    }

    fn odometry() -> Value {
        let mut covariance = vec![0.0; 36];
        covariance[0] = 0.01;
        covariance[35] = 0.002;
        json!({
            "header": header("odom"),
            "child_frame_id": "base_link",
            "pose": {
                "pose": {
                    "position": {"x": 1.5, "y": -2.25, "z": 0.0},
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.25, "w": 0.75},
                },
                "covariance": covariance,
            },
            "twist": {
                "twist": {
                    "linear": {"x": 0.4, "y": 0.0, "z": 0.0},
                    "angular": {"x": 0.0, "y": 0.0, "z": -0.1},
                },
                "covariance": covariance,
            },
        })
    }

    /// Messages of every kind of field: nested, fixed arrays, sequences of messages, bytes,
    /// strings, bools, floats of both widths (values an f32 holds exactly), constants' types.
    fn samples() -> Vec<(&'static str, Value)> {
        let pose = json!({
            "position": {"x": 3.0, "y": 4.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        });
        vec![
            ("nav_msgs/msg/Odometry", odometry()),
            (
                "geometry_msgs/msg/TwistStamped",
                json!({"header": header("base_link"), "twist": {
                    "linear": {"x": 0.5, "y": 0.0, "z": 0.0},
                    "angular": {"x": 0.0, "y": 0.0, "z": 0.25}}}),
            ),
            (
                "sensor_msgs/msg/NavSatFix",
                json!({
                    "header": header("gnss_link"),
                    "status": {"status": 2, "service": 1},
                    "latitude": 47.5, "longitude": 8.25, "altitude": 448.0,
                    "position_covariance": [0.0004, 0.0, 0.0, 0.0, 0.0004, 0.0, 0.0, 0.0, 0.0016],
                    "position_covariance_type": 1,
                }),
            ),
            (
                "visualization_msgs/msg/MarkerArray",
                json!({"markers": [{
                    "header": header("map"), "ns": "zones", "id": 3, "type": 4, "action": 0,
                    "pose": pose, "scale": {"x": 0.1, "y": 0.0, "z": 0.0},
                    "color": {"r": 1.0, "g": 0.5, "b": 0.0, "a": 1.0},
                    "lifetime": {"sec": 0, "nanosec": 0}, "frame_locked": false,
                    "points": [{"x": 0.0, "y": 0.0, "z": 0.0}, {"x": 1.0, "y": 2.0, "z": 0.0}],
                    "colors": [], "texture_resource": "",
                    "texture": {"header": header(""), "format": "png", "data": [137, 80, 78]},
                    "uv_coordinates": [{"u": 0.5, "v": 0.25}], "text": "keep out",
                    "mesh_resource": "", "mesh_file": {"filename": "", "data": []},
                    "mesh_use_embedded_materials": true,
                }]}),
            ),
            (
                "tf2_msgs/msg/TFMessage",
                json!({"transforms": [{
                    "header": header("odom"), "child_frame_id": "base_link",
                    "transform": {"translation": {"x": 1.5, "y": -2.25, "z": 0.0},
                                  "rotation": {"x": 0.0, "y": 0.0, "z": 0.5, "w": 0.5}},
                }, {
                    "header": header("map"), "child_frame_id": "odom",
                    "transform": {"translation": {"x": 0.0, "y": 0.0, "z": 0.0},
                                  "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
                }]}),
            ),
            (
                "diagnostic_msgs/msg/DiagnosticArray",
                json!({"header": header(""), "status": [{
                    "level": 1, "name": "chassisd: drives", "message": "warm",
                    "hardware_id": "can0",
                    "values": [{"key": "temperature", "value": "61"}],
                }]}),
            ),
            (
                "rcl_interfaces/msg/Log",
                json!({"stamp": {"sec": 5, "nanosec": 6}, "level": 30, "name": "chassisd",
                       "msg": "RTK float", "file": "", "function": "", "line": 0}),
            ),
            (
                "sensor_msgs/msg/BatteryState",
                json!({
                    "header": header("base_link"), "voltage": 51.5, "temperature": 25.0,
                    "current": -3.25, "charge": 40.0, "capacity": 50.0, "design_capacity": 50.0,
                    "percentage": 0.75, "power_supply_status": 2, "power_supply_health": 1,
                    "power_supply_technology": 4, "present": true,
                    "cell_voltage": [3.25, 3.5], "cell_temperature": [], "location": "",
                    "serial_number": "",
                }),
            ),
            (
                "std_msgs/msg/Float64MultiArray",
                json!({"layout": {"dim": [{"label": "x", "size": 2, "stride": 2}],
                       "data_offset": 0}, "data": [1.0, -2.0]}),
            ),
            (
                "nav2_msgs/msg/NavigateToPoseFeedback",
                json!({
                    "current_pose": {"header": header("map"), "pose": pose},
                    "navigation_time": {"sec": 2, "nanosec": 500_000_000},
                    "estimated_time_remaining": {"sec": 0, "nanosec": 0},
                    "number_of_recoveries": 0, "distance_remaining": 6.0,
                }),
            ),
            (
                "nav2_msgs/msg/NavigateToPoseResult",
                json!({"error_code": 0, "error_msg": ""}),
            ),
        ]
    }

    #[test]
    fn json_goes_to_cdr_as_its_generated_type_would() {
        let twist = geometry_msgs::Twist {
            linear: geometry_msgs::Vector3 {
                x: 0.5,
                y: 0.0,
                z: 0.0,
            },
            angular: geometry_msgs::Vector3 {
                x: 0.0,
                y: 0.0,
                z: -0.25,
            },
        };
        let msg = json!({"linear": {"x": 0.5, "y": 0.0, "z": 0.0},
                         "angular": {"x": 0.0, "y": 0.0, "z": -0.25}});
        assert_eq!(cdr("geometry_msgs/msg/Twist", &msg), Ok(le(&twist)));
        // Every spelling of the type.
        assert_eq!(cdr("geometry_msgs/Twist", &msg), Ok(le(&twist)));
        assert_eq!(
            cdr("geometry_msgs::msg::dds_::Twist_", &msg),
            Ok(le(&twist))
        );

        let mut covariance = [0.0; 36];
        covariance[0] = 0.01;
        covariance[35] = 0.002;
        let typed = nav_msgs::Odometry {
            header: typed_header("odom"),
            child_frame_id: "base_link".into(),
            pose: geometry_msgs::PoseWithCovariance {
                pose: geometry_msgs::Pose {
                    position: geometry_msgs::Point {
                        x: 1.5,
                        y: -2.25,
                        z: 0.0,
                    },
                    orientation: geometry_msgs::Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: 0.25,
                        w: 0.75,
                    },
                },
                covariance,
            },
            twist: geometry_msgs::TwistWithCovariance {
                twist: geometry_msgs::Twist {
                    linear: geometry_msgs::Vector3 {
                        x: 0.4,
                        y: 0.0,
                        z: 0.0,
                    },
                    angular: geometry_msgs::Vector3 {
                        x: 0.0,
                        y: 0.0,
                        z: -0.1,
                    },
                },
                covariance,
            },
        };
        let bytes = cdr("nav_msgs/msg/Odometry", &odometry()).unwrap();
        assert_eq!(bytes, le(&typed));
        // Header (4 + 4 + 4 + "odom\0" + 3 padding), child frame (4 + 10 + 2), 2 × 7 + 2 × 36
        // + 2 × 6 doubles: as rosbags (724 bytes with the encapsulation header).
        assert_eq!(bytes.len(), 720);
        assert_eq!(&bytes[8..16], b"\x05\0\0\0odom");
    }

    #[test]
    fn the_type_checks_every_field() {
        let twist = |linear: Value| json!({"linear": linear, "angular": {"x": 0, "y": 0, "z": 0}});
        let t = "geometry_msgs/msg/Twist";
        assert!(cdr(t, &twist(json!({"x": 1, "y": 0, "z": 0}))).is_ok());
        // A wrong field, a missing one, one too many, a wrong type, a missing message.
        assert!(cdr(t, &twist(json!({"x": 1, "y": 0, "zz": 0}))).is_err());
        assert!(cdr(t, &twist(json!({"x": 1, "y": 0}))).is_err());
        assert!(cdr(t, &twist(json!({"x": 1, "y": 0, "z": 0, "w": 0}))).is_err());
        assert!(cdr(t, &twist(json!({"x": "1", "y": 0, "z": 0}))).is_err());
        assert!(cdr(t, &json!({"linear": {"x": 0, "y": 0, "z": 0}})).is_err());
        // Out of range for its integer, a fixed array of the wrong length, an unknown type.
        let log = |level: i64| {
            json!({"stamp": {"sec": 0, "nanosec": 0}, "level": level, "name": "", "msg": "",
                   "file": "", "function": "", "line": 0})
        };
        assert!(cdr("rcl_interfaces/msg/Log", &log(50)).is_ok());
        assert!(cdr("rcl_interfaces/msg/Log", &log(256)).is_err());
        assert!(cdr("rcl_interfaces/msg/Log", &log(-1)).is_err());
        let mut odom = odometry();
        odom["pose"]["covariance"] = json!(vec![0.0; 35]);
        assert!(cdr("nav_msgs/msg/Odometry", &odom).is_err());
        assert!(cdr("nav_msgs/msg/Odometree", &odometry()).is_err());
    }

    #[test]
    fn null_is_nan_where_a_float_is_and_nowhere_else() {
        let t = "geometry_msgs/msg/Vector3";
        let bytes = cdr(t, &json!({"x": null, "y": 0, "z": 0})).unwrap();
        assert!(f64::from_le_bytes(bytes[..8].try_into().unwrap()).is_nan());
        assert_eq!(
            decode(t, &bytes),
            Ok(json!({"x": null, "y": 0.0, "z": 0.0}))
        );
        let status = json!({"status": null, "service": 1});
        assert!(cdr("sensor_msgs/msg/NavSatStatus", &status).is_err());
        let string = json!({"data": null});
        assert!(cdr("std_msgs/msg/String", &string).is_err());
    }

    #[test]
    fn decode_gives_back_what_was_encoded() {
        for (type_name, msg) in samples() {
            let bytes = cdr(type_name, &msg).unwrap_or_else(|e| panic!("{type_name}: {e}"));
            assert_eq!(decode(type_name, &bytes).as_ref(), Ok(&msg), "{type_name}");
            // The zeros that fill the last word pass; anything else after the end does not.
            let mut padded = bytes.clone();
            padded.extend([0; PADDING]);
            assert_eq!(decode(type_name, &padded).as_ref(), Ok(&msg), "{type_name}");
            padded.push(0);
            assert!(decode(type_name, &padded).is_err(), "{type_name}");
            padded.truncate(bytes.len() + 1);
            padded[bytes.len()] = 1;
            assert!(decode(type_name, &padded).is_err(), "{type_name}");
        }
    }

    #[test]
    fn a_truncated_message_is_an_error() {
        for (type_name, msg) in samples() {
            let bytes = cdr(type_name, &msg).unwrap();
            for end in 0..bytes.len() {
                assert!(
                    decode(type_name, &bytes[..end]).is_err(),
                    "{type_name} cut at {end}"
                );
            }
        }
    }

    /// Random bytes, and valid messages with random bytes changed, as every type: errors or
    /// messages, never a panic; lengths that claim more than there is are errors.
    #[test]
    fn decode_never_panics() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(52);
        let types: Vec<&str> = MESSAGE_REGISTRY
            .descriptors()
            .iter()
            .map(|d| d.ros_type_name)
            .collect();
        let valid: Vec<Vec<u8>> = samples().iter().map(|(t, m)| cdr(t, m).unwrap()).collect();
        for round in 0..20_000 {
            let bytes: Vec<u8> = if round % 2 == 0 {
                let len = rng.random_range(0..256);
                (0..len).map(|_| rng.random()).collect()
            } else {
                let mut bytes = valid[rng.random_range(0..valid.len())].clone();
                for _ in 0..rng.random_range(1..4) {
                    let at = rng.random_range(0..bytes.len());
                    bytes[at] = rng.random();
                }
                bytes
            };
            for type_name in &types {
                let _ = decode(type_name, &bytes);
            }
        }
        // A sequence of 4 billion points in 8 bytes: an error, without allocating for them.
        let huge = [0xff, 0xff, 0xff, 0xff, 0, 0, 0, 0];
        assert!(decode("nav_msgs/msg/Path", &[&[0u8; 12][..], &huge].concat()).is_err());
        assert!(decode("std_msgs/msg/String", &huge).is_err());
        assert!(decode("std_msgs/msg/Float64MultiArray", &[0u8; 8]).is_err());
    }

    #[test]
    fn every_topic_the_node_publishes_or_takes_has_its_interface() {
        use crate::api::ros2::topics::{TAKEN, TOPICS};
        let types = TOPICS
            .iter()
            .map(|t| t.msg_type)
            .chain(TAKEN.iter().map(|t| t.msg_type));
        for msg_type in types {
            let descriptor = MESSAGE_REGISTRY.get(msg_type);
            assert!(
                descriptor.is_some(),
                "no {msg_type} in crates/core/src/api/ros2/interfaces"
            );
            // The DDS name ROS 2 gives it: package::msg::dds_::Type_.
            let (package, name) = msg_type.split_once("/msg/").unwrap();
            assert_eq!(
                descriptor.unwrap().ros2_type_name,
                format!("{package}::msg::dds_::{name}_")
            );
        }
    }

    /// What `api::ros2`'s publisher makes of poses, an IMU sample, a fix and a lost one, a
    /// status tick and an event, after its start (each with its topic), and the status.
    fn published() -> (Vec<(&'static str, Value)>, crate::vehicle::VehicleStatus) {
        use crate::api::ros1::messages::ImuNoise;
        use crate::api::ros1::odometry::OdometryNoise;
        use crate::api::ros2::messages::Mounts;
        use crate::api::ros2::publisher::{Feed, Publishing, Settings};
        use crate::devices::gnss::{FixQuality, GeoPosition, GnssFix, Timed};
        use crate::time::Timestamp;
        use crate::vehicle::{Localization, PoseReport, VehicleStatus};

        let mut p = Publishing::new(Settings {
            odometry_noise: OdometryNoise {
                speed: (0.01, 0.01),
                yaw_rate: 0.01,
            },
            imu_noise: ImuNoise {
                gyro_rps: 0.01,
                accel_mps2: 0.05,
                orientation_rad: 0.02,
            },
            mounts: Mounts {
                antenna: [0.2, 0.0, 1.0],
                imu: Some([0.0, 0.0, 0.0, 1.0]),
            },
            frames: Default::default(),
            odom_rate_hz: 100.0,
        });
        let t = Timestamp::from_nanos(1_795_000_000_123_456_789);
        let mut out = Vec::new();
        p.on_ready(t, &mut out);
        let report = PoseReport {
            odom: Some(Default::default()),
            map: None,
            frames: None,
            localization: Localization::Uninitialized,
        };
        p.on_feed(&Feed::Poses(t, report), &mut out);
        let sample = crate::devices::imu::ImuSample {
            rx: t,
            accel: nalgebra::Vector3::new(0.1, -0.2, 9.8),
            gyro: nalgebra::Vector3::new(0.001, 0.002, -0.3),
            orientation: None,
        };
        p.on_feed(&Feed::Imu(sample), &mut out);
        let mut fix = GnssFix {
            quality: FixQuality::RtkFloat,
            position: Some(Timed {
                rx: t,
                value: GeoPosition {
                    latitude_deg: 47.5,
                    longitude_deg: 8.25,
                    altitude_msl_m: Some(400.0),
                    geoid_separation_m: Some(48.0),
                    ellipsoid_height_m: None,
                },
            }),
            ..Default::default()
        };
        p.on_feed(&Feed::Fix(t, Box::new(fix)), &mut out);
        // Without a fix: NaN for the position (null in the JSON).
        fix.quality = FixQuality::Invalid;
        p.on_feed(&Feed::Fix(t, Box::new(fix)), &mut out);
        let status = VehicleStatus {
            time: t,
            ..Default::default()
        };
        p.on_feed(&Feed::Status(Box::new(status.clone())), &mut out);
        p.on_feed(&Feed::Event("drive up".into()), &mut out);
        (out, status)
    }

    /// Every message `api::ros2` builds passes its topic's type check.
    #[test]
    fn every_message_the_publisher_makes_has_its_type() {
        use crate::api::ros2::topics;

        let (out, status) = published();
        let mut seen: Vec<&str> = Vec::new();
        for (topic, msg) in &out {
            let msg_type = topics::find(topic).expect("a published topic").msg_type;
            if let Err(e) = cdr(msg_type, msg) {
                panic!("{topic} ({msg_type}): {e}\n{msg:#}");
            }
            seen.push(topic);
        }
        for topic in [
            "/tf_static",
            "/odom",
            "/imu/data",
            "/fix",
            "/plan",
            "/zones",
            "/rosout",
        ] {
            assert!(seen.contains(&topic), "{topic} not made: {seen:?}");
        }

        let mut navigation = crate::api::ros2::navigate::Navigation::default();
        navigation.accepted(1, (10.0, 0.0), status.time);
        for (_, feedback) in navigation.feedback(&status) {
            cdr("nav2_msgs/msg/NavigateToPoseFeedback", &feedback).unwrap();
        }
    }

    /// Every type's RIHS01 hash is the one ROS 2 Jazzy computes from its definition (as
    /// rosbags 0.11.9 does: nav2_msgs' from the three messages here, under their names here).
    #[test]
    fn the_type_hashes_are_ros2_jazzys() {
        let jazzy: &[(&str, &str)] = &[
            (
                "builtin_interfaces/msg/Duration",
                "e8d009f659816f758b75334ee1a9ca5b5c0b859843261f14c7f937349599d93b",
            ),
            (
                "builtin_interfaces/msg/Time",
                "b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197",
            ),
            (
                "diagnostic_msgs/msg/DiagnosticArray",
                "5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
            ),
            (
                "diagnostic_msgs/msg/DiagnosticStatus",
                "b0e3e692ea2d54a8af2f4ef1930e81556a2db55216b771f8a7d2724ed47bf0e4",
            ),
            (
                "diagnostic_msgs/msg/KeyValue",
                "d68081eaa540288c5440753baecef0c4e16e81a5f78ad68902ded5100413bb42",
            ),
            (
                "geometry_msgs/msg/Point",
                "6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881",
            ),
            (
                "geometry_msgs/msg/Pose",
                "d501954e9476cea2996984e812054b68026ae0bfae789d9a10b23daf35cc90fa",
            ),
            (
                "geometry_msgs/msg/PoseStamped",
                "10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
            ),
            (
                "geometry_msgs/msg/PoseWithCovariance",
                "9a7c0fd234b7f45c6098745ecccd773ca1085670e64107135397aee31c02e1bb",
            ),
            (
                "geometry_msgs/msg/PoseWithCovarianceStamped",
                "26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e",
            ),
            (
                "geometry_msgs/msg/Quaternion",
                "8a765f66778c8ff7c8ab94afcc590a2ed5325a1d9a076ffff38fbce36f458684",
            ),
            (
                "geometry_msgs/msg/Transform",
                "beb83fbe698636351461f6f35d1abb20010c43d55374d81bd041f1ba2581fddc",
            ),
            (
                "geometry_msgs/msg/TransformStamped",
                "0a241f87d04668d94099cbb5ba11691d5ad32c2f29682e4eb5653424bd275206",
            ),
            (
                "geometry_msgs/msg/Twist",
                "9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
            ),
            (
                "geometry_msgs/msg/TwistStamped",
                "5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
            ),
            (
                "geometry_msgs/msg/TwistWithCovariance",
                "49f574f033f095d8b6cd1beaca5ca7925e296e84af1716d16c89d38b059c8c18",
            ),
            (
                "geometry_msgs/msg/Vector3",
                "cc12fe83e4c02719f1ce8070bfd14aecd40f75a96696a67a2a1f37f7dbb0765d",
            ),
            (
                "nav2_msgs/msg/NavigateToPoseFeedback",
                "9f100117d8db6d3df3dd4a2d626c9ade56e05c0d90d586b3d0276f69ed8089d6",
            ),
            (
                "nav2_msgs/msg/NavigateToPoseGoal",
                "62884970566cd605fa5b6ec24ac26f7dd03d262acc027dd1c75db98e22ff5def",
            ),
            (
                "nav2_msgs/msg/NavigateToPoseResult",
                "e3b6c4b35447656c29e74acf967561ab7849d26995b1a241238f1885a21ceed5",
            ),
            (
                "nav_msgs/msg/Odometry",
                "3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
            ),
            (
                "nav_msgs/msg/Path",
                "1957a5bb3cee5da65c4e52e52b65a93df227efce4c20f8458b36e73066ca334b",
            ),
            (
                "rcl_interfaces/msg/Log",
                "e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac",
            ),
            (
                "sensor_msgs/msg/BatteryState",
                "4bee5dfce981c98faa6828b868307a0a73f992ed0789f374ee96c8f840e69741",
            ),
            (
                "sensor_msgs/msg/CompressedImage",
                "15640771531571185e2efc8a100baf923961a4d15d5569652e6cb6691e8e371a",
            ),
            (
                "sensor_msgs/msg/Imu",
                "7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
            ),
            (
                "sensor_msgs/msg/NavSatFix",
                "62223ab3fe210a15976021da7afddc9e200dc9ec75231c1b6a557fc598a65404",
            ),
            (
                "sensor_msgs/msg/NavSatStatus",
                "d1ed3befa628e09571bd273b888ba1c1fd187c9a5e0006b385d7e5e9095a3204",
            ),
            (
                "std_msgs/msg/ColorRGBA",
                "77a7a5b9ae477306097665106e0413ba74440245b1f3d0c6d6405fe5c7813fe8",
            ),
            (
                "std_msgs/msg/Float64MultiArray",
                "1025ddc6b9552d191f89ef1a8d2f60f3d373e28b283d8891ddcc974e8c55397f",
            ),
            (
                "std_msgs/msg/Header",
                "f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
            ),
            (
                "std_msgs/msg/MultiArrayDimension",
                "5e773a60a4c7fc8a54985f307c7837aa2994252a126c301957a24e31282c9cbe",
            ),
            (
                "std_msgs/msg/MultiArrayLayout",
                "4c66e6f78e740ac103a94cf63259f968e48c617e7699e829b63c21a5cb50dac6",
            ),
            (
                "std_msgs/msg/String",
                "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
            ),
            (
                "tf2_msgs/msg/TFMessage",
                "e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
            ),
            (
                "visualization_msgs/msg/Marker",
                "45b13ccf791f225962bf74e746f9644518855d783a6f42ba0cc14fde2b4f3ce0",
            ),
            (
                "visualization_msgs/msg/MarkerArray",
                "86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf",
            ),
            (
                "visualization_msgs/msg/MeshFile",
                "7710ece15a148fb7c9b546364cfb215bb06098087bd6394fe5b73a493508f8c4",
            ),
            (
                "visualization_msgs/msg/UVCoordinate",
                "f27f7ed21fe360c6066944f856b801a0c0d1e94e815b6886444b42d90b196a26",
            ),
        ];
        for (type_name, hash) in jazzy {
            let descriptor = MESSAGE_REGISTRY.get(type_name).expect("generated");
            let generated: String = descriptor
                .ros2_hash
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect();
            assert_eq!(&generated, hash, "{type_name}");
        }
        // Every type generated is here but service_msgs' (a part of roslibrust's own).
        let others = MESSAGE_REGISTRY
            .descriptors()
            .iter()
            .filter(|d| !d.ros_type_name.starts_with("service_msgs/"));
        assert_eq!(others.count(), jazzy.len());
    }
}
