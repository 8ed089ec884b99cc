//! `chassisd bench ros2`: `/odom` at 100 Hz to three subscribers, each a process of its own,
//! through the native ROS 2 node (DDS) and through the rosbridge WebSocket, on the simulated
//! vehicle. For each path: the latency from the pose's stamp to each subscriber, the messages
//! each got, and the CPU the path adds to chassisd (its process and the node's) over a run of
//! the same vehicle that publishes to nobody.
//!
//! DDS discovery multicasts, so the benchmark runs in a network namespace of its own (loopback
//! alone, with a multicast route): [`enter_private_network`] starts it there.
//!
//! A stamp is the engine's clock (wall time at its start plus monotonic time since); a
//! subscriber reads the monotonic clock and the offset the benchmark measured between the
//! two, so a wall clock that NTP slews during the run does not count as latency.

use std::io::Read;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::error::{BenchError, Result, invalid, io};
use super::mqtt::Spread;
use crate::config::ros2::Ros2Config;
use crate::config::websocket::WebsocketConfig;
use crate::runtime::host::{children_running, process_cpu_seconds};
use crate::runtime::links::ros2::CHILD_COMMAND as NODE_COMMAND;
use crate::runtime::modes::sim::{self, SimOptions};
use crate::sim::plant::PlantConfig;

/// The hidden subcommand of the benchmarks' program that runs one subscriber.
pub const LISTEN_COMMAND: &str = "bench-ros2-listen";
/// Set in the benchmark's own network namespace (so it does not start another).
const PRIVATE_NETWORK: &str = "CHASSISD_BENCH_PRIVATE_NETWORK";
/// The ROS 2 domain of the benchmark's namespace.
const DOMAIN: u16 = 0;
/// From the vehicle's start to the subscribers': the node's process joins its domain.
const VEHICLE_START: Duration = Duration::from_secs(2);
/// From the subscribers' start to the measured window: discovery and matching.
const SETTLE: Duration = Duration::from_secs(3);
/// Each subscriber gets at least this share of the messages published in the window.
const DELIVERY_TARGET: f64 = 0.95;
/// The 99th percentile latency target: one control period.
const P99_TARGET_MS: f64 = 10.0;

/// What to run.
#[derive(Debug, Clone)]
pub struct Ros2BenchOptions {
    /// The vehicle.
    pub plant: PlantConfig,
    /// How long each path is measured.
    pub window: Duration,
    /// Subscribers of each path.
    pub subscribers: u32,
    /// `/odom`'s rate, Hz.
    pub rate_hz: f64,
}

/// The way `/odom` leaves chassisd.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Route {
    /// Nobody subscribed: the vehicle alone, the reference for the CPU added.
    Baseline,
    /// The native ROS 2 node, to subscribers on DDS.
    Ros2,
    /// The rosbridge WebSocket server, to WebSocket clients.
    Rosbridge,
}

/// One route's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RouteRun {
    /// The route.
    pub route: Route,
    /// chassisd's CPU over the window (its process, and the node's when one runs), % of one
    /// core.
    pub cpu_percent: f64,
    /// Of which the ROS 2 node's process, % of one core.
    pub node_cpu_percent: f64,
    /// What the route adds to the baseline's, % of one core.
    pub added_cpu_percent: Option<f64>,
    /// From a message's stamp to a subscriber, every subscriber's messages together, ms.
    pub latency_ms: Option<Spread>,
    /// Messages each subscriber got in the window.
    pub received: Vec<u64>,
    /// Messages published in the window.
    pub expected: u64,
    /// The route met its targets (every subscriber's share, the p99 latency).
    pub pass: bool,
}

/// The benchmark's figures: its JSON line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ros2Report {
    /// `/odom`'s rate, Hz.
    pub rate_hz: f64,
    /// Subscribers of each route.
    pub subscribers: u32,
    /// The measured window of each route, s.
    pub window_s: f64,
    /// The routes, the baseline first.
    pub runs: Vec<RouteRun>,
    /// Every route met its targets.
    pub pass: bool,
}

impl Ros2Report {
    /// The figures as a table.
    pub fn table(&self) -> String {
        let mut out = format!(
            "/odom at {} Hz to {} subscribers, {} s per route\n\
             {:<10} {:>8} {:>8} {:>8} {:>9} {:>9} {:>9}  received of expected\n",
            self.rate_hz,
            self.subscribers,
            self.window_s,
            "route",
            "CPU %",
            "node %",
            "added %",
            "p50 ms",
            "p99 ms",
            "max ms"
        );
        let number = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.2}"));
        for run in &self.runs {
            let latency = run.latency_ms.as_ref();
            out += &format!(
                "{:<10} {:>8.2} {:>8.2} {:>8} {:>9} {:>9} {:>9}  {:?} of {}\n",
                serde_json::to_value(run.route)
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_owned))
                    .unwrap_or_default(),
                run.cpu_percent,
                run.node_cpu_percent,
                number(run.added_cpu_percent),
                number(latency.map(|l| l.median)),
                number(latency.map(|l| l.p99)),
                number(latency.map(|l| l.max)),
                run.received,
                run.expected
            );
        }
        out
    }

    /// The one-line JSON summary.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// Starts this program again inside a network namespace of its own (loopback up, a
/// multicast route on it, no other interface), unless it runs in one already: the exit
/// status of the run inside, or `None` when this is it.
pub fn enter_private_network() -> Result<Option<std::process::ExitStatus>> {
    if std::env::var_os(PRIVATE_NETWORK).is_some() {
        return Ok(None);
    }
    if let Some(why) = super::missing_program("ip", "-V", "iproute2") {
        return Err(BenchError::Failed(why));
    }
    let exe = std::env::current_exe().map_err(io("finding this program"))?;
    // SAFETY: geteuid has no preconditions.
    let as_root = unsafe { libc::geteuid() } == 0;
    let status = Command::new("unshare")
        .arg(if as_root { "-n" } else { "-rn" })
        .args([
            "sh",
            "-c",
            "ip link set lo up && ip link set lo multicast on \
             && ip route add 224.0.0.0/4 dev lo && exec \"$0\" \"$@\"",
        ])
        .arg(exe)
        .args(std::env::args_os().skip(1))
        .env(PRIVATE_NETWORK, "1")
        .status()
        .map_err(io(
            "starting the benchmark in a network namespace of its own (unshare, util-linux)",
        ))?;
    Ok(Some(status))
}

/// Runs every route in turn, the baseline first.
pub fn run(options: &Ros2BenchOptions) -> Result<Ros2Report> {
    let mut runs: Vec<RouteRun> = Vec::new();
    for route in [Route::Baseline, Route::Ros2, Route::Rosbridge] {
        let measured = measure(options, route)?;
        let baseline = runs.first().map(|b| b.cpu_percent);
        runs.push(judge(options, route, measured, baseline));
    }
    let pass = runs.iter().all(|r| r.pass);
    Ok(Ros2Report {
        rate_hz: options.rate_hz,
        subscribers: options.subscribers,
        window_s: options.window.as_secs_f64(),
        runs,
        pass,
    })
}

/// What one route's run gave.
struct Measured {
    cpu_percent: f64,
    node_cpu_percent: f64,
    subscribers: Vec<Heard>,
}

/// A route's figures against its targets.
fn judge(
    options: &Ros2BenchOptions,
    route: Route,
    measured: Measured,
    baseline: Option<f64>,
) -> RouteRun {
    let expected = (options.rate_hz * options.window.as_secs_f64()).round() as u64;
    let received: Vec<u64> = measured.subscribers.iter().map(|h| h.received).collect();
    let latencies: Vec<f64> = measured
        .subscribers
        .into_iter()
        .flat_map(|h| h.latencies_ms)
        .collect();
    let latency_ms = Spread::of(latencies);
    let pass = route == Route::Baseline
        || (received.len() == options.subscribers as usize
            && received
                .iter()
                .all(|&n| n as f64 >= DELIVERY_TARGET * expected as f64)
            && latency_ms.is_some_and(|l| l.p99 <= P99_TARGET_MS));
    RouteRun {
        route,
        cpu_percent: measured.cpu_percent,
        node_cpu_percent: measured.node_cpu_percent,
        added_cpu_percent: baseline
            .filter(|_| route != Route::Baseline)
            .map(|b| measured.cpu_percent - b),
        latency_ms,
        expected: if route == Route::Baseline {
            0
        } else {
            expected
        },
        received,
        pass,
    }
}

/// The simulated vehicle with `route`'s link for the whole run; the subscribers started
/// after [`VEHICLE_START`], measured after [`SETTLE`] for the window.
fn measure(options: &Ros2BenchOptions, route: Route) -> Result<Measured> {
    let offset_ns = wall_minus_monotonic_ns();
    let port = super::free_local_port()?;
    let (ros2, websocket) = match route {
        Route::Baseline => (None, None),
        Route::Ros2 => (
            Some(Ros2Config {
                domain_id: Some(DOMAIN),
                odom_rate_hz: options.rate_hz,
                ..Ros2Config::default()
            }),
            None,
        ),
        Route::Rosbridge => (
            None,
            Some(WebsocketConfig {
                odom_rate_hz: options.rate_hz,
                max_clients: options.subscribers.max(1) as usize,
                ..WebsocketConfig::with_bind(&format!("127.0.0.1:{port}"))
            }),
        ),
    };
    // The vehicle outlives the window by a little, for the subscribers' last messages.
    let total = VEHICLE_START + SETTLE + options.window + Duration::from_millis(500);
    let sim = SimOptions {
        plant: options.plant.clone(),
        seed: 1,
        record: None,
        commands_stdin: false,
        scenario: None,
        duration: Some(total),
        mqtt: None,
        ros1: None,
        ros2,
        websocket,
        handle: None,
        ntrip: None,
        zones: None,
    };
    let vehicle = std::thread::spawn(move || -> Result<()> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .map_err(io("the vehicle's runtime"))?;
        let ended = runtime.block_on(sim::run(sim, std::io::sink()));
        runtime.shutdown_background();
        Ok(ended?)
    });
    std::thread::sleep(VEHICLE_START);
    let target = match route {
        Route::Baseline => None,
        Route::Ros2 => Some(format!("dds:{DOMAIN}")),
        Route::Rosbridge => Some(format!("ws:127.0.0.1:{port}")),
    };
    let mut listeners = Vec::new();
    if let Some(target) = &target {
        for _ in 0..options.subscribers {
            listeners.push(start_listener(target, options.window, offset_ns)?);
        }
    }
    std::thread::sleep(SETTLE);
    let (me_before, node_before) = chassisd_cpu_seconds();
    let started = Instant::now();
    std::thread::sleep(options.window);
    let (me, node) = chassisd_cpu_seconds();
    let percent = |seconds: f64| seconds / started.elapsed().as_secs_f64() * 100.0;
    let node_cpu_percent = percent(node - node_before);
    let cpu_percent = percent(me - me_before) + node_cpu_percent;
    let subscribers = listeners
        .into_iter()
        .map(finish_listener)
        .collect::<Result<Vec<_>>>()?;
    vehicle
        .join()
        .map_err(|_| BenchError::Failed("the simulated vehicle's thread panicked".into()))??;
    Ok(Measured {
        cpu_percent,
        node_cpu_percent,
        subscribers,
    })
}

/// CPU time of chassisd so far, s: this process (the vehicle runs in it; the subscribers do
/// not), and the ROS 2 node's process (0 when none runs).
fn chassisd_cpu_seconds() -> (f64, f64) {
    let me = process_cpu_seconds(std::process::id()).unwrap_or(0.0);
    let node: f64 = children_running(NODE_COMMAND)
        .into_iter()
        .filter_map(|(pid, _)| process_cpu_seconds(pid))
        .sum();
    (me, node)
}

/// The wall clock less the monotonic one, ns: a stamp less it is the monotonic time the
/// stamp stands for.
fn wall_minus_monotonic_ns() -> i128 {
    clock_ns(libc::CLOCK_REALTIME) - clock_ns(libc::CLOCK_MONOTONIC)
}

/// Clock `id` now, ns.
fn clock_ns(id: libc::clockid_t) -> i128 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec it is given; both clocks exist on Linux.
    unsafe { libc::clock_gettime(id, &mut t) };
    i128::from(t.tv_sec) * 1_000_000_000 + i128::from(t.tv_nsec)
}

/// A subscriber process: this program's [`LISTEN_COMMAND`].
fn start_listener(target: &str, window: Duration, offset_ns: i128) -> Result<Child> {
    let exe = std::env::current_exe().map_err(io("finding this program"))?;
    Command::new(exe)
        .args([
            LISTEN_COMMAND,
            target,
            &SETTLE.as_secs_f64().to_string(),
            &window.as_secs_f64().to_string(),
            &offset_ns.to_string(),
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .map_err(io("starting a subscriber"))
}

/// A subscriber's figures, once it ends.
fn finish_listener(mut child: Child) -> Result<Heard> {
    let mut out = String::new();
    if let Some(mut stdout) = child.stdout.take() {
        stdout
            .read_to_string(&mut out)
            .map_err(io("reading a subscriber"))?;
    }
    let status = child.wait().map_err(io("waiting for a subscriber"))?;
    let last = out.lines().last().unwrap_or_default();
    serde_json::from_str(last).map_err(|e| {
        BenchError::Failed(format!(
            "a subscriber ended ({status}) without its figures: {e}"
        ))
    })
}

/// What a subscriber heard in its window: its line on standard output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Heard {
    /// Messages of the topic.
    pub received: u64,
    /// Each one's latency, ms.
    pub latencies_ms: Vec<f64>,
}

/// A subscriber's whole life (`LISTEN_COMMAND TARGET SETTLE_S WINDOW_S OFFSET_NS`, TARGET
/// `dds:DOMAIN` or `ws:HOST:PORT`): it subscribes to `/odom`, lets SETTLE_S pass, then
/// prints what it heard in WINDOW_S as one JSON line.
pub fn listen_main(args: &[String]) -> Result<()> {
    let [target, settle, window, offset] = args else {
        return Err(BenchError::Failed(format!(
            "{LISTEN_COMMAND} TARGET SETTLE_S WINDOW_S OFFSET_NS, not {args:?}"
        )));
    };
    let seconds = |s: &str| {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .map(Duration::from_secs_f64)
            .ok_or_else(|| BenchError::Failed(format!("{s:?} is not a number of seconds")))
    };
    let (settle, window) = (seconds(settle)?, seconds(window)?);
    let offset_ns: i128 = offset
        .parse()
        .map_err(invalid("the clock offset is not a number"))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(io("the subscriber's runtime"))?;
    let mut listening = Listening::new(settle, window, offset_ns);
    let heard = runtime.block_on(async {
        if let Some(domain) = target.strip_prefix("dds:") {
            let domain = domain
                .parse()
                .map_err(invalid("the domain is not a number"))?;
            listen_dds(domain, &mut listening).await
        } else if let Some(address) = target.strip_prefix("ws:") {
            listen_rosbridge(address, &mut listening).await
        } else {
            Err(BenchError::Failed(format!("{target:?}: dds:N or ws:ADDR")))
        }
    });
    runtime.shutdown_background();
    heard?;
    println!(
        "{}",
        serde_json::to_string(&listening.heard).unwrap_or_default()
    );
    Ok(())
}

/// A subscriber's clock and what it has heard.
struct Listening {
    window_start: Instant,
    window_end: Instant,
    offset_ns: i128,
    heard: Heard,
}

impl Listening {
    fn new(settle: Duration, window: Duration, offset_ns: i128) -> Self {
        let window_start = Instant::now() + settle;
        Self {
            window_start,
            window_end: window_start + window,
            offset_ns,
            heard: Heard {
                received: 0,
                latencies_ms: Vec::new(),
            },
        }
    }

    /// A message stamped `msg.header.stamp` arrived now.
    fn arrived(&mut self, msg: &Value) -> Result<()> {
        let now = Instant::now();
        let monotonic_ns = clock_ns(libc::CLOCK_MONOTONIC);
        if now < self.window_start || now >= self.window_end {
            return Ok(());
        }
        let stamp = &msg["header"]["stamp"];
        let (Some(sec), Some(nanosec)) = (stamp["sec"].as_i64(), stamp["nanosec"].as_i64()) else {
            return Err(BenchError::Failed(format!("/odom without a stamp: {msg}")));
        };
        let stamp_ns = i128::from(sec) * 1_000_000_000 + i128::from(nanosec);
        let latency_ns = monotonic_ns + self.offset_ns - stamp_ns;
        self.heard.received += 1;
        self.heard.latencies_ms.push(latency_ns as f64 / 1e6);
        Ok(())
    }

    /// The next item of `stream` before the window ends; `None` once it has ended, or
    /// the stream has.
    async fn next_within<S: futures_util::Stream + Unpin>(
        &self,
        stream: &mut S,
    ) -> Option<S::Item> {
        let left = self.window_end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return None;
        }
        tokio::time::timeout(left, stream.next())
            .await
            .ok()
            .flatten()
    }
}

/// A ROS 2 subscriber of `/odom` on `domain`, this machine only, as a node of its own.
async fn listen_dds(domain: u16, listening: &mut Listening) -> Result<()> {
    use crate::api::ros2::topics::{STATE, TOPICS};
    use crate::runtime::links::ros2::child::{name, profile, type_name};
    use crate::runtime::links::ros2::messages::decode;
    use crate::runtime::links::ros2::wire::RawSeed;
    use ros2_client::dds::rustdds::DomainParticipantBuilder;
    use ros2_client::{Context, NodeName, NodeOptions};

    let failed = |what: &'static str| move |e: String| BenchError::Failed(format!("{what}: {e}"));
    let odom = TOPICS
        .iter()
        .find(|t| t.name == "/odom")
        .ok_or_else(|| BenchError::Failed("no /odom in the ROS 2 topics".into()))?;
    let participant = DomainParticipantBuilder::new(domain)
        .with_only_networks([std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST)])
        .build()
        .map_err(|e| BenchError::Failed(format!("DDS participant: {e:?}")))?;
    let context = Context::from_domain_participant(participant)
        .map_err(|e| BenchError::Failed(format!("ROS 2 context: {e:?}")))?;
    let node_name = NodeName::new("/", &format!("odom_listener_{}", std::process::id()))
        .map_err(|e| BenchError::Failed(format!("node name: {e:?}")))?;
    let mut node = context
        .new_node(node_name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| BenchError::Failed(format!("ROS 2 node: {e:?}")))?;
    let spinner = node
        .spinner()
        .map_err(|e| BenchError::Failed(format!("spinner: {e:?}")))?;
    tokio::spawn(spinner.spin());
    let qos = profile(STATE);
    let topic = node
        .create_topic(
            &name("", odom.name).map_err(failed("topic"))?,
            type_name(odom.msg_type),
            &qos,
        )
        .map_err(|e| BenchError::Failed(format!("/odom: {e:?}")))?;
    let reader = node
        .create_subscription::<Vec<u8>>(&topic, Some(qos))
        .map_err(|e| BenchError::Failed(format!("/odom: {e:?}")))?;
    let mut stream = Box::pin(reader.async_stream_seed(RawSeed));
    while let Some(sample) = listening.next_within(&mut stream).await {
        let (payload, _) = sample.map_err(|e| BenchError::Failed(format!("/odom: {e:?}")))?;
        let msg = decode(odom.msg_type, &payload).map_err(failed("/odom's CDR"))?;
        listening.arrived(&msg)?;
    }
    Ok(())
}

/// A rosbridge client subscribed to `/odom` at `address`.
async fn listen_rosbridge(address: &str, listening: &mut Listening) -> Result<()> {
    use tokio_tungstenite::tungstenite::Message;

    let stream = tokio::net::TcpStream::connect(address)
        .await
        .map_err(io(format!("connecting to {address}")))?;
    stream.set_nodelay(true).map_err(io("TCP_NODELAY"))?;
    let (mut socket, _) = tokio_tungstenite::client_async(format!("ws://{address}/"), stream)
        .await
        .map_err(invalid("the WebSocket handshake"))?;
    let subscribe = serde_json::json!({
        "op": "subscribe", "topic": "/odom", "type": "nav_msgs/msg/Odometry"
    });
    socket
        .send(Message::Text(subscribe.to_string()))
        .await
        .map_err(invalid("subscribing"))?;
    while let Some(frame) = listening.next_within(&mut socket).await {
        let Message::Text(text) = frame.map_err(invalid("the WebSocket"))? else {
            continue;
        };
        let envelope: Value = serde_json::from_str(&text).map_err(invalid("a message"))?;
        if envelope["op"] == "publish" && envelope["topic"] == "/odom" {
            listening.arrived(&envelope["msg"])?;
        }
    }
    Ok(())
}
