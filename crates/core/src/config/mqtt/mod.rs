//! `[mqtt]`: the links to MQTT brokers and the protocol dialects each carries.
//!
//! Two forms. The one-link form is `[mqtt]` with the broker's keys in it (host, port,
//! credentials, …): one link called `mqtt`, carrying every dialect configured. The fleet form
//! lists links, `[[mqtt.link]]`, each with those keys, a `name` and the `dialects` it carries,
//! and keeps only the dialect tables (`[mqtt.rtk]`, `[mqtt.root]`, `[mqtt.device]`) in
//! `[mqtt]`. A dialect is carried by exactly one link, so whatever it answers or reports goes
//! to the broker its commands came from.

pub mod dialect;
pub mod link;

use std::path::Path;

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::ConfigError;
pub use dialect::{
    DeviceDialectConfig, DialectName, RootDialectConfig, RtkDialectConfig, is_topic_level, is_under,
};
use link::At;
pub use link::{BrokerAddress, MqttLinkConfig, TlsConfig, is_loopback, packet_limit};

/// The most links one vehicle keeps.
pub const MAX_LINKS: usize = 8;

/// `[mqtt]`
#[derive(Debug, Clone, PartialEq)]
pub struct MqttConfig {
    /// The links, in the order they are started.
    pub links: Vec<MqttLinkConfig>,
    /// Dialect `rtk` (rtk-mqtt-protocol.md): bare topics.
    pub rtk: Option<RtkDialectConfig>,
    /// Dialect `root` (root-mqtt-api.rst): `/root/{vehicle_id}/...`.
    pub root: Option<RootDialectConfig>,
    /// Dialect `device` (device-mqtt-api.md): `device/{serial_number}/...`.
    pub device: Option<DeviceDialectConfig>,
    /// Written as `[[mqtt.link]]` (the fleet form) rather than as the one-link `[mqtt]`.
    pub listed: bool,
}

impl Default for MqttConfig {
    fn default() -> Self {
        Self::one(MqttLinkConfig::default())
    }
}

impl MqttConfig {
    /// The one-link form: `link` carries every dialect configured.
    pub fn one(link: MqttLinkConfig) -> Self {
        Self {
            links: vec![link],
            rtk: None,
            root: None,
            device: None,
            listed: false,
        }
    }

    /// The first link: the one-link form's only one.
    pub fn first(&self) -> &MqttLinkConfig {
        // Validation refuses an empty list; a default link stands in for code-built ones.
        static NONE: std::sync::OnceLock<MqttLinkConfig> = std::sync::OnceLock::new();
        self.links
            .first()
            .unwrap_or_else(|| NONE.get_or_init(MqttLinkConfig::default))
    }

    /// The first link, to change.
    pub fn first_mut(&mut self) -> &mut MqttLinkConfig {
        if self.links.is_empty() {
            self.links.push(MqttLinkConfig::default());
        }
        &mut self.links[0]
    }

    /// The dialects whose tables are present, in the engine's order.
    pub fn configured(&self) -> Vec<DialectName> {
        DialectName::ALL
            .into_iter()
            .filter(|d| match d {
                DialectName::Rtk => self.rtk.is_some(),
                DialectName::Root => self.root.is_some(),
                DialectName::Device => self.device.is_some(),
            })
            .collect()
    }

    /// The dialects `link` carries: those it lists, or, when it lists none, every configured
    /// one no other link lists.
    pub fn dialects_of(&self, link: &MqttLinkConfig) -> Vec<DialectName> {
        if !link.dialects.is_empty() {
            return link.dialects.clone();
        }
        self.configured()
            .into_iter()
            .filter(|d| !self.links.iter().any(|l| l.dialects.contains(d)))
            .collect()
    }

    /// The link that carries `dialect`.
    pub fn link_of(&self, dialect: DialectName) -> Option<&MqttLinkConfig> {
        self.links
            .iter()
            .find(|l| l.dialects.contains(&dialect))
            .or_else(|| self.links.iter().find(|l| l.dialects.is_empty()))
    }

    /// The largest message `dialect` takes: its link's `max_payload`.
    pub fn max_payload(&self, dialect: DialectName) -> usize {
        self.link_of(dialect).unwrap_or(self.first()).max_payload
    }

    /// The link that runs the embedded broker, if one does.
    pub fn embedded(&self) -> Option<&MqttLinkConfig> {
        self.links.iter().find(|l| l.embedded_broker)
    }

    /// The topic prefixes of the vehicle on `link`: one per dialect it carries that puts the
    /// vehicle's id in its topics (`/root/{vehicleId}`, `device/{serial_number}`).
    pub fn prefixes(&self, link: &MqttLinkConfig) -> Vec<String> {
        self.dialects_of(link)
            .into_iter()
            .filter_map(|d| match d {
                DialectName::Rtk => None,
                DialectName::Root => self.root.as_ref().map(RootDialectConfig::topic_prefix),
                DialectName::Device => self.device.as_ref().map(DeviceDialectConfig::topic_prefix),
            })
            .collect()
    }

    /// A platform link without a status topic gets `<prefix>/chassisd/status` under its first
    /// dialect's prefix, so its last will is confined with the rest.
    fn settle_platform_status_topics(&mut self) {
        for i in 0..self.links.len() {
            let link = &self.links[i];
            if link.platform
                && link.status_topic.is_none()
                && let Some(prefix) = self.prefixes(link).into_iter().next()
            {
                self.links[i].status_topic = Some(format!("{prefix}/chassisd/status"));
            }
        }
    }

    /// Makes the file paths relative to `base` (the configuration's folder) absolute.
    pub fn resolve(&mut self, base: &Path) {
        for link in &mut self.links {
            link.resolve(base);
        }
        if let Some(dir) = self.rtk.as_mut().and_then(|r| r.trajectory_dir.as_mut())
            && Path::new(dir.as_str()).is_relative()
        {
            *dir = base.join(dir.as_str()).to_string_lossy().into_owned();
        }
    }

    /// Where link `i`'s keys are in the file.
    pub fn key_prefix(&self, i: usize) -> String {
        if self.listed {
            format!("mqtt.link[{i}].")
        } else {
            "mqtt.".into()
        }
    }

    /// Checks each link, each dialect, and how the dialects are spread over the links.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if self.links.is_empty() || self.links.len() > MAX_LINKS {
            return Err(invalid(
                file,
                "link",
                &format!("lists {} links", self.links.len()),
                &format!("list 1 to {MAX_LINKS} [[mqtt.link]] tables"),
            ));
        }
        for (i, link) in self.links.iter().enumerate() {
            link.validate(&At {
                file,
                prefix: self.key_prefix(i),
            })?;
        }
        if let Some(root) = &self.root {
            root.validate(file)?;
        }
        if let Some(device) = &self.device {
            device.validate(file)?;
        }
        self.check_links_apart(file)?;
        self.check_dialects_spread(file)?;
        for (i, link) in self.links.iter().enumerate() {
            if link.platform {
                self.check_confined(
                    link,
                    &At {
                        file,
                        prefix: self.key_prefix(i),
                    },
                )?;
            }
        }
        Ok(())
    }

    /// Links are told apart: by name, by client id, and at most one runs the embedded broker.
    fn check_links_apart(&self, file: &Path) -> Result<(), ConfigError> {
        for (i, link) in self.links.iter().enumerate() {
            let at = At {
                file,
                prefix: self.key_prefix(i),
            };
            let earlier = &self.links[..i];
            if earlier.iter().any(|l| l.name == link.name) {
                return Err(at.invalid(
                    "name",
                    &format!("{:?} names another link too", link.name),
                    "give each link a name of its own",
                ));
            }
            if earlier
                .iter()
                .any(|l| l.base_client_id("v") == link.base_client_id("v"))
            {
                return Err(at.invalid(
                    "client_id",
                    "is another link's client id too: a broker gives an id to its newest \
                     connection, so the links would close each other's sessions",
                    "give each link a client id of its own",
                ));
            }
            if link.embedded_broker && earlier.iter().any(|l| l.embedded_broker) {
                return Err(at.invalid(
                    "embedded_broker",
                    "is set on two links",
                    "run one embedded broker; other links name other brokers",
                ));
            }
        }
        Ok(())
    }

    /// Every dialect named is configured, carried by one link, and every configured one is
    /// carried.
    fn check_dialects_spread(&self, file: &Path) -> Result<(), ConfigError> {
        let configured = self.configured();
        let mut carried = Vec::new();
        for (i, link) in self.links.iter().enumerate() {
            let at = At {
                file,
                prefix: self.key_prefix(i),
            };
            for d in &link.dialects {
                if !configured.contains(d) {
                    return Err(at.invalid(
                        "dialects",
                        &format!("names {0:?}, and [mqtt.{0}] is not configured", d.as_str()),
                        "add the dialect's table under [mqtt], or remove it from the list",
                    ));
                }
                if carried.contains(d) {
                    return Err(at.invalid(
                        "dialects",
                        &format!("names {:?}, which another link carries", d.as_str()),
                        "a dialect is carried by one link: it answers on the broker its \
                         commands came from",
                    ));
                }
                carried.push(*d);
            }
            let open = self.links[..i].iter().any(|l| l.dialects.is_empty());
            if self.links.len() > 1 && link.dialects.is_empty() && open {
                return Err(at.invalid(
                    "dialects",
                    "is empty on two links",
                    "list the dialects of each link, e.g. dialects = [\"root\"]",
                ));
            }
            if self.listed && self.dialects_of(link).is_empty() {
                return Err(at.invalid(
                    "dialects",
                    "leaves the link carrying no dialect",
                    "list the dialects it carries, or remove the link",
                ));
            }
        }
        if let Some(lost) = configured.iter().find(|d| self.link_of(**d).is_none()) {
            return Err(invalid(
                file,
                lost.as_str(),
                "is configured, and no link carries it",
                &format!("add {:?} to a link's dialects", lost.as_str()),
            ));
        }
        Ok(())
    }

    /// A platform link uses no topic outside the vehicle's prefixes: no `rtk` (bare
    /// topics), no embedded broker, a status topic and a mapping forward under a prefix.
    fn check_confined(&self, link: &MqttLinkConfig, at: &At<'_>) -> Result<(), ConfigError> {
        let dialects = self.dialects_of(link);
        if link.embedded_broker {
            return Err(at.invalid(
                "platform",
                "is set on the embedded broker's link: a platform's broker is shared by \
                 many vehicles",
                "keep platform for the link to the fleet's broker",
            ));
        }
        if dialects.contains(&DialectName::Rtk) {
            return Err(at.invalid(
                "dialects",
                "carries \"rtk\" on a platform link: its topics are bare, shared by every \
                 vehicle on the broker",
                "carry rtk on the robot's own broker (a link without platform)",
            ));
        }
        let prefixes = self.prefixes(link);
        if prefixes.is_empty() {
            return Err(at.invalid(
                "dialects",
                "carries no dialect with the vehicle's id in its topics",
                "carry \"root\" or \"device\" on a platform link",
            ));
        }
        let under = |topic: &str| prefixes.iter().any(|p| is_under(topic, p));
        let status = link.status_topic("{name}");
        if !under(&status) {
            return Err(at.invalid(
                "status_topic",
                &format!("{status:?} lies outside the vehicle's topics ({prefixes:?})"),
                "leave it unset (it goes under the vehicle's prefix), or put it there",
            ));
        }
        if dialects.contains(&DialectName::Device)
            && let Some(forward) = self
                .device
                .as_ref()
                .and_then(|d| d.mapping_forward.as_ref())
            && !under(forward)
        {
            return Err(invalid(
                at.file,
                "device.mapping_forward",
                &format!("{forward:?} lies outside the vehicle's topics on a platform link"),
                "put it under the device's prefix, e.g. \"device/<serial>/nav\"",
            ));
        }
        Ok(())
    }
}

/// An invalid value at `mqtt.<key>` in `file`.
fn invalid(file: &Path, key: &str, problem: &str, fix: &str) -> ConfigError {
    ConfigError::invalid(file, &format!("mqtt.{key}"), problem, fix)
}

/// The dialect tables' keys in `[mqtt]`, in either form.
const DIALECT_KEYS: [&str; 3] = ["rtk", "root", "device"];

impl<'de> Deserialize<'de> for MqttConfig {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let mut table = toml::Table::deserialize(deserializer)?;
        let mut dialect_tables = toml::Table::new();
        for key in DIALECT_KEYS {
            if let Some(value) = table.remove(key) {
                dialect_tables.insert(key.into(), value);
            }
        }
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Dialects {
            rtk: Option<RtkDialectConfig>,
            root: Option<RootDialectConfig>,
            device: Option<DeviceDialectConfig>,
        }
        let dialects: Dialects = dialect_tables.try_into().map_err(D::Error::custom)?;
        let (links, listed) = match table.remove("link") {
            Some(links) => {
                if let Some(key) = table.keys().next() {
                    return Err(D::Error::custom(format!(
                        "mqtt.{key} is a link's key, and [[mqtt.link]] lists the links: move it \
                         into each link that needs it"
                    )));
                }
                let links: Vec<MqttLinkConfig> = links.try_into().map_err(D::Error::custom)?;
                (links, true)
            }
            None => {
                let link: MqttLinkConfig = table.try_into().map_err(D::Error::custom)?;
                (vec![link], false)
            }
        };
        let mut config = MqttConfig {
            links,
            rtk: dialects.rtk,
            root: dialects.root,
            device: dialects.device,
            listed,
        };
        config.settle_platform_status_topics();
        Ok(config)
    }
}

impl Serialize for MqttConfig {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::Error as _;
        let mut table = if self.listed || self.links.len() != 1 {
            let mut t = toml::Table::new();
            t.insert(
                "link".into(),
                toml::Value::try_from(&self.links).map_err(S::Error::custom)?,
            );
            t
        } else {
            toml::Table::try_from(self.first()).map_err(S::Error::custom)?
        };
        let dialects = [
            ("rtk", self.rtk.as_ref().map(toml::Value::try_from)),
            ("root", self.root.as_ref().map(toml::Value::try_from)),
            ("device", self.device.as_ref().map(toml::Value::try_from)),
        ];
        for (key, value) in dialects {
            if let Some(value) = value {
                table.insert(key.into(), value.map_err(S::Error::custom)?);
            }
        }
        table.serialize(serializer)
    }
}

#[cfg(test)]
mod tests;
