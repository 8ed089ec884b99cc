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
//! waits for the broker's CONNACK whatever the client does.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::{Buf, BytesMut};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Semaphore;
use tokio_rustls::TlsAcceptor;

use crate::broker::admission::{self, Place, Places, Policy};
use crate::broker::wire::{self, Connect, Refusal, WireError};

/// A client must have sent its whole CONNECT (and finished TLS) within this long.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);
/// The broker must answer a forwarded CONNECT within this long.
const UPSTREAM_TIMEOUT: Duration = Duration::from_secs(5);
/// A write to a client that makes no progress for this long ends the connection: the
/// client stopped reading, and the broker's queue for it should not wait for ever.
const WRITE_STALL: Duration = Duration::from_secs(30);
/// Connections still in their handshake at once. Beyond it a new connection is closed at
/// once, so a flood of silent sockets costs a bounded amount of memory.
pub const MAX_HANDSHAKES: usize = 64;
/// The largest CONNECT read, bytes: a will's payload is the only large field.
const MAX_CONNECT: usize = 64 << 10;
/// Bytes read from a socket at a time.
const READ_CHUNK: usize = 16 << 10;
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
}

impl GateCounters {
    /// The counters as (name, value) pairs, in a fixed order.
    pub fn snapshot(&self) -> [(&'static str, u64); 7] {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        [
            ("admitted", get(&self.admitted)),
            ("refused_credentials", get(&self.refused_credentials)),
            ("refused_full", get(&self.refused_full)),
            ("refused_protocol", get(&self.refused_protocol)),
            ("malformed", get(&self.malformed)),
            ("handshake_dropped", get(&self.handshake_dropped)),
            ("idle_closed", get(&self.idle_closed)),
        ]
    }

    fn refused(&self, why: Refusal) {
        let counter = match why {
            Refusal::BadCredentials | Refusal::NotAuthorized => &self.refused_credentials,
            Refusal::ServerUnavailable => &self.refused_full,
            Refusal::UnacceptableVersion | Refusal::IdentifierRejected => &self.refused_protocol,
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

/// The gate: its settings, the places taken and its counters.
pub struct Gate {
    settings: GateSettings,
    tls: Option<TlsAcceptor>,
    places: Mutex<Places>,
    handshakes: Arc<Semaphore>,
    /// What the gate saw.
    pub counters: GateCounters,
    /// The last refused peer and why, for the summary.
    last_refused: Mutex<Option<(SocketAddr, &'static str)>>,
}

impl Gate {
    /// A gate with `settings`, serving TLS when `tls` is given.
    pub fn new(settings: GateSettings, tls: Option<TlsAcceptor>) -> Arc<Self> {
        Arc::new(Self {
            settings,
            tls,
            places: Mutex::new(Places::default()),
            handshakes: Arc::new(Semaphore::new(MAX_HANDSHAKES)),
            counters: GateCounters::default(),
            last_refused: Mutex::new(None),
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
        // Places are plain counters: a panic elsewhere cannot leave them half-written.
        self.places
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Accepts connections on `listener` for ever.
    pub async fn serve(self: Arc<Self>, listener: TcpListener) {
        loop {
            let (socket, peer) = match listener.accept().await {
                Ok(accepted) => accepted,
                Err(e) => {
                    // Out of descriptors, most likely: wait rather than spin.
                    tracing::warn!(error = %e, "embedded broker: accept failed");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            };
            let Ok(permit) = self.handshakes.clone().try_acquire_owned() else {
                self.counters
                    .handshake_dropped
                    .fetch_add(1, Ordering::Relaxed);
                drop(socket);
                continue;
            };
            let gate = self.clone();
            tokio::spawn(async move {
                gate.connection(socket, peer, permit).await;
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
        let (connect, connect_len) = connect;
        let admitted = admission::admit(&self.settings.policy, &mut self.places(), &connect);
        let place = match admitted {
            Ok(place) => place,
            Err(why) => {
                self.counters.refused(why);
                self.note_refused(peer, why.name());
                let refusal = wire::connack_refusal(connect.version, why);
                let _ = tokio::time::timeout(HANDSHAKE_TIMEOUT, async {
                    stream.write_all(&refusal).await?;
                    stream.shutdown().await
                })
                .await;
                return;
            }
        };
        // The handshake is over: the place, not the permit, now bounds this client.
        drop(permit);
        self.counters.admitted.fetch_add(1, Ordering::Relaxed);
        let _leave = Leave { gate: &self, place };
        let connect_bytes = buf.split_to(connect_len);
        let upstream = match connect.version {
            wire::Version::V5 => self.settings.upstream.v5,
            _ => self.settings.upstream.v4,
        };
        let Some(upstream) = self
            .open_upstream(upstream, &connect_bytes, &mut stream)
            .await
        else {
            return;
        };
        let keep_alive = (connect.keep_alive_s > 0)
            .then(|| Duration::from_secs_f64(f64::from(connect.keep_alive_s) * KEEP_ALIVE_GRACE));
        relay(
            self.clone(),
            stream,
            buf,
            upstream,
            &connect,
            keep_alive,
            peer,
        )
        .await;
    }

    /// Forwards the CONNECT to the broker and its CONNACK to the client. The CONNACK is
    /// awaited whatever the client does; a client gone by then is disconnected from the
    /// broker cleanly. `None` when the session does not go on.
    async fn open_upstream<S: AsyncWrite + Unpin>(
        &self,
        upstream: SocketAddr,
        connect: &[u8],
        client: &mut S,
    ) -> Option<TcpStream> {
        let handshake = async {
            let mut upstream = TcpStream::connect(upstream).await?;
            upstream.set_nodelay(true)?;
            upstream.write_all(connect).await?;
            let mut ack = BytesMut::with_capacity(64);
            let header = loop {
                match wire::header(&ack, MAX_CONNECT) {
                    Ok(Some(h)) if ack.len() >= h.total() => break h,
                    Ok(_) => {}
                    Err(e) => return Err(std::io::Error::other(e)),
                }
                if upstream.read_buf(&mut ack).await? == 0 {
                    return Err(std::io::ErrorKind::UnexpectedEof.into());
                }
            };
            Ok::<_, std::io::Error>((upstream, ack, header))
        };
        let (mut upstream, ack, header) = match tokio::time::timeout(UPSTREAM_TIMEOUT, handshake)
            .await
        {
            Ok(Ok(done)) => done,
            Ok(Err(e)) => {
                tracing::warn!(error = %e, "embedded broker: the broker refused a forwarded connection");
                return None;
            }
            Err(_) => {
                tracing::warn!("embedded broker: the broker did not answer a CONNECT in time");
                return None;
            }
        };
        let accepted = header.kind == wire::kind::CONNACK && wire::connack_accepts(&ack);
        let delivered = tokio::time::timeout(HANDSHAKE_TIMEOUT, client.write_all(&ack))
            .await
            .is_ok_and(|r| r.is_ok());
        if !delivered {
            if accepted {
                let _ = upstream.write_all(&wire::DISCONNECT).await;
            }
            return None;
        }
        // Bytes after the CONNACK (a retained message already) go on in the relay.
        if ack.len() > header.total() {
            let rest = &ack[header.total()..];
            if client.write_all(rest).await.is_err() {
                let _ = upstream.write_all(&wire::DISCONNECT).await;
                return None;
            }
        }
        accepted.then_some(upstream)
    }
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

/// Reads the first packet, which must be a CONNECT. Returns it and its length in `buf`;
/// `None` when the client left first.
async fn read_connect<S: AsyncRead + Unpin>(
    stream: &mut S,
    buf: &mut BytesMut,
) -> Result<Option<(Connect, usize)>, ReadError> {
    loop {
        if let Some(h) = wire::header(buf, MAX_CONNECT)? {
            if h.kind != wire::kind::CONNECT {
                return Err(WireError::NotConnect(h.kind).into());
            }
            if buf.len() >= h.total() {
                let connect = wire::connect(&buf[h.header_len..h.total()])?;
                return Ok(Some((connect, h.total())));
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

/// Carries a session both ways until either side ends it: the client's packets checked one
/// by one on the way in, the broker's copied out.
async fn relay<S: AsyncRead + AsyncWrite + Unpin>(
    gate: Arc<Gate>,
    client: S,
    pending: BytesMut,
    upstream: TcpStream,
    connect: &Connect,
    keep_alive: Option<Duration>,
    peer: SocketAddr,
) {
    let (mut client_rx, mut client_tx) = tokio::io::split(client);
    let (mut upstream_rx, mut upstream_tx) = upstream.into_split();
    let max_packet = gate.settings.max_packet;
    let version = connect.version;
    let inbound = async {
        let mut buf = pending;
        let result = forward_checked(
            &mut client_rx,
            &mut upstream_tx,
            &mut buf,
            max_packet,
            version,
            keep_alive,
        )
        .await;
        // The broker sees the end of the session; without a DISCONNECT first, the will fires.
        let _ = upstream_tx.shutdown().await;
        result
    };
    let outbound = async {
        let mut chunk = vec![0u8; READ_CHUNK];
        loop {
            let n = match upstream_rx.read(&mut chunk).await {
                Ok(0) | Err(_) => break Ok(()),
                Ok(n) => n,
            };
            match tokio::time::timeout(WRITE_STALL, client_tx.write_all(&chunk[..n])).await {
                Ok(Ok(())) => {}
                Ok(Err(_)) => break Ok(()),
                Err(_) => break Err(Ended::Stalled),
            }
        }
    };
    // Whichever side ends first ends the session.
    let ended = tokio::select! {
        r = inbound => r,
        r = outbound => r,
    };
    match ended {
        Ok(()) => {}
        Err(Ended::Malformed(e)) => {
            gate.counters.malformed.fetch_add(1, Ordering::Relaxed);
            gate.note_refused(peer, "malformed packet");
            tracing::debug!(%peer, client = %connect.client_id, error = %e, "embedded broker: connection closed");
        }
        Err(Ended::Idle | Ended::Stalled) => {
            gate.counters.idle_closed.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Why a session ended other than by a side closing it.
#[derive(Debug)]
enum Ended {
    Malformed(WireError),
    Idle,
    Stalled,
}

/// Moves whole, checked packets from `from` to `to`. Returns when `from` closes.
async fn forward_checked<R: AsyncRead + Unpin, W: AsyncWrite + Unpin>(
    from: &mut R,
    to: &mut W,
    buf: &mut BytesMut,
    max_packet: usize,
    version: wire::Version,
    keep_alive: Option<Duration>,
) -> Result<(), Ended> {
    loop {
        // Every whole packet in the buffer, checked, then written in one go; the packets
        // before a bad one still go (they were the client's to send).
        let mut ready = 0;
        let verdict = loop {
            let h = match wire::header(&buf[ready..], max_packet) {
                Ok(Some(h)) => h,
                Ok(None) => break Ok(()),
                Err(e) => break Err(Ended::Malformed(e)),
            };
            if let Err(e) = wire::check_client_packet(&h, version) {
                break Err(Ended::Malformed(e));
            }
            if buf.len() - ready < h.total() {
                break Ok(());
            }
            ready += h.total();
        };
        if ready > 0 {
            if to.write_all(&buf[..ready]).await.is_err() {
                return Ok(());
            }
            buf.advance(ready);
        }
        verdict?;
        buf.reserve(READ_CHUNK);
        let read = from.read_buf(buf);
        let n = match keep_alive {
            Some(limit) => match tokio::time::timeout(limit, read).await {
                Ok(r) => r,
                Err(_) => return Err(Ended::Idle),
            },
            None => read.await,
        };
        match n {
            Ok(0) | Err(_) => return Ok(()),
            Ok(_) => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn whole_packets_pass_and_a_forbidden_one_ends_the_session() {
        // PINGREQ, a QoS 1 PUBLISH split across reads, then a CONNACK (a server's packet).
        let publish = [0x32, 0x07, 0x00, 0x01, b't', 0x00, 0x05, b'h', b'i'];
        let (mut client, mut gate_side) = tokio::io::duplex(1024);
        let (mut broker_side, mut broker) = tokio::io::duplex(1024);
        let task = tokio::spawn(async move {
            let mut buf = BytesMut::new();
            // The broker's side closes with the task, so its reader sees the end.
            forward_checked(
                &mut gate_side,
                &mut broker_side,
                &mut buf,
                1024,
                wire::Version::V4,
                None,
            )
            .await
        });
        client.write_all(&[0xc0, 0x00]).await.unwrap();
        client.write_all(&publish[..4]).await.unwrap();
        tokio::time::sleep(Duration::from_millis(20)).await;
        client.write_all(&publish[4..]).await.unwrap();
        client.write_all(&[0x20, 0x02, 0x00, 0x00]).await.unwrap();
        let result = task.await.unwrap();
        assert!(
            matches!(result, Err(Ended::Malformed(WireError::Forbidden(2)))),
            "{result:?}"
        );
        let mut got = Vec::new();
        broker.read_to_end(&mut got).await.unwrap();
        let mut expected = vec![0xc0, 0x00];
        expected.extend_from_slice(&publish);
        assert_eq!(got, expected);
    }

    #[tokio::test]
    async fn a_packet_over_the_limit_is_refused_before_its_body_arrives() {
        let (mut client, mut gate_side) = tokio::io::duplex(1024);
        let (mut broker_side, _broker) = tokio::io::duplex(1024);
        let task = tokio::spawn(async move {
            let mut buf = BytesMut::new();
            forward_checked(
                &mut gate_side,
                &mut broker_side,
                &mut buf,
                100,
                wire::Version::V4,
                None,
            )
            .await
        });
        // A PUBLISH that claims 2 MB.
        client
            .write_all(&[0x30, 0x80, 0x80, 0x80, 0x01])
            .await
            .unwrap();
        let result = task.await.unwrap();
        assert!(
            matches!(result, Err(Ended::Malformed(WireError::TooLarge { .. }))),
            "{result:?}"
        );
    }

    #[tokio::test]
    async fn a_silent_client_is_dropped_after_its_keep_alive() {
        let (_client, mut gate_side) = tokio::io::duplex(1024);
        let (mut broker_side, _broker) = tokio::io::duplex(1024);
        let mut buf = BytesMut::new();
        let result = forward_checked(
            &mut gate_side,
            &mut broker_side,
            &mut buf,
            100,
            wire::Version::V4,
            Some(Duration::from_millis(50)),
        )
        .await;
        assert!(matches!(result, Err(Ended::Idle)), "{result:?}");
    }
}
