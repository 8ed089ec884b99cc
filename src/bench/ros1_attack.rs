//! A hostile TCPROS peer for the soak, and the operator's check that the node serves again.
//!
//! The peer asks the master where the node serves `/navi_info` (anyone on the vehicle's
//! network can), then lies about a connection header's length (1 GiB told, up to 64 MB
//! sent) and opens connections it holds without end. Raw sockets: no ROS client does this.
//! They run inside the soak's process, whose memory is chassisd's figure, so they keep
//! their own small: one 1 MB buffer, and the master asked over a plain HTTP exchange rather
//! than an HTTP client library's pools.

use std::time::{Duration, Instant};

use roslibrust::RosServiceType;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use super::attacks::AttackFigures;
use crate::runtime::links::ros1::messages::map_msgs::{AboutRobot, AboutRobotResponse};

/// The service attacked and called.
const SERVICE: &str = "/navi_info";
/// The header length the lie announces, and how much of it is sent at most.
const TOLD: u32 = 1 << 30;
const SENT_AT_MOST: usize = 64 << 20;
/// Connections held at once at most, and how long each may take to open.
const HELD_AT_MOST: usize = 400;
const CONNECT_WITHIN: Duration = Duration::from_millis(200);
/// How long connections are held before they are let go and the lie comes again.
const HOLD_ROUND: Duration = Duration::from_secs(2);
/// A header or answer the operator's call reads at most, bytes.
const ANSWER_AT_MOST: usize = 64 << 10;

/// The node's TCPROS port for [`SERVICE`], as the master at `master` (`host:port`) names
/// it now: its XML-RPC `lookupService`, asked as `caller`.
async fn service_port(master: &str, caller: &str) -> Option<u16> {
    let body = format!(
        "<?xml version=\"1.0\"?><methodCall><methodName>lookupService</methodName><params>\
         <param><value><string>{caller}</string></value></param>\
         <param><value><string>{SERVICE}</string></value></param></params></methodCall>"
    );
    let request = format!(
        "POST / HTTP/1.1\r\nHost: {master}\r\nContent-Type: text/xml\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    let answer = tokio::time::timeout(Duration::from_secs(2), async {
        let mut s = TcpStream::connect(master).await.ok()?;
        s.write_all(request.as_bytes()).await.ok()?;
        let mut answer = Vec::new();
        s.take(ANSWER_AT_MOST as u64)
            .read_to_end(&mut answer)
            .await
            .ok()?;
        Some(answer)
    })
    .await
    .ok()??;
    port_in_lookup_answer(&String::from_utf8_lossy(&answer))
}

/// The port of the service's `rosrpc://host:port` in a `lookupService` answer: its last
/// value (the message before it quotes the URI too); `None` when the master knows none.
fn port_in_lookup_answer(answer: &str) -> Option<u16> {
    let uri = &answer[answer.rfind("rosrpc://")? + "rosrpc://".len()..];
    let end = uri.find('<')?;
    uri[..end]
        .rsplit(':')
        .next()?
        .trim_end_matches('/')
        .parse()
        .ok()
}

/// `host:port` of a master URI (`http://host:port[/]`).
fn master_address(master_uri: &str) -> &str {
    master_uri
        .trim_start_matches("http://")
        .trim_end_matches('/')
}

/// Lies and held connections, round after round, for `hold`.
pub async fn lie_and_hold(master_uri: &str, hold: Duration) -> AttackFigures {
    let until = Instant::now() + hold;
    let mut figures = AttackFigures::default();
    let master = master_address(master_uri);
    while Instant::now() < until {
        let Some(port) = service_port(master, "/soak_attacker").await else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        figures.attempts += 1;
        if lie(port, until).await {
            figures.refused_or_cut += 1;
        }
        let round_end = until.min(Instant::now() + HOLD_ROUND);
        let (tried, refused) = hold_connections(port, round_end).await;
        figures.attempts += tried;
        figures.refused_or_cut += refused;
    }
    figures
}

/// A header announced as [`TOLD`] bytes, then up to [`SENT_AT_MOST`] of it, until
/// `until`; whether the node refused or cut the connection.
async fn lie(port: u16, until: Instant) -> bool {
    let Ok(Ok(mut peer)) =
        tokio::time::timeout(CONNECT_WITHIN, TcpStream::connect(("127.0.0.1", port))).await
    else {
        return true;
    };
    let chunk = vec![b'x'; 1 << 20];
    let sent = tokio::time::timeout_at(until.into(), async {
        peer.write_all(&TOLD.to_le_bytes()).await?;
        for _ in 0..SENT_AT_MOST / chunk.len() {
            peer.write_all(&chunk).await?;
        }
        Ok::<_, std::io::Error>(())
    })
    .await;
    matches!(sent, Ok(Err(_)))
}

/// Connections opened and held until `until` (at most [`HELD_AT_MOST`]); how many were
/// tried, and how many refused or cut by the end.
async fn hold_connections(port: u16, until: Instant) -> (u64, u64) {
    let mut held = Vec::new();
    let (mut tried, mut refused) = (0, 0);
    while Instant::now() < until && held.len() < HELD_AT_MOST {
        tried += 1;
        match tokio::time::timeout(CONNECT_WITHIN, TcpStream::connect(("127.0.0.1", port))).await {
            Ok(Ok(s)) => held.push(s),
            _ => {
                refused += 1;
                // Nobody listens (the node's process restarting): try again a little later.
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        }
    }
    tokio::time::sleep_until(until.into()).await;
    let mut sink = [0u8; 64];
    for mut s in held {
        let cut = matches!(
            tokio::time::timeout(Duration::from_millis(1), s.read(&mut sink)).await,
            Ok(Ok(0) | Err(_))
        );
        refused += u64::from(cut);
    }
    (tried, refused)
}

/// When the node first answers a `/navi_info` call (a well-formed one, as a ROS client
/// makes it), trying until `within` has passed.
pub async fn serves_again(master_uri: &str, within: Duration) -> Option<Instant> {
    let deadline = Instant::now() + within;
    let master = master_address(master_uri);
    while Instant::now() < deadline {
        if let Some(port) = service_port(master, "/soak_operator").await
            && let Ok(Some(())) =
                tokio::time::timeout(Duration::from_secs(1), call_navi_info(port)).await
        {
            return Some(Instant::now());
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    None
}

/// One `/navi_info` call over TCPROS: `Some` when the node answers with status 0.
async fn call_navi_info(port: u16) -> Option<()> {
    let mut s = TcpStream::connect(("127.0.0.1", port)).await.ok()?;
    let fields = [
        "callerid=/soak_operator".to_owned(),
        format!("service={SERVICE}"),
        format!("md5sum={}", AboutRobot::MD5SUM),
    ];
    let mut header = Vec::new();
    for field in &fields {
        header.extend_from_slice(&(field.len() as u32).to_le_bytes());
        header.extend_from_slice(field.as_bytes());
    }
    let mut message = (header.len() as u32).to_le_bytes().to_vec();
    message.extend_from_slice(&header);
    // The request has no fields: a body of length 0.
    message.extend_from_slice(&0u32.to_le_bytes());
    s.write_all(&message).await.ok()?;
    read_framed(&mut s).await?;
    let ok = s.read_u8().await.ok()?;
    let body = read_framed(&mut s).await?;
    let answer: AboutRobotResponse = roslibrust_serde_rosmsg::from_slice(&body).ok()?;
    (ok == 1 && answer.status == 0).then_some(())
}

/// A length-prefixed block (the length kept in front), at most [`ANSWER_AT_MOST`] bytes.
async fn read_framed(s: &mut TcpStream) -> Option<Vec<u8>> {
    let length = s.read_u32_le().await.ok()? as usize;
    if length > ANSWER_AT_MOST {
        return None;
    }
    let mut framed = (length as u32).to_le_bytes().to_vec();
    framed.resize(4 + length, 0);
    s.read_exact(&mut framed[4..]).await.ok()?;
    Some(framed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_port_is_read_from_a_rosmasters_answer() {
        // rosmaster's answer, as it sends it.
        let found = "<?xml version='1.0'?>\n<methodResponse>\n<params>\n<param>\n<value><array><data>\n\
            <value><int>1</int></value>\n<value><string>rosrpc URI: [rosrpc://vm:41234]</string></value>\n\
            <value><string>rosrpc://vm:41234</string></value>\n</data></array></value>\n</param>\n</params>\n</methodResponse>\n";
        assert_eq!(port_in_lookup_answer(found), Some(41234));
        let none = "<value><int>-1</int></value>\n<value><string>no provider</string></value>\n<value><string></string></value>";
        assert_eq!(port_in_lookup_answer(none), None);
    }
}
