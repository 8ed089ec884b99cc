//! The sans-IO engine: routes recorded or live records through the device decoders into the
//! vehicle core, runs the control loop and schedules the status ticks. Live mode and replay
//! both drive this one type, so a live run and the replay of its recording produce the same
//! output.
//!
//! Ticks fall on whole multiples of the control period (10 ms) of the record clock; every
//! tenth is also a status tick (100 ms). A tick at `T` sees every record stamped at or before
//! `T`. Time seen by the core never runs backwards: a record stamped before the previous
//! record is processed at that record's time, and one stamped at or before an emitted tick
//! 1 µs after it. Equal stamps from different sources are ordered by source name, as the
//! recording reader orders them. [`Engine::handle`] returns the time it used, which is what
//! a recording must store.

pub mod drivetrain;

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::time::Duration;

use crate::api::adapter::{Adapter, Handled, Reply};
use crate::api::mqtt::{CoreAccess, Dialects, MQTT_SOURCE, Publish};
use crate::api::trajectory::{MemoryStore, TrajectoryStore};
use crate::config::VehicleConfig;
use crate::config::imu::{ImuConfig, ImuProtocol};
use crate::config::mqtt::DialectName;
use crate::devices::can::{Frame, Received};
use crate::devices::gnss::rtcm::{RtcmFramer, RtcmStats};
use crate::devices::gnss::{GnssReceiver, GnssStats};
use crate::devices::imu::hipnuc::HiPnuc;
use crate::devices::imu::witmotion::WitMotion;
use crate::devices::imu::{ImuDecoder, ImuStats, Mounting};
use crate::record::{Payload, Record};
use crate::time::Timestamp;
use crate::vehicle::chassis::{CONTROL_PERIOD, CommandRejected};
use crate::vehicle::envelope::Envelope;
use crate::vehicle::gate::GateConfig;
use crate::vehicle::zones::ZoneGuard;
use crate::vehicle::{
    CoreConfig, Device, Event, HostUsage, Input, LinkState, MqttLinkStatus, Output, Vehicle,
    VehicleStatus,
};
use drivetrain::{BusStats, Drivetrain};

/// The status period of base_status (10 Hz).
pub const STATUS_PERIOD: Duration = Duration::from_millis(100);

/// Source name of the host load samples (topic `usage`, payload [`HostUsage`] JSON).
pub const HOST_SOURCE: &str = crate::sources::HOST;

/// Source name of the local command channel (`chassisd run --commands-stdin`).
pub const LOCAL_COMMANDS: &str = crate::sources::LOCAL_COMMANDS;

/// Source name of process events: a `shutdown` record (topic `shutdown`, payload the signal's
/// name) marks where live mode stopped the drives on exit, so a replay stops them too.
pub const PROCESS_SOURCE: &str = crate::sources::PROCESS;

/// Source name of the GNSS receiver (its NMEA bytes in, its corrections out).
pub const GNSS_SOURCE: &str = crate::sources::GNSS;

/// Source name of the RTCM 3 corrections from an NTRIP caster (the bytes as it sent them).
pub const CORRECTIONS_SOURCE: &str = crate::sources::CORRECTIONS;

/// The protocol name recordings give the corrections' source.
pub const RTCM_PROTOCOL: &str = "rtcm3";

/// The port name of `[ntrip] port`, where corrections go when not to the receiver's own.
pub const CORRECTIONS_PORT: &str = "rtcm_out";

/// Transmissions kept waiting for their pair in a replay, each side: beyond it the oldest
/// count as differences (a replay's memory must not grow with a gap in the recording).
const MAX_UNPAIRED_TX: usize = 4096;
/// The smallest time step of the record clock.
const ONE_MICRO: Duration = Duration::from_micros(1);

/// The decoder a serial source's bytes go through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decoder {
    /// NMEA 0183 from a GNSS receiver.
    Nmea,
    /// An IMU.
    Imu(ImuProtocol),
}

/// Every serial device kind chassisd decodes, by the protocol name recordings and
/// configurations give it: a new serial protocol is a line here and an arm of
/// [`imu_decoder`] (for an IMU), and both the engine and `chassisd check` build it from them.
pub const SERIAL_KINDS: &[Decoder] = &[
    Decoder::Nmea,
    Decoder::Imu(ImuProtocol::Witmotion),
    Decoder::Imu(ImuProtocol::Hipnuc),
];

/// A fresh decoder for an IMU speaking `protocol`.
pub fn imu_decoder(protocol: ImuProtocol) -> ImuDecoder {
    match protocol {
        ImuProtocol::Witmotion => ImuDecoder::WitMotion(WitMotion::new()),
        ImuProtocol::Hipnuc => ImuDecoder::HiPnuc(HiPnuc::new()),
    }
}

impl Decoder {
    /// The decoder for a recording's `protocol` name.
    pub fn for_protocol(protocol: &str) -> Option<Self> {
        SERIAL_KINDS
            .iter()
            .copied()
            .find(|d| d.protocol() == protocol)
    }

    /// The decoders of a recording's serial sources, by their recorded protocol (a source
    /// whose protocol has none is left out).
    pub fn of_recording(meta: &crate::record::Meta) -> Vec<(String, Self)> {
        meta.sources
            .iter()
            .filter(|s| s.kind == crate::record::SourceKind::Serial)
            .filter_map(|s| Some((s.name.clone(), Self::for_protocol(s.protocol.as_deref()?)?)))
            .collect()
    }

    /// The protocol name recordings use.
    pub fn protocol(self) -> &'static str {
        match self {
            Self::Nmea => "nmea0183",
            Self::Imu(p) => p.name(),
        }
    }
}

/// What the engine produces.
#[derive(Debug, Clone, PartialEq)]
pub enum EngineOutput {
    /// A status snapshot (every 100 ms).
    Status(Box<VehicleStatus>),
    /// Bytes to write to a serial port: whole, valid RTCM frames for the receiver.
    SerialTx {
        /// The port: a serial source's name (`gnss`), or [`CORRECTIONS_PORT`].
        port: String,
        /// The bytes.
        bytes: bytes::Bytes,
    },
    /// A frame to transmit on a CAN interface.
    CanTx {
        /// The interface.
        bus: String,
        /// The frame.
        frame: Frame,
    },
    /// Something for the operator's log: a drive running, a fault raised or cleared, a stop,
    /// a motion's end.
    Event(Event),
    /// The zones changed (an edit): all of them as GeoJSON, for the zones file.
    ZonesChanged(String),
    /// A message for the MQTT broker (a dialect's report or reply).
    Publish(Publish),
    /// A closed-loop motion ended (also announced as an event).
    MotionEnded(crate::control::MotionResult),
    /// The poses at a control tick (only with [`Engine::emit_poses`]: the 100 Hz feed of a
    /// ROS node's odometry).
    Poses(Timestamp, crate::vehicle::PoseReport),
    /// An IMU sample as the core got it, in the vehicle frame (only with
    /// [`Engine::emit_poses`]).
    Imu(crate::devices::imu::ImuSample),
    /// The receiver's solution after a sentence, at the time the sentence came (only with
    /// [`Engine::emit_poses`]: the ROS 2 node's `/fix`).
    Fix(Timestamp, Box<crate::devices::gnss::GnssFix>),
    /// A raw measurement, as decoded (only with [`Engine::emit_measurements`]: what a
    /// calibration fits).
    Measured(Measured),
    /// A mission's progress, with the tag of whoever asked for it.
    Mission {
        /// Who asked.
        tag: Option<crate::control::MotionTag>,
        /// What happened.
        event: crate::control::mission::MissionEvent,
    },
    /// The answer to a command record.
    CommandResult {
        /// The channel it came on.
        source: String,
        /// Its topic.
        topic: String,
        /// The request's id, when its channel waits for the answer.
        request: Option<u64>,
        /// Accepted, or why not.
        result: Result<(), String>,
        /// What a query asked for, as JSON; `None` for a command.
        data: Option<serde_json::Value>,
    },
}

/// A raw measurement for a calibration.
#[derive(Debug, Clone, PartialEq)]
pub enum Measured {
    /// An IMU sample in the sensor's own frame, the configured bias not taken off.
    Imu(crate::devices::imu::ImuSample),
    /// The receiver's fix after a sentence, at the time the sentence arrived.
    Gnss(Timestamp, Box<crate::devices::gnss::GnssFix>),
    /// The wheels' feedback at a control tick.
    Wheels {
        /// Left wheel.
        left: crate::vehicle::chassis::WheelFeedback,
        /// Right wheel.
        right: crate::vehicle::chassis::WheelFeedback,
    },
}

/// Counters of what went through the engine.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct EngineStats {
    /// Records by source.
    pub records_by_source: BTreeMap<String, u64>,
    /// Records from sources with no decoder.
    pub undecoded: u64,
    /// Commands received (a query answered is not one).
    pub commands: u64,
    /// Queries answered (a ROS1 client asking where the vehicle is): they change nothing.
    pub queries: u64,
    /// Commands refused (malformed, or refused by the core).
    pub commands_rejected: u64,
    /// Command records from channels without a dialect yet.
    pub commands_without_dialect: u64,
    /// Records whose time was moved forward to keep the core's time monotonic.
    pub reordered: u64,
    /// Status ticks emitted.
    pub ticks: u64,
    /// Recorded transmissions (replay) that matched what the engine sent.
    pub tx_matched: u64,
    /// Recorded transmissions that differed from what the engine sent, or had no
    /// counterpart.
    pub tx_mismatched: u64,
}

/// Where the records of one source go: resolved from the source's name once, when the
/// engine is built, so a record is routed by a lookup and never by comparing names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Route {
    /// RTCM corrections for the receiver.
    Corrections,
    /// An NMEA receiver.
    Gnss,
    /// An IMU.
    Imu,
    /// A CAN interface.
    Bus,
    /// The process's own events (its shutdown).
    Process,
    /// The host's load samples.
    Host,
    /// A command channel: its protocol's adapter.
    Adapter(AdapterId),
    /// One MQTT link, by its place in the configuration: its commands go to the dialects,
    /// its states to the status.
    MqttLink(usize),
}

/// One of the engine's adapters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum AdapterId {
    /// The MQTT dialects.
    Mqtt,
    /// One of [`crate::api::ADAPTERS`], by its place there.
    Listed(usize),
}

/// The adapter `id` names.
fn adapter_mut<'a>(
    mqtt: &'a mut Dialects,
    listed: &'a mut [Box<dyn Adapter>],
    id: AdapterId,
) -> &'a mut dyn Adapter {
    match id {
        AdapterId::Mqtt => mqtt,
        AdapterId::Listed(i) => listed[i].as_mut(),
    }
}

/// The routes of a configuration's sources: later entries win a name taken twice.
fn routes(
    mqtt_links: &[(String, MqttLinkStatus)],
    nmea: &BTreeMap<String, GnssReceiver>,
    imu: &BTreeMap<String, (ImuDecoder, Mounting)>,
    drivetrain: &Drivetrain,
    adapters: &[Box<dyn Adapter>],
) -> HashMap<String, Route> {
    let listed = adapters
        .iter()
        .enumerate()
        .map(|(i, a)| (a.source(), Route::Adapter(AdapterId::Listed(i))));
    let fixed = [(HOST_SOURCE, Route::Host), (PROCESS_SOURCE, Route::Process)];
    let mut routes: HashMap<String, Route> = listed
        .chain(fixed)
        .map(|(name, route)| (name.to_owned(), route))
        .collect();
    routes.extend(
        drivetrain
            .bus_names()
            .map(|name| (name.to_owned(), Route::Bus)),
    );
    routes.insert(MQTT_SOURCE.to_owned(), Route::Adapter(AdapterId::Mqtt));
    routes.extend(
        mqtt_links
            .iter()
            .enumerate()
            .map(|(i, (source, _))| (source.clone(), Route::MqttLink(i))),
    );
    routes.extend(imu.keys().map(|name| (name.clone(), Route::Imu)));
    routes.extend(nmea.keys().map(|name| (name.clone(), Route::Gnss)));
    routes.insert(CORRECTIONS_SOURCE.to_owned(), Route::Corrections);
    routes
}

/// Records and ticks in, outputs out.
pub struct Engine {
    vehicle: Vehicle,
    /// Each source's route, by name.
    routes: HashMap<String, Route>,
    nmea: BTreeMap<String, GnssReceiver>,
    imu: BTreeMap<String, (ImuDecoder, Mounting)>,
    drivetrain: Drivetrain,
    next_tick: Option<Timestamp>,
    /// Time and source of the last record processed.
    last_record: Option<(Timestamp, String)>,
    /// Time of the last tick emitted.
    last_tick: Option<Timestamp>,
    /// Frames sent and not yet matched against recorded transmissions (replay only).
    sent: Option<VecDeque<(String, Frame)>>,
    /// Recorded transmissions not yet matched (replay only).
    recorded_tx: VecDeque<(String, Received)>,
    /// The drives as last reported, to announce changes.
    drive_states: Vec<(bool, Option<String>)>,
    /// The latched stop's reason at the last status.
    stop_reason: Option<String>,
    /// The MQTT protocol dialects, the MQTT link's adapter.
    dialects: Dialects,
    /// Each MQTT link's recording source and state, for the status.
    mqtt_links: Vec<(String, MqttLinkStatus)>,
    /// The other command channels' adapters ([`crate::api::ADAPTERS`]).
    adapters: Vec<Box<dyn Adapter>>,
    /// Emit the poses every control tick and every IMU sample.
    emit_poses: bool,
    /// Emit every raw measurement.
    emit_measurements: bool,
    /// The corrections relay, with `[ntrip]`.
    corrections: Option<CorrectionsRelay>,
    stats: EngineStats,
}

/// Frames the caster's bytes and passes the valid frames, whole and in order, to the port
/// the receiver takes corrections on.
#[derive(Debug)]
struct CorrectionsRelay {
    framer: RtcmFramer,
    port: String,
}

/// The core as the dialects reach it, at one time.
struct CoreAt<'a> {
    vehicle: &'a mut Vehicle,
    t: Timestamp,
    /// What a command put out beside its answer (a log event, the zones changed), for the
    /// engine's outputs once the adapter is done.
    aside: Vec<EngineOutput>,
}

impl<'a> CoreAt<'a> {
    fn new(vehicle: &'a mut Vehicle, t: Timestamp) -> Self {
        Self {
            vehicle,
            t,
            aside: Vec::new(),
        }
    }
}

impl CoreAccess for CoreAt<'_> {
    fn pose_report(&self) -> crate::vehicle::PoseReport {
        self.vehicle.pose_report(self.t)
    }

    fn command(&mut self, command: crate::vehicle::Command) -> Result<(), CommandRejected> {
        let mut result = Ok(());
        for output in self.vehicle.handle(self.t, Input::Command(command)) {
            match output {
                Output::CommandResult(r) => result = r,
                Output::Event(event) => self.aside.push(EngineOutput::Event(event)),
                Output::ZonesChanged(text) => self.aside.push(EngineOutput::ZonesChanged(text)),
                _ => {}
            }
        }
        result
    }
}

/// An adapter's replies as engine outputs; answers name `source`, the channel the request
/// came on.
fn emit_replies(source: &str, replies: Vec<Reply>, out: &mut Vec<EngineOutput>) {
    out.extend(replies.into_iter().map(|reply| match reply {
        Reply::Publish(message) => EngineOutput::Publish(message),
        Reply::Answer(answer) => EngineOutput::CommandResult {
            source: source.to_owned(),
            topic: answer.topic,
            request: answer.request,
            result: answer.result,
            data: answer.data,
        },
    }))
}

/// What every adapter, the MQTT dialects first, replies to one event, as engine outputs.
fn from_every_adapter(
    mqtt: &mut Dialects,
    listed: &mut [Box<dyn Adapter>],
    mut event: impl FnMut(&mut dyn Adapter, &mut Vec<Reply>),
) -> Vec<EngineOutput> {
    let mut out = Vec::new();
    let every =
        std::iter::once(mqtt as &mut dyn Adapter).chain(listed.iter_mut().map(|a| a.as_mut()));
    for adapter in every {
        let mut replies = Vec::new();
        event(adapter, &mut replies);
        emit_replies(adapter.source(), replies, &mut out);
    }
    out
}

/// Each MQTT link's recording source and its state before any is recorded.
fn mqtt_links(config: &VehicleConfig) -> Vec<(String, MqttLinkStatus)> {
    let links = config.mqtt.iter().flat_map(|m| &m.links);
    links
        .map(|l| {
            let status = MqttLinkStatus {
                name: l.name.clone(),
                up: false,
                since: None,
            };
            (l.source(), status)
        })
        .collect()
}

/// The dialects a configuration turns on, trajectories kept in `trajectories`.
fn dialects(config: &VehicleConfig, trajectories: Box<dyn TrajectoryStore>) -> Dialects {
    match &config.mqtt {
        Some(mqtt) => Dialects::from_config(mqtt, trajectories, crate::api::DIALECTS),
        None => Dialects::default(),
    }
}

impl Engine {
    /// An engine for `config` whose serial `sources` (name and decoder) feed a core;
    /// trajectories are kept in memory.
    pub fn new(config: &VehicleConfig, sources: &[(String, Decoder)]) -> Self {
        Self::with_trajectories(config, sources, Box::new(MemoryStore::default()))
    }

    /// [`Engine::new`], with trajectories kept in `trajectories` (a folder, live).
    pub fn with_trajectories(
        config: &VehicleConfig,
        sources: &[(String, Decoder)],
        trajectories: Box<dyn TrajectoryStore>,
    ) -> Self {
        let nmea = sources
            .iter()
            .filter(|(_, d)| *d == Decoder::Nmea)
            .map(|(name, _)| (name.clone(), GnssReceiver::new()))
            .collect();
        let mounting = config
            .imu
            .as_ref()
            .map(ImuConfig::mounting)
            .unwrap_or_default();
        let imu = sources
            .iter()
            .filter_map(|(name, d)| match d {
                Decoder::Imu(protocol) => Some((name.clone(), (imu_decoder(*protocol), mounting))),
                Decoder::Nmea => None,
            })
            .collect();
        let drivetrain = Drivetrain::new(config);
        let adapters: Vec<Box<dyn Adapter>> = crate::api::ADAPTERS
            .iter()
            .map(|a| a(&config.vehicle.name))
            .collect();
        let mqtt_links = mqtt_links(config);
        let mut vehicle = Vehicle::new(CoreConfig::from_vehicle(config));
        if let Some(z) = &config.zones {
            let guard = ZoneGuard::new(z.set.clone(), z.footprint.radius_m(), z.margin_m);
            let gate = GateConfig::from_zones(z, config.ntrip.is_some());
            vehicle = vehicle.with_envelope(Envelope::new(guard, gate, z.manual));
        }
        Self {
            vehicle,
            routes: routes(&mqtt_links, &nmea, &imu, &drivetrain, &adapters),
            mqtt_links,
            adapters,
            nmea,
            imu,
            drivetrain,
            next_tick: None,
            last_record: None,
            last_tick: None,
            sent: None,
            recorded_tx: VecDeque::new(),
            drive_states: Vec::new(),
            stop_reason: None,
            dialects: dialects(config, trajectories),
            emit_poses: false,
            emit_measurements: false,
            corrections: config.ntrip.as_ref().map(|n| CorrectionsRelay {
                framer: RtcmFramer::new(),
                port: match n.port {
                    Some(_) => CORRECTIONS_PORT.to_owned(),
                    None => GNSS_SOURCE.to_owned(),
                },
            }),
            stats: EngineStats::default(),
        }
    }

    /// Emits [`EngineOutput::Poses`] every control tick, [`EngineOutput::Imu`] for every
    /// sample and [`EngineOutput::Fix`] after every GNSS sentence, for a consumer that
    /// publishes them at their own rate (the ROS nodes).
    pub fn emit_poses(&mut self) {
        self.emit_poses = true;
    }

    /// Emits [`EngineOutput::Measured`] for every IMU sample, GNSS sentence and control
    /// tick's wheel feedback, for a calibration.
    pub fn emit_measurements(&mut self) {
        self.emit_measurements = true;
    }

    /// Replay mode: transmissions are checked against the recording's `T` frames instead of
    /// going anywhere.
    pub fn check_recorded_transmissions(&mut self) {
        self.sent = Some(VecDeque::new());
    }

    /// Sets the first tick to the first control period boundary at or after `t` (live mode
    /// calls it at start; replay lets the session start or the first record set it).
    pub fn start_at(&mut self, t: Timestamp) {
        if self.next_tick.is_none() {
            self.next_tick = Some(t.ceil_to(CONTROL_PERIOD));
        }
    }

    /// The time of the next tick, once known.
    pub fn next_tick(&self) -> Option<Timestamp> {
        self.next_tick
    }

    /// Processes one record; outputs (including those of ticks that fell due before it) go
    /// to `out`. Returns the time the core saw.
    pub fn handle(&mut self, record: &Record, out: &mut Vec<EngineOutput>) -> Timestamp {
        // A recorded transmission is an output of the live run, not an input: it is checked
        // against what this engine sends, and does not move time.
        let route = self.routes.get(record.source.as_str()).copied();
        if let Payload::CanTx(frame) = &record.payload
            && self.sent.is_some()
            && route == Some(Route::Bus)
            && !self.drivetrain.is_listen_only(&record.source)
        {
            self.recorded_transmission(&record.source, frame);
            return record.t;
        }
        let t = self.effective_time(record);
        self.start_at(t);
        self.emit_ticks(|tick| tick < t, out);
        self.last_record = Some((t, record.source.clone()));
        self.count_record(&record.source);
        let mut tx = Vec::new();
        match (route, &record.payload) {
            (Some(Route::Corrections), Payload::Serial(bytes)) => {
                self.relay_corrections(t, bytes, out);
            }
            (Some(Route::Corrections), Payload::Link(state)) => {
                if let Some(relay) = &mut self.corrections
                    && *state == LinkState::Down
                {
                    // A new connection starts a new stream: no frame spans two.
                    relay.framer.reset();
                }
                self.vehicle
                    .handle(t, Input::Link(Device::Corrections, *state));
            }
            (Some(Route::Gnss | Route::Imu), Payload::Serial(bytes)) => {
                self.sensor_bytes(t, &record.source, bytes, out);
            }
            (Some(Route::Gnss), Payload::Link(state)) => {
                self.vehicle.handle(t, Input::Link(Device::Gnss, *state));
            }
            (Some(Route::Imu), Payload::Link(state)) => {
                self.vehicle.handle(t, Input::Link(Device::Imu, *state));
            }
            // The control links' states are recorded and shown in the status; the dialects
            // do not act on them (the heartbeat watchdog does, on silence).
            (Some(Route::MqttLink(i)), Payload::Link(state)) => {
                if let Some((_, link)) = self.mqtt_links.get_mut(i) {
                    link.up = *state == LinkState::Up;
                    link.since = Some(t);
                }
            }
            // An MQTT source no link of this configuration has (an older recording's).
            (Some(Route::Adapter(AdapterId::Mqtt)), Payload::Link(_)) => {}
            (Some(Route::Bus), Payload::Link(state)) => {
                self.drivetrain
                    .link(t, &record.source, *state == LinkState::Up, &mut tx);
            }
            (Some(Route::Bus), Payload::Can(frame)) => {
                self.can_frame(t, &record.source, frame, &mut tx);
            }
            // A monitor sees every frame on the bus, another master's included.
            (Some(Route::Bus), Payload::CanTx(frame))
                if self.drivetrain.is_listen_only(&record.source) =>
            {
                self.can_frame(t, &record.source, frame, &mut tx);
            }
            (Some(Route::Adapter(id)), Payload::Command { topic, payload }) => {
                self.request(t, id, &record.source, (topic, payload), out);
            }
            (Some(Route::MqttLink(_)), Payload::Command { topic, payload }) => {
                let id = AdapterId::Mqtt;
                self.request(t, id, &record.source, (topic, payload), out);
            }
            (Some(Route::Process), Payload::Command { topic, .. }) if topic == "shutdown" => {
                self.vehicle
                    .handle(t, Input::Command(crate::vehicle::Command::Stop));
                self.drivetrain.shut_down(&mut tx);
            }
            (Some(Route::Host), Payload::Command { payload, .. }) => {
                match serde_json::from_slice::<HostUsage>(payload) {
                    Ok(usage) => {
                        self.vehicle.handle(t, Input::Host(usage));
                    }
                    Err(_) => self.stats.undecoded += 1,
                }
            }

            (_, Payload::Command { .. }) => self.stats.commands_without_dialect += 1,
            _ => self.stats.undecoded += 1,
        }
        self.transmit(tx, out);
        t
    }

    /// A CAN frame the live run sent, as recorded: paired with what this engine sends.
    fn recorded_transmission(&mut self, source: &str, frame: &socketcan::CanAnyFrame) {
        self.count_record(source);
        if self.recorded_tx.len() >= MAX_UNPAIRED_TX {
            // Recorded frames this engine never sent: differences, not a growing queue.
            self.recorded_tx.pop_front();
            self.stats.tx_mismatched += 1;
        }
        self.recorded_tx
            .push_back((source.to_owned(), Received::from_socketcan(frame)));
        self.compare_transmissions();
    }

    /// A receiver's or an IMU's bytes: decoded by the source's decoder, each fix or sample to
    /// the core (and, when asked for, out as measured).
    fn sensor_bytes(
        &mut self,
        t: Timestamp,
        source: &str,
        bytes: &[u8],
        out: &mut Vec<EngineOutput>,
    ) {
        let vehicle = &mut self.vehicle;
        let measure = self.emit_measurements;
        let emit = self.emit_poses;
        if let Some(receiver) = self.nmea.get_mut(source) {
            receiver.push(t, bytes, |fix| {
                if measure {
                    out.push(EngineOutput::Measured(Measured::Gnss(t, Box::new(*fix))));
                }
                if emit {
                    out.push(EngineOutput::Fix(t, Box::new(*fix)));
                }
                for output in vehicle.handle(t, Input::Gnss(fix)) {
                    if let Output::Event(event) = output {
                        out.push(EngineOutput::Event(event));
                    }
                }
            });
            if let Some(news) = receiver.take_news() {
                out.push(EngineOutput::Event(Event::Receiver(news)));
            }
        } else if let Some((decoder, mounting)) = self.imu.get_mut(source) {
            decoder.push(t, bytes, |sample| {
                if measure {
                    out.push(EngineOutput::Measured(Measured::Imu(sample)));
                }
                let sample = mounting.apply(&sample);
                vehicle.handle(t, Input::Imu(&sample));
                if emit {
                    out.push(EngineOutput::Imu(sample));
                }
            });
        } else {
            self.stats.undecoded += 1;
        }
    }

    /// A request of adapter `id`'s source: handed to its adapter with the core at `t`,
    /// counted as a command or a query, its replies out.
    fn request(
        &mut self,
        t: Timestamp,
        id: AdapterId,
        source: &str,
        (topic, payload): (&str, &[u8]),
        out: &mut Vec<EngineOutput>,
    ) {
        let adapter = adapter_mut(&mut self.dialects, &mut self.adapters, id);
        let mut core = CoreAt::new(&mut self.vehicle, t);
        let mut replies = Vec::new();
        let handled = adapter.on_request(t, topic, payload, &mut core, &mut replies);
        if handled == Handled::Answered {
            self.stats.queries += 1;
        } else {
            self.stats.commands += 1;
        }
        match handled {
            Handled::Taken | Handled::Answered => {}
            Handled::Refused => self.stats.commands_rejected += 1,
            Handled::NotOwned => self.stats.commands_without_dialect += 1,
        }
        out.append(&mut core.aside);
        emit_replies(source, replies, out);
    }

    /// The valid frames among a caster's `bytes` go to the receiver's port as one write;
    /// the core learns their time.
    fn relay_corrections(&mut self, t: Timestamp, bytes: &[u8], out: &mut Vec<EngineOutput>) {
        let Some(relay) = &mut self.corrections else {
            self.stats.undecoded += 1;
            return;
        };
        let mut whole = Vec::new();
        let mut frames = 0u64;
        relay.framer.push(bytes, |frame, _| {
            whole.extend_from_slice(frame);
            frames += 1;
        });
        if frames == 0 {
            return;
        }
        let input = Input::Corrections {
            frames,
            bytes: whole.len() as u64,
        };
        for output in self.vehicle.handle(t, input) {
            if let Output::Event(event) = output {
                out.push(EngineOutput::Event(event));
            }
        }
        out.push(EngineOutput::SerialTx {
            port: relay.port.clone(),
            bytes: bytes::Bytes::from(whole),
        });
    }

    /// The receiver's latest fix (what a GGA to the caster reports).
    pub fn gnss_fix(&self) -> Option<&crate::devices::gnss::GnssFix> {
        self.vehicle.gnss_fix()
    }

    /// The corrections relay's framing counters, with `[ntrip]`.
    pub fn corrections_stats(&self) -> Option<&RtcmStats> {
        self.corrections.as_ref().map(|r| r.framer.stats())
    }

    fn can_frame(
        &mut self,
        t: Timestamp,
        source: &str,
        frame: &socketcan::CanAnyFrame,
        tx: &mut Vec<(String, Frame)>,
    ) {
        let received = Received::from_socketcan(frame);
        if self.drivetrain.on_frame(t, source, &received, tx)
            && let Some(reading) = self.drivetrain.bms_reading()
        {
            let reading = *reading;
            self.vehicle.handle(t, Input::Bms(&reading));
        }
    }

    fn count_record(&mut self, source: &str) {
        match self.stats.records_by_source.get_mut(source) {
            Some(n) => *n += 1,
            None => {
                self.stats.records_by_source.insert(source.to_owned(), 1);
            }
        }
    }

    /// Pairs recorded transmissions with the frames this engine sent, in order.
    fn compare_transmissions(&mut self) {
        let Some(sent) = &mut self.sent else {
            return;
        };
        while !sent.is_empty() && !self.recorded_tx.is_empty() {
            let (Some((bus, mine)), Some((source, recorded))) =
                (sent.pop_front(), self.recorded_tx.pop_front())
            else {
                break;
            };
            match recorded {
                Received::Data(f) if bus == source && f == mine => self.stats.tx_matched += 1,
                _ => self.stats.tx_mismatched += 1,
            }
        }
    }

    /// Ends a replay: transmissions left over on either side count as differences.
    pub fn finish(&mut self) {
        self.compare_transmissions();
        let left = self.sent.as_ref().map_or(0, VecDeque::len) + self.recorded_tx.len();
        self.stats.tx_mismatched += left as u64;
        if let Some(sent) = &mut self.sent {
            sent.clear();
        }
        self.recorded_tx.clear();
    }

    fn transmit(&mut self, tx: Vec<(String, Frame)>, out: &mut Vec<EngineOutput>) {
        for (bus, frame) in tx {
            match &mut self.sent {
                Some(sent) => {
                    if sent.len() >= MAX_UNPAIRED_TX {
                        // A span with no recorded frames (a gap, or metadata that claims
                        // one): what this engine sent there differs, and is not kept.
                        sent.pop_front();
                        self.stats.tx_mismatched += 1;
                    }
                    sent.push_back((bus, frame));
                }
                None => out.push(EngineOutput::CanTx { bus, frame }),
            }
        }
        self.compare_transmissions();
    }

    /// Emits every tick at or before `t`.
    pub fn advance_to(&mut self, t: Timestamp, out: &mut Vec<EngineOutput>) {
        self.emit_ticks(|tick| tick <= t, out);
    }

    fn emit_ticks(&mut self, due: impl Fn(Timestamp) -> bool, out: &mut Vec<EngineOutput>) {
        while let Some(tick) = self.next_tick.filter(|&tick| due(tick)) {
            self.control_tick(tick, out);
            if self.emit_poses {
                out.push(EngineOutput::Poses(tick, self.vehicle.pose_report(tick)));
            }
            if tick.as_nanos() % STATUS_PERIOD.as_nanos() as u64 == 0 {
                for output in self.vehicle.handle(tick, Input::Tick) {
                    if let Output::Event(event) = &output {
                        out.push(EngineOutput::Event(event.clone()));
                    }
                    if let Output::Status(mut s) = output {
                        s.mqtt_links = self.mqtt_links.iter().map(|(_, l)| l.clone()).collect();
                        self.announce_stop_reason(&s, out);
                        let mut core = CoreAt::new(&mut self.vehicle, tick);
                        let reports =
                            from_every_adapter(&mut self.dialects, &mut self.adapters, |a, r| {
                                a.on_status(&s, &mut core, r)
                            });
                        out.append(&mut core.aside);
                        out.push(EngineOutput::Status(s));
                        out.extend(reports);
                        self.stats.ticks += 1;
                    }
                }
            }
            self.last_tick = Some(tick);
            self.next_tick = Some(tick.saturating_add(CONTROL_PERIOD));
        }
    }

    /// One control step: device timers, feedback to the core, the core's wheel command back.
    fn control_tick(&mut self, t: Timestamp, out: &mut Vec<EngineOutput>) {
        if self.drivetrain.is_empty() {
            return;
        }
        let mut tx = Vec::new();
        self.drivetrain.poll(t, &mut tx);
        if self.drivetrain.has_drives() {
            let feedback = self.drivetrain.feedback();
            if self.emit_measurements {
                out.push(EngineOutput::Measured(Measured::Wheels {
                    left: feedback.left,
                    right: feedback.right,
                }));
            }
            self.announce_drive_changes(&feedback.drives, out);
            self.vehicle.handle(t, Input::Chassis(&feedback));
            for output in self.vehicle.handle(t, Input::ControlTick) {
                match output {
                    Output::Wheels(command) => self.drivetrain.command(t, &command),
                    Output::Event(event) => out.push(EngineOutput::Event(event)),
                    Output::ZonesChanged(text) => out.push(EngineOutput::ZonesChanged(text)),
                    Output::MotionEnded(result) => {
                        out.extend(from_every_adapter(
                            &mut self.dialects,
                            &mut self.adapters,
                            |a, r| a.on_motion_ended(t, &result, r),
                        ));
                        out.push(EngineOutput::MotionEnded(result));
                    }
                    Output::Cutter(on) => {
                        let configured = self.drivetrain.set_cutter(t, on, &mut tx);
                        out.push(EngineOutput::Event(Event::Cutter { on, configured }));
                    }
                    Output::Mission { tag, event } => {
                        out.extend(from_every_adapter(
                            &mut self.dialects,
                            &mut self.adapters,
                            |a, r| a.on_mission_event(t, tag, &event, r),
                        ));
                        out.push(EngineOutput::Mission { tag, event });
                    }
                    Output::Status(_) | Output::CommandResult(_) => {}
                }
            }
            // The new command leaves in this tick, not with the next poll.
            self.drivetrain.flush_commands(t, &mut tx);
        }
        self.transmit(tx, out);
    }

    /// Logs each new reason for a latched stop, and the re-arm that ends it.
    fn announce_stop_reason(
        &mut self,
        status: &crate::vehicle::status::VehicleStatus,
        out: &mut Vec<EngineOutput>,
    ) {
        let reason = status.chassis.as_ref().and_then(|c| c.stop_reason.clone());
        if reason != self.stop_reason {
            out.push(EngineOutput::Event(Event::SafetyStop(reason.clone())));
            self.stop_reason = reason;
        }
    }

    fn announce_drive_changes(
        &mut self,
        drives: &[crate::vehicle::chassis::DriveSummary],
        out: &mut Vec<EngineOutput>,
    ) {
        let now: Vec<(bool, Option<String>)> = drives
            .iter()
            .map(|d| (d.running, d.fault.clone()))
            .collect();
        for (i, d) in drives.iter().enumerate() {
            let before = self.drive_states.get(i).cloned().unwrap_or((false, None));
            if d.fault != before.1 {
                out.push(EngineOutput::Event(Event::DriveFault {
                    drive: d.name.clone(),
                    fault: d.fault.clone(),
                }));
            }
            if d.running && !before.0 {
                out.push(EngineOutput::Event(Event::DriveRunning(d.name.clone())));
            }
        }
        self.drive_states = now;
    }

    /// The record's time, moved forward where needed so the core's time never runs back.
    fn effective_time(&mut self, record: &Record) -> Timestamp {
        let mut t = record.t;
        if let Some(tick) = self.last_tick {
            t = t.max(tick.saturating_add(ONE_MICRO));
        }
        if let Some((last, last_source)) = &self.last_record {
            if t < *last {
                t = *last;
            }
            if t == *last && record.source.as_str() < last_source.as_str() {
                t = t.saturating_add(ONE_MICRO);
            }
        }
        if t != record.t {
            self.stats.reordered += 1;
        }
        t
    }

    /// The topic filters the dialects `carried` names subscribe to (all with `None`).
    pub fn subscriptions(&self, carried: Option<&[DialectName]>) -> Vec<String> {
        self.dialects.subscriptions(carried)
    }

    /// The exact topics the dialects `carried` names act on (all with `None`).
    pub fn command_topics(&self, carried: Option<&[DialectName]>) -> Vec<String> {
        self.dialects.command_topics(carried)
    }

    /// Engine counters.
    pub fn stats(&self) -> &EngineStats {
        &self.stats
    }

    /// Counters of each NMEA source.
    pub fn gnss_stats(&self) -> impl Iterator<Item = (&str, GnssStats)> {
        self.nmea.iter().map(|(name, r)| (name.as_str(), r.stats()))
    }

    /// Counters of each IMU source.
    pub fn imu_stats(&self) -> impl Iterator<Item = (&str, ImuStats)> {
        self.imu
            .iter()
            .map(|(name, (d, _))| (name.as_str(), d.stats()))
    }

    /// Counters of each CAN interface.
    pub fn bus_stats(&self) -> impl Iterator<Item = (&str, &BusStats)> {
        self.drivetrain.stats()
    }

    /// The drives' speed response time learnt so far, s; `None` without drives.
    pub fn response_time(&self) -> Option<f64> {
        self.vehicle.response_time()
    }

    /// The drive train, for diagnostics.
    pub fn drivetrain(&self) -> &Drivetrain {
        &self.drivetrain
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_serial_kind_is_found_by_the_name_recordings_give_it() {
        let mut names = std::collections::BTreeSet::new();
        for kind in SERIAL_KINDS {
            assert!(names.insert(kind.protocol()), "{} twice", kind.protocol());
            assert_eq!(Decoder::for_protocol(kind.protocol()), Some(*kind));
        }
        assert_eq!(Decoder::for_protocol("nmea"), None);
        // Every IMU protocol a configuration may name has its line (the match stops compiling
        // when a protocol is added, so this list cannot fall behind).
        let listed = |p: ImuProtocol| match p {
            ImuProtocol::Witmotion | ImuProtocol::Hipnuc => p,
        };
        for protocol in [ImuProtocol::Witmotion, ImuProtocol::Hipnuc].map(listed) {
            assert!(
                SERIAL_KINDS.contains(&Decoder::Imu(protocol)),
                "{protocol:?}"
            );
        }
    }

    fn rec(us: u64, source: &str) -> Record {
        Record {
            t: Timestamp::from_micros(us),
            source: source.into(),
            payload: Payload::Link(LinkState::Up),
        }
    }

    fn engine() -> Engine {
        Engine::new(
            &VehicleConfig::default(),
            &[("a".into(), Decoder::Nmea), ("b".into(), Decoder::Nmea)],
        )
    }

    fn ticks(out: &[EngineOutput]) -> Vec<u64> {
        out.iter()
            .filter_map(|o| match o {
                EngineOutput::Status(s) => Some(s.time.as_micros()),
                _ => None,
            })
            .collect()
    }

    /// With two links, each link's records come as its own source: its commands reach the
    /// dialects, its answers are marked with their dialect (so the runtime sends them on the
    /// link carrying it), and its up and down reach the status.
    #[test]
    fn each_links_source_reaches_the_dialects_and_its_state_the_status() {
        let config = VehicleConfig::from_toml(
            "[[mqtt.link]]\nname = \"site\"\ndialects = [\"rtk\"]\n\
             [[mqtt.link]]\nname = \"platform\"\nplatform = true\ndialects = [\"root\"]\n\
             [mqtt.rtk]\n[mqtt.root]\nvehicle_id = \"v1\"\n",
            std::path::Path::new("vehicle.toml"),
        )
        .expect("configuration");
        let mut e = Engine::new(&config, &[]);
        let mut out = Vec::new();
        e.handle(
            &Record {
                t: Timestamp::from_micros(1_000),
                source: "mqtt-platform".into(),
                payload: Payload::Link(LinkState::Up),
            },
            &mut out,
        );
        e.handle(
            &Record {
                t: Timestamp::from_micros(2_000),
                source: "mqtt-platform".into(),
                payload: Payload::Command {
                    topic: "/root/v1/heartbeat/set".into(),
                    payload: bytes::Bytes::from_static(br#"{"clientId": "op"}"#),
                },
            },
            &mut out,
        );
        let notify = out
            .iter()
            .find_map(|o| match o {
                EngineOutput::Publish(p) if p.topic == "/root/v1/heartbeat/notify" => Some(p),
                _ => None,
            })
            .expect("the heartbeat answered");
        assert_eq!(notify.dialect, Some("root"));
        e.advance_to(Timestamp::from_micros(200_000), &mut out);
        let status = out
            .iter()
            .rev()
            .find_map(|o| match o {
                EngineOutput::Status(s) => Some(s),
                _ => None,
            })
            .expect("a status");
        let links: Vec<(&str, bool, Option<u64>)> = status
            .mqtt_links
            .iter()
            .map(|l| (l.name.as_str(), l.up, l.since.map(Timestamp::as_micros)))
            .collect();
        assert_eq!(
            links,
            [("site", false, None), ("platform", true, Some(1_000))]
        );
        let base_status = out.iter().find_map(|o| match o {
            EngineOutput::Publish(p) if p.topic == "base_status" => Some(p),
            _ => None,
        });
        assert_eq!(base_status.map(|p| p.dialect), Some(Some("rtk")));
    }

    /// A refusal answered in the protocol's own reply (the core's, or the dialect's for a
    /// malformed request) is a refused command in the engine's counts, and so in the run's
    /// summary.
    #[test]
    fn a_command_the_core_refuses_counts_as_refused() {
        let config = VehicleConfig::from_toml(
            "[mqtt]\nhost = \"127.0.0.1\"\n\n[mqtt.root]\nvehicle_id = \"v1\"\n",
            std::path::Path::new("vehicle.toml"),
        )
        .expect("configuration");
        let mut e = Engine::new(&config, &[]);
        let mut out = Vec::new();
        let request = |us: u64, topic: &str, payload: &str| Record {
            t: Timestamp::from_micros(us),
            source: MQTT_SOURCE.into(),
            payload: Payload::Command {
                topic: topic.into(),
                payload: bytes::Bytes::from(payload.to_owned()),
            },
        };
        e.handle(
            &request(1_000, "/root/v1/heartbeat/set", r#"{"clientId": "op"}"#),
            &mut out,
        );
        assert_eq!((e.stats().commands, e.stats().commands_rejected), (1, 0));
        // No drives: the core refuses a DRIVE, and the reply says so with its code.
        let drive =
            r#"{"messageId": 1, "messageType": 100, "data": {"linear": 0.1, "angular": 0}}"#;
        e.handle(&request(2_000, "/root/v1/cmd/chassis/set", drive), &mut out);
        assert_eq!((e.stats().commands, e.stats().commands_rejected), (2, 1));
        // Malformed, and an unknown messageType: the dialect answers each with its code.
        e.handle(&request(3_000, "/root/v1/cmd/chassis/set", "{"), &mut out);
        let unknown = r#"{"messageId": 2, "messageType": 77, "data": 0}"#;
        e.handle(
            &request(4_000, "/root/v1/cmd/chassis/set", unknown),
            &mut out,
        );
        assert_eq!((e.stats().commands, e.stats().commands_rejected), (4, 3));
    }

    /// A ROS1 client asking what the build is changes nothing: a query, not an operator's
    /// command (the simulator's script yields only to a command taken); a refused query
    /// counts as a refused request, and the answer carries what was asked for.
    #[test]
    fn a_query_answered_is_no_command() {
        let mut e = Engine::new(&VehicleConfig::default(), &[]);
        let mut out = Vec::new();
        let ask = |us: u64, service: &str| Record {
            t: Timestamp::from_micros(us),
            source: crate::api::ros1::SOURCE.into(),
            payload: Payload::Command {
                topic: service.into(),
                payload: bytes::Bytes::from_static(br#"{"id":1,"msg":{}}"#),
            },
        };
        e.handle(&ask(1_000, "/navi_info"), &mut out);
        assert_eq!((e.stats().queries, e.stats().commands), (1, 0));
        let answered = out.iter().find_map(|o| match o {
            EngineOutput::CommandResult { request, data, .. } => Some((*request, data.clone())),
            _ => None,
        });
        assert!(
            matches!(&answered, Some((Some(1), Some(serde_json::Value::String(about)))) if about.contains("chassisd")),
            "{answered:?}"
        );
        // Never placed: where it is cannot be told.
        e.handle(&ask(2_000, "/get_position"), &mut out);
        let stats = e.stats();
        assert_eq!(
            (stats.queries, stats.commands, stats.commands_rejected),
            (1, 1, 1)
        );
    }

    fn serial(us: u64, source: &str, bytes: &[u8]) -> Record {
        Record {
            t: Timestamp::from_micros(us),
            source: source.into(),
            payload: Payload::Serial(bytes::Bytes::copy_from_slice(bytes)),
        }
    }

    #[test]
    fn only_whole_valid_frames_reach_the_receiver_and_the_core_learns_their_age() {
        use crate::devices::gnss::rtcm::encode;
        let mut config = VehicleConfig::default();
        config.ntrip = Some(crate::config::ntrip::NtripConfig::with_url(
            "ntrip://u:p@127.0.0.1:2101/M",
        ));
        let mut e = Engine::new(&config, &[(GNSS_SOURCE.into(), Decoder::Nmea)]);
        let (a, b) = (encode(&[0x3E, 0xD0, 1, 2]), encode(&[0x43, 0x50, 3]));
        let mut bad = encode(&[0x3E, 0xD0, 9]);
        bad[4] ^= 0xFF;
        // Garbage, a frame split over two records, a corrupted frame, then a whole one.
        let mut stream = b"junk".to_vec();
        stream.extend_from_slice(&a);
        stream.extend_from_slice(&bad);
        stream.extend_from_slice(&b);
        let mut out = Vec::new();
        e.handle(&serial(0, CORRECTIONS_SOURCE, &stream[..7]), &mut out);
        e.handle(&serial(50_000, CORRECTIONS_SOURCE, &stream[7..]), &mut out);
        let written: Vec<u8> = out
            .iter()
            .filter_map(|o| match o {
                EngineOutput::SerialTx { port, bytes } if port == GNSS_SOURCE => {
                    Some(bytes.to_vec())
                }
                _ => None,
            })
            .flatten()
            .collect();
        assert_eq!(written, [a, b].concat());
        let stats = e.corrections_stats().unwrap();
        assert_eq!(
            (stats.frames, stats.invalid_bytes),
            (2, 4 + bad.len() as u64)
        );
        e.advance_to(Timestamp::from_micros(1_000_000), &mut out);
        let age = out.iter().rev().find_map(|o| match o {
            EngineOutput::Status(s) => s.corrections.and_then(|c| c.age_s),
            _ => None,
        });
        assert_eq!(age, Some(0.95));
        // Ten seconds on, and no frame: stale, and said once.
        out.clear();
        e.advance_to(Timestamp::from_micros(11_200_000), &mut out);
        let said: Vec<&String> = out
            .iter()
            .filter_map(|o| match o {
                EngineOutput::Event(Event::Corrections(e)) if e.contains("stopped") => Some(e),
                _ => None,
            })
            .collect();
        assert_eq!(said.len(), 1, "{out:?}");
    }

    #[test]
    fn ticks_fall_on_period_boundaries_after_records_at_the_same_time() {
        let mut e = engine();
        let mut out = Vec::new();
        assert_eq!(
            e.handle(&rec(100_000, "a"), &mut out),
            Timestamp::from_micros(100_000)
        );
        assert!(
            out.is_empty(),
            "the tick at 0.1 s waits for records stamped 0.1 s"
        );
        e.handle(&rec(350_000, "a"), &mut out);
        assert_eq!(ticks(&out), [100_000, 200_000, 300_000]);
        out.clear();
        e.advance_to(Timestamp::from_micros(400_000), &mut out);
        assert_eq!(ticks(&out), [400_000]);
    }

    #[test]
    fn stragglers_move_after_the_tick_and_the_last_record() {
        let mut e = engine();
        let mut out = Vec::new();
        e.start_at(Timestamp::from_micros(0));
        e.advance_to(Timestamp::from_micros(100_000), &mut out);
        // Stamped before the tick that was already emitted.
        assert_eq!(e.handle(&rec(99_000, "b"), &mut out).as_micros(), 100_001);
        // Stamped before the previous record.
        assert_eq!(e.handle(&rec(50_000, "b"), &mut out).as_micros(), 100_001);
        // Same time, but a source that sorts first: after, as the reader would order it.
        assert_eq!(e.handle(&rec(100_001, "a"), &mut out).as_micros(), 100_002);
        assert_eq!(e.stats().reordered, 3);
    }
}
