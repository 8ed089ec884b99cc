//! `[mqtt]`: the broker connection and which protocol dialects speak over it.

use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::{ConfigError, check_range, check_ranges};

/// `[mqtt]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MqttConfig {
    /// Broker host. The protocols expect the robot's own broker.
    #[serde(default = "default_host")]
    pub host: String,
    /// Broker port.
    #[serde(default = "default_port")]
    pub port: u16,
    /// Client id; default `chassisd-<vehicle name>`.
    #[serde(default)]
    pub client_id: Option<String>,
    /// Append 16 random hex digits, drawn at each start, to the client id: MQTT hands an
    /// id to its newest connection, so one an outsider can guess lets them close
    /// chassisd's session. Off for a broker whose ACLs want the exact id.
    #[serde(default = "default_true")]
    pub client_id_suffix: bool,
    /// Client ids the embedded broker refuses to every client but chassisd (besides
    /// chassisd's own, always reserved): e.g. the controlling app's.
    #[serde(default)]
    pub reserved_client_ids: Vec<String>,
    /// User name, if the broker wants one.
    #[serde(default)]
    pub username: Option<String>,
    /// Password (with `username`).
    #[serde(default)]
    pub password: Option<String>,
    /// Keep-alive interval, s.
    #[serde(default = "default_keep_alive_s")]
    pub keep_alive_s: f64,
    /// Longest wait between reconnect attempts, s.
    #[serde(default = "default_reconnect_max_s")]
    pub reconnect_max_s: f64,
    /// Telemetry messages kept while the broker is away; the oldest go first.
    #[serde(default = "default_telemetry_queue")]
    pub telemetry_queue: usize,
    /// Command replies kept while the broker is away.
    #[serde(default = "default_reply_queue")]
    pub reply_queue: usize,
    /// Commands accepted per second on each topic; beyond it they are refused unanswered.
    #[serde(default = "default_command_rate_hz")]
    pub command_rate_hz: f64,
    /// Commands accepted at once on a topic before `command_rate_hz` applies.
    #[serde(default = "default_command_burst")]
    pub command_burst: u32,
    /// Incoming messages larger than this are refused, bytes.
    #[serde(default = "default_max_payload")]
    pub max_payload: usize,
    /// Retained `online` / `offline` (last will) topic; `{name}` is the vehicle name.
    #[serde(default = "default_status_topic")]
    pub status_topic: String,
    /// Start an MQTT broker with chassisd on `host:port` (the no-hardware default). It
    /// requires `username` and `password` of every client, and refuses to listen beyond
    /// loopback without them.
    #[serde(default)]
    pub embedded_broker: bool,
    /// Clients the embedded broker holds at once, chassisd's own link not counted.
    #[serde(default = "default_embedded_max_clients")]
    pub embedded_max_clients: usize,
    /// TLS to the broker.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tls: Option<TlsConfig>,
    /// Dialect `rtk` (rtk-mqtt-protocol.md): bare topics.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rtk: Option<RtkDialectConfig>,
    /// Dialect `root` (root-mqtt-api.rst): `/root/{vehicle_id}/...`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub root: Option<RootDialectConfig>,
    /// Dialect `device` (device-mqtt-api.md): `device/{serial_number}/...`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<DeviceDialectConfig>,
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

/// `[mqtt.tls]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TlsConfig {
    /// CA certificates (PEM) that sign the broker's certificate.
    pub ca_file: String,
    /// Client certificate chain (PEM), for brokers that authenticate clients.
    #[serde(default)]
    pub client_cert_file: Option<String>,
    /// The client certificate's private key (PEM).
    #[serde(default)]
    pub client_key_file: Option<String>,
    /// The embedded broker's certificate chain (PEM), signed by `ca_file`'s CA. With a
    /// client certificate set above, the embedded broker also requires one of every client.
    #[serde(default)]
    pub cert_file: Option<String>,
    /// The embedded broker's private key (PEM).
    #[serde(default)]
    pub key_file: Option<String>,
}

/// `[mqtt.rtk]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RtkDialectConfig {
    /// Where trajectories are kept; none: trajectory commands are refused.
    #[serde(default)]
    pub trajectory_dir: Option<String>,
}

fn default_host() -> String {
    "127.0.0.1".into()
}
fn default_port() -> u16 {
    1883
}
fn default_keep_alive_s() -> f64 {
    5.0
}
fn default_reconnect_max_s() -> f64 {
    2.0
}
fn default_telemetry_queue() -> usize {
    64
}
fn default_reply_queue() -> usize {
    1024
}
fn default_command_rate_hz() -> f64 {
    50.0
}
fn default_command_burst() -> u32 {
    50
}
fn default_true() -> bool {
    true
}
fn default_max_payload() -> usize {
    1 << 20
}
fn default_embedded_max_clients() -> usize {
    64
}
fn default_status_topic() -> String {
    "chassisd/{name}/status".into()
}

impl Default for MqttConfig {
    fn default() -> Self {
        Self {
            host: default_host(),
            port: default_port(),
            client_id: None,
            client_id_suffix: true,
            reserved_client_ids: Vec::new(),
            username: None,
            password: None,
            keep_alive_s: default_keep_alive_s(),
            reconnect_max_s: default_reconnect_max_s(),
            telemetry_queue: default_telemetry_queue(),
            reply_queue: default_reply_queue(),
            command_rate_hz: default_command_rate_hz(),
            command_burst: default_command_burst(),
            max_payload: default_max_payload(),
            status_topic: default_status_topic(),
            embedded_broker: false,
            embedded_max_clients: default_embedded_max_clients(),
            tls: None,
            rtk: None,
            root: None,
            device: None,
        }
    }
}

/// The largest MQTT packet chassisd takes or sends on a link whose messages are at most
/// `max_payload`: four times that (a reply may carry more than a request), at least 1 MiB.
pub fn packet_limit(max_payload: usize) -> usize {
    max_payload.saturating_mul(4).max(1 << 20)
}

impl MqttConfig {
    /// The largest packet taken or sent on this link ([`packet_limit`]).
    pub fn packet_limit(&self) -> usize {
        packet_limit(self.max_payload)
    }

    /// The keep-alive interval.
    pub fn keep_alive(&self) -> Duration {
        Duration::from_secs_f64(self.keep_alive_s)
    }

    /// The longest reconnect back-off.
    pub fn reconnect_max(&self) -> Duration {
        Duration::from_secs_f64(self.reconnect_max_s)
    }

    /// The client id chassisd's link uses for a vehicle called `name`: the configured or
    /// default id, with this process's unguessable tag unless `client_id_suffix` is off.
    pub fn client_id(&self, name: &str) -> String {
        let base = self.base_client_id(name);
        if self.client_id_suffix {
            format!("{base}-{}", crate::secret::process_tag())
        } else {
            base
        }
    }

    /// The configured or default client id without the tag: chassisd's other clients
    /// (`check`, the recorder) add a suffix of their own to it.
    pub fn base_client_id(&self, name: &str) -> String {
        self.client_id
            .clone()
            .unwrap_or_else(|| format!("chassisd-{name}"))
    }

    /// Client ids the embedded broker refuses to everyone but chassisd's link: the base id
    /// (and the link's own, when it is the same) and `reserved_client_ids`.
    pub fn reserved_client_ids(&self, name: &str) -> Vec<String> {
        let mut ids = vec![self.base_client_id(name)];
        ids.extend(self.reserved_client_ids.iter().cloned());
        ids
    }

    /// Where the embedded broker's health goes (retained JSON), for a vehicle called `name`.
    pub fn broker_health_topic(&self, name: &str) -> String {
        format!("{}/broker", self.status_topic(name))
    }

    /// The online/offline topic for a vehicle called `name`.
    pub fn status_topic(&self, name: &str) -> String {
        self.status_topic.replace("{name}", name)
    }

    /// Makes the file paths relative to `base` (the configuration's folder) absolute.
    pub fn resolve(&mut self, base: &Path) {
        let absolute = |p: &mut String| {
            if Path::new(p.as_str()).is_relative() {
                *p = base.join(p.as_str()).to_string_lossy().into_owned();
            }
        };
        if let Some(tls) = &mut self.tls {
            absolute(&mut tls.ca_file);
            tls.client_cert_file.as_mut().map(absolute);
            tls.client_key_file.as_mut().map(absolute);
            tls.cert_file.as_mut().map(absolute);
            tls.key_file.as_mut().map(absolute);
        }
        if let Some(dir) = self.rtk.as_mut().and_then(|r| r.trajectory_dir.as_mut()) {
            absolute(dir);
        }
    }

    /// Checks ranges and consistency.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        self.check_broker_address(file)?;
        self.check_client_identity(file)?;
        self.check_status_topic(file)?;
        self.check_link_limits(file)?;
        if let Some(root) = &self.root {
            root.validate(file)?;
        }
        if let Some(device) = &self.device {
            device.validate(file)?;
        }
        if let Some(tls) = &self.tls {
            tls.check_client_pair(file)?;
        }
        self.validate_embedded_broker(file)
    }

    /// The broker's host and port.
    fn check_broker_address(&self, file: &Path) -> Result<(), ConfigError> {
        if self.host.trim().is_empty() {
            return Err(invalid(
                file,
                "host",
                "is empty",
                "set the broker's address, e.g. \"127.0.0.1\"",
            ));
        }
        if self.port == 0 {
            return Err(invalid(
                file,
                "port",
                "is 0",
                "set the broker's port, e.g. 1883",
            ));
        }
        Ok(())
    }

    /// The credentials, the client id and the ids reserved for other clients.
    fn check_client_identity(&self, file: &Path) -> Result<(), ConfigError> {
        if self.password.is_some() && self.username.is_none() {
            return Err(invalid(
                file,
                "password",
                "is set without a username",
                "set mqtt.username too",
            ));
        }
        if self
            .client_id
            .as_ref()
            .is_some_and(|c| c.is_empty() || c.len() > 128)
        {
            return Err(invalid(
                file,
                "client_id",
                "must be 1 to 128 characters",
                "choose a shorter, non-empty id",
            ));
        }
        if let Some(bad) = self
            .reserved_client_ids
            .iter()
            .find(|id| !crate::broker::admission::routable_client_id(id) || id.is_empty())
        {
            return Err(invalid(
                file,
                "reserved_client_ids",
                &format!("{bad:?} is not a client id a broker can route"),
                "list non-empty ids without + # / $ or control characters",
            ));
        }
        Ok(())
    }

    /// The online/offline topic: one a client can subscribe to by name.
    fn check_status_topic(&self, file: &Path) -> Result<(), ConfigError> {
        if self.status_topic.is_empty() || self.status_topic.contains(['+', '#']) {
            return Err(invalid(
                file,
                "status_topic",
                "must be a non-empty topic without wildcards",
                "use e.g. \"chassisd/{name}/status\"",
            ));
        }
        Ok(())
    }

    /// The link's timings, command rate, queues and largest message.
    fn check_link_limits(&self, file: &Path) -> Result<(), ConfigError> {
        check_ranges(
            file,
            "mqtt.",
            [
                ("keep_alive_s", self.keep_alive_s, 1.0..=600.0, "s"),
                ("reconnect_max_s", self.reconnect_max_s, 0.1..=300.0, "s"),
                (
                    "command_rate_hz",
                    self.command_rate_hz,
                    0.1..=100_000.0,
                    "per s",
                ),
            ],
        )?;
        for (key, n, max) in [
            ("command_burst", self.command_burst as usize, 100_000),
            ("telemetry_queue", self.telemetry_queue, 100_000),
            ("reply_queue", self.reply_queue, 100_000),
            ("max_payload", self.max_payload, 64 << 20),
        ] {
            if n == 0 || n > max {
                return Err(invalid(
                    file,
                    key,
                    &format!("{n} is outside 1..={max}"),
                    "choose a value in range",
                ));
            }
        }
        Ok(())
    }

    /// The embedded broker's own rules: nobody on the network gets in without credentials,
    /// and TLS needs the broker's certificate.
    fn validate_embedded_broker(&self, file: &Path) -> Result<(), ConfigError> {
        let server_tls = self
            .tls
            .as_ref()
            .map(|t| (t.cert_file.is_some(), t.key_file.is_some()));
        if !self.embedded_broker {
            if matches!(server_tls, Some((true, _) | (_, true))) {
                return Err(invalid(
                    file,
                    "tls.cert_file",
                    "is the embedded broker's certificate, and mqtt.embedded_broker is off",
                    "remove tls.cert_file and tls.key_file, or set embedded_broker = true",
                ));
            }
            return Ok(());
        }
        self.check_embedded_credentials(file)?;
        if let Some(has) = server_tls
            && has != (true, true)
        {
            return Err(invalid(
                file,
                "tls.cert_file",
                "the embedded broker serves TLS with a certificate and its key, and one is missing",
                "set tls.cert_file and tls.key_file (PEM, signed by tls.ca_file's CA), or \
                 remove [mqtt.tls]",
            ));
        }
        if self.embedded_max_clients == 0 || self.embedded_max_clients > 1024 {
            return Err(invalid(
                file,
                "embedded_max_clients",
                &format!("{} is outside 1..=1024", self.embedded_max_clients),
                "a vehicle has a handful of clients; 64 is the default",
            ));
        }
        Ok(())
    }

    /// The embedded broker takes nobody from the network without a user name, and no user
    /// name without a password.
    fn check_embedded_credentials(&self, file: &Path) -> Result<(), ConfigError> {
        if self.username.is_none() && !is_loopback(&self.host) {
            return Err(invalid(
                file,
                "username",
                &format!(
                    "is not set, and the embedded broker would listen on {} beyond this \
                     computer: anyone on the network could read everything and drive the \
                     vehicle",
                    self.host
                ),
                "set mqtt.username and mqtt.password (every client must then present them), \
                 or host = \"127.0.0.1\" to keep the broker to this computer",
            ));
        }
        if self.username.is_some() && self.password.as_deref().is_none_or(str::is_empty) {
            return Err(invalid(
                file,
                "password",
                "is not set: the embedded broker requires a user name and a password",
                "set mqtt.password (a long random one), or remove mqtt.username",
            ));
        }
        Ok(())
    }
}

/// An invalid value at `mqtt.<key>` in `file`.
fn invalid(file: &Path, key: &str, problem: &str, fix: &str) -> ConfigError {
    ConfigError::invalid(file, &format!("mqtt.{key}"), problem, fix)
}

impl RootDialectConfig {
    /// `[mqtt.root]`: its topic level, heartbeat timeout and controlling client.
    fn validate(&self, file: &Path) -> Result<(), ConfigError> {
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

impl DeviceDialectConfig {
    /// `[mqtt.device]`: its topic level and the mapping requests' prefix.
    fn validate(&self, file: &Path) -> Result<(), ConfigError> {
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

impl TlsConfig {
    /// A client certificate comes with its key.
    fn check_client_pair(&self, file: &Path) -> Result<(), ConfigError> {
        if self.client_cert_file.is_some() != self.client_key_file.is_some() {
            return Err(invalid(
                file,
                "tls.client_key_file",
                "a client certificate needs its key and the other way round",
                "set both client_cert_file and client_key_file, or neither",
            ));
        }
        Ok(())
    }
}

/// Whether `host` names this computer alone (a loopback address or `localhost`).
pub fn is_loopback(host: &str) -> bool {
    host.eq_ignore_ascii_case("localhost")
        || host
            .trim_start_matches('[')
            .trim_end_matches(']')
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// Whether `s` can stand as one level of a topic: non-empty, no separator or wildcard.
pub fn is_topic_level(s: &str) -> bool {
    !s.is_empty() && !s.contains(['/', '+', '#']) && !s.chars().any(char::is_control)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The error of the default configuration changed by `edit`.
    fn error_with(edit: impl FnOnce(&mut MqttConfig)) -> String {
        let mut m = MqttConfig::default();
        edit(&mut m);
        m.validate(Path::new("v.toml")).unwrap_err().to_string()
    }

    fn tls() -> TlsConfig {
        TlsConfig {
            ca_file: "ca.pem".into(),
            client_cert_file: None,
            client_key_file: None,
            cert_file: None,
            key_file: None,
        }
    }

    #[test]
    fn each_check_names_its_key_and_the_problem() {
        assert!(MqttConfig::default().validate(Path::new("v.toml")).is_ok());
        for (e, expected) in [
            (error_with(|m| m.host = " ".into()), "`mqtt.host`: is empty"),
            (error_with(|m| m.port = 0), "`mqtt.port`: is 0"),
            (
                error_with(|m| m.password = Some("x".into())),
                "`mqtt.password`: is set without a username",
            ),
            (
                error_with(|m| m.client_id = Some("x".repeat(129))),
                "`mqtt.client_id`: must be 1 to 128 characters",
            ),
            (
                error_with(|m| m.reserved_client_ids = vec!["app".into(), "a/b".into()]),
                "`mqtt.reserved_client_ids`: \"a/b\" is not a client id a broker can route",
            ),
            (
                error_with(|m| m.status_topic = "robots/#".into()),
                "`mqtt.status_topic`: must be a non-empty topic without wildcards",
            ),
            (
                error_with(|m| m.keep_alive_s = 0.5),
                "`mqtt.keep_alive_s`: 0.5 is outside 1..=600 s",
            ),
            (
                error_with(|m| m.command_rate_hz = 0.0),
                "`mqtt.command_rate_hz`: 0 is outside 0.1..=100000 per s",
            ),
            (
                error_with(|m| m.reply_queue = 0),
                "`mqtt.reply_queue`: 0 is outside 1..=100000",
            ),
            (
                error_with(|m| {
                    m.root = Some(RootDialectConfig {
                        vehicle_id: "robot1".into(),
                        heartbeat_timeout_s: 3.0,
                        require_heartbeat: false,
                        heartbeat_client_id: Some(String::new()),
                    })
                }),
                "`mqtt.root.heartbeat_client_id`: is empty",
            ),
            (
                error_with(|m| {
                    m.root = Some(RootDialectConfig {
                        vehicle_id: "robot/1".into(),
                        heartbeat_timeout_s: 3.0,
                        require_heartbeat: false,
                        heartbeat_client_id: None,
                    })
                }),
                "`mqtt.root.vehicle_id`: must be one non-empty topic level",
            ),
            (
                error_with(|m| {
                    m.device = Some(DeviceDialectConfig {
                        serial_number: "SN1".into(),
                        mapping_forward: Some("nav/+".into()),
                    })
                }),
                "`mqtt.device.mapping_forward`: must be a non-empty topic prefix",
            ),
            (
                error_with(|m| {
                    m.tls = Some(TlsConfig {
                        client_cert_file: Some("client.pem".into()),
                        ..tls()
                    })
                }),
                "`mqtt.tls.client_key_file`: a client certificate needs its key",
            ),
            (
                error_with(|m| {
                    m.tls = Some(TlsConfig {
                        key_file: Some("broker.key".into()),
                        ..tls()
                    })
                }),
                "`mqtt.tls.cert_file`: is the embedded broker's certificate",
            ),
            (
                error_with(|m| {
                    m.embedded_broker = true;
                    m.embedded_max_clients = 0;
                }),
                "`mqtt.embedded_max_clients`: 0 is outside 1..=1024",
            ),
        ] {
            assert!(e.contains(expected), "{expected}: {e}");
        }
    }

    #[test]
    fn the_first_part_in_error_is_reported() {
        // The address, the identity, the status topic, the link's limits, the dialects,
        // then TLS and the embedded broker.
        let e = error_with(|m| {
            m.port = 0;
            m.client_id = Some(String::new());
        });
        assert!(e.contains("`mqtt.port`"), "{e}");
        let e = error_with(|m| {
            m.status_topic = String::new();
            m.max_payload = 0;
        });
        assert!(e.contains("`mqtt.status_topic`"), "{e}");
        let e = error_with(|m| {
            m.max_payload = 0;
            m.device = Some(DeviceDialectConfig {
                serial_number: String::new(),
                mapping_forward: None,
            });
        });
        assert!(e.contains("`mqtt.max_payload`"), "{e}");
        let e = error_with(|m| {
            m.device = Some(DeviceDialectConfig {
                serial_number: String::new(),
                mapping_forward: None,
            });
            m.tls = Some(TlsConfig {
                client_key_file: Some("client.key".into()),
                ..tls()
            });
        });
        assert!(e.contains("`mqtt.device.serial_number`"), "{e}");
    }
}
