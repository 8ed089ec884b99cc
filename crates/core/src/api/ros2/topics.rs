//! Every topic the ROS 2 node has, each whole on one line: [`TOPICS`], what it publishes
//! (name, ROS 2 type, QoS, what makes it due and how its message is built), and [`TAKEN`],
//! what it subscribes to. The node's process creates its writers and readers from these
//! tables and [`super::publisher::Publishing`] publishes by the first, so a new topic is a
//! line here (and, of a new type, its interface files, from which build.rs generates the
//! type the message is checked and serialised through).

use serde_json::Value;

use super::messages::{self, Mounts};
use crate::api::ros1::messages as ros1;
use crate::api::ros1::messages::ImuNoise;
use crate::api::rosbridge::latches::Latches;
use crate::api::rosbridge::topics::Publish as State;
use crate::api::rosbridge::{envelope, messages as state};
use crate::devices::gnss::GnssFix;
use crate::devices::imu::ImuSample;
use crate::time::Timestamp;

/// How a topic's samples are delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reliability {
    /// Each sample acknowledged and sent again until it is, within the history kept.
    Reliable,
    /// Sent once: a lost sample is lost (ROS 2's sensor data QoS).
    BestEffort,
}

/// Whether a late subscriber gets what was published before it joined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    /// Only what comes after it.
    Volatile,
    /// The last `depth` samples too (ROS1's latching).
    TransientLocal,
}

/// A topic's QoS profile: reliability, durability and the samples kept (keep last).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Delivery.
    pub reliability: Reliability,
    /// Late joiners.
    pub durability: Durability,
    /// Samples kept per writer (and reader).
    pub depth: u32,
}

/// ROS 2's default profile: reliable, volatile, ten kept.
pub const STATE: Qos = Qos {
    reliability: Reliability::Reliable,
    durability: Durability::Volatile,
    depth: 10,
};
/// ROS 2's sensor data profile: best effort, volatile, five kept.
pub const SENSOR_DATA: Qos = Qos {
    reliability: Reliability::BestEffort,
    durability: Durability::Volatile,
    depth: 5,
};
/// A latched topic: reliable, transient local, the last one kept.
pub const LATCHED: Qos = Qos {
    reliability: Reliability::Reliable,
    durability: Durability::TransientLocal,
    depth: 1,
};
/// `/tf`'s: reliable, volatile, a hundred kept (as tf2's broadcasters).
const TF: Qos = Qos {
    reliability: Reliability::Reliable,
    durability: Durability::Volatile,
    depth: 100,
};
/// `/rosout`'s, as rcl gives every node's: reliable, transient local, a thousand kept.
const ROSOUT: Qos = Qos {
    reliability: Reliability::Reliable,
    durability: Durability::TransientLocal,
    depth: 1000,
};

/// What makes a topic due, and its message.
#[derive(Debug, Clone, Copy)]
pub enum Publish {
    /// From the status ticks, the odometry or the events: the rosbridge server's messages,
    /// at their rates (`/odom`'s from `ros2.odom_rate_hz`).
    State(State),
    /// Each IMU sample, with the IMU's noise.
    Imu(fn(&ImuSample, &ImuNoise) -> Value),
    /// Each new solution of the receiver (a position report), at the time it came.
    Fix(fn(Timestamp, &GnssFix) -> Value),
    /// Once, when the node starts: where the sensors sit.
    Static(fn(Timestamp, &Mounts) -> Value),
}

/// One topic the node publishes.
#[derive(Debug, Clone, Copy)]
pub struct Topic {
    /// Its name, under the node's namespace.
    pub name: &'static str,
    /// Its ROS 2 type (`package/msg/Type`), one of `interfaces/`.
    pub msg_type: &'static str,
    /// Its QoS.
    pub qos: Qos,
    /// What makes it due.
    pub publish: Publish,
}

/// `/odom`'s name.
pub const ODOM: &str = "/odom";

/// Every topic the node publishes, in the order a tick's messages go out.
pub const TOPICS: &[Topic] = &[
    Topic {
        name: ODOM,
        msg_type: "nav_msgs/msg/Odometry",
        qos: STATE,
        publish: Publish::State(State::Odometry {
            every: 2,
            build: state::odometry,
        }),
    },
    Topic {
        name: "/imu/data",
        msg_type: "sensor_msgs/msg/Imu",
        qos: SENSOR_DATA,
        publish: Publish::Imu(messages::imu),
    },
    Topic {
        name: "/fix",
        msg_type: "sensor_msgs/msg/NavSatFix",
        qos: STATE,
        publish: Publish::Fix(messages::fix),
    },
    Topic {
        name: "/pose",
        msg_type: "geometry_msgs/msg/PoseWithCovarianceStamped",
        qos: STATE,
        publish: Publish::State(State::Status {
            every: 1,
            build: state::pose,
        }),
    },
    Topic {
        name: "/tf",
        msg_type: "tf2_msgs/msg/TFMessage",
        qos: TF,
        publish: Publish::State(State::Status {
            every: 1,
            build: state::tf,
        }),
    },
    Topic {
        name: "/tf_static",
        msg_type: "tf2_msgs/msg/TFMessage",
        qos: LATCHED,
        publish: Publish::Static(messages::tf_static),
    },
    Topic {
        name: "/wheel_speeds",
        msg_type: "std_msgs/msg/Float64MultiArray",
        qos: STATE,
        publish: Publish::State(State::Status {
            every: 1,
            build: ros1::wheel_speeds,
        }),
    },
    Topic {
        name: "/safety_envelope",
        msg_type: "diagnostic_msgs/msg/DiagnosticStatus",
        qos: STATE,
        publish: Publish::State(State::Status {
            every: 1,
            build: |status| status.envelope.as_ref().map(envelope::status),
        }),
    },
    Topic {
        name: "/battery_state",
        msg_type: "sensor_msgs/msg/BatteryState",
        qos: STATE,
        publish: Publish::State(State::Status {
            every: 10,
            build: state::battery_state,
        }),
    },
    Topic {
        name: "/diagnostics",
        msg_type: "diagnostic_msgs/msg/DiagnosticArray",
        qos: STATE,
        publish: Publish::State(State::Status {
            every: 10,
            build: |status| Some(state::diagnostics(status)),
        }),
    },
    Topic {
        name: "/drive_mode",
        msg_type: "std_msgs/msg/String",
        qos: STATE,
        publish: Publish::State(State::Status {
            every: 10,
            build: ros1::drive_mode,
        }),
    },
    Topic {
        name: "/plan",
        msg_type: "nav_msgs/msg/Path",
        qos: LATCHED,
        publish: Publish::State(State::Latched(Latches::plan)),
    },
    Topic {
        name: "/zones",
        msg_type: "visualization_msgs/msg/MarkerArray",
        qos: LATCHED,
        publish: Publish::State(State::Latched(Latches::zones)),
    },
    Topic {
        name: "/rosout",
        msg_type: "rcl_interfaces/msg/Log",
        qos: ROSOUT,
        publish: Publish::State(State::Event(state::log)),
    },
];

/// One topic the node subscribes to (with `ros2.accept_commands`).
#[derive(Debug, Clone, Copy)]
pub struct Taken {
    /// Its name, under the node's namespace.
    pub name: &'static str,
    /// Its ROS 2 type.
    pub msg_type: &'static str,
    /// The reader's QoS.
    pub qos: Qos,
}

/// `/cmd_vel`'s name (both of its types).
pub const CMD_VEL: &str = "/cmd_vel";
/// `/goal_pose`'s name: RViz2's "2D Goal Pose".
pub const GOAL_POSE: &str = "/goal_pose";
/// `/initialpose`'s name: RViz2's "2D Pose Estimate".
pub const INITIAL_POSE: &str = "/initialpose";
/// `/cmd_vel`'s stamped type (Jazzy's diff_drive_controller, nav2's `enable_stamped_cmd_vel`).
pub const TWIST_STAMPED: &str = "geometry_msgs/msg/TwistStamped";

/// Every topic the node subscribes to. `/cmd_vel` is read best effort, which matches every
/// publisher (a reliable reader would not hear a best-effort teleop); goals and poses are
/// read reliably, as RViz2 sends them.
pub const TAKEN: &[Taken] = &[
    Taken {
        name: CMD_VEL,
        msg_type: "geometry_msgs/msg/Twist",
        qos: SENSOR_DATA,
    },
    Taken {
        name: CMD_VEL,
        msg_type: TWIST_STAMPED,
        qos: SENSOR_DATA,
    },
    Taken {
        name: GOAL_POSE,
        msg_type: "geometry_msgs/msg/PoseStamped",
        qos: STATE,
    },
    Taken {
        name: INITIAL_POSE,
        msg_type: "geometry_msgs/msg/PoseWithCovarianceStamped",
        qos: STATE,
    },
];

/// The published topic called `name`.
pub fn find(name: &str) -> Option<&'static Topic> {
    TOPICS.iter().find(|t| t.name == name)
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
        let types = TOPICS
            .iter()
            .map(|t| t.msg_type)
            .chain(TAKEN.iter().map(|t| t.msg_type));
        for msg_type in types {
            let parts: Vec<&str> = msg_type.split('/').collect();
            assert!(
                parts.len() == 3 && parts[1] == "msg" && parts.iter().all(|p| !p.is_empty()),
                "{msg_type} is not package/msg/Type"
            );
        }
    }

    #[test]
    fn what_a_late_subscriber_needs_is_kept_for_it() {
        for name in ["/plan", "/zones", "/tf_static", "/rosout"] {
            let topic = find(name).unwrap();
            assert_eq!(topic.qos.durability, Durability::TransientLocal, "{name}");
            assert_eq!(topic.qos.reliability, Reliability::Reliable, "{name}");
        }
        let volatile = TOPICS
            .iter()
            .filter(|t| t.qos.durability == Durability::Volatile)
            .count();
        assert_eq!(volatile, TOPICS.len() - 4);
    }

    /// The spec's topics that chassisd does not have are not published: they belong to a
    /// mapping stack, a lidar driver and a navigation stack's localiser.
    #[test]
    fn the_spec_topics_chassisd_lacks_are_not_published() {
        for name in ["/map", "/scan", "/amcl_pose"] {
            assert!(find(name).is_none(), "{name}");
            assert!(
                crate::api::rosbridge::topics::refusal(name).is_some(),
                "{name} has its reason"
            );
        }
    }
}
