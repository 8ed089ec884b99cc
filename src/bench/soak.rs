//! `chassisd bench soak`: the simulated vehicle with its dialects on a broker, driven by a
//! client for minutes while faults come round in cycles: a command flood, a connection
//! flood (more clients than the embedded broker holds, held, then one more), a broker
//! killed (mosquitto started again by the soak, the embedded broker by chassisd itself), a
//! GNSS outage, an IMU stall, lost drive heartbeats and the CAN interface down, and three
//! hostile clients (`bench::attacks`): one presenting chassisd's client id, one sending QoS 2
//! messages it never releases, one retaining 1 MB messages on new topics; and, when the
//! soak runs a rosmaster for the ROS1 node, a TCPROS peer that lies about a header's length
//! and holds connections without end (`bench::ros1_attack`).
//!
//! A client subscribes to base_status and drives the vehicle as an operator would: a
//! heartbeat and a root DRIVE every 200 ms, and a zero DRIVE (the deliberate re-arm)
//! whenever the status says a latched stop awaits one. Each fault is injected, held, and
//! cleared; what base_status shows says when chassisd saw it and when it recovered by
//! itself. For faults that must stop the vehicle (lost heartbeats, the bus down, the
//! broker gone so no command arrives) the simulated drives time the command to stop,
//! which is what the bound is about, and the simulator's truth times the wheels coming to
//! rest, which adds the drives' own lag. chassisd's own resident memory is read every
//! 250 ms and each cycle's floor kept (its helper processes, killed every cycle, give
//! their peaks instead): a leak raises the floor, while
//! the faults' own swings do not, so the floors' slope after the first (warm-up) cycle is
//! not the noise of the faults themselves.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::bench::error::{BenchError, invalid, missing};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use serde::Serialize;
use serde_json::Value;
use tokio::sync::watch;

use super::Broker;
use super::attacks::{self, AttackFigures};
use super::mqtt::Spread;
use crate::config::mqtt::MqttConfig;
use crate::runtime::host::{children_running, resident_memory_bytes};
use crate::runtime::links::broker::CHILD_COMMAND;
use crate::runtime::modes::sim::{self, SimFaults, SimHandle, SimOptions, SimProbe};
use crate::sim::lockstep;
use crate::sim::plant::PlantConfig;
use crate::vehicle::chassis::{CONTROL_PERIOD, status_bits};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// No base_status gap may be longer, outside a broker restart.
pub const GAP_LIMIT: Duration = Duration::from_millis(300);
/// base_status must reach the client in this share of its periods, outside broker restarts.
pub const AVAILABILITY_TARGET: f64 = 0.99;
/// Resident memory may grow at most this fast after the warm-up cycle, MB per hour.
pub const RSS_SLOPE_LIMIT_MB_PER_H: f64 = 1.0;
/// A fault not seen, or not recovered from, within this long is a miss.
const RECOVERY_LIMIT: Duration = Duration::from_secs(20);
/// Quiet time after each fault: recovery, the re-arm and the vehicle back at speed.
const CALM: Duration = Duration::from_secs(6);
/// The driving client's period.
const DRIVE_EVERY: Duration = Duration::from_millis(200);
/// The client drives a circle: forward speed (m/s) and yaw rate (rad/s).
const DRIVE: (f64, f64) = (0.4, 0.2);
/// Below this the vehicle counts as stopped, m/s.
const STOPPED_MPS: f64 = 0.01;
/// A stop is timed only when the vehicle ran at least this fast as the fault began, m/s.
const MOVING_MPS: f64 = 0.2;
/// base_status observations kept per second of the run (10 Hz, with room).
const OBSERVATIONS_PER_S: u64 = 12;

/// A fault the soak injects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// Two clients publish commands as fast as they can (`mqtt_control` and root).
    CommandFlood,
    /// More raw clients connect than the embedded broker holds, and stay; one more tries
    /// at capacity.
    ConnectionFlood,
    /// The broker killed: mosquitto started again after the hold, the embedded broker
    /// restarted by chassisd on its own.
    BrokerRestart,
    /// The receiver sends nothing.
    GnssOutage,
    /// The IMU sends nothing.
    ImuStall,
    /// The wheel drives send no heartbeats.
    DriveHeartbeatLoss,
    /// The CAN interface goes down.
    CanDown,
    /// A client presents chassisd's configured client id every 50 ms.
    ClientIdTakeover,
    /// Clients send QoS 2 messages and never release them.
    UnreleasedQos2,
    /// A client retains 1 MB messages on new topics (64 at most).
    RetainedFlood,
    /// Connections to the WebSocket server's HTTP port send half a request's head, then
    /// nothing (1,000 at most).
    Slowloris,
    /// A TCPROS peer announces a 1 GiB header to the ROS1 node and sends 64 MB of it, then
    /// holds hundreds of connections, round after round.
    TcprosLengthLie,
}

impl FaultKind {
    /// How long the fault holds.
    fn hold(self) -> Duration {
        Duration::from_secs(match self {
            Self::CommandFlood
            | Self::ConnectionFlood
            | Self::ImuStall
            | Self::ClientIdTakeover
            | Self::UnreleasedQos2
            | Self::RetainedFlood
            | Self::Slowloris
            | Self::TcprosLengthLie => 5,
            Self::GnssOutage => 8,
            Self::BrokerRestart | Self::DriveHeartbeatLoss | Self::CanDown => 3,
        })
    }

    /// The fault must bring the wheels to a stop. A killed broker demands one only when it
    /// stays down past the command timeout: mosquitto's does (the soak restarts it after the
    /// hold); chassisd restarts its embedded one within a fraction of that, and commands
    /// that arrive in time rightly keep the vehicle going.
    fn demands_stop(self, broker: Broker) -> bool {
        match self {
            Self::BrokerRestart => broker == Broker::Mosquitto,
            Self::DriveHeartbeatLoss | Self::CanDown => true,
            _ => false,
        }
    }

    /// Whether base_status can show the fault: a flood is refused silently, and while the
    /// broker is gone nothing arrives.
    fn observable(self) -> bool {
        !self.is_outside_the_vehicle()
    }

    /// The fault is a client's (or the broker's own), not the vehicle's.
    fn is_outside_the_vehicle(self) -> bool {
        matches!(
            self,
            Self::CommandFlood
                | Self::ConnectionFlood
                | Self::BrokerRestart
                | Self::ClientIdTakeover
                | Self::UnreleasedQos2
                | Self::RetainedFlood
                | Self::Slowloris
                | Self::TcprosLengthLie
        )
    }

    /// Whether `o` shows the fault; `None` when base_status cannot show it.
    fn shown(self, o: &Observation) -> Option<bool> {
        match self {
            _ if self.is_outside_the_vehicle() => None,
            Self::GnssOutage => Some(!o.gnss),
            Self::ImuStall => Some(!o.imu),
            Self::DriveHeartbeatLoss => Some(o.bits & status_bits::HEARTBEAT_LOST != 0),
            Self::CanDown => Some(o.bits & status_bits::BUS_DOWN != 0),
            _ => None,
        }
    }

    /// Whether `o` shows the vehicle recovered from the fault (the drives enabled again
    /// after a drive-side fault).
    fn recovered(self, o: &Observation) -> bool {
        let enabled = o.bits & status_bits::ENABLED != 0;
        match self {
            Self::GnssOutage => o.gnss,
            Self::ImuStall => o.imu,
            Self::DriveHeartbeatLoss => o.bits & status_bits::HEARTBEAT_LOST == 0 && enabled,
            Self::CanDown => o.bits & status_bits::BUS_DOWN == 0 && enabled,
            _ => true,
        }
    }

    fn sim_faults(self) -> SimFaults {
        SimFaults {
            gnss_outage: self == Self::GnssOutage,
            imu_stall: self == Self::ImuStall,
            drive_heartbeats_lost: self == Self::DriveHeartbeatLoss,
            bus_down: self == Self::CanDown,
        }
    }
}

/// What to run.
#[derive(Debug, Clone)]
pub struct SoakOptions {
    /// The vehicle.
    pub plant: PlantConfig,
    /// The dialects (host and port are set per run); root must be on.
    pub mqtt: MqttConfig,
    /// Length of each run.
    pub run_for: Duration,
    /// The runs, one per broker.
    pub brokers: Vec<Broker>,
    /// Run the ROS1 node on a rosmaster the soak starts, and attack it over TCPROS.
    pub ros1: bool,
}

/// One fault as it was injected and cleared.
#[derive(Debug, Clone, Copy)]
struct Injected {
    kind: FaultKind,
    began: Instant,
    cleared: Instant,
    /// The vehicle's true speed as it began, m/s.
    speed: f64,
    stop: Stop,
    /// A hostile client's figures.
    attack: Option<AttackFigures>,
    /// When the ROS1 node answered a call again, after the TCPROS attack.
    back: Option<Instant>,
}

/// One base_status as the client saw it.
#[derive(Debug, Clone, Copy)]
struct Observation {
    at: Instant,
    bits: u32,
    gnss: bool,
    imu: bool,
}

/// One injected fault.
#[derive(Debug, Clone, Serialize)]
pub struct FaultFigures {
    /// What.
    pub kind: FaultKind,
    /// When it began, s from the run's start.
    pub at_s: f64,
    /// From injection to the first base_status showing it, s (None if base_status
    /// cannot show it, or never did).
    pub detected_s: Option<f64>,
    /// From clearing it to the first base_status showing the vehicle recovered, s.
    pub recovered_s: Option<f64>,
    /// The vehicle's true speed as it began, m/s.
    pub speed_mps: f64,
    /// From injection to both wheel drives commanded to stop (zero targets, quick stop or
    /// disabled), s; timed for faults that demand a stop while the vehicle ran.
    pub stop_command_s: Option<f64>,
    /// From injection to the true speed below 0.01 m/s, s (the drives' lag included).
    pub at_rest_s: Option<f64>,
    /// The bound for the command to stop, with the ramp down to rest in it: cmd_timeout +
    /// one control period + speed / deceleration.
    pub stop_bound_s: Option<f64>,
    /// A hostile client's attempts and how many the broker refused or cut.
    pub attack: Option<super::attacks::AttackFigures>,
    /// Seen (where base_status can show it), recovered, and stopped within the bound.
    pub pass: bool,
}

/// One broker's run.
#[derive(Debug, Clone, Serialize)]
pub struct RunFigures {
    /// `embedded` or `mosquitto`.
    pub broker: String,
    /// Length, s.
    pub seconds: f64,
    /// Fault cycles completed.
    pub cycles: u32,
    /// Resident memory at the start and at the end, MB.
    pub rss_start_mb: f64,
    pub rss_end_mb: f64,
    /// The lowest resident memory of each cycle, MB (sampled every 250 ms).
    pub rss_floor_per_cycle_mb: Vec<f64>,
    /// Least-squares slope of those after the first cycle, MB per hour.
    pub rss_slope_mb_per_h: Option<f64>,
    /// The base_status period the client saw, ms.
    pub status_period_ms: Option<Spread>,
    /// The largest gap between base_status messages outside broker restarts, ms.
    pub largest_gap_ms: f64,
    /// base_status messages seen outside broker restarts per status period there (10 Hz).
    pub status_availability: f64,
    /// The embedded broker's process's largest resident memory, MB (sampled every 250 ms).
    pub broker_peak_mb: Option<f64>,
    /// The ROS1 node's process's largest resident memory, MB (sampled every 250 ms).
    pub ros1_node_peak_mb: Option<f64>,
    /// Every fault.
    pub faults: Vec<FaultFigures>,
    /// Every target met.
    pub pass: bool,
}

/// The soak's figures.
#[derive(Debug, Clone, Serialize)]
pub struct SoakReport {
    /// One run per broker.
    pub runs: Vec<RunFigures>,
    /// Every run passed.
    pub pass: bool,
}

/// Observations, written into memory taken at the start so that keeping them does not
/// grow the resident memory the soak measures.
struct Log {
    observations: Vec<Observation>,
    len: usize,
    acks_ok: Vec<Instant>,
    acks_len: usize,
}

impl Log {
    fn new(run_for: Duration, start: Instant) -> Self {
        let n = (run_for.as_secs() + 30) * OBSERVATIONS_PER_S;
        let blank = Observation {
            at: start,
            bits: 0,
            gnss: false,
            imu: false,
        };
        let acks = (run_for.as_secs() + 30) * (1000 / DRIVE_EVERY.as_millis() as u64 + 1);
        Self {
            observations: vec![blank; n as usize],
            len: 0,
            acks_ok: vec![start; acks as usize],
            acks_len: 0,
        }
    }

    fn observe(&mut self, o: Observation) {
        if let Some(slot) = self.observations.get_mut(self.len) {
            *slot = o;
            self.len += 1;
        }
    }

    fn ack(&mut self, at: Instant) {
        if let Some(slot) = self.acks_ok.get_mut(self.acks_len) {
            *slot = at;
            self.acks_len += 1;
        }
    }

    fn observations(&self) -> &[Observation] {
        &self.observations[..self.len]
    }

    fn last(&self) -> Option<Observation> {
        self.len.checked_sub(1).map(|i| self.observations[i])
    }
}

/// Runs every run in turn.
pub async fn run(options: SoakOptions) -> crate::bench::error::Result<SoakReport> {
    let mut runs = Vec::new();
    for &broker in &options.brokers {
        eprintln!(
            "chassisd bench soak: {} broker for {:.0} s",
            broker.name(),
            options.run_for.as_secs_f64()
        );
        runs.push(run_one(&options, broker).await?);
    }
    let pass = !runs.is_empty() && runs.iter().all(|r| r.pass);
    Ok(SoakReport { runs, pass })
}

async fn run_one(options: &SoakOptions, broker: Broker) -> crate::bench::error::Result<RunFigures> {
    let vehicle_id = super::mqtt::root_vehicle_id(&options.mqtt)?;
    let mut mqtt = options.mqtt.clone();
    let mut mosquitto = broker.start(&mut mqtt)?;
    let rosmaster = options
        .ros1
        .then(super::rosmaster::Rosmaster::start)
        .transpose()?;
    let chassis = lockstep::vehicle_config(&options.plant)?
        .chassis
        .ok_or_else(missing("the simulated vehicle has a chassis"))?;
    let stop_bound = |speed: f64| {
        chassis.cmd_timeout_s + CONTROL_PERIOD.as_secs_f64() + speed / chassis.max_decel_mps2
    };

    // The WebSocket server, for the slowloris, on a free loopback port.
    let websocket_port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map_err(invalid("a free loopback port"))?
        .port();
    let start = Instant::now();
    let log = Arc::new(Mutex::new(Log::new(options.run_for, start)));
    let (handle, faults_tx, probe) = SimHandle::new();
    let sim = tokio::spawn(sim::run(
        SimOptions {
            plant: options.plant.clone(),
            seed: 1,
            record: None,
            commands_stdin: false,
            scenario: None,
            duration: Some(options.run_for + Duration::from_secs(3)),
            mqtt: Some(mqtt.clone()),
            ros1: rosmaster.as_ref().map(|m| crate::config::ros1::Ros1Config {
                master_uri: m.uri(),
                ..Default::default()
            }),
            ros2: None,
            websocket: Some(crate::config::websocket::WebsocketConfig {
                bind: format!("127.0.0.1:{websocket_port}"),
                ..Default::default()
            }),
            handle: Some(handle),
            ntrip: None,
            zones: None,
        },
        std::io::sink(),
    ));
    let topics = Topics::new(&vehicle_id);
    let client = tokio::spawn(drive(
        mqtt.first().host.clone(),
        mqtt.first().port,
        topics.clone(),
        log.clone(),
        start + options.run_for,
    ));

    // Warm up: the drives enabled and the vehicle at speed.
    tokio::time::sleep(CALM).await;
    let mut schedule: Vec<FaultKind> = vec![
        FaultKind::CommandFlood,
        FaultKind::ConnectionFlood,
        FaultKind::BrokerRestart,
        FaultKind::GnssOutage,
        FaultKind::ImuStall,
        FaultKind::DriveHeartbeatLoss,
        FaultKind::CanDown,
        FaultKind::ClientIdTakeover,
        FaultKind::UnreleasedQos2,
        FaultKind::RetainedFlood,
        FaultKind::Slowloris,
    ];
    if rosmaster.is_some() {
        schedule.push(FaultKind::TcprosLengthLie);
    }
    let master_uri = rosmaster.as_ref().map(|m| m.uri()).unwrap_or_default();
    let own_id = mqtt
        .first()
        .base_client_id(&lockstep::vehicle_config(&options.plant)?.vehicle.name);
    let cycle_length: Duration = schedule.iter().map(|k| k.hold() + CALM).sum();
    let rss_start = resident_memory_bytes().unwrap_or(0);
    let floors = Arc::new(Floors::new(
        (options.run_for.as_secs_f64() / cycle_length.as_secs_f64()) as usize + 1,
    ));
    let sampler = tokio::spawn(sample_floors(floors.clone()));
    let mut injected: Vec<Injected> = Vec::new();
    let mut broker_down: Vec<(Instant, Instant)> = Vec::new();
    let mut cycles = 0;
    while start.elapsed() + cycle_length <= options.run_for {
        if sim.is_finished() {
            return Err(BenchError::Failed(
                "the simulation ended early (a signal?)".into(),
            ));
        }
        floors.start_cycle(cycles as usize);
        for &kind in &schedule {
            let speed = probe.borrow().truth.v;
            let began = Instant::now();
            let flood = match kind {
                FaultKind::CommandFlood => {
                    let run = flood(
                        mqtt.first().host.clone(),
                        mqtt.first().port,
                        topics.clone(),
                        kind.hold(),
                    );
                    Some(tokio::spawn(async move { run.await.map(|()| None) }))
                }
                FaultKind::ConnectionFlood => {
                    let run =
                        connection_flood(mqtt.first().host.clone(), mqtt.first().port, kind.hold());
                    Some(tokio::spawn(async move { run.await.map(|()| None) }))
                }
                FaultKind::ClientIdTakeover
                | FaultKind::UnreleasedQos2
                | FaultKind::RetainedFlood => Some(tokio::spawn(attack(
                    kind,
                    mqtt.first().host.clone(),
                    mqtt.first().port,
                    own_id.clone(),
                ))),
                FaultKind::Slowloris => {
                    let hold = kind.hold();
                    Some(tokio::spawn(async move {
                        Ok(Some(
                            attacks::slowloris("127.0.0.1", websocket_port, hold).await,
                        ))
                    }))
                }
                FaultKind::TcprosLengthLie => {
                    Some(tokio::spawn(tcpros_attack(master_uri.clone(), kind.hold())))
                }
                FaultKind::BrokerRestart => {
                    match mosquitto.as_mut() {
                        Some(m) => m.stop(),
                        // chassisd notices and starts it again by itself.
                        None => kill_embedded_broker(),
                    }
                    None
                }
                _ => {
                    faults_tx.send_replace(kind.sim_faults());
                    None
                }
            };
            let timed = kind.demands_stop(broker) && speed.abs() >= MOVING_MPS;
            let stop = if timed {
                time_stop(&probe, began, kind.hold()).await
            } else {
                Stop::default()
            };
            tokio::time::sleep_until((began + kind.hold()).into()).await;
            faults_tx.send_replace(SimFaults::default());
            if let Some(m) = mosquitto
                .as_mut()
                .filter(|_| kind == FaultKind::BrokerRestart)
            {
                tokio::task::block_in_place(|| m.restart())?;
            }
            let attacked = match flood {
                Some(f) => f.await.map_err(invalid("flood task"))??,
                None => None,
            };
            let cleared = Instant::now();
            if kind == FaultKind::BrokerRestart {
                broker_down.push((began, cleared));
            }
            let back = match kind {
                FaultKind::TcprosLengthLie => node_serves_again(&master_uri).await?,
                _ => None,
            };
            injected.push(Injected {
                kind,
                began,
                cleared,
                speed,
                stop,
                attack: attacked,
                back,
            });
            tokio::time::sleep(CALM).await;
        }
        cycles += 1;
    }
    let rss_end = resident_memory_bytes().unwrap_or(0);
    sampler.abort();
    let rss_floors = floors.take(cycles as usize);
    client.await.map_err(invalid("client task"))??;
    sim.await.map_err(invalid("simulation task"))??;
    drop(mosquitto);

    let log = log
        .lock()
        .map_err(|_| BenchError::Failed("the client panicked".into()))?;
    let observations = log.observations();
    let acks = &log.acks_ok[..log.acks_len];
    let first_status_after = |t: Instant| observations.iter().find(|o| o.at >= t).map(|o| o.at);
    // A broker restart's window lasts until the first status after it.
    let windows: Vec<(Instant, Instant)> = broker_down
        .iter()
        .map(|&(a, b)| (a, first_status_after(b).unwrap_or(b)))
        .collect();
    let periods: Vec<f64> = observations
        .windows(2)
        .map(|w| w[1].at.duration_since(w[0].at).as_secs_f64() * 1000.0)
        .collect();
    let outside_restarts =
        |w: &&[Observation]| !windows.iter().any(|&(a, b)| w[1].at >= a && w[0].at <= b);
    let largest_gap_ms = observations
        .windows(2)
        .filter(outside_restarts)
        .map(|w| w[1].at.duration_since(w[0].at).as_secs_f64() * 1000.0)
        .fold(0.0, f64::max);
    // Messages outside restarts, per 100 ms period there.
    let (seen, spanned) =
        observations
            .windows(2)
            .filter(outside_restarts)
            .fold((0.0, 0.0), |(n, span), w| {
                (
                    n + 1.0,
                    span + w[1].at.duration_since(w[0].at).as_secs_f64(),
                )
            });
    let status_availability = if spanned > 0.0 {
        (seen / (spanned * 10.0)).min(1.0)
    } else {
        0.0
    };
    let broker_peak = floors
        .broker_peak
        .load(std::sync::atomic::Ordering::Relaxed);
    let node_peak = floors.node_peak.load(std::sync::atomic::Ordering::Relaxed);
    let faults: Vec<FaultFigures> = injected
        .iter()
        .map(|i| {
            let Injected {
                kind,
                began,
                cleared,
                speed,
                stop,
                attack,
                back,
            } = *i;
            let detected_s = observations
                .iter()
                .find(|o| o.at >= began && kind.shown(o) == Some(true))
                .map(|o| o.at.duration_since(began).as_secs_f64());
            let recovered_at = match kind {
                // Telemetry is back.
                FaultKind::BrokerRestart => first_status_after(cleared),
                // The node answers a call again.
                FaultKind::TcprosLengthLie => back,
                // Commands are taken again: the driver's next DRIVE is acknowledged.
                _ if kind.is_outside_the_vehicle() => acks.iter().find(|&&a| a >= cleared).copied(),
                _ => observations
                    .iter()
                    .find(|o| o.at >= cleared && kind.recovered(o))
                    .map(|o| o.at),
            };
            let recovered_s = recovered_at.map(|a| a.duration_since(cleared).as_secs_f64());
            let timed = kind.demands_stop(broker) && speed.abs() >= MOVING_MPS;
            let stop_bound_s = timed.then(|| stop_bound(speed.abs()));
            let limit = RECOVERY_LIMIT.as_secs_f64();
            let seen = !kind.observable() || detected_s.is_some_and(|d| d <= limit);
            let pass = seen
                && recovered_s.is_some_and(|r| r <= limit)
                && (!timed
                    || stop
                        .command_s
                        .zip(stop_bound_s)
                        .is_some_and(|(s, b)| s <= b));
            FaultFigures {
                kind,
                at_s: began.duration_since(start).as_secs_f64(),
                detected_s,
                recovered_s,
                speed_mps: speed,
                stop_command_s: stop.command_s,
                at_rest_s: stop.at_rest_s,
                stop_bound_s,
                attack,
                pass,
            }
        })
        .collect();
    let slope = slope_per_hour(&rss_floors[rss_floors.len().min(1)..], cycle_length);
    let pass = cycles >= 2
        && slope.is_some_and(|s| s < RSS_SLOPE_LIMIT_MB_PER_H)
        && largest_gap_ms <= GAP_LIMIT.as_secs_f64() * 1000.0
        && status_availability >= AVAILABILITY_TARGET
        && faults.iter().all(|f| f.pass);
    Ok(RunFigures {
        broker: broker.name().into(),
        seconds: start.elapsed().as_secs_f64(),
        cycles,
        rss_start_mb: rss_start as f64 / 1e6,
        rss_end_mb: rss_end as f64 / 1e6,
        rss_floor_per_cycle_mb: rss_floors,
        rss_slope_mb_per_h: slope,
        status_period_ms: Spread::of(periods),
        largest_gap_ms,
        status_availability,
        // Only this run's own broker: a mosquitto run has none of chassisd's.
        broker_peak_mb: (broker == Broker::Embedded && broker_peak > 0)
            .then(|| broker_peak as f64 / 1e6),
        ros1_node_peak_mb: (node_peak > 0).then(|| node_peak as f64 / 1e6),
        faults,
        pass,
    })
}

/// The least-squares slope of `samples` taken `every` apart, per hour; `None` with fewer
/// than two.
fn slope_per_hour(samples: &[f64], every: Duration) -> Option<f64> {
    if samples.len() < 2 {
        return None;
    }
    let n = samples.len() as f64;
    let xs = (0..samples.len()).map(|i| i as f64 * every.as_secs_f64() / 3600.0);
    let mean_x = xs.clone().sum::<f64>() / n;
    let mean_y = samples.iter().sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (x, y) in xs.zip(samples) {
        sxy += (x - mean_x) * (y - mean_y);
        sxx += (x - mean_x) * (x - mean_x);
    }
    (sxx > 0.0).then(|| sxy / sxx)
}

/// How often resident memory is read for the cycles' floors.
const RSS_SAMPLE_EVERY: Duration = Duration::from_millis(250);

/// The lowest resident memory seen in each cycle. A leak raises the floor; the swings of a
/// burst (a flood's buffers, the broker's queues, garbage the 10 s trim has not handed back
/// yet) do not, and a single sample per cycle caught them at random: ±0.4 MB at the same
/// calm moment of each cycle, where 1 MB/h is 0.017 MB a cycle.
struct Floors {
    cycle: std::sync::atomic::AtomicUsize,
    mb: Mutex<Vec<f64>>,
    /// The embedded broker's largest resident memory seen, bytes.
    broker_peak: std::sync::atomic::AtomicU64,
    /// The ROS1 node's process's largest resident memory seen, bytes.
    node_peak: std::sync::atomic::AtomicU64,
}

impl Floors {
    /// Room for `cycles` cycles, taken now so that keeping them grows nothing.
    fn new(cycles: usize) -> Self {
        Self {
            cycle: std::sync::atomic::AtomicUsize::new(usize::MAX),
            mb: Mutex::new(vec![f64::INFINITY; cycles]),
            broker_peak: std::sync::atomic::AtomicU64::new(0),
            node_peak: std::sync::atomic::AtomicU64::new(0),
        }
    }

    fn start_cycle(&self, cycle: usize) {
        self.cycle
            .store(cycle, std::sync::atomic::Ordering::Relaxed);
    }

    fn sample(&self, mb: f64) {
        let cycle = self.cycle.load(std::sync::atomic::Ordering::Relaxed);
        if let Ok(mut floors) = self.mb.lock()
            && let Some(floor) = floors.get_mut(cycle)
        {
            *floor = floor.min(mb);
        }
    }

    /// The floors of the first `cycles` cycles.
    fn take(&self, cycles: usize) -> Vec<f64> {
        self.mb
            .lock()
            .map(|f| f.iter().take(cycles).copied().collect())
            .unwrap_or_default()
    }
}

/// Samples chassisd's own floors, and the peaks of its helper processes. The helpers are
/// killed in every cycle (the broker by the soak, the ROS1 node by the TCPROS attack) and
/// start small again, so they cannot carry a leak from one cycle to the next, and counted
/// in the floors they would show their restarts instead.
async fn sample_floors(floors: Arc<Floors>) {
    let mut every = tokio::time::interval(RSS_SAMPLE_EVERY);
    loop {
        every.tick().await;
        floors.sample(resident_memory_bytes().unwrap_or(0) as f64 / 1e6);
        floors.broker_peak.fetch_max(
            embedded_broker_memory(),
            std::sync::atomic::Ordering::Relaxed,
        );
        floors
            .node_peak
            .fetch_max(ros1_node_memory(), std::sync::atomic::Ordering::Relaxed);
    }
}

/// When a stop came, s from the fault's start.
#[derive(Debug, Clone, Copy, Default)]
struct Stop {
    /// Both wheel drives commanded to stop.
    command_s: Option<f64>,
    /// The true speed below [`STOPPED_MPS`].
    at_rest_s: Option<f64>,
}

/// From `began`, how long until the drives are commanded to stop and until the wheels
/// rest, each `None` if it does not happen within `within`.
async fn time_stop(probe: &watch::Receiver<SimProbe>, began: Instant, within: Duration) -> Stop {
    let mut stop = Stop::default();
    let mut poll = tokio::time::interval(Duration::from_millis(5));
    while began.elapsed() < within && (stop.command_s.is_none() || stop.at_rest_s.is_none()) {
        poll.tick().await;
        let now = *probe.borrow();
        let since = Some(began.elapsed().as_secs_f64());
        if now.wheels_commanded_to_stop {
            stop.command_s = stop.command_s.or(since);
        }
        if now.truth.v.abs() < STOPPED_MPS {
            stop.at_rest_s = stop.at_rest_s.or(since);
        }
    }
    stop
}

/// The root dialect's topics the client uses.
#[derive(Debug, Clone)]
struct Topics {
    chassis_set: String,
    chassis_ack: String,
    heartbeat: String,
}

impl Topics {
    fn new(vehicle_id: &str) -> Self {
        Self {
            chassis_set: format!("/root/{vehicle_id}/cmd/chassis/set"),
            chassis_ack: format!("/root/{vehicle_id}/cmd/chassis/ack"),
            heartbeat: format!("/root/{vehicle_id}/heartbeat/set"),
        }
    }
}

/// The operator's client: watches base_status and drives until `until`.
async fn drive(
    host: String,
    port: u16,
    topics: Topics,
    log: Arc<Mutex<Log>>,
    until: Instant,
) -> crate::bench::error::Result<()> {
    let mut o = MqttOptions::new(format!("chassisd-soak-{}", std::process::id()), host, port);
    o.set_keep_alive(Duration::from_secs(5));
    let (client, mut events) = AsyncClient::new(o, 64);
    events.set_network_options(crate::runtime::links::mqtt::low_latency());
    let mut next_drive = Instant::now();
    let mut id = 0u64;
    while Instant::now() < until {
        if Instant::now() >= next_drive {
            next_drive += DRIVE_EVERY;
            id += 1;
            let latched = log
                .lock()
                .ok()
                .and_then(|l| l.last())
                .is_some_and(|o| o.bits & status_bits::AWAITING_COMMAND != 0);
            let (v, w) = if latched { (0.0, 0.0) } else { DRIVE };
            let drive = format!(
                r#"{{"messageId":{id},"timestamp":"soak","messageType":100,"data":{{"linear":{v},"angular":{w}}}}}"#
            );
            // A full request queue (the broker gone) loses these; the next ones follow.
            let _ = client.try_publish(
                &topics.heartbeat,
                QoS::AtMostOnce,
                false,
                r#"{"timestamp":"soak"}"#,
            );
            let _ = client.try_publish(&topics.chassis_set, QoS::AtMostOnce, false, drive);
        }
        match tokio::time::timeout(Duration::from_millis(20), events.poll()).await {
            Ok(Ok(Event::Incoming(Packet::ConnAck(_)))) => {
                // Subscriptions again on every (re)connection: the session is clean.
                let _ = client.try_subscribe("base_status", QoS::AtMostOnce);
                let _ = client.try_subscribe(&topics.chassis_ack, QoS::AtMostOnce);
            }
            Ok(Ok(Event::Incoming(Packet::Publish(p)))) => {
                let at = Instant::now();
                let v: Value = serde_json::from_slice(&p.payload).unwrap_or_default();
                let Ok(mut log) = log.lock() else {
                    break;
                };
                if p.topic == "base_status" {
                    log.observe(Observation {
                        at,
                        bits: v["robot"]["robot_status"].as_u64().unwrap_or(0) as u32,
                        gnss: v["sensor"]["gnss"] == true,
                        imu: v["sensor"]["imu"] == true,
                    });
                } else if v["data"]["code"] == 0 {
                    log.ack(at);
                }
            }
            Ok(Ok(_)) | Err(_) => {}
            // The broker is gone: try again shortly.
            Ok(Err(_)) => tokio::time::sleep(Duration::from_millis(50)).await,
        }
    }
    Ok(())
}

/// One of `bench::attacks`' hostile clients for `kind`, on the broker at `host:port`
/// whose chassisd has the configured client id `own_id`.
async fn attack(
    kind: FaultKind,
    host: String,
    port: u16,
    own_id: String,
) -> crate::bench::error::Result<Option<AttackFigures>> {
    let hold = kind.hold();
    Ok(Some(match kind {
        FaultKind::ClientIdTakeover => attacks::take_over(&host, port, &own_id, hold).await,
        FaultKind::UnreleasedQos2 => attacks::unreleased_qos2(&host, port, hold).await,
        _ => attacks::retained_flood(&host, port, hold).await,
    }))
}

/// The embedded broker's process's resident memory, bytes (0 when there is none).
fn embedded_broker_memory() -> u64 {
    children_running(CHILD_COMMAND)
        .iter()
        .map(|&(_, rss)| rss)
        .sum()
}

/// The ROS1 node's process's resident memory, bytes (0 when there is none).
fn ros1_node_memory() -> u64 {
    #[cfg(feature = "ros1")]
    let running = children_running(crate::runtime::links::ros1::CHILD_COMMAND);
    #[cfg(not(feature = "ros1"))]
    let running: Vec<(u32, u64)> = Vec::new();
    running.iter().map(|&(_, rss)| rss).sum()
}

/// The TCPROS attack (`bench::ros1_attack`) on the node of the master at `master_uri`.
async fn tcpros_attack(
    master_uri: String,
    hold: Duration,
) -> crate::bench::error::Result<Option<AttackFigures>> {
    #[cfg(feature = "ros1")]
    return Ok(Some(
        super::ros1_attack::lie_and_hold(&master_uri, hold).await,
    ));
    #[cfg(not(feature = "ros1"))]
    Err(BenchError::Failed(format!(
        "this build has no ROS1 node to attack ({master_uri}, {hold:?})"
    )))
}

/// When the node answers a call again after the TCPROS attack (`None`: not within
/// [`RECOVERY_LIMIT`]).
async fn node_serves_again(master_uri: &str) -> crate::bench::error::Result<Option<Instant>> {
    #[cfg(feature = "ros1")]
    return Ok(super::ros1_attack::serves_again(master_uri, RECOVERY_LIMIT).await);
    #[cfg(not(feature = "ros1"))]
    Err(BenchError::Failed(format!(
        "this build has no ROS1 node ({master_uri})"
    )))
}

/// Kills the embedded broker's process (SIGKILL), as a crash would end it.
fn kill_embedded_broker() {
    for (pid, _) in children_running(CHILD_COMMAND) {
        // SAFETY: a plain signal to a child process of ours, found a moment ago.
        unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) };
    }
}

/// Raw clients beyond the embedded broker's limit, connected and held for `hold`; then one
/// more at capacity. Each connects with an identifier of its own and keeps quiet.
async fn connection_flood(
    host: String,
    port: u16,
    hold: Duration,
) -> crate::bench::error::Result<()> {
    let until = Instant::now() + hold;
    let mut held = Vec::new();
    for i in 0..FLOOD_CONNECTIONS + 1 {
        let id = format!("soak-hold-{}-{i}", std::process::id());
        let connect = tokio::time::timeout(Duration::from_secs(2), async {
            let mut s = tokio::net::TcpStream::connect((host.as_str(), port)).await?;
            s.write_all(&crate::broker::wire::plain_connect(&id, 60))
                .await?;
            let mut ack = [0u8; 4];
            s.read_exact(&mut ack).await?;
            Ok::<_, std::io::Error>(s)
        })
        .await;
        if let Ok(Ok(s)) = connect {
            held.push(s);
        }
    }
    tokio::time::sleep_until(until.into()).await;
    drop(held);
    Ok(())
}

/// Connections the connection flood holds: beyond the embedded broker's 64.
const FLOOD_CONNECTIONS: usize = 80;

/// Two misbehaving clients' worth of commands, as fast as the connection takes them, for
/// `hold`: cancel_task on `mqtt_control` and an unknown root message type.
async fn flood(
    host: String,
    port: u16,
    topics: Topics,
    hold: Duration,
) -> crate::bench::error::Result<()> {
    let o = MqttOptions::new(
        format!("chassisd-soak-flood-{}", std::process::id()),
        host,
        port,
    );
    let (client, mut events) = AsyncClient::new(o, 256);
    events.set_network_options(crate::runtime::links::mqtt::low_latency());
    // The flood ends when its time is up, whatever the connection does.
    let poller = tokio::spawn(async move { while events.poll().await.is_ok() {} });
    let until = Instant::now() + hold;
    let rtk = r#"{"cmd":"cancel_task","cmd_type":"task_control"}"#;
    let root = r#"{"messageId":1,"timestamp":"flood","messageType":999,"data":{}}"#;
    while Instant::now() < until {
        if tokio::time::timeout(until.saturating_duration_since(Instant::now()), async {
            client
                .publish(crate::api::rtk::MQTT_CONTROL, QoS::AtMostOnce, false, rtk)
                .await?;
            client
                .publish(&topics.chassis_set, QoS::AtMostOnce, false, root)
                .await
        })
        .await
        .is_err()
        {
            break;
        }
    }
    let _ = client.disconnect().await;
    poller.abort();
    Ok(())
}

impl RunFigures {
    /// Human-readable lines.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let opt = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.3}"));
        let mut out = String::new();
        let _ = writeln!(
            out,
            "soak on {}: {:.0} s, {} cycles; RSS {:.2} -> {:.2} MB, floor per cycle {:?} MB, slope {} MB/h; embedded broker peak {} MB; ROS1 node peak {} MB; base_status p99 {} ms, largest gap {:.1} ms, {:.2} % of periods (outside broker restarts)",
            self.broker,
            self.seconds,
            self.cycles,
            self.rss_start_mb,
            self.rss_end_mb,
            self.rss_floor_per_cycle_mb
                .iter()
                .map(|m| (m * 100.0).round() / 100.0)
                .collect::<Vec<_>>(),
            opt(self.rss_slope_mb_per_h),
            opt(self.broker_peak_mb),
            opt(self.ros1_node_peak_mb),
            self.status_period_ms
                .as_ref()
                .map_or("-".to_owned(), |s| format!("{:.1}", s.p99)),
            self.largest_gap_ms,
            self.status_availability * 100.0,
        );
        let _ = writeln!(
            out,
            "{:<22} {:>8} {:>10} {:>11} {:>8} {:>8} {:>8} {:>8} {:>13} {:>5}",
            "fault",
            "at s",
            "detected s",
            "recovered s",
            "speed",
            "stop s",
            "bound s",
            "rest s",
            "refused/tried",
            ""
        );
        for f in &self.faults {
            let _ = writeln!(
                out,
                "{:<22} {:>8.1} {:>10} {:>11} {:>8.2} {:>8} {:>8} {:>8} {:>13} {:>5}",
                serde_json::to_value(f.kind)
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_owned))
                    .unwrap_or_default(),
                f.at_s,
                opt(f.detected_s),
                opt(f.recovered_s),
                f.speed_mps,
                opt(f.stop_command_s),
                opt(f.stop_bound_s),
                opt(f.at_rest_s),
                f.attack.map_or("-".to_owned(), |a| format!(
                    "{}/{}",
                    a.refused_or_cut, a.attempts
                )),
                if f.pass { "ok" } else { "MISS" },
            );
        }
        out
    }
}

impl SoakReport {
    /// The one-line JSON summary.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slope_of_a_line_and_of_a_flat_series() {
        let hour = Duration::from_secs(3600);
        assert_eq!(slope_per_hour(&[1.0], hour), None);
        let s = slope_per_hour(&[10.0, 11.0, 12.0], hour).unwrap();
        assert!((s - 1.0).abs() < 1e-12, "{s}");
        let minute = Duration::from_secs(60);
        let flat = slope_per_hour(&[10.0, 10.0, 10.0, 10.0], minute).unwrap();
        assert!(flat.abs() < 1e-12, "{flat}");
    }

    #[test]
    fn faults_are_read_from_the_status_flags() {
        let o = |bits, gnss, imu| Observation {
            at: Instant::now(),
            bits,
            gnss,
            imu,
        };
        let healthy = o(status_bits::ENABLED, true, true);
        for kind in [
            FaultKind::GnssOutage,
            FaultKind::ImuStall,
            FaultKind::DriveHeartbeatLoss,
            FaultKind::CanDown,
        ] {
            assert_eq!(kind.shown(&healthy), Some(false), "{kind:?}");
            assert!(kind.recovered(&healthy), "{kind:?}");
        }
        assert_eq!(FaultKind::GnssOutage.shown(&o(1, false, true)), Some(true));
        assert_eq!(FaultKind::ImuStall.shown(&o(1, true, false)), Some(true));
        let lost = o(status_bits::HEARTBEAT_LOST, true, true);
        assert_eq!(FaultKind::DriveHeartbeatLoss.shown(&lost), Some(true));
        // Cleared but not yet enabled again is not recovered.
        assert!(!FaultKind::CanDown.recovered(&o(0, true, true)));
        assert_eq!(FaultKind::CommandFlood.shown(&healthy), None);
    }
}
