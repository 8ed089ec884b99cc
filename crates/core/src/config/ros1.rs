//! `[ros1]`: the native ROS1 node of ros1-navigation-interface.txt (the `ros1` feature).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{ConfigError, check_range};

/// `[ros1]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Ros1Config {
    /// The ROS master, as `ROS_MASTER_URI` gives it.
    #[serde(default = "default_master_uri")]
    pub master_uri: String,
    /// The node's name in the graph.
    #[serde(default = "default_node_name")]
    pub node_name: String,
    /// Messages taken per second on each subscribed topic, and calls on each service; beyond
    /// it messages are dropped and calls refused, counted and logged in a summary (as MQTT
    /// commands over `mqtt.command_rate_hz`).
    #[serde(default = "default_command_rate_hz")]
    pub command_rate_hz: f64,
    /// Messages (or calls) taken at once on a topic (or service) before `command_rate_hz`
    /// applies.
    #[serde(default = "default_command_burst")]
    pub command_burst: u32,
}

fn default_master_uri() -> String {
    "http://127.0.0.1:11311".into()
}

fn default_node_name() -> String {
    "/chassisd".into()
}

fn default_command_rate_hz() -> f64 {
    100.0
}

fn default_command_burst() -> u32 {
    20
}

impl Default for Ros1Config {
    fn default() -> Self {
        Self {
            master_uri: default_master_uri(),
            node_name: default_node_name(),
            command_rate_hz: default_command_rate_hz(),
            command_burst: default_command_burst(),
        }
    }
}

impl Ros1Config {
    /// The defaults with this master (`--ros-master URI`).
    pub fn with_master(master_uri: &str) -> Self {
        Self {
            master_uri: master_uri.to_owned(),
            ..Self::default()
        }
    }

    /// Checks the values; `file` names the configuration in the error.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        let host = self.master_uri.strip_prefix("http://").unwrap_or("");
        if host.is_empty() || host.chars().any(char::is_whitespace) {
            return Err(ConfigError::invalid(
                file,
                "ros1.master_uri",
                format!("{:?} is not an http:// URI with a host", self.master_uri),
                "write it as ROS_MASTER_URI is written, e.g. \"http://127.0.0.1:11311\"",
            ));
        }
        let name = self.node_name.strip_prefix('/').unwrap_or(&self.node_name);
        let valid = name.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
            && name.split('/').all(|part| {
                !part.is_empty() && part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            });
        if !valid {
            return Err(ConfigError::invalid(
                file,
                "ros1.node_name",
                format!("{:?} is not a ROS name", self.node_name),
                "use letters, digits and _ in parts separated by /, starting with a letter, \
                 e.g. \"/chassisd\"",
            ));
        }
        check_range(
            file,
            "ros1.command_rate_hz",
            self.command_rate_hz,
            1.0..=10_000.0,
            "messages/s",
        )?;
        check_range(
            file,
            "ros1.command_burst",
            f64::from(self.command_burst),
            1.0..=10_000.0,
            "messages",
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uris_and_names_are_checked_with_the_fix() {
        let file = Path::new("v.toml");
        assert!(Ros1Config::default().validate(file).is_ok());
        let bad = |c: Ros1Config| c.validate(file).unwrap_err().to_string();
        let uri = bad(Ros1Config::with_master("localhost:11311"));
        assert!(
            uri.contains("ros1.master_uri") && uri.contains("http://127.0.0.1:11311"),
            "{uri}"
        );
        let name = bad(Ros1Config {
            node_name: "/9 lives".into(),
            ..Default::default()
        });
        assert!(name.contains("ros1.node_name"), "{name}");
        assert!(
            Ros1Config {
                node_name: "robot_1/chassisd".into(),
                ..Default::default()
            }
            .validate(file)
            .is_ok()
        );
    }
}
