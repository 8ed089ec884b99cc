//! One MQTT link: a broker (with failover brokers), the identity and TLS chassisd presents
//! there, its queues, limits and reconnect manners. `[mqtt]` itself is one link; each
//! `[[mqtt.link]]` is another.

use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::dialect::DialectName;
use crate::config::{ConfigError, check_ranges};

/// One link's settings: `[mqtt]` (the one-link form) or a `[[mqtt.link]]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MqttLinkConfig {
    /// The link's name in logs, `check`, the status and its recording source.
    #[serde(default = "default_name")]
    pub name: String,
    /// The dialects it carries; empty: every configured dialect no other link names.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dialects: Vec<DialectName>,
    /// A fleet platform's broker, shared by many vehicles: every topic the link uses lies
    /// under the vehicle's own prefix (so one ACL line confines it), and its keep-alive and
    /// reconnect back-off default to a shared broker's manners.
    #[serde(default)]
    pub platform: bool,
    /// Broker host. The protocols expect the robot's own broker.
    #[serde(default = "default_host")]
    pub host: String,
    /// Broker port.
    #[serde(default = "default_port")]
    pub port: u16,
    /// Further brokers (`host:port`) of the same service, tried in turn when the one in use
    /// fails; names are resolved again at every attempt.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub failover: Vec<String>,
    /// Client id; default `chassisd-<vehicle name>` (`-<link name>` after it on a link not
    /// called `mqtt`).
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
    /// Keep-alive interval, s; default 5 (30 on a platform link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keep_alive_s: Option<f64>,
    /// The first reconnect back-off's bound, s; default 0.1 (2 on a platform link). Each
    /// wait is drawn evenly from zero to a bound that doubles per failed attempt.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reconnect_min_s: Option<f64>,
    /// The largest reconnect back-off bound, s; default 2 (30 on a platform link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reconnect_max_s: Option<f64>,
    /// Telemetry messages kept while the broker is away; the oldest go first.
    #[serde(default = "default_telemetry_queue")]
    pub telemetry_queue: usize,
    /// Command replies kept while the broker is away.
    #[serde(default = "default_reply_queue")]
    pub reply_queue: usize,
    /// The QoS chassisd subscribes to its command topics with: 1, or 0 for a broker that
    /// keeps a clean session's QoS 1 subscription on one node (RabbitMQ before 3.12: the
    /// vehicle cannot subscribe on another node while that one is down). With a clean
    /// session the two lose the same: what was in flight when the connection broke.
    #[serde(default = "default_command_qos")]
    pub command_qos: u8,
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
    /// Default `chassisd/{name}/status`; on a platform link, `chassisd/status` under the
    /// vehicle's prefix (the first dialect's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status_topic: Option<String>,
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

/// The name of the one-link form's link, and of its recording source.
pub const DEFAULT_LINK_NAME: &str = "mqtt";

fn default_name() -> String {
    DEFAULT_LINK_NAME.into()
}
fn default_host() -> String {
    "127.0.0.1".into()
}
fn default_port() -> u16 {
    1883
}
fn default_command_qos() -> u8 {
    1
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

impl Default for MqttLinkConfig {
    fn default() -> Self {
        Self {
            name: default_name(),
            dialects: Vec::new(),
            platform: false,
            host: default_host(),
            port: default_port(),
            failover: Vec::new(),
            client_id: None,
            client_id_suffix: true,
            reserved_client_ids: Vec::new(),
            username: None,
            password: None,
            keep_alive_s: None,
            reconnect_min_s: None,
            reconnect_max_s: None,
            telemetry_queue: default_telemetry_queue(),
            reply_queue: default_reply_queue(),
            command_qos: default_command_qos(),
            command_rate_hz: default_command_rate_hz(),
            command_burst: default_command_burst(),
            max_payload: default_max_payload(),
            status_topic: None,
            embedded_broker: false,
            embedded_max_clients: default_embedded_max_clients(),
            tls: None,
        }
    }
}

/// The largest MQTT packet chassisd takes or sends on a link whose messages are at most
/// `max_payload`: four times that (a reply may carry more than a request), at least 1 MiB.
pub fn packet_limit(max_payload: usize) -> usize {
    max_payload.saturating_mul(4).max(1 << 20)
}

/// `value` seconds as a duration; `fallback` for a value no duration holds (negative, NaN or
/// too large: validation refuses those, this keeps an unchecked configuration from panicking).
fn seconds(value: f64, fallback: f64) -> Duration {
    Duration::try_from_secs_f64(value).unwrap_or(Duration::from_secs_f64(fallback))
}

/// One broker of a link.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BrokerAddress {
    /// Host name or address, resolved at each connection attempt.
    pub host: String,
    /// TCP port.
    pub port: u16,
}

impl std::fmt::Display for BrokerAddress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.host.contains(':') {
            write!(f, "[{}]:{}", self.host, self.port)
        } else {
            write!(f, "{}:{}", self.host, self.port)
        }
    }
}

/// `host:port` (`[v6]:port` for an IPv6 address) as a broker, or why not.
pub fn parse_broker(text: &str) -> Result<BrokerAddress, String> {
    let (host, port) = text
        .rsplit_once(':')
        .ok_or_else(|| format!("{text:?} has no port"))?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    let port: u16 = port
        .parse()
        .ok()
        .filter(|p| *p != 0)
        .ok_or_else(|| format!("{text:?}: the port must be 1 to 65535"))?;
    if host.trim().is_empty() {
        return Err(format!("{text:?} has no host"));
    }
    Ok(BrokerAddress {
        host: host.to_owned(),
        port,
    })
}

impl MqttLinkConfig {
    /// The largest packet taken or sent on this link ([`packet_limit`]).
    pub fn packet_limit(&self) -> usize {
        packet_limit(self.max_payload)
    }

    /// The keep-alive interval.
    pub fn keep_alive(&self) -> Duration {
        seconds(self.keep_alive_s(), 5.0)
    }

    /// The first reconnect back-off's bound.
    pub fn reconnect_min(&self) -> Duration {
        seconds(self.reconnect_min_s(), 0.1)
    }

    /// The largest reconnect back-off bound.
    pub fn reconnect_max(&self) -> Duration {
        seconds(self.reconnect_max_s(), 2.0)
    }

    /// `keep_alive_s`, or its default (5 s; 30 s on a platform link), unchecked.
    fn keep_alive_s(&self) -> f64 {
        self.keep_alive_s
            .unwrap_or(if self.platform { 30.0 } else { 5.0 })
    }

    /// `reconnect_min_s`, or its default (0.1 s; 2 s on a platform link), unchecked.
    fn reconnect_min_s(&self) -> f64 {
        self.reconnect_min_s
            .unwrap_or(if self.platform { 2.0 } else { 0.1 })
    }

    /// `reconnect_max_s`, or its default (2 s; 30 s on a platform link), unchecked.
    fn reconnect_max_s(&self) -> f64 {
        self.reconnect_max_s
            .unwrap_or(if self.platform { 30.0 } else { 2.0 })
    }

    /// The brokers in the order they are tried: `host:port`, then `failover`. Entries that
    /// do not parse were refused by validation and are left out.
    pub fn brokers(&self) -> Vec<BrokerAddress> {
        std::iter::once(BrokerAddress {
            host: self.host.clone(),
            port: self.port,
        })
        .chain(self.failover.iter().filter_map(|b| parse_broker(b).ok()))
        .collect()
    }

    /// The recording source of the link's commands and states: `mqtt` for the link called
    /// so (the one-link form's), `mqtt-<name>` for the others.
    pub fn source(&self) -> String {
        if self.name == DEFAULT_LINK_NAME {
            crate::sources::MQTT.to_owned()
        } else {
            format!("{}-{}", crate::sources::MQTT, self.name)
        }
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
        match (&self.client_id, self.name.as_str()) {
            (Some(id), _) => id.clone(),
            (None, DEFAULT_LINK_NAME) => format!("chassisd-{name}"),
            (None, link) => format!("chassisd-{name}-{link}"),
        }
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
        self.status_topic
            .as_deref()
            .unwrap_or("chassisd/{name}/status")
            .replace("{name}", name)
    }

    /// Makes the file paths relative to `base` (the configuration's folder) absolute.
    pub fn resolve(&mut self, base: &Path) {
        if let Some(tls) = &mut self.tls {
            let absolute = |p: &mut String| {
                if Path::new(p.as_str()).is_relative() {
                    *p = base.join(p.as_str()).to_string_lossy().into_owned();
                }
            };
            absolute(&mut tls.ca_file);
            tls.client_cert_file.as_mut().map(absolute);
            tls.client_key_file.as_mut().map(absolute);
            tls.cert_file.as_mut().map(absolute);
            tls.key_file.as_mut().map(absolute);
        }
    }

    /// Checks ranges and consistency; `at` names the link's keys in errors.
    pub(super) fn validate(&self, at: &At<'_>) -> Result<(), ConfigError> {
        self.check_name(at)?;
        self.check_broker_addresses(at)?;
        self.check_client_identity(at)?;
        self.check_status_topic(at)?;
        self.check_link_limits(at)?;
        if let Some(tls) = &self.tls {
            tls.check_client_pair(at)?;
        }
        self.validate_embedded_broker(at)
    }

    /// A name that can stand in a file name and a log: lowercase words.
    fn check_name(&self, at: &At<'_>) -> Result<(), ConfigError> {
        let plain = |b: u8| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-';
        if self.name.is_empty() || self.name.len() > 32 || !self.name.bytes().all(plain) {
            return Err(at.invalid(
                "name",
                &format!(
                    "{:?} is not 1 to 32 lowercase letters, digits or '-'",
                    self.name
                ),
                "name the link e.g. \"site\" or \"platform\"",
            ));
        }
        Ok(())
    }

    /// The broker's host and port, and the failover brokers.
    fn check_broker_addresses(&self, at: &At<'_>) -> Result<(), ConfigError> {
        if self.host.trim().is_empty() {
            return Err(at.invalid(
                "host",
                "is empty",
                "set the broker's address, e.g. \"127.0.0.1\"",
            ));
        }
        if self.port == 0 {
            return Err(at.invalid("port", "is 0", "set the broker's port, e.g. 1883"));
        }
        if let Some(problem) = self.failover.iter().find_map(|b| parse_broker(b).err()) {
            return Err(at.invalid(
                "failover",
                &problem,
                "list the other brokers as \"host:port\", e.g. [\"node2.example.com:8883\"]",
            ));
        }
        if self.embedded_broker && !self.failover.is_empty() {
            return Err(at.invalid(
                "failover",
                "is set on the link of the embedded broker, which is this computer's own",
                "remove failover, or embedded_broker",
            ));
        }
        if self.failover.len() > 16 {
            return Err(at.invalid(
                "failover",
                &format!("lists {} brokers", self.failover.len()),
                "list at most 16; a load balancer's name serves a larger cluster",
            ));
        }
        Ok(())
    }

    /// The credentials, the client id and the ids reserved for other clients.
    fn check_client_identity(&self, at: &At<'_>) -> Result<(), ConfigError> {
        if self.password.is_some() && self.username.is_none() {
            return Err(at.invalid(
                "password",
                "is set without a username",
                "set the username too",
            ));
        }
        if self
            .client_id
            .as_ref()
            .is_some_and(|c| c.is_empty() || c.len() > 128)
        {
            return Err(at.invalid(
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
            return Err(at.invalid(
                "reserved_client_ids",
                &format!("{bad:?} is not a client id a broker can route"),
                "list non-empty ids without + # / $ or control characters",
            ));
        }
        Ok(())
    }

    /// The online/offline topic: one a client can subscribe to by name.
    fn check_status_topic(&self, at: &At<'_>) -> Result<(), ConfigError> {
        if self
            .status_topic
            .as_ref()
            .is_some_and(|t| t.is_empty() || t.contains(['+', '#']))
        {
            return Err(at.invalid(
                "status_topic",
                "must be a non-empty topic without wildcards",
                "use e.g. \"chassisd/{name}/status\"",
            ));
        }
        Ok(())
    }

    /// The link's timings, command rate, queues and largest message.
    fn check_link_limits(&self, at: &At<'_>) -> Result<(), ConfigError> {
        check_ranges(
            at.file,
            &at.prefix,
            [
                // The values as given: a negative or NaN one is refused here, before any
                // becomes a Duration.
                ("keep_alive_s", self.keep_alive_s(), 1.0..=600.0, "s"),
                ("reconnect_min_s", self.reconnect_min_s(), 0.01..=60.0, "s"),
                ("reconnect_max_s", self.reconnect_max_s(), 0.1..=600.0, "s"),
                (
                    "command_rate_hz",
                    self.command_rate_hz,
                    0.1..=100_000.0,
                    "per s",
                ),
            ],
        )?;
        if self.command_qos > 1 {
            return Err(at.invalid(
                "command_qos",
                &format!("{} is not 0 or 1", self.command_qos),
                "commands are subscribed at QoS 1 (the default) or 0",
            ));
        }
        if self.reconnect_min_s() > self.reconnect_max_s() {
            return Err(at.invalid(
                "reconnect_min_s",
                "is above reconnect_max_s",
                "the first back-off bound is the smaller one",
            ));
        }
        for (key, n, max) in [
            ("command_burst", self.command_burst as usize, 100_000),
            ("telemetry_queue", self.telemetry_queue, 100_000),
            ("reply_queue", self.reply_queue, 100_000),
            ("max_payload", self.max_payload, 64 << 20),
        ] {
            if n == 0 || n > max {
                return Err(at.invalid(
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
    fn validate_embedded_broker(&self, at: &At<'_>) -> Result<(), ConfigError> {
        let server_tls = self
            .tls
            .as_ref()
            .map(|t| (t.cert_file.is_some(), t.key_file.is_some()));
        if !self.embedded_broker {
            if matches!(server_tls, Some((true, _) | (_, true))) {
                return Err(at.invalid(
                    "tls.cert_file",
                    "is the embedded broker's certificate, and embedded_broker is off",
                    "remove tls.cert_file and tls.key_file, or set embedded_broker = true",
                ));
            }
            return Ok(());
        }
        self.check_embedded_credentials(at)?;
        if let Some(has) = server_tls
            && has != (true, true)
        {
            return Err(at.invalid(
                "tls.cert_file",
                "the embedded broker serves TLS with a certificate and its key, and one is missing",
                "set tls.cert_file and tls.key_file (PEM, signed by tls.ca_file's CA), or \
                 remove the link's tls table",
            ));
        }
        if self.embedded_max_clients == 0 || self.embedded_max_clients > 1024 {
            return Err(at.invalid(
                "embedded_max_clients",
                &format!("{} is outside 1..=1024", self.embedded_max_clients),
                "a vehicle has a handful of clients; 64 is the default",
            ));
        }
        Ok(())
    }

    /// The embedded broker takes nobody from the network without a user name, and no user
    /// name without a password.
    fn check_embedded_credentials(&self, at: &At<'_>) -> Result<(), ConfigError> {
        if self.username.is_none() && !is_loopback(&self.host) {
            return Err(at.invalid(
                "username",
                &format!(
                    "is not set, and the embedded broker would listen on {} beyond this \
                     computer: anyone on the network could read everything and drive the \
                     vehicle",
                    self.host
                ),
                "set username and password (every client must then present them), or \
                 host = \"127.0.0.1\" to keep the broker to this computer",
            ));
        }
        if self.username.is_some() && self.password.as_deref().is_none_or(str::is_empty) {
            return Err(at.invalid(
                "password",
                "is not set: the embedded broker requires a user name and a password",
                "set password (a long random one), or remove username",
            ));
        }
        Ok(())
    }
}

impl TlsConfig {
    /// A client certificate comes with its key.
    fn check_client_pair(&self, at: &At<'_>) -> Result<(), ConfigError> {
        if self.client_cert_file.is_some() != self.client_key_file.is_some() {
            return Err(at.invalid(
                "tls.client_key_file",
                "a client certificate needs its key and the other way round",
                "set both client_cert_file and client_key_file, or neither",
            ));
        }
        Ok(())
    }

    /// Every file it names, with its key under the link's table.
    pub fn files(&self) -> [(&'static str, Option<&String>); 5] {
        [
            ("tls.ca_file", Some(&self.ca_file)),
            ("tls.client_cert_file", self.client_cert_file.as_ref()),
            ("tls.client_key_file", self.client_key_file.as_ref()),
            ("tls.cert_file", self.cert_file.as_ref()),
            ("tls.key_file", self.key_file.as_ref()),
        ]
    }
}

/// Where a link's keys are in a configuration file: `mqtt.` for the one-link form,
/// `mqtt.link[i].` for the others.
pub struct At<'a> {
    /// The configuration file.
    pub file: &'a Path,
    /// The keys' prefix, with its dot.
    pub prefix: String,
}

impl At<'_> {
    /// An invalid value at the link's `key`.
    pub fn invalid(&self, key: &str, problem: &str, fix: &str) -> ConfigError {
        ConfigError::invalid(self.file, &format!("{}{key}", self.prefix), problem, fix)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brokers_parse_with_their_port_and_v6_in_brackets() {
        assert_eq!(
            parse_broker("node2.example.com:8883"),
            Ok(BrokerAddress {
                host: "node2.example.com".into(),
                port: 8883
            })
        );
        let v6 = parse_broker("[::1]:1883").unwrap();
        assert_eq!(
            (v6.host.as_str(), v6.to_string()),
            ("::1", "[::1]:1883".into())
        );
        assert!(parse_broker("node2").unwrap_err().contains("no port"));
        assert!(parse_broker("node2:0").unwrap_err().contains("1 to 65535"));
        assert!(parse_broker(":1883").unwrap_err().contains("no host"));
    }

    #[test]
    fn a_platform_link_defaults_to_a_shared_brokers_manners() {
        let site = MqttLinkConfig::default();
        let platform = MqttLinkConfig {
            platform: true,
            ..MqttLinkConfig::default()
        };
        assert_eq!(
            (
                site.keep_alive(),
                site.reconnect_min(),
                site.reconnect_max()
            ),
            (
                Duration::from_secs(5),
                Duration::from_millis(100),
                Duration::from_secs(2)
            )
        );
        assert_eq!(
            (
                platform.keep_alive(),
                platform.reconnect_min(),
                platform.reconnect_max()
            ),
            (
                Duration::from_secs(30),
                Duration::from_secs(2),
                Duration::from_secs(30)
            )
        );
    }

    #[test]
    fn ids_and_sources_keep_the_one_link_forms_names() {
        let one = MqttLinkConfig::default();
        assert_eq!(one.base_client_id("mower"), "chassisd-mower");
        assert_eq!(one.source(), "mqtt");
        let platform = MqttLinkConfig {
            name: "platform".into(),
            ..MqttLinkConfig::default()
        };
        assert_eq!(platform.base_client_id("mower"), "chassisd-mower-platform");
        assert_eq!(platform.source(), "mqtt-platform");
    }
}
