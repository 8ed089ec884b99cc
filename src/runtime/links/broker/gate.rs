//! The gate in front of the embedded broker: every client connects here, not to rumqttd.
//! A client is admitted only after a well-formed CONNECT with the configured credentials
//! and a free place; every packet it sends afterwards is framed, bounded and checked to be
//! a client's before it reaches the broker. Refusals are answered with mosquitto's CONNACK
//! codes and summarised in the log every few seconds, never once per client.
//!
//! What rumqttd 0.20 cannot survive is kept from it here: a client beyond its connection
//! limit, an identifier it cannot route (both leave a stale last-will entry that panics
//! the next connection under that identifier and poisons the broker for good), and a client
//! that hangs up before its CONNACK (the same entry, through a failed write). The gate
//! waits for the broker's CONNACK whatever the client does, and however late: a client is
//! let go after 5 s, but the broker's socket stays open for its answer (up to 60 s, 16 such
//! at once), and the session it accepted is then ended cleanly.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::BytesMut;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Semaphore;
use tokio_rustls::TlsAcceptor;

use super::identifiers::{Identifiers, Turn};
use super::relay::{Ended, Relay};
use crate::broker::admission::{self, Place, Places, Policy};
use crate::broker::held::{self, Held};
use crate::broker::session;
use crate::broker::wire::{self, Connect, Header, Refusal, WireError};

/// A client must have sent its whole CONNECT (and finished TLS) within this long.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);
/// The broker must answer a forwarded CONNECT within this long.
const UPSTREAM_TIMEOUT: Duration = Duration::from_secs(5);
/// How long a CONNACK the broker owes is still waited for once the client has been let go.
const LATE_CONNACK_WAIT: Duration = Duration::from_secs(60);
/// Forwarded CONNECTs waited for at once after their client was let go; beyond it the
/// socket is closed at once (a broker that slow is restarted by its supervisor anyway).
const MAX_LATE_CONNACKS: usize = 16;
/// Connections still in their handshake at once. Beyond it a new connection is closed at
/// once, so a flood of silent sockets costs a bounded amount of memory.
pub const MAX_HANDSHAKES: usize = 64;
/// The largest CONNECT read, bytes: a will's payload is the only large field.
const MAX_CONNECT: usize = 64 << 10;
/// A client with a keep-alive of k seconds is dropped after 1.5 k of silence (MQTT 3.1.1
/// section 3.1.2.10).
const KEEP_ALIVE_GRACE: f64 = 1.5;

/// The gate's settings.
#[derive(Debug, Clone)]
pub struct GateSettings {
    /// Who is let in.
    pub policy: Policy,
    /// The broker behind the gate (loopback).
    pub upstream: Upstreams,
    /// The largest packet a client may send, bytes.
    pub max_packet: usize,
    /// chassisd's own topics, always served whatever others invented.
    pub reserved_topics: Vec<String>,
}

/// rumqttd's listeners, one per protocol version (each speaks only its own).
#[derive(Debug, Clone, Copy)]
pub struct Upstreams {
    /// MQTT 3.1.1.
    pub v4: SocketAddr,
    /// MQTT 5.
    pub v5: SocketAddr,
}

/// What the gate saw, for the summary, the supervisor and `check`.
#[derive(Debug, Default)]
pub struct GateCounters {
    /// Clients admitted since start.
    pub admitted: AtomicU64,
    /// Refused for a wrong or missing user name or password.
    pub refused_credentials: AtomicU64,
    /// Refused at the client limit.
    pub refused_full: AtomicU64,
    /// Refused for a protocol version or client identifier.
    pub refused_protocol: AtomicU64,
    /// Closed for a malformed or forbidden packet.
    pub malformed: AtomicU64,
    /// Closed for not finishing the handshake in time, or for too many at once.
    pub handshake_dropped: AtomicU64,
    /// Closed for keep-alive silence or a client that stopped reading.
    pub idle_closed: AtomicU64,
    /// Refused for presenting chassisd's identifier (or a reserved one), or a last will on
    /// chassisd's own topics.
    pub refused_reserved: AtomicU64,
    /// Closed for making the broker hold more than its budget (topic names, retained
    /// messages, messages in flight).
    pub over_budget: AtomicU64,
    /// Admitted by the gate but not by the broker behind it.
    pub upstream_failed: AtomicU64,
}

impl GateCounters {
    /// The counters as (name, value) pairs, in a fixed order: `admitted` first, then every
    /// kind of refusal or closing.
    pub fn snapshot(&self) -> [(&'static str, u64); 10] {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        [
            ("admitted", get(&self.admitted)),
            ("refused_credentials", get(&self.refused_credentials)),
            ("refused_full", get(&self.refused_full)),
            ("refused_protocol", get(&self.refused_protocol)),
            ("refused_reserved", get(&self.refused_reserved)),
            ("malformed", get(&self.malformed)),
            ("over_budget", get(&self.over_budget)),
            ("handshake_dropped", get(&self.handshake_dropped)),
            ("idle_closed", get(&self.idle_closed)),
            ("upstream_failed", get(&self.upstream_failed)),
        ]
    }

    fn refused(&self, why: Refusal) {
        let counter = match why {
            Refusal::BadCredentials | Refusal::NotAuthorized => &self.refused_credentials,
            Refusal::ServerUnavailable => &self.refused_full,
            Refusal::UnacceptableVersion | Refusal::IdentifierRejected => &self.refused_protocol,
            Refusal::ReservedIdentifier | Refusal::ReservedWill => &self.refused_reserved,
            Refusal::QuotaExceeded => &self.over_budget,
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

/// The gate: its settings, the places taken and its counters.
pub struct Gate {
    settings: GateSettings,
    tls: Option<TlsAcceptor>,
    places: Mutex<Places>,
    identifiers: Arc<Identifiers>,
    held: Mutex<Held>,
    handshakes: Arc<Semaphore>,
    /// Forwarded CONNECTs whose CONNACK is still awaited after their client was let go.
    late_connacks: Arc<Semaphore>,
    /// What the gate saw.
    pub counters: GateCounters,
    /// The last refused peer and why, for the summary.
    last_refused: Mutex<Option<(SocketAddr, &'static str)>>,
    /// Accepts that failed (out of descriptors).
    accept_failures: AtomicU64,
}

impl Gate {
    /// A gate with `settings`, serving TLS when `tls` is given.
    pub fn new(settings: GateSettings, tls: Option<TlsAcceptor>) -> Arc<Self> {
        let held = Held::new(
            settings.reserved_topics.iter().cloned(),
            settings.max_packet,
        );
        Arc::new(Self {
            settings,
            tls,
            places: Mutex::new(Places::default()),
            identifiers: Arc::new(Identifiers::default()),
            held: Mutex::new(held),
            handshakes: Arc::new(Semaphore::new(MAX_HANDSHAKES)),
            late_connacks: Arc::new(Semaphore::new(MAX_LATE_CONNACKS)),
            counters: GateCounters::default(),
            last_refused: Mutex::new(None),
            accept_failures: AtomicU64::new(0),
        })
    }

    /// Clients connected now (chassisd's own included).
    pub fn connected(&self) -> usize {
        let places = self.places();
        places.clients + places.own
    }

    /// The last refused peer and why.
    pub fn last_refused(&self) -> Option<(SocketAddr, &'static str)> {
        *self
            .last_refused
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn places(&self) -> std::sync::MutexGuard<'_, Places> {
        lock(&self.places)
    }

    /// What the broker holds: topic and filter names, retained messages and their bytes,
    /// bytes of unreleased QoS 2 messages.
    pub fn holdings(&self) -> [(&'static str, u64); 4] {
        let held = lock(&self.held);
        [
            ("topic_names", held.names.len() as u64),
            ("retained", held.retained.len() as u64),
            ("retained_bytes", held.retained.bytes() as u64),
            ("in_flight_bytes", held.in_flight_bytes as u64),
        ]
    }

    /// Accepts connections on `listener` for ever.
    pub async fn serve(self: Arc<Self>, listener: TcpListener) {
        loop {
            let (socket, peer) = match listener.accept().await {
                Ok(accepted) => accepted,
                Err(e) => {
                    // Out of descriptors, most likely: wait rather than spin, and say so at
                    // the 1st, 2nd, 4th... failure, not at each.
                    let n = self.accept_failures.fetch_add(1, Ordering::Relaxed) + 1;
                    if n.is_power_of_two() {
                        tracing::warn!(error = %e, failures = n, "embedded broker: accept failed");
                    }
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            };
            // A descriptor of the process's client budget, then a handshake place.
            let (Some(descriptor), Ok(permit)) = (
                crate::runtime::descriptors::try_acquire(),
                self.handshakes.clone().try_acquire_owned(),
            ) else {
                self.counters
                    .handshake_dropped
                    .fetch_add(1, Ordering::Relaxed);
                drop(socket);
                continue;
            };
            let gate = self.clone();
            tokio::spawn(async move {
                gate.connection(socket, peer, permit).await;
                drop(descriptor);
            });
        }
    }

    async fn connection(
        self: Arc<Self>,
        socket: TcpStream,
        peer: SocketAddr,
        permit: tokio::sync::OwnedSemaphorePermit,
    ) {
        tune(&socket);
        match self.tls.clone() {
            Some(acceptor) => {
                match tokio::time::timeout(HANDSHAKE_TIMEOUT, acceptor.accept(socket)).await {
                    Ok(Ok(stream)) => self.client(stream, peer, permit).await,
                    Ok(Err(e)) => {
                        tracing::debug!(%peer, error = %e, "embedded broker: TLS handshake failed");
                        self.counters
                            .handshake_dropped
                            .fetch_add(1, Ordering::Relaxed);
                        self.note_refused(peer, "TLS handshake failed");
                    }
                    Err(_) => {
                        self.counters
                            .handshake_dropped
                            .fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            None => self.client(socket, peer, permit).await,
        }
    }

    fn note_refused(&self, peer: SocketAddr, why: &'static str) {
        *self
            .last_refused
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = Some((peer, why));
    }

    async fn client<S: AsyncRead + AsyncWrite + Unpin>(
        self: Arc<Self>,
        mut stream: S,
        peer: SocketAddr,
        permit: tokio::sync::OwnedSemaphorePermit,
    ) {
        let mut buf = BytesMut::with_capacity(1024);
        let connect = match tokio::time::timeout(
            HANDSHAKE_TIMEOUT,
            read_connect(&mut stream, &mut buf),
        )
        .await
        {
            Ok(Ok(Some(c))) => c,
            Ok(Ok(None)) => return,
            Ok(Err(e)) => {
                tracing::debug!(%peer, error = %e, "embedded broker: bad CONNECT");
                self.counters.malformed.fetch_add(1, Ordering::Relaxed);
                self.note_refused(peer, "malformed CONNECT");
                return;
            }
            Err(_) => {
                self.counters
                    .handshake_dropped
                    .fetch_add(1, Ordering::Relaxed);
                return;
            }
        };
        let (connect, header) = connect;
        // The places' lock is let go before the will is judged (which may give the place
        // back): held across both, the gate's one thread would wait for itself.
        let admitted = admission::admit(&self.settings.policy, &mut self.places(), &connect);
        let admitted = admitted.and_then(|place| match self.judge_will(&connect, place) {
            Ok(()) => Ok(place),
            Err(why) => {
                self.places().leave(place);
                Err(why)
            }
        });
        let place = match admitted {
            Ok(place) => place,
            Err(why) => {
                self.counters.refused(why);
                self.note_refused(peer, why.name());
                self.refuse(&mut stream, connect.version, why).await;
                return;
            }
        };
        // The handshake is over: the place, not the permit, now bounds this client.
        drop(permit);
        let _leave = Leave { gate: &self, place };
        // One session per identifier: a newer one takes over once the broker let the older
        // one go. An empty identifier is the broker's to assign, unique each time.
        let turn = if connect.client_id.is_empty() {
            None
        } else {
            match self.identifiers.take_turn(&connect.client_id).await {
                Some(turn) => Some(turn),
                None => {
                    self.counters.refused(Refusal::ServerUnavailable);
                    self.note_refused(peer, "identifier still in use");
                    self.refuse(&mut stream, connect.version, Refusal::ServerUnavailable)
                        .await;
                    return;
                }
            }
        };
        self.counters.admitted.fetch_add(1, Ordering::Relaxed);
        let mut connect_bytes = buf.split_to(header.total());
        wire::force_clean_session(&mut connect_bytes, &header);
        if connect.keep_alive_s == 0 {
            wire::set_keep_alive(&mut connect_bytes, &header, wire::NO_KEEP_ALIVE_UPSTREAM);
        }
        let upstream = match connect.version {
            wire::Version::V5 => self.settings.upstream.v5,
            _ => self.settings.upstream.v4,
        };
        let upstream = match self
            .open_upstream(upstream, &connect_bytes, connect.version, &mut stream)
            .await
        {
            Upstream::Open(upstream) => upstream,
            Upstream::Closed => return,
            Upstream::Late(upstream, ack) => {
                // The identifier stays taken until the broker has let this session go.
                self.end_when_answered(upstream, ack, turn);
                return;
            }
        };
        let relay = Relay {
            version: connect.version,
            // chassisd's own link publishes its reports under names of its own choosing.
            trusted: place == Place::Own,
            max_packet: self.settings.max_packet,
            keep_alive: (connect.keep_alive_s > 0).then(|| {
                Duration::from_secs_f64(f64::from(connect.keep_alive_s) * KEEP_ALIVE_GRACE)
            }),
            max_packet_to_client: connect.max_packet_to_client,
            held: &self.held,
        };
        match relay.run(stream, buf, upstream, turn.as_ref()).await {
            Ended::Violation(v @ session::Violation::OverBudget(_)) => {
                self.counters.over_budget.fetch_add(1, Ordering::Relaxed);
                self.note_refused(peer, "over the broker's budget");
                tracing::debug!(%peer, client = %connect.client_id, violation = %v, "embedded broker: session ended");
            }
            Ended::Violation(v) => {
                self.counters.malformed.fetch_add(1, Ordering::Relaxed);
                self.note_refused(peer, "protocol violation");
                tracing::debug!(%peer, client = %connect.client_id, violation = %v, "embedded broker: session ended");
            }
            Ended::Idle | Ended::Stalled => {
                self.counters.idle_closed.fetch_add(1, Ordering::Relaxed);
            }
            Ended::ClientClosed
            | Ended::ClientDisconnected
            | Ended::BrokerClosed
            | Ended::TakenOver => {}
        }
    }

    /// Whether a CONNECT's last will may be kept: its topic is one the broker serves, not
    /// one of chassisd's own (a will is no command, nor a report of the vehicle's), and a
    /// name the broker may hold.
    fn judge_will(&self, connect: &Connect, place: Place) -> Result<(), Refusal> {
        let Some(topic) = connect.will_topic.as_deref() else {
            return Ok(());
        };
        let mut held = lock(&self.held);
        if place != Place::Own && held.names.is_reserved(topic) {
            return Err(Refusal::ReservedWill);
        }
        if place != Place::Own
            && connect
                .retained_will
                .is_some_and(|len| len > held::MAX_RETAINED_WILL)
        {
            return Err(Refusal::QuotaExceeded);
        }
        let admitted = session::valid_topic(topic)
            && topic.len() <= held::MAX_TOPIC_BYTES
            && held.names.admit(topic).is_ok();
        if admitted {
            Ok(())
        } else {
            Err(Refusal::ServerUnavailable)
        }
    }

    /// Answers a CONNECT with a refusal in the client's version, and closes.
    async fn refuse<S: AsyncWrite + Unpin>(
        &self,
        stream: &mut S,
        version: wire::Version,
        why: Refusal,
    ) {
        let refusal = wire::connack_refusal(version, why);
        let _ = tokio::time::timeout(HANDSHAKE_TIMEOUT, async {
            stream.write_all(&refusal).await?;
            stream.shutdown().await
        })
        .await;
    }

    /// Forwards the CONNECT to the broker and its CONNACK to the client. The CONNACK is
    /// awaited whatever the client does; a client gone by then is disconnected from the
    /// broker cleanly. A broker slower than [`UPSTREAM_TIMEOUT`] loses the client, but its
    /// socket stays open ([`Upstream::Late`]): rumqttd 0.20 writes its CONNACK however late,
    /// and a write to a closed socket leaves a stale last-will entry that panics the next
    /// connection under the same identifier.
    async fn open_upstream<S: AsyncWrite + Unpin>(
        &self,
        upstream: SocketAddr,
        connect: &[u8],
        version: wire::Version,
        client: &mut S,
    ) -> Upstream {
        let forward = async {
            let mut upstream = TcpStream::connect(upstream).await?;
            upstream.set_nodelay(true)?;
            upstream.write_all(connect).await?;
            Ok::<_, std::io::Error>(upstream)
        };
        let mut upstream = match tokio::time::timeout(UPSTREAM_TIMEOUT, forward).await {
            Ok(Ok(upstream)) => upstream,
            Ok(Err(e)) => {
                self.upstream_failed(&e.to_string());
                return Upstream::Closed;
            }
            Err(_) => {
                self.upstream_failed("it did not take the connection in time");
                return Upstream::Closed;
            }
        };
        let mut ack = BytesMut::with_capacity(64);
        let header =
            match tokio::time::timeout(UPSTREAM_TIMEOUT, read_connack(&mut upstream, &mut ack))
                .await
            {
                Ok(Ok(header)) => header,
                Ok(Err(e)) => {
                    self.upstream_failed(&e.to_string());
                    return Upstream::Closed;
                }
                Err(_) => {
                    self.upstream_failed("it did not answer the CONNECT in time");
                    return Upstream::Late(upstream, ack);
                }
            };
        let accepted = header.kind == wire::kind::CONNACK && wire::connack_accepts(&ack);
        // A 5.0 client is told the gate's limits, which it would otherwise learn by being
        // disconnected.
        let ack = match version {
            wire::Version::V5 if accepted => wire::connack_v5_with_limits(
                &ack[..header.total()],
                held::MAX_IN_FLIGHT,
                self.settings.max_packet,
            )
            .map_or(ack.clone(), |rewritten| {
                let mut whole = BytesMut::from(&rewritten[..]);
                whole.extend_from_slice(&ack[header.total()..]);
                whole
            }),
            _ => ack,
        };
        let delivered = tokio::time::timeout(HANDSHAKE_TIMEOUT, client.write_all(&ack))
            .await
            .is_ok_and(|r| r.is_ok());
        if !delivered {
            if accepted {
                // The broker ends the session itself, with no will.
                disconnect(&mut upstream).await;
            }
            return Upstream::Closed;
        }
        if accepted {
            Upstream::Open(upstream)
        } else {
            Upstream::Closed
        }
    }

    /// Counts a forwarded connection the broker did not take, for the summary: one line per
    /// client would let a client flood the log.
    fn upstream_failed(&self, why: &str) {
        tracing::debug!(%why, "embedded broker: the broker did not take a forwarded connection");
        self.counters
            .upstream_failed
            .fetch_add(1, Ordering::Relaxed);
    }

    /// Waits (in the background, at most [`LATE_CONNACK_WAIT`]) for the CONNACK of a
    /// session whose client was let go, then ends that session cleanly; `turn` keeps its
    /// identifier until then. With [`MAX_LATE_CONNACKS`] already waiting, closes at once.
    fn end_when_answered(&self, mut upstream: TcpStream, mut ack: BytesMut, turn: Option<Turn>) {
        let Ok(permit) = self.late_connacks.clone().try_acquire_owned() else {
            return;
        };
        tokio::spawn(async move {
            let answered =
                tokio::time::timeout(LATE_CONNACK_WAIT, read_connack(&mut upstream, &mut ack))
                    .await;
            if let Ok(Ok(header)) = answered
                && header.kind == wire::kind::CONNACK
                && wire::connack_accepts(&ack)
            {
                disconnect(&mut upstream).await;
            }
            drop((turn, permit));
        });
    }
}

/// What became of a forwarded CONNECT.
enum Upstream {
    /// The broker accepted it and the client has its CONNACK: the session goes on.
    Open(TcpStream),
    /// The session does not go on, and nothing is owed.
    Closed,
    /// The broker did not answer in time: the client is let go, and the broker's CONNACK,
    /// when it comes, ends the session (what was read of it so far kept).
    Late(TcpStream, BytesMut),
}

/// Reads the broker's answer to a CONNECT into `ack`: its header once whole.
async fn read_connack(upstream: &mut TcpStream, ack: &mut BytesMut) -> std::io::Result<Header> {
    loop {
        match wire::header(ack, MAX_CONNECT) {
            Ok(Some(h)) if ack.len() >= h.total() => return Ok(h),
            Ok(_) => {}
            Err(e) => return Err(std::io::Error::other(e)),
        }
        if upstream.read_buf(ack).await? == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
    }
}

/// Ends an accepted session from the client's side: the broker ends it itself, with no
/// will, and the socket is drained until it closes (at most [`UPSTREAM_TIMEOUT`]).
async fn disconnect(upstream: &mut TcpStream) {
    let _ = upstream.write_all(&wire::DISCONNECT).await;
    let mut sink = [0u8; 1024];
    let _ = tokio::time::timeout(UPSTREAM_TIMEOUT, async {
        while upstream.read(&mut sink).await.is_ok_and(|n| n > 0) {}
    })
    .await;
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // Plain counters and sets: a panic elsewhere cannot leave them half-written.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Gives a client's place back when its connection ends, however it ends.
struct Leave<'a> {
    gate: &'a Gate,
    place: Place,
}

impl Drop for Leave<'_> {
    fn drop(&mut self) {
        self.gate.places().leave(self.place);
    }
}

/// No Nagle delay on small packets; keepalive probes find peers that vanished.
fn tune(socket: &TcpStream) {
    let _ = socket.set_nodelay(true);
    let keepalive = socket2::TcpKeepalive::new()
        .with_time(Duration::from_secs(60))
        .with_interval(Duration::from_secs(10))
        .with_retries(6);
    let _ = socket2::SockRef::from(socket).set_tcp_keepalive(&keepalive);
}

/// Reads the first packet, which must be a CONNECT. Returns it and its fixed header;
/// `None` when the client left first.
async fn read_connect<S: AsyncRead + Unpin>(
    stream: &mut S,
    buf: &mut BytesMut,
) -> Result<Option<(Connect, Header)>, ReadError> {
    loop {
        if let Some(h) = wire::header(buf, MAX_CONNECT)? {
            if h.kind != wire::kind::CONNECT {
                return Err(WireError::NotConnect(h.kind).into());
            }
            if buf.len() >= h.total() {
                let connect = wire::connect(&buf[h.header_len..h.total()])?;
                return Ok(Some((connect, h)));
            }
        }
        if stream.read_buf(buf).await? == 0 {
            return Ok(None);
        }
    }
}

/// A CONNECT that could not be read.
#[derive(Debug, thiserror::Error)]
enum ReadError {
    #[error("{0}")]
    Wire(#[from] WireError),
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An MQTT 3.1.1 CONNECT of `client_id`, clean session, keep-alive 60 s.
    fn connect(client_id: &str) -> Vec<u8> {
        let mut body = vec![0, 4, b'M', b'Q', b'T', b'T', 4, 0x02, 0, 60];
        body.extend_from_slice(&(client_id.len() as u16).to_be_bytes());
        body.extend_from_slice(client_id.as_bytes());
        let mut packet = vec![0x10, body.len() as u8];
        packet.extend(body);
        packet
    }

    /// A broker slower than the gate's patience still finds its socket open when it answers
    /// (rumqttd 0.20's failed CONNACK write would leave a last-will entry that panics the
    /// next connection under the identifier), and the session it accepted is then ended.
    #[tokio::test]
    async fn a_connack_later_than_the_timeout_is_still_read_and_the_session_ended() {
        let slow_broker = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let upstream = slow_broker.local_addr().expect("address");
        let broker = tokio::spawn(async move {
            let (mut s, _) = slow_broker.accept().await.expect("the gate forwards");
            let mut connect = [0u8; 256];
            let _ = s.read(&mut connect).await;
            tokio::time::sleep(UPSTREAM_TIMEOUT + Duration::from_millis(500)).await;
            s.write_all(&[0x20, 0x02, 0x00, 0x00]).await.expect("write");
            let mut rest = Vec::new();
            let _ = s.read_to_end(&mut rest).await;
            rest
        });
        let settings = GateSettings {
            policy: Policy {
                credentials: None,
                max_clients: 4,
                own_client_id: None,
                reserved_client_ids: Vec::new(),
            },
            upstream: Upstreams {
                v4: upstream,
                v5: upstream,
            },
            max_packet: 1 << 16,
            reserved_topics: Vec::new(),
        };
        let front = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let address = front.local_addr().expect("address");
        tokio::spawn(Gate::new(settings, None).serve(front));
        let mut client = TcpStream::connect(address).await.expect("connect");
        client.write_all(&connect("late-1")).await.expect("write");
        let mut answer = Vec::new();
        let _ = tokio::time::timeout(Duration::from_secs(10), client.read_to_end(&mut answer))
            .await
            .expect("the client is let go");
        assert!(answer.is_empty(), "{answer:?}");
        let rest = tokio::time::timeout(Duration::from_secs(10), broker)
            .await
            .expect("the broker's session ends")
            .expect("the broker task");
        assert_eq!(
            rest,
            wire::DISCONNECT,
            "the accepted session is ended cleanly"
        );
    }
}
