//! The ROS1 types generated from `crates/core/src/api/ros1/interfaces` (build.rs), and the wire form of
//! a message given as JSON (`api::ros1::messages` builds them), checked by its type.

include!(concat!(env!("OUT_DIR"), "/ros1_interfaces.rs"));

/// `msg` (JSON, fields as `descriptor`'s type names them) checked against that type and
/// serialised for the wire: its length, then its fields.
pub fn wire(
    descriptor: &'static roslibrust::MessageDescriptor,
    msg: &serde_json::Value,
) -> Result<Vec<u8>, String> {
    let message = descriptor.message_from(msg).map_err(|e| e.to_string())?;
    let mut bytes = vec![0u8; 4];
    message
        .serialize_with(&mut roslibrust_serde_rosmsg::Serializer::new(&mut bytes))
        .map_err(|e| e.to_string())?;
    let length = u32::try_from(bytes.len() - 4).map_err(|_| "message over 4 GiB".to_owned())?;
    bytes[..4].copy_from_slice(&length.to_le_bytes());
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_goes_on_the_wire_as_its_generated_type_would() {
        let int16 = MESSAGE_REGISTRY.get("std_msgs/Int16").expect("generated");
        let typed = roslibrust_serde_rosmsg::to_vec(&std_msgs::Int16 { data: -7 }).unwrap();
        assert_eq!(wire(int16, &serde_json::json!({"data": -7})), Ok(typed));
        // The type checks every field: a wrong one, a missing one, or one out of range.
        assert!(wire(int16, &serde_json::json!({"date": 1})).is_err());
        assert!(wire(int16, &serde_json::json!({"data": 70000})).is_err());
    }

    /// Each JSON message on the wire, byte for byte what its generated type gives for the
    /// same values (built here field by field, as the node built them before).
    #[test]
    fn the_json_messages_serialise_as_their_typed_messages() {
        use crate::api::ros1::messages as json;
        use crate::api::ros1::odometry::OdometryCovariance;
        use roslibrust::codegen::integral_types::Time;
        use roslibrust_serde_rosmsg::to_vec;

        let t = crate::time::Timestamp::from_nanos(1_795_000_000_123_456_789);
        let header = |seq: u32, frame: &str| std_msgs::Header {
            seq,
            stamp: Time {
                secs: 1_795_000_000u32 as i32,
                nsecs: 123_456_789,
            },
            frame_id: frame.to_owned(),
        };
        let q = |yaw: f64| {
            let [x, y, z, w] = crate::api::ros1::yaw_quaternion(yaw);
            geometry_msgs::Quaternion { x, y, z, w }
        };
        let on_wire = |msg_type: &str, msg: &serde_json::Value| {
            wire(MESSAGE_REGISTRY.get(msg_type).expect("generated"), msg).expect("fits")
        };

        let odom = crate::fusion::odometry::OdomPose {
            x: 1.5,
            y: -2.25,
            yaw: 0.3,
            v: 0.4,
            w: -0.1,
        };
        let mut covariance = OdometryCovariance {
            pose: [0.0; 36],
            twist: [0.0; 36],
        };
        covariance.pose[0] = 0.01;
        covariance.twist[35] = 0.002;
        let typed = nav_msgs::Odometry {
            header: header(7, "odom"),
            child_frame_id: "base_link".into(),
            pose: geometry_msgs::PoseWithCovariance {
                pose: geometry_msgs::Pose {
                    position: geometry_msgs::Point {
                        x: 1.5,
                        y: -2.25,
                        z: 0.0,
                    },
                    orientation: q(0.3),
                },
                covariance: covariance.pose,
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
                covariance: covariance.twist,
            },
        };
        assert_eq!(
            on_wire(
                "nav_msgs/Odometry",
                &json::odometry(t, 7, &odom, &covariance)
            ),
            to_vec(&typed).unwrap()
        );

        let pose = crate::vehicle::Pose2D {
            x: 3.0,
            y: 4.0,
            yaw: -1.0,
        };
        let typed = geometry_msgs::PoseStamped {
            header: header(9, "map"),
            pose: geometry_msgs::Pose {
                position: geometry_msgs::Point {
                    x: 3.0,
                    y: 4.0,
                    z: 0.0,
                },
                orientation: q(-1.0),
            },
        };
        assert_eq!(
            on_wire(
                "geometry_msgs/PoseStamped",
                &json::pose_stamped(t, 9, &pose)
            ),
            to_vec(&typed).unwrap()
        );

        let report = crate::vehicle::PoseReport {
            odom: Some(odom),
            map: None,
            frames: None,
            localization: crate::vehicle::Localization::Uninitialized,
        };
        let typed = tf2_msgs::TFMessage {
            transforms: vec![geometry_msgs::TransformStamped {
                header: header(0, "odom"),
                child_frame_id: "base_link".into(),
                transform: geometry_msgs::Transform {
                    translation: geometry_msgs::Vector3 {
                        x: 1.5,
                        y: -2.25,
                        z: 0.0,
                    },
                    rotation: q(0.3),
                },
            }],
        };
        assert_eq!(
            on_wire("tf2_msgs/TFMessage", &json::tf(t, &report).unwrap()),
            to_vec(&typed).unwrap()
        );

        let noise = json::ImuNoise {
            gyro_rps: 0.01,
            accel_mps2: 0.05,
            orientation_rad: 0.02,
        };
        let sample = crate::devices::imu::ImuSample {
            rx: t,
            accel: nalgebra::Vector3::new(0.1, -0.2, 9.8),
            gyro: nalgebra::Vector3::new(0.001, 0.002, -0.3),
            orientation: None,
        };
        let diagonal = |v: f64| [v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v];
        let mut unknown = [0.0; 9];
        unknown[0] = -1.0;
        let typed = sensor_msgs::Imu {
            header: header(3, "base_link"),
            orientation: geometry_msgs::Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            },
            orientation_covariance: unknown,
            angular_velocity: geometry_msgs::Vector3 {
                x: 0.001,
                y: 0.002,
                z: -0.3,
            },
            angular_velocity_covariance: diagonal(0.01f64.powi(2)),
            linear_acceleration: geometry_msgs::Vector3 {
                x: 0.1,
                y: -0.2,
                z: 9.8,
            },
            linear_acceleration_covariance: diagonal(0.05f64.powi(2)),
        };
        assert_eq!(
            on_wire("sensor_msgs/Imu", &json::imu(&sample, 3, &noise)),
            to_vec(&typed).unwrap()
        );
        assert_eq!(
            on_wire("std_msgs/Int16", &json::code(41)),
            to_vec(&std_msgs::Int16 { data: 41 }).unwrap()
        );
    }

    #[test]
    fn every_advertised_topic_has_its_interface() {
        for topic in crate::api::ros1::topics::TOPICS {
            assert!(
                MESSAGE_REGISTRY.get(topic.msg_type).is_some(),
                "{}: no {} in crates/core/src/api/ros1/interfaces",
                topic.name,
                topic.msg_type
            );
        }
    }
}
