//! `[mqtt.rtk]`, `[mqtt.root]`, `[mqtt.device]`: the protocol dialects, each carried by one
//! link, and the names links list them by.

use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::invalid;
use crate::config::{ConfigError, check_range};

/// A dialect, as a link's `dialects` names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DialectName {
    /// rtk-mqtt-protocol.md: bare topics, for the site's app on the robot's own broker.
    Rtk,
    /// root-mqtt-api.rst: `/root/{vehicleId}/...`.
    Root,
    /// device-mqtt-api.md: `device/{serial_number}/...`.
    Device,
}

impl DialectName {
    /// Every dialect, in the order the engine builds them.
    pub const ALL: [DialectName; 3] = [Self::Rtk, Self::Root, Self::Device];

    /// The word in configurations, logs and the dialects' own `name()`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Rtk => "rtk",
            Self::Root => "root",
            Self::Device => "device",
        }
    }

    /// The dialect called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|d| d.as_str() == name)
    }
}

/// `[mqtt.root]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RootDialectConfig {
    /// The `{vehicleId}` of the topics.
    pub vehicle_id: String,
    /// Once a client sends heartbeats, silence for this long stops the vehicle, s.
    #[serde(default = "default_heartbeat_timeout_s")]
    pub heartbeat_timeout_s: f64,
    /// Watch the heartbeat from start: no heartbeat within the timeout of start stops the
    /// vehicle too.
    #[serde(default)]
    pub require_heartbeat: bool,
    /// Follow only heartbeats whose `clientId` member is this (the MQTT client id of the
    /// controlling client); others are answered but do not feed the watchdog.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heartbeat_client_id: Option<String>,
}

fn default_heartbeat_timeout_s() -> f64 {
    3.0
}

impl RootDialectConfig {
    /// The heartbeat timeout.
    pub fn heartbeat_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.heartbeat_timeout_s)
    }

    /// Every topic of the dialect lies under this prefix (with a `/` after it).
    pub fn topic_prefix(&self) -> String {
        format!("/root/{}", self.vehicle_id)
    }

    /// `[mqtt.root]`: its topic level, heartbeat timeout and controlling client.
    pub(super) fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if !is_topic_level(&self.vehicle_id) {
            return Err(invalid(
                file,
                "root.vehicle_id",
                "must be one non-empty topic level (no '/', '+' or '#')",
                "use the vehicle's id, e.g. \"robot1\"",
            ));
        }
        check_range(
            file,
            "mqtt.root.heartbeat_timeout_s",
            self.heartbeat_timeout_s,
            0.3..=600.0,
            "s",
        )?;
        if self
            .heartbeat_client_id
            .as_deref()
            .is_some_and(str::is_empty)
        {
            return Err(invalid(
                file,
                "root.heartbeat_client_id",
                "is empty",
                "name the controlling client's id, or remove the key",
            ));
        }
        Ok(())
    }
}

/// `[mqtt.device]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceDialectConfig {
    /// The `{serial_number}` of the topics.
    pub serial_number: String,
    /// Topic prefix where the navigation stack takes mapping requests (`<prefix>/start_mapping`
    /// …) and answers them (`<prefix>/start_mapping/ack` …); none: they are refused.
    #[serde(default)]
    pub mapping_forward: Option<String>,
}

impl DeviceDialectConfig {
    /// Every topic of the dialect but the mapping forward lies under this prefix.
    pub fn topic_prefix(&self) -> String {
        format!("device/{}", self.serial_number)
    }

    /// `[mqtt.device]`: its topic level and the mapping requests' prefix.
    pub(super) fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if !is_topic_level(&self.serial_number) {
            return Err(invalid(
                file,
                "device.serial_number",
                "must be one non-empty topic level (no '/', '+' or '#')",
                "use the serial number as printed, e.g. \"SN20260001\"",
            ));
        }
        if self
            .mapping_forward
            .as_ref()
            .is_some_and(|f| f.is_empty() || f.contains(['+', '#']))
        {
            return Err(invalid(
                file,
                "device.mapping_forward",
                "must be a non-empty topic prefix without wildcards",
                "use e.g. \"nav/SN20260001\"",
            ));
        }
        Ok(())
    }
}

/// `[mqtt.rtk]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RtkDialectConfig {
    /// Where trajectories are kept; none: trajectory commands are refused.
    #[serde(default)]
    pub trajectory_dir: Option<String>,
}

/// Whether `s` can stand as one level of a topic: non-empty, no separator or wildcard.
pub fn is_topic_level(s: &str) -> bool {
    !s.is_empty() && !s.contains(['/', '+', '#']) && !s.chars().any(char::is_control)
}

/// Whether `topic` is `prefix` or lies below it.
pub fn is_under(topic: &str, prefix: &str) -> bool {
    topic
        .strip_prefix(prefix)
        .is_some_and(|rest| rest.is_empty() || rest.starts_with('/'))
}
