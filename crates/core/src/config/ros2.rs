//! `[ros2]`: the native ROS 2 node on DDS (the `ros2` feature): the topics of
//! device-mqtt-api.md, the odometry and frames a ROS 2 stack expects, and a
//! `navigate_to_pose` action server.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{ConfigError, check_range};

/// `[ros2]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Config {
    /// The DDS domain; `None`: `ROS_DOMAIN_ID` when it is set, else 0 (as every ROS 2 node).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub domain_id: Option<u16>,
    /// The namespace every topic and the action sit under (`""`: none, `/robot_1`).
    #[serde(default)]
    pub namespace: String,
    /// The node's name in the graph.
    #[serde(default = "default_node_name")]
    pub node_name: String,
    /// Where DDS discovery looks for peers.
    #[serde(default)]
    pub discovery: Discovery,
    /// The network interface DDS uses (its IPv4 address); `None`: loopback for
    /// `discovery = "localhost"`, every interface for `"subnet"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interface: Option<String>,
    /// Whether `/cmd_vel`, `/goal_pose`, `/initialpose` and `navigate_to_pose` are taken;
    /// `false` publishes only.
    #[serde(default = "default_true")]
    pub accept_commands: bool,
    /// How the vehicle's other nodes frame a service's requests (and so an action's);
    /// `None`: as `RMW_IMPLEMENTATION` says, else Fast DDS's (ROS 2's default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub middleware: Option<Middleware>,
    /// `/odom`'s rate, Hz (the control loop's 100 Hz at most).
    #[serde(default = "default_odom_rate_hz")]
    pub odom_rate_hz: f64,
    /// The frame ids of the messages and the transforms.
    #[serde(default)]
    pub frames: Ros2Frames,
    /// Messages taken per second on each subscribed topic (and goals on the action);
    /// beyond it they are dropped, counted and logged in a summary.
    #[serde(default = "default_command_rate_hz")]
    pub command_rate_hz: f64,
    /// Messages taken at once on a topic before `command_rate_hz` applies.
    #[serde(default = "default_command_burst")]
    pub command_burst: u32,
}

/// `ros2.discovery`, as ROS 2's `ROS_AUTOMATIC_DISCOVERY_RANGE`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Discovery {
    /// Peers on this machine only: DDS runs on the loopback interface.
    #[default]
    Localhost,
    /// Peers on the local network (multicast discovery on `interface`, or every one).
    Subnet,
}

/// `ros2.middleware`: the RMW implementation of the vehicle's other nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Middleware {
    /// `rmw_fastrtps_cpp`, ROS 2's default: a request's identity travels in the RTPS
    /// message.
    #[default]
    Fastdds,
    /// `rmw_cyclonedds_cpp`: a 16-byte header (client id, sequence number) in front of each
    /// request and reply.
    Cyclonedds,
}

/// `[ros2.frames]`: REP-105's names by default.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Frames {
    /// The fixed world frame the GNSS places the vehicle in.
    #[serde(default = "default_map")]
    pub map: String,
    /// The continuous, drifting odometry frame.
    #[serde(default = "default_odom")]
    pub odom: String,
    /// The vehicle's own frame.
    #[serde(default = "default_base")]
    pub base: String,
    /// The GNSS antenna (`/fix`'s frame).
    #[serde(default = "default_gnss")]
    pub gnss: String,
    /// The IMU as mounted.
    #[serde(default = "default_imu")]
    pub imu: String,
}

fn default_node_name() -> String {
    "chassisd".into()
}

fn default_true() -> bool {
    true
}

fn default_odom_rate_hz() -> f64 {
    50.0
}

fn default_command_rate_hz() -> f64 {
    100.0
}

fn default_command_burst() -> u32 {
    20
}

fn default_map() -> String {
    "map".into()
}

fn default_odom() -> String {
    "odom".into()
}

fn default_base() -> String {
    "base_link".into()
}

fn default_gnss() -> String {
    "gnss_link".into()
}

fn default_imu() -> String {
    "imu_link".into()
}

impl Default for Ros2Frames {
    fn default() -> Self {
        Self {
            map: default_map(),
            odom: default_odom(),
            base: default_base(),
            gnss: default_gnss(),
            imu: default_imu(),
        }
    }
}

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            domain_id: None,
            namespace: String::new(),
            node_name: default_node_name(),
            discovery: Discovery::default(),
            interface: None,
            accept_commands: true,
            middleware: None,
            odom_rate_hz: default_odom_rate_hz(),
            frames: Ros2Frames::default(),
            command_rate_hz: default_command_rate_hz(),
            command_burst: default_command_burst(),
        }
    }
}

/// The largest domain id: DDS's port arithmetic leaves no room above it.
pub const MAX_DOMAIN_ID: u16 = 232;

/// Whether `token` is one part of a ROS 2 name: a letter or `_` first, then letters,
/// digits and `_`.
fn is_name_token(token: &str) -> bool {
    token
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

impl Ros2Config {
    /// The domain for `ROS_DOMAIN_ID`'s value `env` (the configured one first); an unset
    /// or unreadable variable is 0, as for ROS 2's own nodes, and the reason comes back.
    pub fn domain(&self, env: Option<&str>) -> Result<u16, String> {
        if let Some(id) = self.domain_id {
            return Ok(id);
        }
        match env.map(str::trim) {
            None | Some("") => Ok(0),
            Some(text) => text
                .parse::<u16>()
                .ok()
                .filter(|id| *id <= MAX_DOMAIN_ID)
                .ok_or_else(|| {
                    format!("ROS_DOMAIN_ID={text:?} is not a domain id (0 to {MAX_DOMAIN_ID})")
                }),
        }
    }

    /// The middleware for `RMW_IMPLEMENTATION`'s value `env` (the configured one first):
    /// `rmw_cyclonedds_cpp` is Cyclone DDS's; unset or any other, Fast DDS's, ROS 2's default.
    pub fn middleware(&self, env: Option<&str>) -> Middleware {
        self.middleware.unwrap_or(match env.map(str::trim) {
            Some("rmw_cyclonedds_cpp") => Middleware::Cyclonedds,
            _ => Middleware::Fastdds,
        })
    }

    /// Checks the values; `file` names the configuration in the error. (That `interface`
    /// exists is checked where the node starts: the core asks the system nothing.)
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if let Some(id) = self.domain_id
            && id > MAX_DOMAIN_ID
        {
            return Err(ConfigError::invalid(
                file,
                "ros2.domain_id",
                format!("{id} is above {MAX_DOMAIN_ID}, the largest DDS domain"),
                "use a domain from 0 to 232 (ROS 2 advises 0 to 101 on Linux)",
            ));
        }
        let namespace_ok = self.namespace.is_empty()
            || self
                .namespace
                .strip_prefix('/')
                .is_some_and(|rest| rest.split('/').all(is_name_token));
        if !namespace_ok {
            return Err(ConfigError::invalid(
                file,
                "ros2.namespace",
                format!("{:?} is not a ROS 2 namespace", self.namespace),
                "leave it empty, or write /name (parts of letters, digits and _, each \
                 starting with a letter), e.g. \"/robot_1\"",
            ));
        }
        if !is_name_token(&self.node_name) {
            return Err(ConfigError::invalid(
                file,
                "ros2.node_name",
                format!("{:?} is not a ROS 2 node name", self.node_name),
                "use letters, digits and _, starting with a letter, e.g. \"chassisd\"",
            ));
        }
        if let Some(name) = &self.interface
            && (name.is_empty() || name.len() > 15 || name.contains(['/', ' ', '\0']))
        {
            return Err(ConfigError::invalid(
                file,
                "ros2.interface",
                format!("{name:?} is not a network interface's name"),
                "name the interface as `ip link` lists it, e.g. \"eth0\"",
            ));
        }
        self.frames.validate(file)?;
        check_range(
            file,
            "ros2.odom_rate_hz",
            self.odom_rate_hz,
            1.0..=100.0,
            "Hz",
        )?;
        check_range(
            file,
            "ros2.command_rate_hz",
            self.command_rate_hz,
            1.0..=10_000.0,
            "messages/s",
        )?;
        check_range(
            file,
            "ros2.command_burst",
            f64::from(self.command_burst),
            1.0..=10_000.0,
            "messages",
        )
    }
}

impl Ros2Frames {
    fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        let frames = [
            ("map", &self.map),
            ("odom", &self.odom),
            ("base", &self.base),
            ("gnss", &self.gnss),
            ("imu", &self.imu),
        ];
        for (key, frame) in frames {
            // tf2 refuses a frame id with a leading slash, and an empty one is no frame.
            let valid = !frame.is_empty()
                && !frame.starts_with('/')
                && frame
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/');
            if !valid {
                return Err(ConfigError::invalid(
                    file,
                    &format!("ros2.frames.{key}"),
                    format!("{frame:?} is not a tf2 frame id"),
                    "use letters, digits, _ and / with no leading slash, e.g. \"base_link\"",
                ));
            }
        }
        let mut names: Vec<&str> = frames.iter().map(|(_, f)| f.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        if names.len() != frames.len() {
            return Err(ConfigError::invalid(
                file,
                "ros2.frames",
                "two frames have the same id",
                "give each of map, odom, base, gnss and imu its own frame id",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refusal(c: Ros2Config) -> String {
        c.validate(Path::new("v.toml")).unwrap_err().to_string()
    }

    #[test]
    fn the_defaults_are_valid_and_names_are_checked_with_the_fix() {
        assert!(Ros2Config::default().validate(Path::new("v.toml")).is_ok());
        let namespace = refusal(Ros2Config {
            namespace: "robot 1".into(),
            ..Default::default()
        });
        assert!(
            namespace.contains("ros2.namespace") && namespace.contains("/robot_1"),
            "{namespace}"
        );
        assert!(
            Ros2Config {
                namespace: "/site_a/robot_1".into(),
                ..Default::default()
            }
            .validate(Path::new("v.toml"))
            .is_ok()
        );
        assert!(
            refusal(Ros2Config {
                node_name: "/chassisd".into(),
                ..Default::default()
            })
            .contains("ros2.node_name")
        );
        assert!(
            refusal(Ros2Config {
                domain_id: Some(233),
                ..Default::default()
            })
            .contains("232")
        );
        let frames = Ros2Frames {
            gnss: "base_link".into(),
            ..Default::default()
        };
        assert!(
            refusal(Ros2Config {
                frames,
                ..Default::default()
            })
            .contains("same id")
        );
    }

    #[test]
    fn the_domain_is_configured_else_ros_domain_id_else_0() {
        let unset = Ros2Config::default();
        assert_eq!(unset.domain(None), Ok(0));
        assert_eq!(unset.domain(Some("")), Ok(0));
        assert_eq!(unset.domain(Some("42")), Ok(42));
        assert!(unset.domain(Some("300")).unwrap_err().contains("0 to 232"));
        assert!(unset.domain(Some("x")).is_err());
        let set = Ros2Config {
            domain_id: Some(7),
            ..Default::default()
        };
        assert_eq!(set.domain(Some("42")), Ok(7));
    }

    #[test]
    fn a_section_reads_from_toml_with_its_words() {
        let c: Ros2Config = toml::from_str(
            "discovery = \"subnet\"\nmiddleware = \"cyclonedds\"\ninterface = \"eth0\"\n\
             accept_commands = false\n[frames]\nbase = \"base_footprint\"\n",
        )
        .unwrap();
        assert_eq!(c.discovery, Discovery::Subnet);
        assert_eq!(c.middleware(None), Middleware::Cyclonedds);
        assert_eq!(
            c.middleware(Some("rmw_fastrtps_cpp")),
            Middleware::Cyclonedds,
            "the configuration's first"
        );
        let unset = Ros2Config::default();
        assert_eq!(unset.middleware(None), Middleware::Fastdds);
        assert_eq!(
            unset.middleware(Some("rmw_cyclonedds_cpp")),
            Middleware::Cyclonedds
        );
        assert!(!c.accept_commands);
        assert_eq!(c.frames.base, "base_footprint");
        assert_eq!(c.frames.map, "map");
        assert!(toml::from_str::<Ros2Config>("discovery = \"wan\"").is_err());
    }
}
