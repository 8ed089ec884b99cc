//! The embedded MQTT broker (rumqttd) of the no-hardware default. rumqttd's `start()` blocks
//! and only logs a failed bind, so the port is probed first and the broker is checked to be
//! listening afterwards: if something else owns the port, chassisd fails loudly.

use std::collections::HashMap;
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use rumqttd::{Broker, Config, ConnectionSettings, RouterConfig, ServerSettings};

/// How long the broker may take to listen.
const START_TIMEOUT: Duration = Duration::from_secs(5);

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
            max_connections: 1000,
            max_outgoing_packet_count: 200,
            max_segment_size: 100 << 20,
            max_segment_count: 10,
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
    tracing::info!(%addr, "embedded MQTT broker listening");
    Ok(())
}
