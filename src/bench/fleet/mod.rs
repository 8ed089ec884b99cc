//! `bench fleet`: many simulated vehicles in one process, each with its own engine, plant and
//! platform link (sharing nothing but the process), on a set of broker nodes, with an
//! operator client on each node. It measures the vehicles' report periods and the commands'
//! round trips; then it kills one node and measures how the fleet comes back: the connects
//! per second that followed, the time until every vehicle was back, and whether any command
//! was lost or executed twice.
//!
//! The nodes are either independent mosquitto brokers (a vehicle is on one of them, so the
//! operator sends each command to every node) or a cluster (the operator sends each command
//! once, through the node that is never killed).

mod nodes;

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use serde::Serialize;
use serde_json::Value;
use tokio::sync::{mpsc, watch};

use super::error::{BenchError, Result, invalid};
use super::mqtt::Spread;
use crate::api::trajectory::MemoryStore;
use crate::config::mqtt::{DialectName, MqttConfig, MqttLinkConfig, RootDialectConfig};
use crate::engine::EngineOutput;
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::modes::sim::RTK_FIXED;
use crate::runtime::session::Links;
use crate::sim::lockstep::{Lockstep, PLANT_STEP, Sections, Sink};
use crate::sim::plant::PlantConfig;
use crate::vehicle::LinkState;
use crate::vehicle::chassis::CONTROL_PERIOD;
pub use nodes::{MosquittoNodes, NamedNodes, Nodes, RabbitNodes};

/// The report each vehicle's platform link carries at 5 Hz: its period is the fleet's.
const REPORT: &str = "report/chassis/general";
/// Its period, ms.
const REPORT_PERIOD_MS: f64 = 200.0;
/// Commands the operators send per second, across the fleet.
const COMMANDS_PER_S: f64 = 20.0;
/// How long every vehicle may take to report after the start.
const ALL_UP_WITHIN: Duration = Duration::from_secs(60);
/// How long after the last command its answer may still come.
const LAST_ANSWER_WITHIN: Duration = Duration::from_secs(3);
/// At most this share of the vehicles that came back may come back in any one second (with
/// the platform's default bounds the share is about a quarter: a first wait of up to 2 s on
/// the dead node, then up to 4 s to the next).
pub const MAX_SHARE_PER_SECOND: f64 = 0.35;
/// The share is held only from this many returning vehicles: fewer are too few to spread.
const SPREAD_FROM: usize = 50;

/// What to run.
pub struct FleetOptions {
    /// The simulated vehicle.
    pub plant: PlantConfig,
    /// How many vehicles.
    pub vehicles: usize,
    /// Steady running before the kill, and again after every vehicle is back.
    pub steady: Duration,
    /// Kill node 0 after the first steady span (and start it again at the end).
    pub kill: bool,
    /// The platform links' back-off bounds, s (`reconnect_min_s`, `reconnect_max_s`).
    pub reconnect: (f64, f64),
    /// The platform links' `command_qos`.
    pub command_qos: u8,
}

/// One vehicle's link going up or down, as its engine received it.
#[derive(Debug, Clone, Copy)]
struct LinkEvent {
    vehicle: usize,
    at: Instant,
    up: bool,
}

/// What an operator saw.
#[derive(Debug, Clone)]
enum Seen {
    Report { vehicle: usize },
    Answer { vehicle: usize, id: u64 },
}

/// An operator's observation: which node's operator, what, when.
#[derive(Debug, Clone)]
struct Observation {
    node: usize,
    seen: Seen,
    at: Instant,
}

/// The figures.
#[derive(Debug, Clone, Serialize)]
pub struct FleetReport {
    /// Vehicles run.
    pub vehicles: usize,
    /// Broker nodes, and whether they are one cluster.
    pub nodes: usize,
    /// Whether the nodes are a cluster.
    pub clustered: bool,
    /// The QoS the vehicles subscribed to their commands with.
    pub command_qos: u8,
    /// Each node's CPU while every vehicle ran steadily, % of one core.
    pub node_cpu_percent: Vec<Option<f64>>,
    /// Seconds until every vehicle reported, from the start.
    pub all_up_s: Option<f64>,
    /// The report period across all vehicles outside their outages, ms.
    pub report_period_ms: Option<Spread>,
    /// The commands' round trips (sent → answer at the operator), ms.
    pub command_round_trip_ms: Option<Spread>,
    /// Commands sent, answered once, never answered, answered more than once.
    pub commands: CommandCounts,
    /// The node kill, when one was made.
    pub failover: Option<Failover>,
    /// Whether every target held.
    pub pass: bool,
    /// The targets missed.
    pub missed: Vec<String>,
}

/// What became of the commands.
#[derive(Debug, Clone, Default, Serialize)]
pub struct CommandCounts {
    /// Sent.
    pub sent: usize,
    /// Executed and answered exactly once.
    pub once: usize,
    /// Never executed, though sent while the vehicle was connected.
    pub lost: usize,
    /// Executed, but no answer reached the operator.
    pub unanswered: usize,
    /// Arrived at the vehicle while connected, but never executed.
    pub dropped: usize,
    /// Sent to a vehicle that stayed connected while the fleet failed over, and lost by the
    /// brokers: it never reached the vehicle, or its answer never reached the operator. A
    /// RabbitMQ cluster drops a few such messages in the moment a node dies.
    pub lost_in_failover: usize,
    /// Answered more than once, though the vehicle stayed connected.
    pub twice: usize,
    /// Sent while the vehicle's link was down (clean sessions: never executed late).
    pub during_outage: usize,
    /// Of those, answered anyway (sent just before the vehicle's link saw the loss).
    pub during_outage_answered: usize,
    /// Of those, answered more than once: the vehicle sends a reply again when the broker
    /// went away before acknowledging it (at least once, as QoS 1 promises).
    pub during_outage_answer_copies: usize,
    /// Executed more than once by their vehicle (its engine answered them more than once),
    /// at any time.
    pub executed_twice: usize,
}

/// How the fleet came back after a node was killed.
#[derive(Debug, Clone, Serialize)]
pub struct Failover {
    /// Vehicles whose link went down.
    pub vehicles_down: usize,
    /// Of them, back up before the bench gave up.
    pub vehicles_back: usize,
    /// From the kill until the last of them was back, s.
    pub all_back_s: Option<f64>,
    /// Connects in each second after the kill.
    pub connects_per_second: Vec<usize>,
    /// The largest second's share of the vehicles that came back.
    pub max_share_per_second: f64,
    /// The longest gap in any vehicle's reports across the kill, ms.
    pub longest_report_gap_ms: Option<f64>,
    /// Vehicles whose link went down again after they came back.
    pub relapsed: usize,
}

/// Runs the fleet on `nodes`.
pub async fn run(options: FleetOptions, mut nodes: Box<dyn Nodes>) -> Result<FleetReport> {
    if options.vehicles == 0 || nodes.count() == 0 {
        return Err(BenchError::Failed(
            "a fleet needs vehicles and a node".into(),
        ));
    }
    let (first, largest) = options.reconnect;
    if !(0.01..=60.0).contains(&first) || !(first..=600.0).contains(&largest) {
        return Err(BenchError::Failed(format!(
            "back-off bounds {first} s and {largest} s: the first must lie in 0.01..=60 s, \
             the largest between it and 600 s"
        )));
    }
    let clock = RecordClock::start();
    let (stop_tx, stop) = watch::channel(false);
    let links: Arc<Mutex<Vec<LinkEvent>>> = Arc::default();
    let tally: Tally = Arc::default();
    let (seen_tx, mut seen) = mpsc::unbounded_channel();
    let operators = (0..nodes.count())
        .map(|i| operator(i, nodes.address(i), options.command_qos, seen_tx.clone()))
        .collect::<Vec<_>>();
    let started = Instant::now();
    let mut vehicles = Vec::new();
    for v in 0..options.vehicles {
        let mqtt = vehicle_mqtt(v, &*nodes, &options);
        let plant = options.plant.clone();
        let (links, tally, stop) = (links.clone(), tally.clone(), stop.clone());
        vehicles.push(tokio::spawn(vehicle(
            v, plant, mqtt, clock, links, tally, stop,
        )));
    }
    let mut log = Timeline {
        reports_from: nodes.clustered().then(|| nodes.count() - 1),
        ..Timeline::default()
    };
    // Every vehicle reports.
    let all_up = log
        .wait(&mut seen, ALL_UP_WITHIN, |l| {
            l.reporting() == options.vehicles
        })
        .await
        .then(|| started.elapsed().as_secs_f64());
    let mut commands = Commander::new(options.vehicles);
    let clustered = nodes.clustered();
    let via = |alive: &[bool]| -> Vec<usize> {
        if clustered {
            // Once, through the last node: it is never killed.
            vec![alive.len() - 1]
        } else {
            (0..alive.len()).filter(|i| alive[*i]).collect()
        }
    };
    let mut alive = vec![true; nodes.count()];
    let cpu_before: Vec<Option<f64>> = (0..nodes.count()).map(|i| nodes.cpu_seconds(i)).collect();
    let steady_from = Instant::now();
    commands
        .drive(
            &mut log,
            &mut seen,
            &operators,
            &via(&alive),
            options.steady,
        )
        .await;
    let steady_s = steady_from.elapsed().as_secs_f64();
    let node_cpu_percent: Vec<Option<f64>> = cpu_before
        .iter()
        .enumerate()
        .map(|(i, before)| Some((nodes.cpu_seconds(i)? - (*before)?) / steady_s * 100.0))
        .collect();
    let mut failover = None;
    if options.kill && nodes.count() > 1 {
        let killed_at = Instant::now();
        nodes.stop(0)?;
        alive[0] = false;
        // Commands go on while the fleet comes back; it has the largest back-off bound
        // and ten seconds to do so.
        let give_up = Duration::from_secs_f64(options.reconnect.1) + Duration::from_secs(10);
        let deadline = killed_at + give_up;
        while Instant::now() < deadline && !all_back(&links, killed_at) {
            commands
                .drive(
                    &mut log,
                    &mut seen,
                    &operators,
                    &via(&alive),
                    Duration::from_millis(250),
                )
                .await;
        }
        commands
            .drive(
                &mut log,
                &mut seen,
                &operators,
                &via(&alive),
                options.steady,
            )
            .await;
        nodes.start(0)?;
        failover = Some((killed_at, give_up));
    }
    // The last answers.
    log.wait(&mut seen, LAST_ANSWER_WITHIN, |_| false).await;
    let _ = stop_tx.send(true);
    for v in vehicles {
        let _ = v.await;
    }
    let events = links.lock().map(|l| l.clone()).unwrap_or_default();
    let failover = failover.map(|(at, give_up)| (at, failover_figures(&events, &log, at, give_up)));
    if let Ok(tally) = tally.lock() {
        log.arrived = tally.arrived.clone();
        log.executed = tally.executed.clone();
    }
    let mut report = FleetReport::new(
        &options, &*nodes, all_up, &log, &commands, &events, failover,
    );
    report.node_cpu_percent = node_cpu_percent;
    Ok(report)
}

/// Whether every vehicle whose link went down after `since` is up again.
fn all_back(links: &Mutex<Vec<LinkEvent>>, since: Instant) -> bool {
    let Ok(events) = links.lock() else {
        return false;
    };
    let mut state: HashMap<usize, bool> = HashMap::new();
    for e in events.iter().filter(|e| e.at >= since) {
        state.insert(e.vehicle, e.up);
    }
    !state.is_empty() && state.values().all(|up| *up)
}

/// The platform link of vehicle `v`: its id `v0007`, its first node `v % nodes`, the
/// others as failover.
fn vehicle_mqtt(v: usize, nodes: &dyn Nodes, options: &FleetOptions) -> MqttConfig {
    let n = nodes.count();
    let order: Vec<usize> = (0..n).map(|k| (v + k) % n).collect();
    let (host, port) = nodes.address(order[0]);
    let failover = order[1..]
        .iter()
        .map(|&i| {
            let (h, p) = nodes.address(i);
            format!("{h}:{p}")
        })
        .collect();
    let link = MqttLinkConfig {
        name: "platform".into(),
        dialects: vec![DialectName::Root],
        platform: true,
        host,
        port,
        failover,
        client_id: Some(format!("fleet-{}", vehicle_id(v))),
        reconnect_min_s: Some(options.reconnect.0),
        reconnect_max_s: Some(options.reconnect.1),
        command_qos: options.command_qos,
        status_topic: Some(format!("/root/{}/chassisd/status", vehicle_id(v))),
        ..MqttLinkConfig::default()
    };
    MqttConfig {
        root: Some(RootDialectConfig {
            vehicle_id: vehicle_id(v),
            heartbeat_timeout_s: 3.0,
            require_heartbeat: false,
            heartbeat_client_id: None,
        }),
        listed: true,
        ..MqttConfig::one(link)
    }
}

/// Vehicle `v`'s id.
fn vehicle_id(v: usize) -> String {
    format!("v{v:04}")
}

/// Vehicle `v`'s number from its id.
fn vehicle_of(id: &str) -> Option<usize> {
    id.strip_prefix('v')?.parse().ok()
}

/// Routes a vehicle's outputs to its links.
struct FleetSink {
    vehicle: usize,
    links: Links,
    tally: Tally,
}

/// What reached the vehicles, by (vehicle, messageId): each command's arrivals at its
/// vehicle's link, and its executions (the engine's answers, told apart from copies of an
/// answer the link sent again).
#[derive(Default, Clone)]
struct Tallies {
    arrived: HashMap<(usize, u64), u32>,
    executed: HashMap<(usize, u64), u32>,
}

type Tally = Arc<Mutex<Tallies>>;

/// The `messageId` of a DRIVE command or its answer.
fn message_id(payload: &[u8]) -> Option<u64> {
    serde_json::from_slice::<Value>(payload).ok()?["messageId"].as_u64()
}

impl Sink for FleetSink {
    fn record(&mut self, _record: &Record) {}
    fn output(&mut self, output: EngineOutput) {
        if let EngineOutput::Publish(p) = &output
            && p.topic.ends_with("/cmd/chassis/ack")
            && let Some(id) = message_id(&p.payload)
            && let Ok(mut tally) = self.tally.lock()
        {
            *tally.executed.entry((self.vehicle, id)).or_default() += 1;
        }
        let _ = self.links.route(output);
    }
}

/// One vehicle: its plant and engine stepped in real time, its link's records fed in, its
/// link's ups and downs noted, until `stop`.
async fn vehicle(
    v: usize,
    plant: PlantConfig,
    mqtt: MqttConfig,
    clock: RecordClock,
    events: Arc<Mutex<Vec<LinkEvent>>>,
    tally: Tally,
    mut stop: watch::Receiver<bool>,
) -> Result<()> {
    let sections = Sections {
        mqtt: Some(mqtt),
        ntrip: None,
        zones: None,
    };
    let mut sim = Lockstep::with_sections(
        plant,
        v as u64 + 1,
        clock.now(),
        sections,
        Box::new(MemoryStore::default()),
    )
    .map_err(invalid("the fleet's vehicle"))?;
    let config = sim.config().clone();
    let (tx, mut records) = mpsc::channel(256);
    let mut sources = Vec::new();
    let links = Links::start(sim.engine_mut(), &config, None, clock, &tx, &mut sources)
        .map_err(invalid("the fleet vehicle's links"))?;
    drop(tx);
    let mut sink = FleetSink {
        vehicle: v,
        links,
        tally: tally.clone(),
    };
    let mut pace = tokio::time::interval(CONTROL_PERIOD);
    pace.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    loop {
        tokio::select! {
            _ = pace.tick() => {
                let now = clock.now();
                while sim.time().saturating_add(PLANT_STEP) <= now {
                    sim.step(RTK_FIXED, &mut sink);
                }
            }
            record = records.recv() => {
                let Some(record) = record else { return Ok(()) };
                if let Payload::Link(state) = record.payload
                    && let Ok(mut e) = events.lock()
                {
                    e.push(LinkEvent { vehicle: v, at: Instant::now(), up: state == LinkState::Up });
                }
                if let Payload::Command { topic, payload } = &record.payload
                    && topic.ends_with("/cmd/chassis/set")
                    && let Some(id) = message_id(payload)
                    && let Ok(mut tally) = tally.lock()
                {
                    *tally.arrived.entry((v, id)).or_default() += 1;
                }
                sim.input(&record.source, record.payload, &mut sink);
            }
            _ = stop.changed() => return Ok(()),
        }
    }
}

/// An operator's client on node `node`: subscribes to every vehicle's report and command
/// answers (again after each reconnect) and tells what it sees.
fn operator(
    node: usize,
    (host, port): (String, u16),
    qos: u8,
    seen: mpsc::UnboundedSender<Observation>,
) -> AsyncClient {
    // The vehicles' command QoS: advice for any subscriber of such a cluster.
    let qos = if qos == 0 {
        QoS::AtMostOnce
    } else {
        QoS::AtLeastOnce
    };
    let mut o = MqttOptions::new(format!("fleet-operator-{node}"), host, port);
    o.set_keep_alive(Duration::from_secs(5));
    o.set_clean_session(true);
    let (client, mut events) = AsyncClient::new(o, 4096);
    events.set_network_options(crate::runtime::links::mqtt::low_latency());
    let subscriber = client.clone();
    tokio::spawn(async move {
        loop {
            match events.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    for filter in [
                        format!("/root/+/{REPORT}"),
                        "/root/+/cmd/chassis/ack".into(),
                    ] {
                        let _ = subscriber.try_subscribe(filter, qos);
                    }
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    let at = Instant::now();
                    let mut levels = p.topic.split('/');
                    let vehicle = levels.nth(2).and_then(vehicle_of);
                    let Some(vehicle) = vehicle else { continue };
                    let what = if p.topic.ends_with("/cmd/chassis/ack") {
                        let ack: Value = serde_json::from_slice(&p.payload).unwrap_or_default();
                        match ack["messageId"].as_u64() {
                            Some(id) => Seen::Answer { vehicle, id },
                            None => continue,
                        }
                    } else {
                        Seen::Report { vehicle }
                    };
                    if seen
                        .send(Observation {
                            node,
                            seen: what,
                            at,
                        })
                        .is_err()
                    {
                        return;
                    }
                }
                Ok(_) => {}
                Err(_) => tokio::time::sleep(Duration::from_millis(200)).await,
            }
        }
    });
    client
}

/// Everything the operators saw, in order, and what the vehicles executed.
#[derive(Default)]
struct Timeline {
    /// Each vehicle's report arrivals (copies from several operators within 20 ms merged).
    reports: BTreeMap<usize, Vec<Instant>>,
    /// Each command's answers, by (vehicle, id): when, and from which node's operator.
    answers: HashMap<(usize, u64), Vec<(Instant, usize)>>,
    /// Reports are taken from this node's operator alone (a cluster's, whose operators all
    /// see every report), or from every node's.
    reports_from: Option<usize>,
    /// Each command's arrivals at its vehicle, once the run is over.
    arrived: HashMap<(usize, u64), u32>,
    /// Each command's executions at its vehicle, once the run is over.
    executed: HashMap<(usize, u64), u32>,
}

impl Timeline {
    /// Takes what has arrived.
    fn take(&mut self, o: Observation) {
        match o.seen {
            Seen::Report { vehicle } if self.reports_from.is_none_or(|n| n == o.node) => {
                let arrivals = self.reports.entry(vehicle).or_default();
                let copy = arrivals
                    .last()
                    .is_some_and(|last| o.at.duration_since(*last) < Duration::from_millis(20));
                if !copy {
                    arrivals.push(o.at);
                }
            }
            Seen::Report { .. } => {}
            Seen::Answer { vehicle, id } => {
                self.answers
                    .entry((vehicle, id))
                    .or_default()
                    .push((o.at, o.node));
            }
        }
    }

    /// Vehicles that reported at least once.
    fn reporting(&self) -> usize {
        self.reports.len()
    }

    /// Takes observations until `done` or `within` passed; whether `done` held.
    async fn wait(
        &mut self,
        seen: &mut mpsc::UnboundedReceiver<Observation>,
        within: Duration,
        done: impl Fn(&Self) -> bool,
    ) -> bool {
        let deadline = tokio::time::Instant::now() + within;
        while !done(self) {
            match tokio::time::timeout_at(deadline, seen.recv()).await {
                Ok(Some(o)) => self.take(o),
                Ok(None) | Err(_) => return done(self),
            }
        }
        true
    }
}

/// Sends the commands: DRIVE at zero speed, each with an id of its own, round the fleet.
struct Commander {
    vehicles: usize,
    next_vehicle: usize,
    /// (vehicle, id, sent at).
    sent: Vec<(usize, u64, Instant)>,
}

impl Commander {
    fn new(vehicles: usize) -> Self {
        Self {
            vehicles,
            next_vehicle: 0,
            sent: Vec::new(),
        }
    }

    /// Sends commands for `span` through the operators `via`, taking observations between.
    async fn drive(
        &mut self,
        log: &mut Timeline,
        seen: &mut mpsc::UnboundedReceiver<Observation>,
        operators: &[AsyncClient],
        via: &[usize],
        span: Duration,
    ) {
        let every = Duration::from_secs_f64(1.0 / COMMANDS_PER_S);
        let end = Instant::now() + span;
        while Instant::now() < end {
            let v = self.next_vehicle;
            self.next_vehicle = (v + 1) % self.vehicles;
            let id = self.sent.len() as u64 + 1;
            let payload = format!(
                r#"{{"messageId":{id},"timestamp":"fleet","messageType":100,"data":{{"linear":0.0,"angular":0.0}}}}"#
            );
            let topic = format!("/root/{}/cmd/chassis/set", vehicle_id(v));
            self.sent.push((v, id, Instant::now()));
            for &node in via {
                if let Some(client) = operators.get(node) {
                    let _ = client.try_publish(&topic, QoS::AtLeastOnce, false, payload.clone());
                }
            }
            log.wait(seen, every, |_| false).await;
        }
    }
}

/// The figures of the failover after the kill at `killed_at`.
fn failover_figures(
    events: &[LinkEvent],
    log: &Timeline,
    killed_at: Instant,
    give_up: Duration,
) -> Failover {
    let after: Vec<&LinkEvent> = events.iter().filter(|e| e.at >= killed_at).collect();
    let mut down: Vec<usize> = after.iter().filter(|e| !e.up).map(|e| e.vehicle).collect();
    down.sort_unstable();
    down.dedup();
    let mut back: HashMap<usize, Instant> = HashMap::new();
    for e in after.iter().filter(|e| e.up) {
        back.entry(e.vehicle).or_insert(e.at);
    }
    // A vehicle that lost its link again after it came back (a broker closing the new
    // session, as a cluster does that holds its subscription on the dead node).
    let mut downs: HashMap<usize, usize> = HashMap::new();
    for e in after.iter().filter(|e| !e.up) {
        *downs.entry(e.vehicle).or_default() += 1;
    }
    let relapsed = downs.values().filter(|n| **n > 1).count();
    let seconds = give_up.as_secs() as usize + 1;
    let mut per_second = vec![0usize; seconds];
    for at in back.values() {
        let s = at.duration_since(killed_at).as_secs() as usize;
        if let Some(n) = per_second.get_mut(s) {
            *n += 1;
        }
    }
    while per_second.len() > 1 && per_second.last() == Some(&0) {
        per_second.pop();
    }
    let largest = per_second.iter().copied().max().unwrap_or(0);
    let all_back = (!down.is_empty() && down.iter().all(|v| back.contains_key(v))).then(|| {
        back.values()
            .map(|at| at.duration_since(killed_at).as_secs_f64())
            .fold(0.0, f64::max)
    });
    let longest_gap = down
        .iter()
        .filter_map(|v| log.reports.get(v))
        .flat_map(|arrivals| arrivals.windows(2).map(|w| w[1].duration_since(w[0])))
        .max()
        .map(|d| d.as_secs_f64() * 1000.0);
    Failover {
        vehicles_down: down.len(),
        vehicles_back: down.iter().filter(|v| back.contains_key(v)).count(),
        all_back_s: all_back,
        connects_per_second: per_second,
        max_share_per_second: if back.is_empty() {
            0.0
        } else {
            largest as f64 / back.len() as f64
        },
        longest_report_gap_ms: longest_gap,
        relapsed,
    }
}

/// How long before the kill a command may have been in flight through the killed node.
const IN_FLIGHT: Duration = Duration::from_millis(100);

/// Each vehicle's outages: from its link going down (or, for a vehicle on the node killed at
/// `killed_at`, from just before the kill: a command sent then was in flight through the
/// node) until its first report after its link came back up (the report follows the
/// subscription on the same connection, so the broker has taken that by then).
fn outages(
    events: &[LinkEvent],
    log: &Timeline,
    killed_at: Option<Instant>,
) -> HashMap<usize, Vec<(Instant, Instant)>> {
    let mut spans: HashMap<usize, Vec<(Instant, Instant)>> = HashMap::new();
    let mut open: HashMap<usize, Instant> = HashMap::new();
    let far = Instant::now() + Duration::from_secs(3600);
    for e in events {
        if !e.up {
            let from = match killed_at {
                Some(k) if e.at >= k => k.checked_sub(IN_FLIGHT).unwrap_or(k),
                _ => e.at,
            };
            open.entry(e.vehicle).or_insert(from);
        } else if let Some(from) = open.remove(&e.vehicle) {
            let reported = log
                .reports
                .get(&e.vehicle)
                .and_then(|arrivals| arrivals.iter().find(|a| **a >= e.at).copied())
                .unwrap_or(far);
            spans.entry(e.vehicle).or_default().push((from, reported));
        }
    }
    for (v, from) in open {
        spans.entry(v).or_default().push((from, far));
    }
    spans
}

impl FleetReport {
    fn new(
        options: &FleetOptions,
        nodes: &dyn Nodes,
        all_up_s: Option<f64>,
        log: &Timeline,
        commands: &Commander,
        events: &[LinkEvent],
        failover: Option<(Instant, Failover)>,
    ) -> Self {
        let outages = outages(events, log, failover.as_ref().map(|(at, _)| *at));
        // From the kill until the fleet was back (or the bench gave up on it).
        let failing_over = failover.as_ref().map(|(at, f)| {
            let back = f
                .all_back_s
                .map_or(Duration::from_secs(3600), Duration::from_secs_f64);
            (*at, *at + back)
        });
        let failover = failover.map(|(_, f)| f);
        let in_outage = |v: usize, a: Instant, b: Instant| {
            outages
                .get(&v)
                .is_some_and(|spans| spans.iter().any(|(from, to)| a <= *to && b >= *from))
        };
        let periods: Vec<f64> = log
            .reports
            .iter()
            .flat_map(|(v, arrivals)| {
                arrivals
                    .windows(2)
                    .filter(|w| !in_outage(*v, w[0], w[1]))
                    .map(|w| w[1].duration_since(w[0]).as_secs_f64() * 1000.0)
                    .collect::<Vec<_>>()
            })
            .collect();
        let counting = |node: usize| !nodes.clustered() || node == nodes.count() - 1;
        let mut counts = CommandCounts::default();
        let mut round_trips = Vec::new();
        for &(v, id, at) in &commands.sent {
            counts.sent += 1;
            let answers: Vec<Instant> = log
                .answers
                .get(&(v, id))
                .map(|a| {
                    a.iter()
                        .filter(|(_, node)| counting(*node))
                        .map(|(t, _)| *t)
                        .collect()
                })
                .unwrap_or_default();
            let executions = log.executed.get(&(v, id)).copied().unwrap_or(0);
            let arrived = log.arrived.contains_key(&(v, id));
            counts.executed_twice += usize::from(executions > 1);
            let failing_over = failing_over.is_some_and(|(from, to)| at >= from && at <= to);
            if in_outage(v, at, at) {
                counts.during_outage += 1;
                counts.during_outage_answered += usize::from(!answers.is_empty());
                counts.during_outage_answer_copies += usize::from(answers.len() > 1);
            } else if arrived && executions == 0 {
                counts.dropped += 1;
            } else if executions == 0 || answers.is_empty() {
                if failing_over {
                    counts.lost_in_failover += 1;
                } else if executions == 0 {
                    counts.lost += 1;
                } else {
                    counts.unanswered += 1;
                }
            } else if answers.len() == 1 {
                counts.once += 1;
            } else {
                counts.twice += 1;
            }
            if let Some(first) = answers.first() {
                round_trips.push(first.duration_since(at).as_secs_f64() * 1000.0);
            }
        }
        let report_period_ms = Spread::of(periods);
        let mut missed = Vec::new();
        if all_up_s.is_none() {
            missed.push(format!(
                "not every vehicle reported within {} s",
                ALL_UP_WITHIN.as_secs()
            ));
        }
        if counts.lost > 0 || counts.twice > 0 {
            missed.push(format!(
                "{} commands lost (never executed) and {} answered twice while their vehicles \
                 were connected",
                counts.lost, counts.twice
            ));
        }
        if counts.executed_twice > 0 || counts.dropped > 0 || counts.unanswered > 0 {
            missed.push(format!(
                "{} commands executed twice, {} dropped by their vehicle and {} unanswered",
                counts.executed_twice, counts.dropped, counts.unanswered
            ));
        }
        match &report_period_ms {
            Some(s) if (s.median - REPORT_PERIOD_MS).abs() <= REPORT_PERIOD_MS * 0.2 => {}
            other => missed.push(format!(
                "the report period's median is not within 20 % of {REPORT_PERIOD_MS} ms: {:?}",
                other.as_ref().map(|s| s.median)
            )),
        }
        if let Some(f) = &failover {
            if f.all_back_s.is_none() {
                missed.push(format!(
                    "{} of {} vehicles came back after the kill",
                    f.vehicles_back, f.vehicles_down
                ));
            }
            if f.relapsed > 0 {
                missed.push(format!(
                    "{} vehicles lost their link again after they came back",
                    f.relapsed
                ));
            }
            // Reports flow again within a second of the last vehicle's return.
            if let (Some(gap), Some(back)) = (f.longest_report_gap_ms, f.all_back_s)
                && gap > (back + 1.0) * 1000.0
            {
                missed.push(format!(
                    "a vehicle's reports stopped for {gap:.0} ms, though all were back after \
                     {back:.1} s"
                ));
            }
            if f.vehicles_back >= SPREAD_FROM && f.max_share_per_second > MAX_SHARE_PER_SECOND {
                missed.push(format!(
                    "{:.0} % of the returning vehicles came back in one second (at most {:.0} %)",
                    f.max_share_per_second * 100.0,
                    MAX_SHARE_PER_SECOND * 100.0
                ));
            }
        }
        Self {
            vehicles: options.vehicles,
            nodes: nodes.count(),
            clustered: nodes.clustered(),
            command_qos: options.command_qos,
            node_cpu_percent: Vec::new(),
            all_up_s,
            report_period_ms,
            command_round_trip_ms: Spread::of(round_trips),
            commands: counts,
            failover,
            pass: missed.is_empty(),
            missed,
        }
    }

    /// The figures as a table.
    pub fn table(&self) -> String {
        let spread = |s: &Option<Spread>| {
            s.as_ref().map_or("-".into(), |s| {
                format!(
                    "median {:.1}, p99 {:.1}, max {:.1} (n {})",
                    s.median, s.p99, s.max, s.n
                )
            })
        };
        let mut t = format!(
            "vehicles: {} on {} {} node(s), commands subscribed at QoS {}\n\
             all reporting after: {}\n\
             report period, ms: {}\n\
             command round trip, ms: {}\n\
             commands: {} sent, {} executed and answered once, {} lost, {} executed twice, {} \
             answered twice, {} unanswered, {} dropped by the vehicle, {} lost by the brokers \
             while the fleet failed over; {} sent during their vehicle's outage ({} answered, \
             {} of them twice)\n",
            self.vehicles,
            self.nodes,
            if self.clustered {
                "clustered"
            } else {
                "independent"
            },
            self.command_qos,
            self.all_up_s.map_or("-".into(), |s| format!("{s:.1} s")),
            spread(&self.report_period_ms),
            spread(&self.command_round_trip_ms),
            self.commands.sent,
            self.commands.once,
            self.commands.lost,
            self.commands.executed_twice,
            self.commands.twice,
            self.commands.unanswered,
            self.commands.dropped,
            self.commands.lost_in_failover,
            self.commands.during_outage,
            self.commands.during_outage_answered,
            self.commands.during_outage_answer_copies,
        );
        let cpu: Vec<String> = self
            .node_cpu_percent
            .iter()
            .map(|c| c.map_or("-".into(), |c| format!("{c:.1} %")))
            .collect();
        t += &format!("each node's CPU while steady: {}\n", cpu.join(", "));
        if let Some(f) = &self.failover {
            t += &format!(
                "node 0 killed: {} vehicles lost it, {} back ({} lost it again), all back after \
                 {}; connects per second after the kill {:?} (largest share {:.0} %); longest \
                 report gap {}\n",
                f.vehicles_down,
                f.vehicles_back,
                f.relapsed,
                f.all_back_s.map_or("-".into(), |s| format!("{s:.2} s")),
                f.connects_per_second,
                f.max_share_per_second * 100.0,
                f.longest_report_gap_ms
                    .map_or("-".into(), |g| format!("{g:.0} ms")),
            );
        }
        t
    }

    /// The figures as one JSON line.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}
