//! The ROS1 types generated from `src/api/ros1/interfaces` (build.rs), and the messages
//! built from the core's poses and samples, stamped and framed by REP-103/105.

include!(concat!(env!("OUT_DIR"), "/ros1_interfaces.rs"));

use crate::api::ros1::odometry::OdometryCovariance;
use crate::api::ros1::{BASE_FRAME, MAP_FRAME, ODOM_FRAME, ros_time, yaw_quaternion};
use crate::devices::imu::ImuSample;
use crate::fusion::odometry::OdomPose;
use crate::time::Timestamp;
use crate::vehicle::{Pose2D, PoseReport};

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

/// The IMU's noise, 1σ, for `/imu/data`'s covariances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuNoise {
    /// Angular rate, rad/s.
    pub gyro_rps: f64,
    /// Specific force, m/s².
    pub accel_mps2: f64,
    /// The sensor's own orientation, rad.
    pub orientation_rad: f64,
}

fn header(t: Timestamp, seq: u32, frame: &str) -> std_msgs::Header {
    let (secs, nsecs) = ros_time(t);
    std_msgs::Header {
        seq,
        // ROS1 time is two uint32 on the wire; roslibrust types them i32, which carries the
        // same 32 bits.
        stamp: roslibrust::codegen::integral_types::Time {
            secs: secs as i32,
            nsecs: nsecs as i32,
        },
        frame_id: frame.to_owned(),
    }
}

fn quaternion([x, y, z, w]: [f64; 4]) -> geometry_msgs::Quaternion {
    geometry_msgs::Quaternion { x, y, z, w }
}

fn vector(v: &nalgebra::Vector3<f64>) -> geometry_msgs::Vector3 {
    geometry_msgs::Vector3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

/// A diagonal 3×3 covariance, row-major.
fn diagonal(variance: f64) -> [f64; 9] {
    let mut m = [0.0; 9];
    m[0] = variance;
    m[4] = variance;
    m[8] = variance;
    m
}

/// `/raw_odom`: the `odom` frame's pose and the speeds in the vehicle frame.
pub fn odometry(
    t: Timestamp,
    seq: u32,
    odom: &OdomPose,
    covariance: &OdometryCovariance,
) -> nav_msgs::Odometry {
    nav_msgs::Odometry {
        header: header(t, seq, ODOM_FRAME),
        child_frame_id: BASE_FRAME.to_owned(),
        pose: geometry_msgs::PoseWithCovariance {
            pose: geometry_msgs::Pose {
                position: geometry_msgs::Point {
                    x: odom.x,
                    y: odom.y,
                    z: 0.0,
                },
                orientation: quaternion(yaw_quaternion(odom.yaw)),
            },
            covariance: covariance.pose,
        },
        twist: geometry_msgs::TwistWithCovariance {
            twist: geometry_msgs::Twist {
                linear: geometry_msgs::Vector3 {
                    x: odom.v,
                    y: 0.0,
                    z: 0.0,
                },
                angular: geometry_msgs::Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: odom.w,
                },
            },
            covariance: covariance.twist,
        },
    }
}

/// `/tracked_pose`: the fused pose in the map frame.
pub fn pose_stamped(t: Timestamp, seq: u32, pose: &Pose2D) -> geometry_msgs::PoseStamped {
    geometry_msgs::PoseStamped {
        header: header(t, seq, MAP_FRAME),
        pose: geometry_msgs::Pose {
            position: geometry_msgs::Point {
                x: pose.x,
                y: pose.y,
                z: 0.0,
            },
            orientation: quaternion(yaw_quaternion(pose.yaw)),
        },
    }
}

/// One transform: `child` placed at `pose` in `parent`.
fn transform(
    t: Timestamp,
    parent: &str,
    child: &str,
    pose: &Pose2D,
) -> geometry_msgs::TransformStamped {
    geometry_msgs::TransformStamped {
        // tf ignores seq; each transform's is 0, as tf's own broadcasters leave it.
        header: header(t, 0, parent),
        child_frame_id: child.to_owned(),
        transform: geometry_msgs::Transform {
            translation: geometry_msgs::Vector3 {
                x: pose.x,
                y: pose.y,
                z: 0.0,
            },
            rotation: quaternion(yaw_quaternion(pose.yaw)),
        },
    }
}

/// `/tf`: map→odom (the correction GNSS estimates) and odom→base_link (the dead reckoning)
/// once the vehicle is placed, odom→base_link alone before; `None` without odometry.
pub fn tf(t: Timestamp, report: &PoseReport) -> Option<tf2_msgs::TFMessage> {
    let transforms = match (report.frames, report.odom) {
        (Some(f), _) => vec![
            transform(t, MAP_FRAME, ODOM_FRAME, &f.map_to_odom),
            transform(t, ODOM_FRAME, BASE_FRAME, &f.odom_to_base),
        ],
        (None, Some(o)) => vec![transform(
            t,
            ODOM_FRAME,
            BASE_FRAME,
            &Pose2D {
                x: o.x,
                y: o.y,
                yaw: o.yaw,
            },
        )],
        (None, None) => return None,
    };
    Some(tf2_msgs::TFMessage { transforms })
}

/// `/imu/data`: a sample in the vehicle frame (the mounting applied), stamped when it was
/// received. Without the sensor's own orientation, orientation_covariance[0] is -1, as
/// sensor_msgs/Imu says.
pub fn imu(sample: &ImuSample, seq: u32, noise: &ImuNoise) -> sensor_msgs::Imu {
    let (orientation, orientation_covariance) = match sample.orientation {
        Some(q) => (
            quaternion([q.i, q.j, q.k, q.w]),
            diagonal(noise.orientation_rad.powi(2)),
        ),
        None => {
            let mut unknown = [0.0; 9];
            unknown[0] = -1.0;
            (quaternion([0.0, 0.0, 0.0, 1.0]), unknown)
        }
    };
    sensor_msgs::Imu {
        header: header(sample.rx, seq, BASE_FRAME),
        orientation,
        orientation_covariance,
        angular_velocity: vector(&sample.gyro),
        angular_velocity_covariance: diagonal(noise.gyro_rps.powi(2)),
        linear_acceleration: vector(&sample.accel),
        linear_acceleration_covariance: diagonal(noise.accel_mps2.powi(2)),
    }
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

    #[test]
    fn every_published_topic_has_its_interface() {
        for topic in crate::api::ros1::published::STATUS_TOPICS {
            assert!(
                MESSAGE_REGISTRY.get(topic.msg_type).is_some(),
                "{}: no {} in src/api/ros1/interfaces",
                topic.name,
                topic.msg_type
            );
        }
    }
}
