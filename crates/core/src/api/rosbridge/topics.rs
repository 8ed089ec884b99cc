//! Which topics and services the server has, with their types and rates, and the ones it
//! refuses with the reason.

/// How a topic flows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Flow {
    /// chassisd publishes it, at about this rate (Hz; 0 when it changes).
    Published(f64),
    /// Clients publish it.
    Subscribed,
}

/// One topic.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Topic {
    /// Its name.
    pub name: &'static str,
    /// Its ROS 2 type.
    pub msg_type: &'static str,
    /// Its direction.
    pub flow: Flow,
}

/// The fused pose.
pub const POSE: &str = "/pose";
/// The wheel odometry.
pub const ODOM: &str = "/odom";
/// The frame tree: map→odom (the GNSS correction) and odom→base_link (the dead reckoning).
pub const TF: &str = "/tf";
/// The battery.
pub const BATTERY_STATE: &str = "/battery_state";
/// The health of each part.
pub const DIAGNOSTICS: &str = "/diagnostics";
/// The wheels' measured speeds.
pub const WHEEL_SPEEDS: &str = "/wheel_speeds";
/// Who may drive.
pub const DRIVE_MODE: &str = "/drive_mode";
/// The path of the move under way.
pub const PLAN: &str = "/plan";
/// The zones, as markers (latched: sent to a new subscriber at once, then on change).
pub const ZONES: &str = "/zones";
/// The gate and the vehicle's margin from the nearest zone.
pub const SAFETY_ENVELOPE: &str = "/safety_envelope";
/// The engine's events.
pub const ROSOUT: &str = "/rosout";
/// A goal to drive to.
pub const GOAL_POSE: &str = "/goal_pose";
/// A velocity command.
pub const CMD_VEL: &str = "/cmd_vel";

/// Every topic the server has.
pub const TOPICS: &[Topic] = &[
    Topic {
        name: POSE,
        msg_type: "geometry_msgs/msg/PoseWithCovarianceStamped",
        flow: Flow::Published(10.0),
    },
    Topic {
        name: ODOM,
        msg_type: "nav_msgs/msg/Odometry",
        flow: Flow::Published(50.0),
    },
    Topic {
        name: TF,
        msg_type: "tf2_msgs/msg/TFMessage",
        flow: Flow::Published(10.0),
    },
    Topic {
        name: BATTERY_STATE,
        msg_type: "sensor_msgs/msg/BatteryState",
        flow: Flow::Published(1.0),
    },
    Topic {
        name: DIAGNOSTICS,
        msg_type: "diagnostic_msgs/msg/DiagnosticArray",
        flow: Flow::Published(1.0),
    },
    Topic {
        name: WHEEL_SPEEDS,
        msg_type: "std_msgs/msg/Float64MultiArray",
        flow: Flow::Published(10.0),
    },
    Topic {
        name: DRIVE_MODE,
        msg_type: "std_msgs/msg/String",
        flow: Flow::Published(1.0),
    },
    Topic {
        name: PLAN,
        msg_type: "nav_msgs/msg/Path",
        flow: Flow::Published(0.0),
    },
    Topic {
        name: ZONES,
        msg_type: "visualization_msgs/msg/MarkerArray",
        flow: Flow::Published(0.0),
    },
    Topic {
        name: SAFETY_ENVELOPE,
        msg_type: "diagnostic_msgs/msg/DiagnosticStatus",
        flow: Flow::Published(10.0),
    },
    Topic {
        name: ROSOUT,
        msg_type: "rcl_interfaces/msg/Log",
        flow: Flow::Published(0.0),
    },
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

/// The topics whose last message goes to a new subscriber at once (what matters until it
/// changes: the path under way, the zones).
pub const LATCHED: &[&str] = &[PLAN, ZONES];

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
