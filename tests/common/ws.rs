//! A WebSocket client written byte by byte, as an attacker's or a browser's would be: the
//! handshake with any Host and Origin, masked text frames of any size, frames read raw.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::Duration;

/// Opens a handshake to `127.0.0.1:port` for `path` with `host` and, if given, `origin`.
/// Returns the socket and the response's status code.
pub fn handshake(port: u16, path: &str, host: &str, origin: Option<&str>) -> (TcpStream, u16) {
    handshake_on(connect_from([127, 0, 0, 1], port), path, host, origin)
}

/// A connection to `127.0.0.1:port` from the loopback address `source` (any of 127/8: each
/// is a host of its own to a server counting connections per address).
pub fn connect_from(source: [u8; 4], port: u16) -> TcpStream {
    let socket =
        socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).expect("socket");
    let from = std::net::SocketAddr::from((source, 0));
    socket.bind(&from.into()).expect("bind the source address");
    let to = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    socket.connect(&to.into()).expect("connect");
    socket.into()
}

/// [`handshake`] over the connection `s`.
pub fn handshake_on(
    mut s: TcpStream,
    path: &str,
    host: &str,
    origin: Option<&str>,
) -> (TcpStream, u16) {
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    let origin = origin.map_or(String::new(), |o| format!("Origin: {o}\r\n"));
    let request = format!(
        "GET {path} HTTP/1.1\r\nHost: {host}\r\n{origin}Upgrade: websocket\r\n\
         Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\
         Sec-WebSocket-Version: 13\r\n\r\n"
    );
    s.write_all(request.as_bytes()).expect("send the handshake");
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        if s.read(&mut byte).expect("read the response") == 0 {
            break;
        }
        head.push(byte[0]);
    }
    let head = String::from_utf8_lossy(&head);
    let code = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (s, code)
}

/// Sends `text` as one masked text frame.
pub fn send_text(s: &mut TcpStream, text: &str) -> std::io::Result<()> {
    let payload = text.as_bytes();
    let mut frame = vec![0x81];
    match payload.len() {
        n if n < 126 => frame.push(0x80 | n as u8),
        n if n <= 0xffff => {
            frame.push(0x80 | 126);
            frame.extend_from_slice(&(n as u16).to_be_bytes());
        }
        n => {
            frame.push(0x80 | 127);
            frame.extend_from_slice(&(n as u64).to_be_bytes());
        }
    }
    let mask = [1u8, 2, 3, 4];
    frame.extend_from_slice(&mask);
    frame.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
    s.write_all(&frame)
}

/// The next frame: (opcode, payload); `None` when the connection ended.
pub fn read_frame(s: &mut TcpStream) -> Option<(u8, Vec<u8>)> {
    let mut exactly = |n: usize| -> Option<Vec<u8>> {
        let mut buf = vec![0u8; n];
        s.read_exact(&mut buf).ok()?;
        Some(buf)
    };
    let head = exactly(2)?;
    let mut length = u64::from(head[1] & 0x7f);
    if length == 126 {
        let b = exactly(2)?;
        length = u64::from(u16::from_be_bytes([b[0], b[1]]));
    } else if length == 127 {
        let b = exactly(8)?;
        length = u64::from_be_bytes(b.try_into().ok()?);
    }
    let payload = exactly(usize::try_from(length).ok()?)?;
    Some((head[0] & 0x0f, payload))
}

/// The next text frame's JSON, skipping other frames; `None` when the connection ended
/// (or a Close frame came).
pub fn next_json(s: &mut TcpStream) -> Option<serde_json::Value> {
    loop {
        let (opcode, payload) = read_frame(s)?;
        match opcode {
            1 => return serde_json::from_slice(&payload).ok(),
            8 => return None,
            _ => {}
        }
    }
}
