//! What every mode that runs the engine shares (`run`, `calibrate --drive` and `sim`): the
//! links a configuration names, started in one order beside the engine, the recorder, and
//! one route for every engine output. A new link is a module of `runtime::links` and a line
//! in [`Links::start`] and [`Links::route`]; the modes do not change.

use std::path::Path;

use tokio::sync::mpsc;

use crate::api::log_budget::{self, LogBudget, SharedBudget};
use crate::api::mqtt::Publish;
use crate::config::VehicleConfig;
use crate::config::mqtt::DialectName;
use crate::devices::gnss::GnssFix;
use crate::engine::{CORRECTIONS_SOURCE, Engine, EngineOutput, HOST_SOURCE, RTCM_PROTOCOL};
use crate::record::{Record, RecordingWriter, SourceMeta};
use crate::runtime::clock::RecordClock;
use crate::runtime::error::{Result, invalid};
use crate::runtime::host;
use crate::runtime::links::broker::{self, EmbeddedBroker};
use crate::runtime::links::mqtt::{self, MqttSender, MqttSpec};
use crate::runtime::links::ntrip::{self, CorrectionsClient};
use crate::runtime::links::ros1::{self, Ros1Link};
use crate::runtime::links::ros2::{self, Ros2Link};
use crate::runtime::links::websocket::{self, WebsocketLink};
use crate::runtime::recorder::Recorder;
use crate::runtime::zones_writer::ZonesWriter;
use crate::time::Timestamp;

/// The log lines of refused commands, shared by every link.
static REFUSED: SharedBudget = SharedBudget::new(LogBudget::new());
/// The log lines of messages no MQTT link carries.
static UNROUTED: SharedBudget = SharedBudget::new(LogBudget::new());

/// The embedded broker, when the configuration asks for one. Started first, before the
/// drivers: its process takes a moment to start on a slow PC, and nothing that keeps time
/// (the drives' set-up) should wait meanwhile.
pub fn start_broker(config: &VehicleConfig) -> Result<Option<EmbeddedBroker>> {
    match &config.mqtt {
        Some(m) => broker::start_if_embedded(m, &config.vehicle.name),
        None => Ok(None),
    }
}

/// The links of a running engine: where its outputs go beyond the mode's own (status lines,
/// frames), and where commands and corrections come from.
pub struct Links {
    clock: RecordClock,
    /// Each MQTT link, with the dialects it carries.
    mqtt: Vec<MqttRoute>,
    ros1: Option<Ros1Link>,
    ros2: Option<Ros2Link>,
    websocket: Option<WebsocketLink>,
    corrections: Option<CorrectionsClient>,
    zones: Option<ZonesWriter>,
}

impl Links {
    /// Starts every link `config` names for `engine`: NTRIP corrections, MQTT (on `broker`
    /// when it is embedded, with the host monitor for the root dialect), the ROS1 node, the
    /// rosbridge WebSocket, and the zones file's writer. Their records go to `tx`; each
    /// recorded source is added to `sources` unless already there.
    pub fn start(
        engine: &mut Engine,
        config: &VehicleConfig,
        broker: Option<EmbeddedBroker>,
        clock: RecordClock,
        tx: &mpsc::Sender<Record>,
        sources: &mut Vec<SourceMeta>,
    ) -> Result<Self> {
        let mut add = |meta: SourceMeta| {
            if !sources.iter().any(|s| s.name == meta.name) {
                sources.push(meta);
            }
        };
        let corrections = match &config.ntrip {
            Some(n) => {
                add(SourceMeta::serial(CORRECTIONS_SOURCE, RTCM_PROTOCOL));
                Some(ntrip::spawn(n, clock, tx.clone())?)
            }
            None => None,
        };
        let mut mqtt = Vec::new();
        if let Some(m) = &config.mqtt {
            if m.root.is_some() {
                add(SourceMeta::commands(
                    HOST_SOURCE,
                    &format!("{HOST_SOURCE}.log"),
                ));
                host::spawn(clock, tx.clone());
            }
            for link in &m.links {
                let source = link.source();
                add(SourceMeta::commands(&source, &format!("{source}.log")));
                let dialects = m.dialects_of(link);
                let spec = MqttSpec {
                    config: link.clone(),
                    vehicle: config.vehicle.name.clone(),
                    subscriptions: engine.subscriptions(Some(&dialects)),
                    command_topics: engine.command_topics(Some(&dialects)),
                };
                let sender = mqtt::spawn(spec, clock, tx.clone())?;
                if link.embedded_broker
                    && let Some(b) = broker.clone()
                {
                    broker::spawn_health_reports(
                        b,
                        sender.clone(),
                        link.broker_health_topic(&config.vehicle.name),
                    );
                }
                mqtt.push(MqttRoute {
                    name: link.name.clone(),
                    dialects,
                    sender,
                });
            }
        }
        let ros1 = match config.ros1.clone() {
            Some(r) => {
                add(ros1::source_meta());
                Some(ros1::start(engine, config, r, clock, tx.clone())?)
            }
            None => None,
        };
        let ros2 = match config.ros2.clone() {
            Some(r) => {
                add(ros2::source_meta());
                Some(ros2::start(engine, config, r, clock, tx.clone())?)
            }
            None => None,
        };
        let websocket = match config.websocket.clone() {
            Some(w) => {
                add(websocket::source_meta());
                Some(websocket::start(engine, config, w, clock, tx.clone())?)
            }
            None => None,
        };
        Ok(Self {
            clock,
            mqtt,
            ros1,
            ros2,
            websocket,
            corrections,
            zones: zones_writer(config),
        })
    }

    /// Whether any link may send records (commands, corrections).
    pub fn any(&self) -> bool {
        !self.mqtt.is_empty()
            || self.ros1.is_some()
            || self.ros2.is_some()
            || self.websocket.is_some()
            || self.corrections.is_some()
    }

    /// Tells the caster where the vehicle is (a VRS or nearest-base mount needs it).
    pub fn update_position(&self, fix: Option<&GnssFix>) {
        if let Some(c) = &self.corrections {
            c.update_position(fix);
        }
    }

    /// Routes one engine output: what the WebSocket server sees of it, what the ROS1 node
    /// publishes, messages to MQTT, zones to their file, events and command answers to the
    /// log. Returns the others (status lines and frames), which each mode routes itself.
    pub fn route(&mut self, output: EngineOutput) -> Option<EngineOutput> {
        if let Some(link) = &mut self.websocket {
            link.see(&output);
        }
        if let Some(link) = &mut self.ros2 {
            link.see(&output);
        }
        let output = match &mut self.ros1 {
            Some(link) => link.take(output)?,
            None => output,
        };
        match output {
            EngineOutput::Publish(message) => self.publish(message),
            EngineOutput::Event(event) => tracing::info!("{event}"),
            // What only a ROS node publishes; none took it.
            EngineOutput::Poses(..) | EngineOutput::Imu(_) | EngineOutput::Fix(..) => {}
            EngineOutput::ZonesChanged(text) => match &self.zones {
                Some(writer) => writer.write(text),
                None => {
                    tracing::warn!("the zones changed, but they have no file to be written to")
                }
            },
            // A query (a ROS1 client asking where the vehicle is) may come often: not logged.
            EngineOutput::CommandResult {
                result: Ok(()),
                data: Some(_),
                ..
            } => {}
            EngineOutput::CommandResult {
                source,
                topic,
                result: Ok(()),
                ..
            } => tracing::info!(%source, %topic, "command accepted"),
            // Said a few times per period: a client can be refused as fast as it asks.
            EngineOutput::CommandResult {
                source,
                topic,
                result: Err(reason),
                ..
            } => {
                if let Some(left_out) = log_budget::allow(&REFUSED, self.clock.now()) {
                    tracing::warn!(%source, %topic, %reason, left_out, "command refused");
                }
            }
            other => return Some(other),
        }
        None
    }
}

/// One MQTT link as the router sees it.
struct MqttRoute {
    name: String,
    dialects: Vec<DialectName>,
    sender: MqttSender,
}

impl Links {
    /// Sends `message` on the link that carries its dialect: answers go back to the broker
    /// their requests came from.
    fn publish(&self, message: Publish) {
        let dialect = message.dialect.and_then(DialectName::from_name);
        let route = self
            .mqtt
            .iter()
            .find(|r| dialect.is_some_and(|d| r.dialects.contains(&d)));
        match route {
            Some(r) => r.sender.send(message),
            None => {
                if let Some(left_out) = log_budget::allow(&UNROUTED, self.clock.now()) {
                    tracing::error!(
                        topic = %message.topic,
                        dialect = ?message.dialect,
                        links = ?self.mqtt.iter().map(|r| r.name.as_str()).collect::<Vec<_>>(),
                        left_out,
                        "MQTT message of a dialect no link carries: not sent"
                    );
                }
            }
        }
    }
}

/// The recorder of a session into the new folder `dir`: the configuration in force, every
/// source, and the stored trajectories as they were at the start.
pub fn start_recorder(
    dir: &Path,
    config: &VehicleConfig,
    start: Timestamp,
    sources: Vec<SourceMeta>,
    trajectories: Option<&[u8]>,
) -> Result<Recorder> {
    let mut writer = RecordingWriter::create(
        dir,
        &config.vehicle.name,
        start,
        Some(&config.to_effective_toml()),
        sources,
    )
    .map_err(invalid(format!(
        "cannot start recording in {}",
        dir.display()
    )))?;
    if let Some(snapshot) = trajectories {
        writer
            .attach_trajectories(snapshot)
            .map_err(invalid("cannot record the stored trajectories"))?;
    }
    tracing::info!(folder = %dir.display(), "recording");
    Ok(Recorder::start(writer))
}

/// Says what the zones do, once at start.
pub fn log_zones(config: &VehicleConfig) {
    if let Some(z) = &config.zones {
        tracing::info!(
            zones = z.set.zones().len(),
            "zones: every motion's way is checked before it starts and the braking way every \
             tick, autonomous work runs only while the GNSS gate is open; ROS1 /set_shape and /set_region \
             edit them, the WebSocket's /zones and /safety_envelope and the live page show them"
        );
    }
}

/// The writer of the zones file, when the configuration names one.
fn zones_writer(config: &VehicleConfig) -> Option<ZonesWriter> {
    let file = config.zones.as_ref()?.file.clone()?;
    match ZonesWriter::start(file) {
        Ok(w) => Some(w),
        Err(e) => {
            tracing::error!(error = %e, "cannot start the zones writer: edits are not kept");
            None
        }
    }
}
