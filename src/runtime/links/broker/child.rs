//! The embedded broker's own process (`chassisd broker-child`, started by chassisd, never
//! by hand): rumqttd on a loopback port only this process knows, the gate on the address
//! clients use, and a probe that keeps asking rumqttd for a PINGRESP. Any panic in here,
//! or a broker that stops answering, ends the process, and chassisd starts a new one: a
//! fault of the broker never reaches the vehicle's control loop, its drives or its memory.
//!
//! Settings arrive as one JSON line on standard input (so the password is never on a
//! command line); standard input's end means chassisd is gone, and so is this process.
//! Standard output carries `ready` once clients can connect, then a `stats` line of the
//! gate's counters every few seconds.

use std::collections::HashMap;
use std::io::{BufRead, Write};
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, TcpListener as StdListener};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::runtime::error::{RuntimeError, invalid, io};
use rumqttd::{Broker, Config, ConnectionSettings, RouterConfig, ServerSettings};
use serde::{Deserialize, Serialize};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use super::gate::{Gate, GateSettings, Upstreams};
use crate::broker::admission::{Credentials, Policy};
use crate::broker::wire;

/// Size of one memory segment of a filter's log, as rumqttd counts it: payload and topic
/// bytes (a larger message still fits whole). Each stored message also costs rumqttd about
/// 300 bytes it does not count, so a filter of small messages (a 5 Hz heartbeat of 60
/// bytes) holds several times its counted size, and at 4 × 64 KiB took 26 minutes to fill:
/// the soak saw that as memory still climbing after half an hour. 8 KiB holds about 1.5 s
/// of base_status; a subscriber that falls behind also has rumqttd's 200-message outgoing
/// queue, about 20 s of base_status.
pub const SEGMENT_BYTES: usize = 8 << 10;
/// Segments kept per filter, the one being filled included.
pub const SEGMENTS: usize = 2;
/// How often the probe asks the broker for a PINGRESP.
const PROBE_EVERY: Duration = Duration::from_millis(250);
/// A PINGRESP later than this means the broker is stuck: the process ends so that chassisd
/// starts a working one (together with [`PROBE_EVERY`], a hang is noticed within a second).
const PROBE_TIMEOUT: Duration = Duration::from_millis(700);
/// How long rumqttd may take to listen.
const START_TIMEOUT: Duration = Duration::from_secs(5);
/// How often the counters go to chassisd and, when they changed, to the log.
pub const STATS_EVERY: Duration = Duration::from_secs(5);
/// The longest settings line read.
const MAX_SETTINGS: usize = 64 << 10;
/// Exit status when the broker stopped answering (a panic exits with 101, as Rust does).
pub const EXIT_UNRESPONSIVE: i32 = 75;

/// What chassisd tells the broker process.
#[derive(Clone, Serialize, Deserialize)]
pub struct ChildSettings {
    /// Where clients connect.
    pub listen: SocketAddr,
    /// Clients at once, chassisd's own not counted.
    pub max_clients: usize,
    /// The largest packet a client may send, bytes.
    pub max_packet: usize,
    /// Required of every client when set: (user name, password).
    pub credentials: Option<(String, String)>,
    /// chassisd's own client identifier, which always finds a place.
    pub own_client_id: Option<String>,
    /// Identifiers refused to every other client.
    pub reserved_client_ids: Vec<String>,
    /// TLS on the listener.
    pub tls: Option<super::tls::ServerTls>,
    /// chassisd's own topics, always served whatever others invented.
    pub reserved_topics: Vec<String>,
}

impl std::fmt::Debug for ChildSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChildSettings")
            .field("listen", &self.listen)
            .field("max_clients", &self.max_clients)
            .field("credentials", &self.credentials.as_ref().map(|c| &c.0))
            .finish_non_exhaustive()
    }
}

/// One line on standard output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum ChildReport {
    /// Clients can connect.
    Ready,
    /// The gate's counters since the process started, and the clients connected now.
    Stats {
        connected: usize,
        counters: HashMap<String, u64>,
    },
}

/// The process's whole life; returns only on error (its end is an exit).
pub fn main() -> Result<(), RuntimeError> {
    // A panic anywhere in here (rumqttd's router included) leaves the broker half-dead:
    // end the process, so chassisd notices and starts a whole one.
    crate::runtime::child_process::end_on_panic("broker");
    let mut stdin = std::io::stdin().lock();
    let mut line = String::new();
    std::io::Read::take(&mut stdin, MAX_SETTINGS as u64)
        .read_line(&mut line)
        .map_err(io("reading the broker's settings"))?;
    let settings: ChildSettings =
        serde_json::from_str(&line).map_err(invalid("the broker's settings are not valid JSON"))?;
    let upstream = start_rumqttd(settings.max_clients, settings.max_packet)?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(io("the broker's runtime"))?;
    let gate = runtime.block_on(open_gate(&settings, upstream))?;
    let probe_id = format!("chassisd-probe-{:016x}", crate::secret::unguessable());
    runtime.spawn(probe(upstream.v4, probe_id));
    runtime.spawn(report_stats(gate.clone()));
    say(&ChildReport::Ready);
    tracing::info!(addr = %settings.listen, tls = settings.tls.is_some(),
        credentials = settings.credentials.is_some(), max_clients = settings.max_clients,
        "embedded MQTT broker listening");
    // chassisd holds the other end: its end (exit, crash, kill) is this process's end.
    drop(stdin);
    runtime.block_on(async {
        let _ = tokio::task::spawn_blocking(|| {
            let _ = std::io::copy(&mut std::io::stdin(), &mut std::io::sink());
        })
        .await;
    });
    std::process::exit(0);
}

/// Writes one report line to chassisd.
fn say(report: &ChildReport) {
    if let Ok(line) = serde_json::to_string(report) {
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "{line}");
        let _ = out.flush();
    }
}

/// A loopback port free now, for one of rumqttd's listeners.
fn free_loopback_port() -> Result<SocketAddr, RuntimeError> {
    let port = StdListener::bind(SocketAddrV4::new(Ipv4Addr::LOCALHOST, 0))
        .and_then(|l| l.local_addr())
        .map_err(io("finding a loopback port for the broker"))?
        .port();
    Ok(SocketAddr::from((Ipv4Addr::LOCALHOST, port)))
}

/// Starts rumqttd with an MQTT 3.1.1 and an MQTT 5 listener on free loopback ports, and
/// returns their addresses once both answer.
fn start_rumqttd(max_clients: usize, max_packet: usize) -> Result<Upstreams, RuntimeError> {
    let upstreams = Upstreams {
        v4: free_loopback_port()?,
        v5: free_loopback_port()?,
    };
    let server = |listen| ServerSettings {
        name: "chassisd".into(),
        listen,
        tls: None,
        next_connection_delay_ms: 0,
        connections: ConnectionSettings {
            connection_timeout_ms: 5_000,
            max_payload_size: max_packet,
            max_inflight_count: 100,
            auth: None,
            external_auth: None,
            dynamic_filters: true,
        },
    };
    let config = Config {
        id: 0,
        router: RouterConfig {
            // Well above the gate's limit: rumqttd frees a place only once its router has
            // seen the old connection go, which can lag a quick reconnect.
            max_connections: 2 * max_clients + 16,
            max_outgoing_packet_count: 200,
            max_segment_size: SEGMENT_BYTES,
            max_segment_count: SEGMENTS,
            custom_segment: None,
            initialized_filters: None,
            shared_subscriptions_strategy: Default::default(),
        },
        v4: Some(HashMap::from([("v4".to_owned(), server(upstreams.v4))])),
        v5: Some(HashMap::from([("v5".to_owned(), server(upstreams.v5))])),
        ..Default::default()
    };
    std::thread::Builder::new()
        .name("rumqttd".into())
        .spawn(move || {
            let mut broker = Broker::new(config);
            if let Err(e) = broker.start() {
                tracing::error!(error = %e, "embedded broker: rumqttd stopped");
            }
            // rumqttd only returns on failure: without it this process has no purpose.
            std::process::exit(1);
        })
        .map_err(io("starting rumqttd's thread"))?;
    let deadline = Instant::now() + START_TIMEOUT;
    for addr in [upstreams.v4, upstreams.v5] {
        while std::net::TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_err() {
            if Instant::now() > deadline {
                return Err(RuntimeError::Failed(format!(
                    "rumqttd is not listening on {addr} after {START_TIMEOUT:?}"
                )));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
    Ok(upstreams)
}

/// Opens the clients' listener with the gate on it.
async fn open_gate(
    settings: &ChildSettings,
    upstream: Upstreams,
) -> Result<Arc<Gate>, RuntimeError> {
    let listener = tokio::net::TcpListener::bind(settings.listen)
        .await
        .map_err(io(format!(
            "embedded broker: cannot listen on {} (another broker running there?)",
            settings.listen
        )))?;
    let tls = settings
        .tls
        .as_ref()
        .map(super::tls::ServerTls::acceptor)
        .transpose()?;
    let gate = Gate::new(
        GateSettings {
            policy: Policy {
                credentials: settings
                    .credentials
                    .clone()
                    .map(|(username, password)| Credentials { username, password }),
                max_clients: settings.max_clients,
                own_client_id: settings.own_client_id.clone(),
                reserved_client_ids: settings.reserved_client_ids.clone(),
            },
            upstream,
            max_packet: settings.max_packet,
            reserved_topics: settings.reserved_topics.clone(),
        },
        tls,
    );
    tokio::spawn(gate.clone().serve(listener));
    Ok(gate)
}

/// Asks rumqttd for a PINGRESP every [`PROBE_EVERY`] over a connection of its own; ends the
/// process when one is late or the connection is lost.
async fn probe(upstream: SocketAddr, client_id: String) {
    let fail = |why: &str| -> ! {
        tracing::error!("embedded broker: {why}; the broker process ends and chassisd restarts it");
        std::process::exit(EXIT_UNRESPONSIVE);
    };
    let connected = tokio::time::timeout(START_TIMEOUT, async {
        let mut s = TcpStream::connect(upstream).await?;
        s.set_nodelay(true)?;
        s.write_all(&wire::plain_connect(&client_id, 60)).await?;
        let mut ack = [0u8; 4];
        s.read_exact(&mut ack).await?;
        Ok::<_, std::io::Error>((s, ack))
    })
    .await;
    let mut stream = match connected {
        Ok(Ok((s, ack))) if wire::connack_accepts(&ack) => s,
        _ => fail("the broker refused its own probe"),
    };
    let mut every = tokio::time::interval(PROBE_EVERY);
    let mut answer = [0u8; 2];
    loop {
        every.tick().await;
        let round = tokio::time::timeout(PROBE_TIMEOUT, async {
            stream.write_all(&[0xc0, 0x00]).await?;
            stream.read_exact(&mut answer).await
        })
        .await;
        match round {
            Ok(Ok(_)) if answer == [0xd0, 0x00] => {}
            Ok(Ok(_)) => fail("the broker answered its probe with something other than PINGRESP"),
            Ok(Err(_)) => fail("the broker closed its probe's connection"),
            Err(_) => fail("the broker did not answer its probe within 0.7 s"),
        }
    }
}

/// Sends the counters to chassisd every [`STATS_EVERY`], and logs what changed: one summary
/// line for every refusal and closing of the period, never one per client.
async fn report_stats(gate: Arc<Gate>) {
    let mut every = tokio::time::interval(STATS_EVERY);
    let mut before = gate.counters.snapshot();
    loop {
        every.tick().await;
        let now = gate.counters.snapshot();
        let connected = gate.connected();
        let holdings = gate.holdings();
        let mut counters: HashMap<String, u64> =
            now.iter().map(|(k, v)| ((*k).to_owned(), *v)).collect();
        counters.extend(holdings.iter().map(|(k, v)| ((*k).to_owned(), *v)));
        say(&ChildReport::Stats {
            connected,
            counters,
        });
        let changes: Vec<String> = now
            .iter()
            .zip(&before)
            .skip(1)
            .filter(|(n, b)| n.1 > b.1)
            .map(|(n, b)| format!("{}={}", n.0, n.1 - b.1))
            .collect();
        if !changes.is_empty() {
            let last = gate.last_refused();
            let held = holdings
                .iter()
                .map(|(k, v)| format!("{k}={v}"))
                .collect::<Vec<_>>()
                .join(" ");
            tracing::warn!(
                connected,
                admitted = now[0].1 - before[0].1,
                refused = %changes.join(" "),
                held = %held,
                last_peer = ?last.map(|l| l.0),
                last_reason = last.map_or("", |l| l.1),
                "embedded broker: connections refused or closed in the last {} s",
                STATS_EVERY.as_secs()
            );
        }
        before = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_probes_connect_is_one_the_gate_would_read() {
        let packet = wire::plain_connect("chassisd-probe-0123456789abcdef", 60);
        let h = wire::header(&packet, 1 << 16).unwrap().unwrap();
        assert_eq!(h.total(), packet.len());
        let c = wire::connect(&packet[h.header_len..]).unwrap();
        assert_eq!(c.client_id, "chassisd-probe-0123456789abcdef");
        assert_eq!(c.keep_alive_s, 60);
    }

    #[test]
    fn the_password_never_reaches_debug_output() {
        let s = ChildSettings {
            listen: "127.0.0.1:1883".parse().unwrap(),
            max_clients: 8,
            max_packet: 1 << 20,
            credentials: Some(("op".into(), "hunter2".into())),
            own_client_id: None,
            reserved_client_ids: Vec::new(),
            tls: None,
            reserved_topics: Vec::new(),
        };
        assert!(!format!("{s:?}").contains("hunter2"));
    }
}
