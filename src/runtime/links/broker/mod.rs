//! The embedded MQTT broker of the no-hardware default, and of vehicles without a broker of
//! their own. It runs as a process of its own ([`child`]: rumqttd behind the [`gate`]),
//! started and watched from here: when it ends for any reason, chassisd logs why, counts
//! it, and starts a new one at once, on the same address. Its faults never reach chassisd's
//! own threads, drives or memory.
//!
//! Two settings inside make it fit a vehicle that runs for months (see [`child`]): memory
//! bounded per subscription filter, and TCP_NODELAY on every connection (the gate's), so a
//! small packet never waits behind a delayed ACK.

pub mod child;
pub mod gate;
mod identifiers;
mod relay;
pub mod tls;

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, TcpListener, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::process::Child;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::runtime::child_process;
use crate::runtime::error::{RuntimeError, invalid, io};

use crate::api::mqtt::Publish;
use crate::config::mqtt::{MqttConfig, MqttLinkConfig};
use crate::runtime::links::mqtt::MqttSender;
use child::{ChildReport, ChildSettings};
use tls::ServerTls;

/// How long a new broker process may take to accept clients.
const START_TIMEOUT: Duration = Duration::from_secs(10);
/// The first wait before a restart; doubled while restarts keep failing.
const FIRST_BACKOFF: Duration = Duration::from_millis(100);
/// The longest wait between restarts.
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// A broker that lived this long resets the back-off: its end was an accident, not a loop.
const STABLE_AFTER: Duration = Duration::from_secs(30);
/// The broker process may hold this much memory; beyond it, it is restarted. Its own bounds
/// (names, segments, clients) keep it far below: this is the backstop for what they miss.
pub const MAX_BROKER_RSS_MB: u64 = 256;
/// The hidden subcommand that runs [`child::main`].
pub const CHILD_COMMAND: &str = "broker-child";

/// What the broker's supervisor knows, shared with whoever reports it.
#[derive(Debug, Default)]
struct Shared {
    restarts: AtomicU64,
    pid: AtomicU32,
    stats: Mutex<Option<(usize, HashMap<String, u64>)>>,
    last_exit: Mutex<Option<String>>,
}

/// The running embedded broker.
#[derive(Debug, Clone)]
pub struct EmbeddedBroker {
    addr: SocketAddr,
    shared: Arc<Shared>,
}

/// How the embedded broker stands, for the log, `check` and monitoring clients.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BrokerHealth {
    /// Times the broker process ended and was started again.
    pub restarts: u64,
    /// Why it last ended, if it did.
    pub last_exit: Option<String>,
    /// Clients connected at the last report.
    pub connected: Option<usize>,
    /// The gate's counters at the last report (admitted, refused by reason, closed).
    pub counters: HashMap<String, u64>,
}

impl EmbeddedBroker {
    /// Where clients connect.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The broker process's id now (0 between a stop and its restart).
    pub fn pid(&self) -> u32 {
        self.shared.pid.load(Ordering::Relaxed)
    }

    /// How the broker stands.
    pub fn health(&self) -> BrokerHealth {
        let stats = lock(&self.shared.stats).clone();
        BrokerHealth {
            restarts: self.shared.restarts.load(Ordering::Relaxed),
            last_exit: lock(&self.shared.last_exit).clone(),
            connected: stats.as_ref().map(|s| s.0),
            counters: stats.map(|s| s.1).unwrap_or_default(),
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // Plain values: a panic elsewhere cannot leave them half-written.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The broker's settings from `[mqtt]`'s link `config`, for the vehicle called `vehicle`.
pub fn settings(
    mqtt: &MqttConfig,
    config: &MqttLinkConfig,
    vehicle: &str,
) -> Result<ChildSettings, RuntimeError> {
    let listen: SocketAddr = (config.host.as_str(), config.port)
        .to_socket_addrs()
        .map_err(io(format!(
            "embedded broker: bad address {}:{}",
            config.host, config.port
        )))?
        .next()
        .ok_or_else(|| {
            RuntimeError::Failed(format!(
                "embedded broker: {}:{} resolves to nothing",
                config.host, config.port
            ))
        })?;
    let tls = config.tls.as_ref().and_then(|t| {
        Some(ServerTls {
            cert_file: t.cert_file.clone()?,
            key_file: t.key_file.clone()?,
            client_ca_file: t.client_cert_file.is_some().then(|| t.ca_file.clone()),
        })
    });
    // chassisd's own topics (commands, answers, reports) stay served whatever names other
    // clients invent.
    let mut reserved_topics = crate::api::mqtt::Dialects::from_config(
        mqtt,
        Box::new(crate::api::trajectory::Unconfigured),
        crate::api::DIALECTS,
    )
    .topics(Some(&mqtt.dialects_of(config)));
    reserved_topics.extend([
        config.status_topic(vehicle),
        config.broker_health_topic(vehicle),
    ]);
    Ok(ChildSettings {
        listen,
        max_clients: config.embedded_max_clients,
        max_packet: config.packet_limit(),
        credentials: config
            .username
            .clone()
            .map(|u| (u, config.password.clone().unwrap_or_default())),
        own_client_id: Some(config.client_id(vehicle)),
        reserved_client_ids: config.reserved_client_ids(vehicle),
        tls,
        reserved_topics,
    })
}

/// Starts the embedded broker when a link of `[mqtt]` asks for one, for the vehicle
/// `vehicle` (whose own link always finds a place in it).
pub fn start_if_embedded(
    mqtt: &MqttConfig,
    vehicle: &str,
) -> Result<Option<EmbeddedBroker>, RuntimeError> {
    let Some(link) = mqtt.embedded() else {
        return Ok(None);
    };
    start(settings(mqtt, link, vehicle)?).map(Some)
}

/// Publishes the broker's health (restarts, clients, refusals) retained on
/// [`MqttLinkConfig::broker_health_topic`] every [`child::STATS_EVERY`], for `chassisd check`
/// and any monitoring client.
pub fn spawn_health_reports(broker: EmbeddedBroker, mqtt: MqttSender, topic: String) {
    tokio::spawn(async move {
        let mut every = tokio::time::interval(child::STATS_EVERY);
        loop {
            every.tick().await;
            let Ok(payload) = serde_json::to_vec(&broker.health()) else {
                continue;
            };
            mqtt.send(Publish {
                retain: true,
                ..Publish::reply(topic.clone(), payload)
            });
        }
    });
}

/// Starts the broker process and returns once it accepts clients; from then on it is
/// restarted whenever it ends. Fails loudly if its address is taken.
pub fn start(settings: ChildSettings) -> Result<EmbeddedBroker, RuntimeError> {
    let addr = settings.listen;
    // Probe: a port someone else holds is a start-up error, not a restart loop.
    drop(TcpListener::bind(addr).map_err(io(format!(
        "embedded broker: cannot listen on {addr} (another broker running there?)"
    )))?);
    let exe = child_process::self_exe("embedded broker")?;
    let line = serde_json::to_string(&settings).map_err(invalid("embedded broker: settings"))?;
    let shared = Arc::new(Shared::default());
    let running = spawn(&exe, &line, &shared)?;
    let supervisor = {
        let shared = shared.clone();
        move || supervise(exe, line, running, shared)
    };
    std::thread::Builder::new()
        .name("broker-watch".into())
        .spawn(supervisor)
        .map_err(io("embedded broker: cannot start its supervisor"))?;
    Ok(EmbeddedBroker { addr, shared })
}

/// A broker process and the pipe whose end tells it chassisd is gone.
struct Running {
    child: Child,
    /// Held, never written after the settings: dropping it (chassisd's exit) ends the child.
    _stdin: std::process::ChildStdin,
    started: Instant,
}

/// Starts one broker process and waits until it accepts clients.
fn spawn(exe: &Path, settings: &str, shared: &Arc<Shared>) -> Result<Running, RuntimeError> {
    let mut child = child_process::helper_command(exe, CHILD_COMMAND)
        .spawn()
        .map_err(io(format!("embedded broker: cannot run {}", exe.display())))?;
    let (Some(mut stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
        let _ = child.kill();
        return Err(RuntimeError::Failed(
            "embedded broker: its pipes were not set up".into(),
        ));
    };
    if let Err(e) = writeln!(stdin, "{settings}") {
        let _ = child.kill();
        let _ = child.wait();
        return Err(io("embedded broker: cannot hand over its settings")(e));
    }
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let reader_shared = shared.clone();
    std::thread::Builder::new()
        .name("broker-reports".into())
        .spawn(move || read_reports(stdout, ready_tx, reader_shared))
        .map_err(io("embedded broker: cannot start its report reader"))?;
    match ready_rx.recv_timeout(START_TIMEOUT) {
        Ok(()) => {
            shared.pid.store(child.id(), Ordering::Relaxed);
            Ok(Running {
                child,
                _stdin: stdin,
                started: Instant::now(),
            })
        }
        Err(_) => {
            let _ = child.kill();
            let status = child.wait().map(|s| s.to_string()).unwrap_or_default();
            Err(RuntimeError::Failed(format!(
                "embedded broker: did not start ({status}); its log lines above say why"
            )))
        }
    }
}

/// Reads the broker process's report lines until its standard output closes.
fn read_reports(
    stdout: std::process::ChildStdout,
    ready: std::sync::mpsc::Sender<()>,
    shared: Arc<Shared>,
) {
    // Lines are the child's own, short; a bound keeps a broken one from growing.
    let mut reader = BufReader::new(stdout);
    let mut line = String::new();
    loop {
        line.clear();
        match std::io::Read::take(&mut reader, 1 << 16).read_line(&mut line) {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
        match serde_json::from_str::<ChildReport>(&line) {
            Ok(ChildReport::Ready) => {
                let _ = ready.send(());
            }
            Ok(ChildReport::Stats {
                connected,
                counters,
            }) => {
                *lock(&shared.stats) = Some((connected, counters));
                check_memory(shared.pid.load(Ordering::Relaxed));
            }
            Err(_) => tracing::debug!(line = line.trim_end(), "embedded broker: unknown report"),
        }
    }
}

/// Ends the broker process `pid` (the supervisor then starts another) when it holds more
/// than [`MAX_BROKER_RSS_MB`].
fn check_memory(pid: u32) {
    if pid == 0 {
        return;
    }
    let rss_mb = child_process::rss_mb(pid);
    if let Some(mb) = rss_mb.filter(|&mb| mb > MAX_BROKER_RSS_MB) {
        tracing::error!(
            rss_mb = mb,
            limit_mb = MAX_BROKER_RSS_MB,
            "embedded broker holds too much memory; it is restarted"
        );
        // SAFETY: a plain signal to our own child process.
        unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) };
    }
}

/// Waits for the broker process to end, then starts another, for as long as chassisd runs.
fn supervise(exe: PathBuf, settings: String, mut running: Running, shared: Arc<Shared>) {
    let mut backoff = FIRST_BACKOFF;
    loop {
        let status = running.child.wait();
        shared.pid.store(0, Ordering::Relaxed);
        let lived = running.started.elapsed();
        let why = match status {
            Ok(s) => child_process::describe_exit(
                s,
                &[(child::EXIT_UNRESPONSIVE, "it stopped answering its probe")],
            ),
            Err(e) => format!("cannot be waited for: {e}"),
        };
        let restarts = shared.restarts.fetch_add(1, Ordering::Relaxed) + 1;
        *lock(&shared.last_exit) = Some(why.clone());
        *lock(&shared.stats) = None;
        tracing::error!(
            reason = %why,
            lived_s = lived.as_secs_f64(),
            restarts,
            "embedded broker stopped; starting it again (clients reconnect)"
        );
        if lived > STABLE_AFTER {
            backoff = FIRST_BACKOFF;
        }
        running = loop {
            std::thread::sleep(backoff);
            backoff = (backoff * 2).min(MAX_BACKOFF);
            match spawn(&exe, &settings, &shared) {
                Ok(r) => break r,
                Err(e) => {
                    tracing::error!(error = %e, "embedded broker: restart failed; trying again")
                }
            }
        };
        tracing::info!(restarts, "embedded broker running again");
    }
}
