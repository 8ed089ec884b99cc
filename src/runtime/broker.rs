//! The embedded MQTT broker (rumqttd) of the no-hardware default. rumqttd's `start()` blocks
//! and only logs a failed bind, so the port is probed first and the broker is checked to be
//! listening afterwards: if something else owns the port, chassisd fails loudly.
//!
//! Two settings make it fit a vehicle that runs for months:
//! - Memory: rumqttd keeps every subscription filter's messages in a log of memory segments
//!   for subscribers that fall behind, dropping the oldest segment when the count is reached.
//!   Its own default (10 × 100 MiB per filter) grew about 44 MB an hour from base_status alone,
//!   and a command flood filled it at once. [`SEGMENT_BYTES`] × [`SEGMENTS`] bounds it.
//! - Latency: rumqttd sets no `TCP_NODELAY` on the connections it accepts, so Nagle's
//!   algorithm held each small packet (a DRIVE ack, a base_status) behind the client's delayed
//!   ACK, up to 45 ms. Linux gives an accepted socket the options of its listener, so the
//!   option is set on rumqttd's listener, found among this process's descriptors by address.

use std::collections::HashMap;
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::os::fd::BorrowedFd;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use rumqttd::{Broker, Config, ConnectionSettings, RouterConfig, ServerSettings};

/// How long the broker may take to listen.
const START_TIMEOUT: Duration = Duration::from_secs(5);
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
/// Clients at once: a vehicle has a handful; each costs buffers.
const MAX_CONNECTIONS: usize = 64;

/// Starts a broker on `host:port` in its own thread and returns once it accepts connections.
pub fn start(host: &str, port: u16, max_payload: usize) -> anyhow::Result<()> {
    let addr: SocketAddr = (host, port)
        .to_socket_addrs()
        .with_context(|| format!("embedded broker: bad address {host}:{port}"))?
        .next()
        .with_context(|| format!("embedded broker: {host}:{port} resolves to nothing"))?;
    // Probe: if the port is taken, rumqttd would only log it.
    drop(TcpListener::bind(addr).with_context(|| {
        format!("embedded broker: cannot listen on {addr} (another broker running there?)")
    })?);
    let server = ServerSettings {
        name: "chassisd".into(),
        listen: addr,
        tls: None,
        next_connection_delay_ms: 1,
        connections: ConnectionSettings {
            connection_timeout_ms: 60_000,
            max_payload_size: max_payload.saturating_mul(4).max(1 << 20),
            max_inflight_count: 100,
            auth: None,
            external_auth: None,
            dynamic_filters: true,
        },
    };
    let config = Config {
        id: 0,
        router: RouterConfig {
            max_connections: MAX_CONNECTIONS,
            max_outgoing_packet_count: 200,
            max_segment_size: SEGMENT_BYTES,
            max_segment_count: SEGMENTS,
            custom_segment: None,
            initialized_filters: None,
            shared_subscriptions_strategy: Default::default(),
        },
        v4: Some(HashMap::from([("v4".to_owned(), server)])),
        ..Default::default()
    };
    std::thread::Builder::new()
        .name("mqtt-broker".into())
        .spawn(move || {
            let mut broker = Broker::new(config);
            if let Err(e) = broker.start() {
                tracing::error!(error = %e, "embedded broker stopped");
            }
        })
        .context("embedded broker: cannot start its thread")?;
    let deadline = Instant::now() + START_TIMEOUT;
    while TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_err() {
        if Instant::now() > deadline {
            bail!("embedded broker: not listening on {addr} after {START_TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    match set_nodelay_on_listener(addr) {
        Ok(true) => {}
        Ok(false) => {
            tracing::warn!(%addr, "embedded broker: its listener was not found; replies may lag up to 40 ms (Nagle)")
        }
        Err(e) => {
            tracing::warn!(%addr, error = %e, "embedded broker: cannot set TCP_NODELAY; replies may lag up to 40 ms (Nagle)")
        }
    }
    tracing::info!(%addr, "embedded MQTT broker listening");
    Ok(())
}

/// Sets `TCP_NODELAY` on this process's socket listening on `addr`; false if there is none.
fn set_nodelay_on_listener(addr: SocketAddr) -> std::io::Result<bool> {
    for entry in std::fs::read_dir("/proc/self/fd")? {
        let entry = entry?;
        let Some(fd) = entry
            .file_name()
            .to_str()
            .and_then(|n| n.parse::<i32>().ok())
        else {
            continue;
        };
        let is_socket = std::fs::read_link(entry.path())
            .is_ok_and(|target| target.to_string_lossy().starts_with("socket:"));
        if !is_socket {
            continue;
        }
        // SAFETY: the descriptor was open when listed, and is only used for these calls. If
        // another thread closed it since, the calls fail (EBADF) or reach whatever socket took
        // the number, which is changed only if it is a listener on `addr`: the broker's own.
        let fd = unsafe { BorrowedFd::borrow_raw(fd) };
        let socket = socket2::SockRef::from(&fd);
        let listening_here = socket.is_listener().unwrap_or(false)
            && socket.local_addr().ok().and_then(|a| a.as_socket()) == Some(addr);
        if listening_here {
            socket.set_tcp_nodelay(true)?;
            return Ok(true);
        }
    }
    Ok(false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn connections_the_broker_accepts_do_not_wait_for_nagle() {
        let port = TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("free port")
            .port();
        start("127.0.0.1", port, 1 << 16).expect("broker starts");
        // The accepted side's option is not visible from the client; a listener of our own
        // on the same kind of address shows the search finds only the right socket.
        let other = TcpListener::bind("127.0.0.1:0").expect("bind");
        let other_addr = other.local_addr().expect("addr");
        assert!(set_nodelay_on_listener(SocketAddr::from(([127, 0, 0, 1], port))).expect("scan"));
        assert!(!socket2::SockRef::from(&other).tcp_nodelay().expect("get"));
        assert!(set_nodelay_on_listener(other_addr).expect("scan"));
        let _client = TcpStream::connect(other_addr).expect("connect");
        let (accepted, _) = other.accept().expect("accept");
        assert!(
            socket2::SockRef::from(&accepted)
                .tcp_nodelay()
                .expect("get"),
            "an accepted socket inherits its listener's TCP_NODELAY"
        );
    }
}
