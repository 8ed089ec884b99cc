//! Cost of what the ROS1 node publishes, per message: each built as JSON of its ROS1 type
//! (`api::ros1::messages`), checked by its generated type and serialised for the wire
//! (`runtime::links::ros1::messages::wire`), against the typed message the node serialised
//! before. `/raw_odom` goes out at 100 Hz and `/imu/data` at the IMU's rate (up to 200 Hz),
//! so a message must cost well under the 10 ms control period.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};

use chassisd::api::ros1::messages::{self, ImuNoise};
use chassisd::api::ros1::odometry::OdometryCovariance;
use chassisd::devices::imu::ImuSample;
use chassisd::fusion::odometry::OdomPose;
use chassisd::runtime::links::ros1::messages::{MESSAGE_REGISTRY, nav_msgs, wire};
use chassisd::time::Timestamp;

fn ros1(c: &mut Criterion) {
    let t = Timestamp::from_nanos(1_795_000_000_123_456_789);
    let odom = OdomPose {
        x: 12.5,
        y: -3.25,
        yaw: 0.7,
        v: 0.8,
        w: 0.1,
    };
    let covariance = OdometryCovariance {
        pose: [0.01; 36],
        twist: [0.002; 36],
    };
    let odometry = MESSAGE_REGISTRY
        .get("nav_msgs/Odometry")
        .expect("generated");
    c.bench_function("ros1/raw_odom json+wire", |b| {
        b.iter(|| {
            let msg = messages::odometry(t, black_box(7), &odom, &covariance);
            wire(odometry, &msg).expect("fits")
        })
    });
    let msg = messages::odometry(t, 7, &odom, &covariance);
    let typed: nav_msgs::Odometry =
        serde_json::from_value(msg).expect("the JSON is the typed message's");
    c.bench_function("ros1/raw_odom typed (before)", |b| {
        b.iter(|| roslibrust_serde_rosmsg::to_vec(black_box(&typed)).expect("serialises"))
    });
    let imu = MESSAGE_REGISTRY.get("sensor_msgs/Imu").expect("generated");
    let sample = ImuSample {
        rx: t,
        accel: nalgebra::Vector3::new(0.1, -0.2, 9.8),
        gyro: nalgebra::Vector3::new(0.001, 0.002, -0.3),
        orientation: None,
    };
    let noise = ImuNoise {
        gyro_rps: 0.01,
        accel_mps2: 0.05,
        orientation_rad: 0.02,
    };
    c.bench_function("ros1/imu json+wire", |b| {
        b.iter(|| wire(imu, &messages::imu(&sample, black_box(3), &noise)).expect("fits"))
    });
}

criterion_group!(benches, ros1);
criterion_main!(benches);
