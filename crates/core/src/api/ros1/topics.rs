//! Every topic the node publishes, each whole on one line of [`TOPICS`]: its name, its ROS
//! type (one of `interfaces/`), what it keeps for a slow subscriber, what makes it due and
//! how its message is built. The node advertises this table and
//! [`super::publisher::Publishing`] publishes by it, so a new topic is a line here (and, of
//! a new type, its interface files: the node serialises the JSON through the type build.rs
//! generates from them, which checks every field).

use std::time::Duration;

use serde_json::Value;

use super::messages::{self, ImuNoise};
use super::odometry::OdometryCovariance;
use super::status;
use crate::devices::imu::ImuSample;
use crate::time::Timestamp;
use crate::vehicle::{PoseReport, VehicleStatus};

/// One topic the node publishes.
#[derive(Debug, Clone, Copy)]
pub struct Topic {
    /// Its name.
    pub name: &'static str,
    /// Its ROS type (`package/Type`), one of `interfaces/`.
    pub msg_type: &'static str,
    /// Messages kept for a slow subscriber.
    pub queue: usize,
    /// Latched: a new subscriber gets the last message at once.
    pub latched: bool,
    /// What makes it due, and its message.
    pub publish: Publish,
}

/// What makes a topic due, and how its message is built (`None`: nothing to say this time).
#[derive(Debug, Clone, Copy)]
pub enum Publish {
    /// The poses of a control tick (100 Hz), at most once a `period` (`None`: every tick).
    Poses {
        /// The shortest time between two messages.
        period: Option<Duration>,
        /// Its message.
        build: fn(&PoseTick) -> Option<Value>,
    },
    /// Each IMU sample, with its sequence number and the IMU's noise.
    Imu(fn(&ImuSample, u32, &ImuNoise) -> Value),
    /// Every `every`th status tick (10 Hz); the sequence number is the tick's.
    Status {
        /// Status ticks from one message to the next.
        every: u64,
        /// Its message.
        build: fn(&VehicleStatus, u32) -> Option<Value>,
    },
    /// A status code (std_msgs/Int16), when [`status::StatusTopics`] says it changed.
    Code(status::Topic),
}

/// What a pose topic's message is built from.
#[derive(Debug, Clone, Copy)]
pub struct PoseTick<'a> {
    /// The control tick's time.
    pub t: Timestamp,
    /// Its poses.
    pub report: &'a PoseReport,
    /// The sequence number of the last `odom` pose.
    pub seq: u32,
    /// The `odom` pose's covariances, when the tick has one.
    pub covariance: Option<OdometryCovariance>,
}

/// `/tracked_pose`'s and `/tf`'s period (15 Hz).
const TRACKED_POSE_PERIOD: Duration = Duration::from_nanos(1_000_000_000 / 15);

/// A topic of the status codes: latched, one message kept, std_msgs/Int16.
const fn code(name: &'static str, topic: status::Topic) -> Topic {
    Topic {
        name,
        msg_type: "std_msgs/Int16",
        queue: 1,
        latched: true,
        publish: Publish::Code(topic),
    }
}

/// A topic kept ten messages deep for a slow subscriber, not latched.
const fn plain(name: &'static str, msg_type: &'static str, publish: Publish) -> Topic {
    Topic {
        name,
        msg_type,
        queue: 10,
        latched: false,
        publish,
    }
}

/// Every topic the node publishes, in the order it advertises them and a tick's messages
/// go out.
pub const TOPICS: &[Topic] = &[
    plain(
        "/raw_odom",
        "nav_msgs/Odometry",
        Publish::Poses {
            period: None,
            build: |p| {
                let covariance = p.covariance.as_ref()?;
                Some(messages::odometry(
                    p.t,
                    p.seq,
                    p.report.odom.as_ref()?,
                    covariance,
                ))
            },
        },
    ),
    plain("/imu/data", "sensor_msgs/Imu", Publish::Imu(messages::imu)),
    plain(
        "/tracked_pose",
        "geometry_msgs/PoseStamped",
        Publish::Poses {
            period: Some(TRACKED_POSE_PERIOD),
            build: |p| {
                let (pose, _) = p.report.map?;
                Some(messages::pose_stamped(p.t, p.seq, &pose))
            },
        },
    ),
    plain(
        "/tf",
        "tf2_msgs/TFMessage",
        Publish::Poses {
            period: Some(TRACKED_POSE_PERIOD),
            build: |p| messages::tf(p.t, p.report),
        },
    ),
    plain(
        "/wheel_speeds",
        "std_msgs/Float64MultiArray",
        Publish::Status {
            every: 1,
            build: |status, _| messages::wheel_speeds(status),
        },
    ),
    plain(
        "/drive_mode",
        "std_msgs/String",
        Publish::Status {
            every: 10,
            build: |status, _| messages::drive_mode(status),
        },
    ),
    code("/androidmsg_initstatus", status::Topic::Init),
    code("/androidmsg_emergencystatus", status::Topic::Emergency),
    code("/androidmsg_chargestatus", status::Topic::Charge),
    code("/power_report", status::Topic::Power),
    code("/androidmsg_locationstatus", status::Topic::Location),
    code("/androidmsg_navigationstatus", status::Topic::Navigation),
    code("/androidmsg_virtualmapstatus", status::Topic::VirtualMap),
];

/// The topic that carries the status code `code`.
pub fn of_code(code: status::Topic) -> Option<&'static Topic> {
    TOPICS
        .iter()
        .find(|t| matches!(t.publish, Publish::Code(c) if c == code))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_topic_is_named_once() {
        let mut names: Vec<&str> = TOPICS.iter().map(|t| t.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), TOPICS.len());
    }

    #[test]
    fn every_status_code_has_its_latched_int16_topic() {
        for code in status::Topic::ALL {
            let topic = of_code(code).expect("every status code is published");
            assert_eq!(topic.msg_type, "std_msgs/Int16", "{}", topic.name);
            assert!(topic.latched, "{}", topic.name);
        }
        let codes = TOPICS
            .iter()
            .filter(|t| matches!(t.publish, Publish::Code(_)))
            .count();
        assert_eq!(codes, status::Topic::ALL.len(), "one topic a code");
        assert!(
            TOPICS
                .iter()
                .filter(|t| t.latched)
                .all(|t| matches!(t.publish, Publish::Code(_))),
            "only the codes are latched"
        );
    }

    /// Each type's definition is in `interfaces/`, from which build.rs generates the type
    /// the node serialises through.
    #[test]
    fn every_type_has_its_interface_definition() {
        let interfaces =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/api/ros1/interfaces");
        for topic in TOPICS {
            let (package, name) = topic.msg_type.split_once('/').expect("package/Type");
            let definition = interfaces
                .join(package)
                .join("msg")
                .join(format!("{name}.msg"));
            assert!(
                definition.is_file(),
                "{}: no {}",
                topic.name,
                definition.display()
            );
        }
    }
}
