//! The messages the node publishes, as JSON of their ROS1 types (the field names of
//! `interfaces/`), built from the core's poses, samples, status and codes, stamped and framed by
//! REP-103/105. The node serialises each through its generated type, which checks every
//! field.

use serde_json::{Value, json};

use super::odometry::OdometryCovariance;
use super::{BASE_FRAME, MAP_FRAME, ODOM_FRAME, ros_time, yaw_quaternion};
use crate::devices::imu::ImuSample;
use crate::fusion::odometry::OdomPose;
use crate::time::Timestamp;
use crate::vehicle::chassis::DriveMode;
use crate::vehicle::{Pose2D, PoseReport, VehicleStatus};

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

/// std_msgs/Header. ROS1 time is two uint32 on the wire; the generated type holds them as
/// i32, which carries the same 32 bits.
pub fn header(t: Timestamp, seq: u32, frame: &str) -> Value {
    let (secs, nsecs) = ros_time(t);
    json!({
        "seq": seq,
        "stamp": {"secs": secs as i32, "nsecs": nsecs as i32},
        "frame_id": frame,
    })
}

/// geometry_msgs/Quaternion.
pub fn quaternion([x, y, z, w]: [f64; 4]) -> Value {
    json!({"x": x, "y": y, "z": z, "w": w})
}

fn vector(v: &nalgebra::Vector3<f64>) -> Value {
    json!({"x": v.x, "y": v.y, "z": v.z})
}

/// A diagonal 3×3 covariance, row-major.
pub fn diagonal(variance: f64) -> [f64; 9] {
    let mut m = [0.0; 9];
    m[0] = variance;
    m[4] = variance;
    m[8] = variance;
    m
}

/// A planar pose: z 0, a rotation about z.
fn pose(x: f64, y: f64, yaw: f64) -> Value {
    json!({
        "position": {"x": x, "y": y, "z": 0.0},
        "orientation": quaternion(yaw_quaternion(yaw)),
    })
}

/// `/raw_odom` (nav_msgs/Odometry): the `odom` frame's pose and the speeds in the vehicle
/// frame.
pub fn odometry(t: Timestamp, seq: u32, odom: &OdomPose, covariance: &OdometryCovariance) -> Value {
    json!({
        "header": header(t, seq, ODOM_FRAME),
        "child_frame_id": BASE_FRAME,
        "pose": {
            "pose": pose(odom.x, odom.y, odom.yaw),
            "covariance": covariance.pose.to_vec(),
        },
        "twist": {
            "twist": {
                "linear": {"x": odom.v, "y": 0.0, "z": 0.0},
                "angular": {"x": 0.0, "y": 0.0, "z": odom.w},
            },
            "covariance": covariance.twist.to_vec(),
        },
    })
}

/// `/tracked_pose` (geometry_msgs/PoseStamped): the fused pose in the map frame.
pub fn pose_stamped(t: Timestamp, seq: u32, p: &Pose2D) -> Value {
    json!({"header": header(t, seq, MAP_FRAME), "pose": pose(p.x, p.y, p.yaw)})
}

/// One transform: `child` placed at `p` in `parent`.
fn transform(t: Timestamp, parent: &str, child: &str, p: &Pose2D) -> Value {
    json!({
        // tf ignores seq; each transform's is 0, as tf's own broadcasters leave it.
        "header": header(t, 0, parent),
        "child_frame_id": child,
        "transform": {
            "translation": {"x": p.x, "y": p.y, "z": 0.0},
            "rotation": quaternion(yaw_quaternion(p.yaw)),
        },
    })
}

/// `/tf` (tf2_msgs/TFMessage): map→odom (the correction GNSS estimates) and odom→base_link
/// (the dead reckoning) once the vehicle is placed, odom→base_link alone before; `None`
/// without odometry.
pub fn tf(t: Timestamp, report: &PoseReport) -> Option<Value> {
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
    Some(json!({"transforms": transforms}))
}

/// `/imu/data` (sensor_msgs/Imu): a sample in the vehicle frame (the mounting applied),
/// stamped when it was received.
pub fn imu(sample: &ImuSample, seq: u32, noise: &ImuNoise) -> Value {
    let mut msg = imu_fields(sample, noise);
    msg.insert("header".into(), header(sample.rx, seq, BASE_FRAME));
    Value::Object(msg)
}

/// sensor_msgs/Imu's fields but its header (the same in ROS1 and ROS 2). Without the
/// sensor's own orientation, orientation_covariance[0] is -1, as sensor_msgs/Imu says.
pub fn imu_fields(sample: &ImuSample, noise: &ImuNoise) -> serde_json::Map<String, Value> {
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
    [
        ("orientation", orientation),
        ("orientation_covariance", json!(orientation_covariance)),
        ("angular_velocity", vector(&sample.gyro)),
        (
            "angular_velocity_covariance",
            json!(diagonal(noise.gyro_rps.powi(2))),
        ),
        ("linear_acceleration", vector(&sample.accel)),
        (
            "linear_acceleration_covariance",
            json!(diagonal(noise.accel_mps2.powi(2))),
        ),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v))
    .collect()
}

/// A status code topic's std_msgs/Int16.
pub fn code(data: i16) -> Value {
    json!({"data": data})
}

/// `/wheel_speeds` (std_msgs/Float64MultiArray): the left and the right wheel's measured
/// surface speed, m/s (forward positive); nothing without a drive train. The rosbridge server
/// publishes the same message (std_msgs keeps its fields in ROS 2).
pub fn wheel_speeds(status: &VehicleStatus) -> Option<Value> {
    let odometry = status.chassis.as_ref()?.odometry;
    Some(json!({
        "layout": {
            "dim": [{"label": "left_right", "size": 2, "stride": 2}],
            "data_offset": 0,
        },
        "data": [odometry.left_mps, odometry.right_mps],
    }))
}

/// `/drive_mode` (std_msgs/String): who may drive, `manual` (velocity commands) or
/// `navigation` (autonomous moves only); nothing without a drive train. Rosbridge publishes
/// it too.
pub fn drive_mode(status: &VehicleStatus) -> Option<Value> {
    let mode = match status.mode? {
        DriveMode::Manual => "manual",
        DriveMode::Navigation => "navigation",
    };
    Some(json!({ "data": mode }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wheel_speeds_are_left_then_right() {
        let mut status = VehicleStatus::default();
        assert!(wheel_speeds(&status).is_none(), "no drive train, no speeds");
        status.chassis = Some(crate::vehicle::chassis::ChassisStatus {
            odometry: crate::vehicle::chassis::WheelOdometry {
                left_mps: 0.25,
                right_mps: 0.5,
                ..Default::default()
            },
            ..Default::default()
        });
        let msg = wheel_speeds(&status).unwrap();
        assert_eq!(msg["data"], json!([0.25, 0.5]));
        assert_eq!(msg["layout"]["dim"][0]["size"], 2);
    }

    #[test]
    fn the_drive_mode_is_named() {
        let mut status = VehicleStatus::default();
        assert!(drive_mode(&status).is_none(), "no drive train, no mode");
        status.mode = Some(DriveMode::Navigation);
        assert_eq!(drive_mode(&status), Some(json!({"data": "navigation"})));
        status.mode = Some(DriveMode::Manual);
        assert_eq!(drive_mode(&status), Some(json!({"data": "manual"})));
    }
}
