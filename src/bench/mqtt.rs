//! `chassisd bench mqtt`: the MQTT surface under a stopwatch. The simulated vehicle runs in
//! real time with its MQTT dialects (and records its session). A client subscribes to
//! base_status and, once the drives are enabled, measures its period on its own clock and sends
//! root DRIVE commands (with heartbeats), timing each from publish to its ack (broker →
//! chassisd → broker → client). The rest of a command's way, from chassisd taking it to the
//! first drive RPDO that carries the new target, is read from the recording: both are stamped
//! there on the simulation's clock, the one the engine runs on.

use std::path::Path;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crate::bench::error::{BenchError, invalid, missing};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use serde::Serialize;
use serde_json::Value;

use crate::api::mqtt::MQTT_SOURCE;
use crate::config::mqtt::MqttConfig;
use crate::record::{Payload, RecordingReader};
use crate::runtime::modes::sim::{self, SimOptions};
use crate::sim::plant::{LEFT_NODE, PlantConfig, SIM_BUS};
use crate::time::Timestamp;
use crate::vehicle::chassis::status_bits;

/// The base_status period the protocol asks for.
const STATUS_PERIOD_MS: f64 = 100.0;
/// A DRIVE command every this long.
const DRIVE_EVERY: Duration = Duration::from_millis(500);

/// What to run.
pub struct MqttBenchOptions {
    /// The vehicle.
    pub plant: PlantConfig,
    /// How long to measure.
    pub duration: Duration,
    /// The MQTT settings of the daemon (broker, dialects; root must be on).
    pub mqtt: MqttConfig,
}

/// Median, 99th percentile and maximum of a set of figures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    /// Median.
    pub median: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Maximum.
    pub max: f64,
    /// How many.
    pub n: usize,
}

impl Spread {
    /// The spread of `values`; `None` when there are none.
    pub fn of(mut values: Vec<f64>) -> Option<Self> {
        if values.is_empty() {
            return None;
        }
        values.sort_by(f64::total_cmp);
        let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
        Some(Self {
            median: at(0.5),
            p99: at(0.99),
            max: values[values.len() - 1],
            n: values.len(),
        })
    }
}

/// The figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MqttReport {
    /// base_status period as the subscriber saw it, ms.
    pub status_period_ms: Option<Spread>,
    /// Largest |period − 100 ms|, ms.
    pub status_max_jitter_ms: Option<f64>,
    /// DRIVE: publish → ack received, on the client's clock, ms.
    pub drive_round_trip_ms: Option<Spread>,
    /// DRIVE: taken by chassisd → the first RPDO with the new target, simulation clock, ms.
    pub command_to_rpdo_ms: Option<Spread>,
    /// DRIVE commands sent, and acknowledged with code 0.
    pub drives: (usize, usize),
}

/// The DRIVE round trip's p99 a broker must keep within, ms.
pub const DRIVE_P99_TARGET_MS: f64 = 5.0;
/// The largest deviation of the base_status period from 100 ms a broker may show, ms.
pub const PERIOD_DEVIATION_TARGET_MS: f64 = 5.0;

/// One broker's figures and verdict.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BrokerRun {
    /// `embedded`, `mosquitto` or `external`.
    pub broker: String,
    /// The figures.
    #[serde(flatten)]
    pub report: MqttReport,
    /// Every DRIVE acknowledged, its p99 round trip and the period's largest deviation
    /// within their targets.
    pub pass: bool,
}

impl BrokerRun {
    /// `report`'s verdict against the targets.
    pub fn new(broker: &str, report: MqttReport) -> Self {
        let pass = report.drives.0 > 0
            && report.drives.0 == report.drives.1
            && report
                .drive_round_trip_ms
                .as_ref()
                .is_some_and(|s| s.p99 <= DRIVE_P99_TARGET_MS)
            && report
                .status_max_jitter_ms
                .is_some_and(|j| j <= PERIOD_DEVIATION_TARGET_MS);
        Self {
            broker: broker.to_owned(),
            report,
            pass,
        }
    }
}

/// Every broker's run: the JSON line of `chassisd bench mqtt`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MqttComparison {
    /// The runs, in order.
    pub runs: Vec<BrokerRun>,
    /// Why a broker asked for was left out.
    pub skipped: Option<String>,
    /// Every run passed.
    pub pass: bool,
}

impl MqttComparison {
    /// The comparison of `runs`.
    pub fn new(runs: Vec<BrokerRun>, skipped: Option<String>) -> Self {
        let pass = !runs.is_empty() && runs.iter().all(|r| r.pass);
        Self {
            runs,
            skipped,
            pass,
        }
    }

    /// The one-line JSON summary.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// The vehicle id of `mqtt`'s root dialect, which a benchmark's DRIVE commands need.
pub fn root_vehicle_id(mqtt: &MqttConfig) -> crate::bench::error::Result<String> {
    mqtt.root
        .as_ref()
        .map(|r| r.vehicle_id.clone())
        .ok_or_else(missing(
            "the root dialect must be on (DRIVE is one of its commands)",
        ))
}

/// Runs the benchmark.
pub async fn run(options: MqttBenchOptions) -> crate::bench::error::Result<MqttReport> {
    let vehicle_id = root_vehicle_id(&options.mqtt)?;
    let dir = std::env::temp_dir().join(format!(
        "chassisd-bench-mqtt-{}-{}",
        std::process::id(),
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
            .as_micros()
    ));
    let (host, port) = (options.mqtt.first().host.clone(), options.mqtt.first().port);
    let sim = tokio::spawn(sim::run(
        SimOptions {
            plant: options.plant.clone(),
            seed: 1,
            record: Some(dir.clone()),
            commands_stdin: false,
            scenario: None,
            duration: Some(options.duration + Duration::from_secs(4)),
            mqtt: Some(options.mqtt.clone()),
            ros1: None,
            ros2: None,
            websocket: None,
            handle: None,
            ntrip: None,
            zones: None,
        },
        std::io::sink(),
    ));

    let mut o = MqttOptions::new(format!("chassisd-bench-{}", std::process::id()), host, port);
    o.set_keep_alive(Duration::from_secs(5));
    let (client, mut events) = AsyncClient::new(o, 64);
    events.set_network_options(crate::runtime::links::mqtt::low_latency());
    let chassis_set = format!("/root/{vehicle_id}/cmd/chassis/set");
    let chassis_ack = format!("/root/{vehicle_id}/cmd/chassis/ack");
    let heartbeat = format!("/root/{vehicle_id}/heartbeat/set");
    client
        .subscribe("base_status", QoS::AtMostOnce)
        .await
        .map_err(invalid("subscribe"))?;
    client.subscribe(&chassis_ack, QoS::AtLeastOnce).await?;

    let mut arrivals: Vec<Instant> = Vec::new();
    let mut sent: Vec<(u64, Instant)> = Vec::new();
    let mut round_trips: Vec<f64> = Vec::new();
    let mut acked = 0usize;
    let mut measuring_since: Option<Instant> = None;
    let mut next_drive = Instant::now();
    let give_up = Instant::now() + Duration::from_secs(20);
    loop {
        let now = Instant::now();
        if let Some(since) = measuring_since {
            if now.duration_since(since) >= options.duration {
                break;
            }
            if now >= next_drive {
                next_drive = now + DRIVE_EVERY;
                let id = sent.len() as u64 + 1;
                let linear = if id.is_multiple_of(2) { 0.4 } else { 0.2 };
                let drive = format!(
                    r#"{{"messageId":{id},"timestamp":"bench","messageType":100,"data":{{"linear":{linear},"angular":0.0}}}}"#
                );
                beat(&client, &heartbeat).await?;
                sent.push((id, Instant::now()));
                client
                    .publish(&chassis_set, QoS::AtLeastOnce, false, drive)
                    .await?;
            }
        } else if now > give_up {
            return Err(BenchError::Failed(
                "no base_status with the drives enabled within 20 s: is the broker reachable?"
                    .into(),
            ));
        }
        let event = tokio::time::timeout(Duration::from_millis(50), events.poll()).await;
        match event {
            Ok(Ok(Event::Incoming(Packet::Publish(p)))) if p.topic == "base_status" => {
                // Measuring starts once the drives are enabled, so the first DRIVE does not
                // time their enable sequence.
                if measuring_since.is_none() {
                    let status: Value = serde_json::from_slice(&p.payload).unwrap_or_default();
                    let bits = status["robot"]["robot_status"].as_u64().unwrap_or(0);
                    if bits & u64::from(status_bits::ENABLED) == 0 {
                        continue;
                    }
                }
                measuring_since.get_or_insert(Instant::now());
                arrivals.push(Instant::now());
            }
            Ok(Ok(Event::Incoming(Packet::Publish(p)))) if p.topic == chassis_ack => {
                let ack: Value = serde_json::from_slice(&p.payload).unwrap_or_default();
                if ack["data"]["code"] == 0 {
                    acked += 1;
                }
                if let Some((_, at)) = sent.iter().find(|(id, _)| ack["messageId"] == *id) {
                    round_trips.push(at.elapsed().as_secs_f64() * 1000.0);
                }
            }
            Ok(Ok(_)) | Err(_) => {}
            // The broker is still starting: try again.
            Ok(Err(_)) => tokio::time::sleep(Duration::from_millis(100)).await,
        }
    }
    // Heartbeats go on until the simulation ends, so its end is not a lost control link.
    while !sim.is_finished() {
        beat(&client, &heartbeat).await?;
        let until = Instant::now() + DRIVE_EVERY;
        while Instant::now() < until && !sim.is_finished() {
            let _ = tokio::time::timeout(Duration::from_millis(50), events.poll()).await;
        }
    }
    drop(client);
    sim.await.map_err(invalid("simulation task"))??;

    let periods: Vec<f64> = arrivals
        .windows(2)
        .map(|w| w[1].duration_since(w[0]).as_secs_f64() * 1000.0)
        .collect();
    let jitter = periods
        .iter()
        .map(|p| (p - STATUS_PERIOD_MS).abs())
        .reduce(f64::max);
    let to_rpdo = command_to_rpdo(&dir);
    std::fs::remove_dir_all(&dir).ok();
    Ok(MqttReport {
        status_period_ms: Spread::of(periods),
        status_max_jitter_ms: jitter,
        drive_round_trip_ms: Spread::of(round_trips),
        command_to_rpdo_ms: Spread::of(to_rpdo?),
        drives: (sent.len(), acked),
    })
}

/// One control-link heartbeat of the root dialect.
async fn beat(client: &AsyncClient, topic: &str) -> crate::bench::error::Result<()> {
    client
        .publish(topic, QoS::AtLeastOnce, false, r#"{"timestamp":"bench"}"#)
        .await
        .map_err(invalid("publish a heartbeat"))
}

/// From the recording: for each DRIVE chassisd took, how long until the left drive's RPDO
/// first carried a target other than the one before it, ms.
fn command_to_rpdo(dir: &Path) -> crate::bench::error::Result<Vec<f64>> {
    let (_, reader) = RecordingReader::open(dir).map_err(invalid(format!(
        "the benchmark's recording in {}",
        dir.display()
    )))?;
    let rpdo = 0x200 + u32::from(LEFT_NODE.get());
    let mut received: Vec<Timestamp> = Vec::new();
    let mut targets: Vec<(Timestamp, i32)> = Vec::new();
    for record in reader {
        match &record.payload {
            Payload::Command { topic, .. }
                if record.source == MQTT_SOURCE && topic.ends_with("/cmd/chassis/set") =>
            {
                received.push(record.t);
            }
            Payload::CanTx(frame) if record.source == SIM_BUS => {
                let frame = crate::devices::can::Received::from_socketcan(frame);
                if let crate::devices::can::Received::Data(f) = frame
                    && f.id() == rpdo
                    && let Some(bytes) = f.data().get(2..6)
                {
                    let target = i32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
                    targets.push((record.t, target));
                }
            }
            _ => {}
        }
    }
    let mut latencies = Vec::new();
    for arrived in &received {
        let before = targets
            .iter()
            .rev()
            .find(|(t, _)| t < arrived)
            .map(|(_, v)| *v);
        if let Some((t, _)) = targets
            .iter()
            .find(|(t, v)| t >= arrived && Some(*v) != before)
        {
            latencies.push(t.saturating_since(*arrived).as_secs_f64() * 1000.0);
        }
    }
    Ok(latencies)
}

impl MqttReport {
    /// Human-readable lines.
    pub fn table(&self) -> String {
        let line = |name: &str, s: &Option<Spread>| match s {
            Some(s) => format!(
                "{name:<34} median {:>7.2} ms  p99 {:>7.2} ms  max {:>7.2} ms  (n = {})\n",
                s.median, s.p99, s.max, s.n
            ),
            None => format!("{name:<34} no samples\n"),
        };
        let mut out = String::new();
        out.push_str(&line("base_status period", &self.status_period_ms));
        out.push_str(&format!(
            "{:<34} {:.2} ms\n",
            "base_status max |period - 100 ms|",
            self.status_max_jitter_ms.unwrap_or(f64::NAN)
        ));
        out.push_str(&line("DRIVE publish -> ack", &self.drive_round_trip_ms));
        out.push_str(&line(
            "DRIVE chassisd -> CAN RPDO (sim)",
            &self.command_to_rpdo_ms,
        ));
        out.push_str(&format!(
            "{:<34} {} sent, {} acknowledged with code 0\n",
            "DRIVE commands", self.drives.0, self.drives.1
        ));
        out
    }
}
