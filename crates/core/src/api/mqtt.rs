//! What the MQTT dialects share: the messages they publish, the trait each dialect
//! implements, and the router that hands an incoming message to the dialect owning its topic.
//! Dialects are sans-IO like the core: messages in, messages out; the runtime moves them.

pub use crate::api::adapter::CoreAccess;
pub use crate::api::adapter::Handled;
use crate::api::adapter::{Adapter, Reply};
pub use crate::api::publish::{Publish, Qos};
use crate::api::trajectory::TrajectoryStore;
use crate::config::mqtt::{DialectName, MqttConfig};
use crate::control::mission::MissionEvent;
use crate::control::{MotionResult, MotionTag};
use crate::time::Timestamp;
use crate::vehicle::VehicleStatus;

/// Source name of MQTT messages in recordings and the engine.
pub const MQTT_SOURCE: &str = crate::sources::MQTT;

/// One protocol dialect.
pub trait Dialect: Send {
    /// Its name in logs (`rtk`, `root`, `device`).
    fn name(&self) -> &'static str;
    /// Topic filters to subscribe to.
    fn subscriptions(&self) -> Vec<String>;
    /// The exact topics it acts on. The wildcard subscriptions also bring invented names,
    /// which the link rate-limits together, before any decoding.
    fn command_topics(&self) -> Vec<String>;
    /// Every exact topic it takes or publishes (its commands, answers and reports): the
    /// embedded broker serves these whatever names other clients invent.
    fn topics(&self) -> Vec<String>;
    /// Whether an incoming message on `topic` is for this dialect.
    fn owns(&self, topic: &str) -> bool;
    /// Handles an incoming message at `t`; replies go to `out`. `Refused` when it answered
    /// with an error (malformed, unknown, or refused by the core), so the run counts it.
    fn on_message(
        &mut self,
        t: Timestamp,
        topic: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) -> Handled;
    /// Publishes what is due at a status tick, and acts on what the time says (a
    /// heartbeat that stopped).
    fn on_status(
        &mut self,
        status: &VehicleStatus,
        core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    );
    /// A motion ended at `t`: the dialect that tagged it answers its request.
    fn on_motion_ended(&mut self, _t: Timestamp, _result: &MotionResult, _out: &mut Vec<Publish>) {}
    /// A mission it tagged made progress at `t`.
    fn on_mission_event(
        &mut self,
        _t: Timestamp,
        _id: u64,
        _event: &MissionEvent,
        _out: &mut Vec<Publish>,
    ) {
    }
}

/// What a dialect is built from: the MQTT configuration, and the trajectory store, which
/// the dialect that keeps trajectories takes.
pub struct DialectSetup<'a> {
    /// The `[mqtt]` configuration; each dialect reads its own table.
    pub mqtt: &'a MqttConfig,
    /// The trajectory store, until a dialect takes it.
    pub trajectories: Option<Box<dyn TrajectoryStore>>,
}

/// A dialect's entry point: the dialect, when the configuration turns it on. Each dialect
/// module provides one, and [`crate::api::DIALECTS`] lists them.
pub type DialectFactory = fn(&mut DialectSetup<'_>) -> Option<Box<dyn Dialect>>;

/// The MQTT link's adapter: every dialect in force, each owning its topics; what a dialect
/// publishes goes out as [`Reply::Publish`].
impl Adapter for Dialects {
    fn source(&self) -> &'static str {
        MQTT_SOURCE
    }

    fn on_request(
        &mut self,
        t: Timestamp,
        topic: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Reply>,
    ) -> Handled {
        let Some(d) = self.dialects.iter_mut().find(|d| d.owns(topic)) else {
            return Handled::NotOwned;
        };
        let mut handled = Handled::Taken;
        let name = d.name();
        publishing(out, name, |p| {
            handled = d.on_message(t, topic, payload, core, p)
        });
        handled
    }

    fn on_status(
        &mut self,
        status: &VehicleStatus,
        core: &mut dyn CoreAccess,
        out: &mut Vec<Reply>,
    ) {
        for d in &mut self.dialects {
            let name = d.name();
            publishing(out, name, |p| d.on_status(status, core, p));
        }
    }

    fn on_motion_ended(&mut self, t: Timestamp, result: &MotionResult, out: &mut Vec<Reply>) {
        if let Some(d) = result.tag.and_then(|tag| self.owner(tag)) {
            let name = d.name();
            publishing(out, name, |p| d.on_motion_ended(t, result, p));
        }
    }

    fn on_mission_event(
        &mut self,
        t: Timestamp,
        tag: Option<MotionTag>,
        event: &MissionEvent,
        out: &mut Vec<Reply>,
    ) {
        if let Some(tag) = tag
            && let Some(d) = self.owner(tag)
        {
            let name = d.name();
            publishing(out, name, |p| d.on_mission_event(t, tag.id, event, p));
        }
    }
}

/// What the dialect called `name` publishes, as replies marked with its name, so the
/// runtime sends them on the link that carries it.
fn publishing(out: &mut Vec<Reply>, name: &'static str, dialect: impl FnOnce(&mut Vec<Publish>)) {
    let mut publishes = Vec::new();
    dialect(&mut publishes);
    out.extend(publishes.into_iter().map(|p| {
        Reply::Publish(Publish {
            dialect: Some(name),
            ..p
        })
    }));
}

/// The dialects in force, in the order they were configured.
#[derive(Default)]
pub struct Dialects {
    dialects: Vec<Box<dyn Dialect>>,
}

impl Dialects {
    /// `dialects`; each checks its own payload size limit.
    pub fn new(dialects: Vec<Box<dyn Dialect>>) -> Self {
        Self { dialects }
    }

    /// The dialects `mqtt` turns on, each built by its own entry in `factories`;
    /// trajectories are kept in `trajectories`.
    pub fn from_config(
        mqtt: &MqttConfig,
        trajectories: Box<dyn TrajectoryStore>,
        factories: &[DialectFactory],
    ) -> Self {
        let mut setup = DialectSetup {
            mqtt,
            trajectories: Some(trajectories),
        };
        Self::new(factories.iter().filter_map(|f| f(&mut setup)).collect())
    }

    /// The topic filters of the dialects `carried` names (every dialect's with `None`).
    pub fn subscriptions(&self, carried: Option<&[DialectName]>) -> Vec<String> {
        self.carried(carried)
            .flat_map(|d| d.subscriptions())
            .collect()
    }

    /// Every exact topic the dialects `carried` names take or publish.
    pub fn topics(&self, carried: Option<&[DialectName]>) -> Vec<String> {
        self.carried(carried).flat_map(|d| d.topics()).collect()
    }

    /// The exact topics the dialects `carried` names act on.
    pub fn command_topics(&self, carried: Option<&[DialectName]>) -> Vec<String> {
        self.carried(carried)
            .flat_map(|d| d.command_topics())
            .collect()
    }

    /// The dialects `carried` names (all with `None`): one link's.
    fn carried<'a>(
        &'a self,
        carried: Option<&'a [DialectName]>,
    ) -> impl Iterator<Item = &'a Box<dyn Dialect>> {
        self.dialects.iter().filter(move |d| {
            carried.is_none_or(|names| names.iter().any(|n| n.as_str() == d.name()))
        })
    }

    /// The dialect that tagged a motion or mission.
    fn owner(&mut self, tag: MotionTag) -> Option<&mut Box<dyn Dialect>> {
        self.dialects.iter_mut().find(|d| d.name() == tag.owner)
    }
}
