//! Every topic the server has, each whole on one line of [`TOPICS`]: its name, its ROS 2
//! type, and either what makes chassisd publish it and how its message is built, or that
//! clients publish it. `/rosapi/topics` lists this table, `subscribe` and `advertise` check
//! against it and [`super::publisher::Publishing`] publishes by it, so a new published topic
//! is a line here and its message. Also the topics it refuses, with the reason.

use serde_json::Value;

use super::latches::Latches;
use super::{envelope, messages};
use crate::api::ros1::messages as ros1;
use crate::api::ros1::odometry::OdometryCovariance;
use crate::fusion::odometry::OdomPose;
use crate::time::Timestamp;
use crate::vehicle::VehicleStatus;

/// How a topic flows.
#[derive(Debug, Clone, Copy)]
pub enum Flow {
    /// chassisd publishes it.
    Published(Publish),
    /// Clients publish it.
    Subscribed,
}

/// What makes chassisd publish a topic, and how its message is built (`None`: nothing to
/// say this time). Messages are built only for a subscriber that is due for one, except a
/// latched topic's, which is kept for the next subscriber.
#[derive(Debug, Clone, Copy)]
pub enum Publish {
    /// Every `every`th status tick (10 Hz).
    Status {
        /// Status ticks from one message to the next.
        every: u64,
        /// Its message.
        build: fn(&VehicleStatus) -> Option<Value>,
    },
    /// Every `every`th control tick (100 Hz) with an `odom` pose, and the covariance
    /// integrated over the ticks that carry one.
    Odometry {
        /// Control ticks from one message to the next.
        every: u64,
        /// Its message.
        build: fn(Timestamp, &OdomPose, &OdometryCovariance) -> Value,
    },
    /// Latched: when what it carries changes (and first at the first status), and at once
    /// to a new subscriber. Its message, when [`Latches`] finds it changed.
    Latched(fn(&mut Latches, &VehicleStatus) -> Option<Value>),
    /// Each of the engine's events, stamped when the server takes it.
    Event(fn(Timestamp, &str) -> Value),
}

/// One topic.
#[derive(Debug, Clone, Copy)]
pub struct Topic {
    /// Its name.
    pub name: &'static str,
    /// Its ROS 2 type.
    pub msg_type: &'static str,
    /// Its direction.
    pub flow: Flow,
}

impl Topic {
    /// Whether a new subscriber gets its last message at once.
    pub fn is_latched(&self) -> bool {
        matches!(self.flow, Flow::Published(Publish::Latched(_)))
    }
}

/// A goal to drive to.
pub const GOAL_POSE: &str = "/goal_pose";
/// A velocity command.
pub const CMD_VEL: &str = "/cmd_vel";

/// A topic chassisd publishes.
const fn published(name: &'static str, msg_type: &'static str, publish: Publish) -> Topic {
    Topic {
        name,
        msg_type,
        flow: Flow::Published(publish),
    }
}

/// Every topic the server has, in the order `/rosapi/topics` lists them. Within a status
/// tick the faster topics go out first, each rate in this order.
pub const TOPICS: &[Topic] = &[
    // The fused pose.
    published(
        "/pose",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        Publish::Status {
            every: 1,
            build: messages::pose,
        },
    ),
    // The wheel odometry, by default at 50 Hz (`every: 2`); `websocket.odom_rate_hz` (ROS 2:
    // `ros2.odom_rate_hz`) sets the rate the server publishes.
    published(
        "/odom",
        "nav_msgs/msg/Odometry",
        Publish::Odometry {
            every: 2,
            build: messages::odometry,
        },
    ),
    // The frame tree: map→odom (the GNSS correction) and odom→base_link (the dead
    // reckoning).
    published(
        "/tf",
        "tf2_msgs/msg/TFMessage",
        Publish::Status {
            every: 1,
            build: messages::tf,
        },
    ),
    published(
        "/battery_state",
        "sensor_msgs/msg/BatteryState",
        Publish::Status {
            every: 10,
            build: messages::battery_state,
        },
    ),
    // The health of each part.
    published(
        "/diagnostics",
        "diagnostic_msgs/msg/DiagnosticArray",
        Publish::Status {
            every: 10,
            build: |status| Some(messages::diagnostics(status)),
        },
    ),
    // std_msgs keeps its fields in ROS 2: the ROS1 node's messages.
    published(
        "/wheel_speeds",
        "std_msgs/msg/Float64MultiArray",
        Publish::Status {
            every: 1,
            build: ros1::wheel_speeds,
        },
    ),
    published(
        "/drive_mode",
        "std_msgs/msg/String",
        Publish::Status {
            every: 10,
            build: ros1::drive_mode,
        },
    ),
    // The path of the move under way.
    published(
        "/plan",
        "nav_msgs/msg/Path",
        Publish::Latched(Latches::plan),
    ),
    // The zones, as markers.
    published(
        "/zones",
        "visualization_msgs/msg/MarkerArray",
        Publish::Latched(Latches::zones),
    ),
    // The gate and the vehicle's margin from the nearest zone.
    published(
        "/safety_envelope",
        "diagnostic_msgs/msg/DiagnosticStatus",
        Publish::Status {
            every: 1,
            build: |status| status.envelope.as_ref().map(envelope::status),
        },
    ),
    // The engine's events.
    published(
        "/rosout",
        "rcl_interfaces/msg/Log",
        Publish::Event(messages::log),
    ),
    Topic {
        name: GOAL_POSE,
        msg_type: "geometry_msgs/msg/PoseStamped",
        flow: Flow::Subscribed,
    },
    Topic {
        name: CMD_VEL,
        msg_type: "geometry_msgs/msg/Twist",
        flow: Flow::Subscribed,
    },
];

/// The topic called `name`.
pub fn find(name: &str) -> Option<&'static Topic> {
    TOPICS.iter().find(|t| t.name == name)
}

/// Why a topic of the spec (or a usual one) that chassisd does not have is refused.
pub fn refusal(name: &str) -> Option<&'static str> {
    Some(match name {
        "/map" => {
            "/map (nav_msgs/OccupancyGrid) belongs to a mapping stack; chassisd has no map. \
             Run the mapping stack's own rosbridge for it"
        }
        "/scan" => {
            "/scan (sensor_msgs/LaserScan) belongs to a lidar driver; chassisd reads no lidar"
        }
        "/amcl_pose" => {
            "/amcl_pose belongs to a navigation stack's localiser (AMCL); chassisd publishes \
             its fused pose on /pose"
        }
        _ => return None,
    })
}

/// Whether a client's `type` names `topic`'s type: ROS 1 spelling (`geometry_msgs/Twist`)
/// and ROS 2 spelling (`geometry_msgs/msg/Twist`) both do.
pub fn type_matches(topic: &Topic, given: &str) -> bool {
    given == topic.msg_type || given == topic.msg_type.replacen("/msg/", "/", 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_topic_is_named_once_with_a_ros2_type() {
        let mut names: Vec<&str> = TOPICS.iter().map(|t| t.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), TOPICS.len());
        for topic in TOPICS {
            let mut parts = topic.msg_type.split('/');
            assert!(
                parts.next().is_some_and(|p| !p.is_empty())
                    && parts.next() == Some("msg")
                    && parts.next().is_some_and(|p| !p.is_empty())
                    && parts.next().is_none(),
                "{}: {} is not package/msg/Type",
                topic.name,
                topic.msg_type
            );
        }
    }

    #[test]
    fn only_the_plan_and_the_zones_are_latched() {
        let latched: Vec<&str> = TOPICS
            .iter()
            .filter(|t| t.is_latched())
            .map(|t| t.name)
            .collect();
        assert_eq!(latched, ["/plan", "/zones"]);
    }

    #[test]
    fn both_spellings_of_a_type_match() {
        let twist = find(CMD_VEL).unwrap();
        assert!(type_matches(twist, "geometry_msgs/Twist"));
        assert!(type_matches(twist, "geometry_msgs/msg/Twist"));
        assert!(!type_matches(twist, "geometry_msgs/TwistStamped"));
    }

    #[test]
    fn the_spec_topics_chassisd_lacks_say_whose_they_are() {
        assert!(refusal("/map").unwrap().contains("mapping stack"));
        assert!(refusal("/scan").unwrap().contains("lidar"));
        assert!(refusal("/amcl_pose").unwrap().contains("/pose"));
        assert!(refusal("/pose").is_none());
    }
}
