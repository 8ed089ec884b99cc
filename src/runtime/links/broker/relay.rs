//! One admitted client's session, carried between the client and the broker. The client's
//! packets are judged one by one (`broker::session`) on the way in; the broker's are framed
//! on the way out so that the client's acknowledgements can be checked against them.
//!
//! However a session ends, the gate waits for the broker to close its side before it lets
//! the identifier go: the broker then has seen the session end, and a new session under the
//! same identifier cannot race it. After a client's DISCONNECT the gate does not close the
//! broker's side at all; the broker ends the session itself, and no last will fires.

use std::sync::Mutex;
use std::time::Duration;

use bytes::{Buf, BytesMut};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpStream;

use super::identifiers::Turn;
use crate::broker::held::Held;
use crate::broker::session::{Pass, Session, Violation};
use crate::broker::wire::{self, Version};

/// Bytes read from a socket at a time.
const READ_CHUNK: usize = 16 << 10;
/// A write to a client that makes no progress for this long ends the session: the client
/// stopped reading, and the broker's queue for it should not wait for ever.
const WRITE_STALL: Duration = Duration::from_secs(30);
/// How long the broker may take to close its side once the session is over.
const BROKER_CLOSE: Duration = Duration::from_secs(2);

/// How a session ended.
#[derive(Debug)]
pub enum Ended {
    /// The client closed its connection.
    ClientClosed,
    /// The client said DISCONNECT.
    ClientDisconnected,
    /// The broker closed the session.
    BrokerClosed,
    /// A newer session took the identifier over.
    TakenOver,
    /// The client sent what the broker must not see.
    Violation(Violation),
    /// The client said nothing for longer than its keep-alive allows.
    Idle,
    /// The client stopped reading.
    Stalled,
}

/// What a session needs of the gate.
pub struct Relay<'a> {
    /// The version the client speaks.
    pub version: Version,
    /// chassisd's own link: its topic names are not limited.
    pub trusted: bool,
    /// The largest packet the client may send, bytes.
    pub max_packet: usize,
    /// Silence allowed from the client (1.5 keep-alive), if it has a keep-alive.
    pub keep_alive: Option<Duration>,
    /// The largest packet the client accepts (MQTT 5's `Maximum Packet Size`): larger ones
    /// the broker sends are not passed on.
    pub max_packet_to_client: Option<usize>,
    /// What the broker holds for every session.
    pub held: &'a Mutex<Held>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // Sets of ids and names: a panic elsewhere cannot leave them half-written.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Relay<'_> {
    /// Carries the session until it ends, then waits for the broker to close its side.
    pub async fn run<S: AsyncRead + AsyncWrite + Unpin>(
        &self,
        client: S,
        pending: BytesMut,
        upstream: TcpStream,
        turn: Option<&Turn>,
    ) -> Ended {
        let session = Mutex::new(if self.trusted {
            Session::trusted(self.version, self.max_packet)
        } else {
            Session::new(self.version, self.max_packet)
        });
        let (mut client_rx, mut client_tx) = tokio::io::split(client);
        let (mut upstream_rx, mut upstream_tx) = upstream.into_split();
        let ended = {
            let inbound = self.inbound(&mut client_rx, &mut upstream_tx, pending, &session);
            let outbound = outbound(
                &mut upstream_rx,
                &mut client_tx,
                &session,
                self.max_packet_to_client,
            );
            let taken_over = async {
                match turn {
                    Some(turn) => turn.taken_over().await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                ended = inbound => ended,
                ended = outbound => ended,
                () = taken_over => Ended::TakenOver,
            }
        };
        lock(&session).end(&mut lock(self.held));
        if let (Ended::Violation(v), Version::V5) = (&ended, self.version) {
            // A 5.0 client is told why (a 3.1.1 one can only be closed on).
            let reason = wire::disconnect_v5(v.reason_code());
            let _ = tokio::time::timeout(BROKER_CLOSE, client_tx.write_all(&reason)).await;
        }
        if !matches!(ended, Ended::BrokerClosed) {
            if !matches!(ended, Ended::ClientDisconnected) {
                // The broker sees the session end; without a DISCONNECT the will fires.
                let _ = upstream_tx.shutdown().await;
            }
            let mut sink = vec![0u8; READ_CHUNK];
            let _ = tokio::time::timeout(BROKER_CLOSE, async {
                while upstream_rx.read(&mut sink).await.is_ok_and(|n| n > 0) {}
            })
            .await;
        }
        let _ = client_tx.shutdown().await;
        ended
    }

    /// Moves whole, judged packets from the client to the broker until the session ends.
    async fn inbound<R: AsyncRead + Unpin, W: AsyncWrite + Unpin>(
        &self,
        from: &mut R,
        to: &mut W,
        mut buf: BytesMut,
        session: &Mutex<Session>,
    ) -> Ended {
        loop {
            // Every whole packet in the buffer, judged, then written in one go; those
            // before a bad one still go (they were the client's to send).
            let mut ready = 0;
            // A large packet still arriving holds room in the gate's buffers until it is whole.
            lock(session).release_buffer(&mut lock(self.held));
            let verdict = loop {
                let h = match wire::header(&buf[ready..], self.max_packet) {
                    Ok(Some(h)) => h,
                    Ok(None) => break None,
                    Err(e) => break Some(Ended::Violation(e.into())),
                };
                if let Err(e) = wire::check_client_packet(&h, self.version) {
                    break Some(Ended::Violation(e.into()));
                }
                if buf.len() - ready < h.total() {
                    let reserved = lock(session).reserve_buffer(h.total(), &mut lock(self.held));
                    break reserved.err().map(Ended::Violation);
                }
                let packet = &buf[ready..ready + h.total()];
                let pass = lock(session).from_client(&h, packet, &mut lock(self.held));
                match pass {
                    Ok(Pass::Forward) => ready += h.total(),
                    Ok(Pass::LastOne) => {
                        ready += h.total();
                        break Some(Ended::ClientDisconnected);
                    }
                    Err(v) => break Some(Ended::Violation(v)),
                }
            };
            if ready > 0 {
                if to.write_all(&buf[..ready]).await.is_err() {
                    return Ended::BrokerClosed;
                }
                buf.advance(ready);
            }
            if let Some(ended) = verdict {
                return ended;
            }
            buf.reserve(READ_CHUNK);
            let read = from.read_buf(&mut buf);
            let n = match self.keep_alive {
                Some(limit) => match tokio::time::timeout(limit, read).await {
                    Ok(r) => r,
                    Err(_) => return Ended::Idle,
                },
                None => read.await,
            };
            if !n.is_ok_and(|n| n > 0) {
                return Ended::ClientClosed;
            }
        }
    }
}

/// Moves the broker's packets to the client, noting each in the session. Packets larger
/// than the client accepts (`limit`) are dropped, as MQTT 5 has the server do.
async fn outbound<R: AsyncRead + Unpin, W: AsyncWrite + Unpin>(
    from: &mut R,
    to: &mut W,
    session: &Mutex<Session>,
    limit: Option<usize>,
) -> Ended {
    let mut buf = BytesMut::with_capacity(READ_CHUNK);
    loop {
        buf.reserve(READ_CHUNK);
        if !from.read_buf(&mut buf).await.is_ok_and(|n| n > 0) {
            return Ended::BrokerClosed;
        }
        // The broker's packets are bounded by its own packet limit.
        loop {
            let mut ready = 0;
            let mut skip = 0;
            while let Ok(Some(h)) = wire::header(&buf[ready..], usize::MAX) {
                if buf.len() - ready < h.total() {
                    break;
                }
                if limit.is_some_and(|limit| h.total() > limit) {
                    skip = h.total();
                    break;
                }
                lock(session).from_broker(&h, &buf[ready..ready + h.total()]);
                ready += h.total();
            }
            if ready > 0 {
                match tokio::time::timeout(WRITE_STALL, to.write_all(&buf[..ready])).await {
                    Ok(Ok(())) => buf.advance(ready),
                    Ok(Err(_)) => return Ended::ClientClosed,
                    Err(_) => return Ended::Stalled,
                }
            }
            if skip == 0 {
                break;
            }
            buf.advance(skip);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn relay(held: &Mutex<Held>, keep_alive: Option<Duration>) -> Relay<'_> {
        Relay {
            version: Version::V4,
            trusted: false,
            max_packet: 1024,
            keep_alive,
            max_packet_to_client: None,
            held,
        }
    }

    #[tokio::test]
    async fn whole_packets_pass_and_a_forbidden_one_ends_the_session() {
        // PINGREQ, a QoS 0 PUBLISH split across reads, then a CONNACK (a server's packet).
        let publish = [0x30, 0x05, 0x00, 0x01, b't', b'h', b'i'];
        let names = Mutex::new(Held::new([], 1024));
        let session = Mutex::new(Session::new(Version::V4, 1024));
        let (mut client, mut gate_side) = tokio::io::duplex(1024);
        let (mut broker_side, mut broker) = tokio::io::duplex(1024);
        let r = relay(&names, None);
        let inbound = r.inbound(&mut gate_side, &mut broker_side, BytesMut::new(), &session);
        let feed = async {
            client.write_all(&[0xc0, 0x00]).await.unwrap();
            client.write_all(&publish[..4]).await.unwrap();
            tokio::time::sleep(Duration::from_millis(20)).await;
            client.write_all(&publish[4..]).await.unwrap();
            client.write_all(&[0x20, 0x02, 0x00, 0x00]).await.unwrap();
        };
        let (ended, ()) = tokio::join!(inbound, feed);
        assert!(
            matches!(
                ended,
                Ended::Violation(Violation::Wire(wire::WireError::Forbidden(2)))
            ),
            "{ended:?}"
        );
        drop(broker_side);
        let mut got = Vec::new();
        broker.read_to_end(&mut got).await.unwrap();
        let mut expected = vec![0xc0, 0x00];
        expected.extend_from_slice(&publish);
        assert_eq!(got, expected);
    }

    #[tokio::test]
    async fn a_packet_over_the_limit_is_refused_before_its_body_arrives() {
        let names = Mutex::new(Held::new([], 1024));
        let session = Mutex::new(Session::new(Version::V4, 1024));
        let (mut client, mut gate_side) = tokio::io::duplex(1024);
        let (mut broker_side, _broker) = tokio::io::duplex(1024);
        // A PUBLISH that claims 2 MB.
        client
            .write_all(&[0x30, 0x80, 0x80, 0x80, 0x01])
            .await
            .unwrap();
        let ended = relay(&names, None)
            .inbound(&mut gate_side, &mut broker_side, BytesMut::new(), &session)
            .await;
        assert!(
            matches!(
                ended,
                Ended::Violation(Violation::Wire(wire::WireError::TooLarge { .. }))
            ),
            "{ended:?}"
        );
    }

    #[tokio::test]
    async fn a_silent_client_is_dropped_after_its_keep_alive() {
        let names = Mutex::new(Held::new([], 1024));
        let session = Mutex::new(Session::new(Version::V4, 1024));
        let (_client, mut gate_side) = tokio::io::duplex(1024);
        let (mut broker_side, _broker) = tokio::io::duplex(1024);
        let ended = relay(&names, Some(Duration::from_millis(50)))
            .inbound(&mut gate_side, &mut broker_side, BytesMut::new(), &session)
            .await;
        assert!(matches!(ended, Ended::Idle), "{ended:?}");
    }

    #[tokio::test]
    async fn a_client_acknowledges_only_what_the_broker_delivered() {
        let names = Mutex::new(Held::new([], 1024));
        let session = Mutex::new(Session::new(Version::V4, 1024));
        // The broker delivers a QoS 1 PUBLISH with id 7.
        let (mut broker, mut broker_side) = tokio::io::duplex(1024);
        let (mut to_client, mut client) = tokio::io::duplex(1024);
        broker
            .write_all(&[0x32, 0x06, 0x00, 0x01, b't', 0x00, 0x07, b'x'])
            .await
            .unwrap();
        drop(broker);
        assert!(matches!(
            outbound(&mut broker_side, &mut to_client, &session, None).await,
            Ended::BrokerClosed
        ));
        let mut delivered = [0u8; 8];
        client.read_exact(&mut delivered).await.unwrap();
        // Its PUBACK passes; a PUBACK for id 8 ends the session.
        let (mut c, mut gate_side) = tokio::io::duplex(1024);
        let (mut up, _sink) = tokio::io::duplex(1024);
        c.write_all(&[0x40, 0x02, 0x00, 0x07, 0x40, 0x02, 0x00, 0x08])
            .await
            .unwrap();
        let ended = relay(&names, None)
            .inbound(&mut gate_side, &mut up, BytesMut::new(), &session)
            .await;
        assert!(
            matches!(
                ended,
                Ended::Violation(Violation::UnknownPacketId { kind: 4, id: 8 })
            ),
            "{ended:?}"
        );
    }
}
