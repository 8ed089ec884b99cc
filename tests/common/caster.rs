//! A small NTRIP caster for the client's tests: it serves one behaviour on 127.0.0.1 (a
//! stream paced in chunks of odd sizes, a head and then silence, a refusal, a close at
//! once) to every mountpoint, a sourcetable naming MOUNT to `GET /`, and keeps when each client connected and what each sent after its request (the
//! GGA sentences). The real casters' tests are `tests/suite/ntrip_casters.rs`.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// What the caster does with each client.
#[derive(Clone)]
pub enum Behaviour {
    /// Sends `head`, then `body` in chunks whose sizes cycle through `chunks`, one chunk
    /// every `every`; then keeps the connection open. Without `repeat`, later connections
    /// get the head and nothing more (a base station that went off the air).
    Stream {
        head: String,
        body: Vec<u8>,
        chunks: Vec<usize>,
        every: Duration,
        repeat: bool,
    },
    /// Sends `head` (a 200) and then nothing.
    Silent { head: String },
    /// Answers 401 Unauthorized and closes.
    Unauthorized,
    /// Closes at once, without a word.
    Close,
}

/// A connection as the caster saw it.
#[derive(Debug, Clone)]
pub struct Connection {
    /// When it was accepted.
    pub at: Instant,
    /// The request head.
    pub request: String,
    /// The lines the client sent after its request, with when each arrived.
    pub lines: Vec<(Instant, String)>,
}

/// The running caster; it stops serving when dropped (its threads end with the test).
pub struct Caster {
    pub port: u16,
    connections: Arc<Mutex<Vec<Connection>>>,
}

impl Caster {
    pub fn start(behaviour: Behaviour) -> Caster {
        Self::listen(behaviour, None)
    }

    /// [`Caster::start`] behind TLS, with the certificate `cert` and its key `key` (PEM).
    pub fn start_tls(
        behaviour: Behaviour,
        cert: &std::path::Path,
        key: &std::path::Path,
    ) -> Caster {
        use rustls::pki_types::pem::PemObject;
        use rustls::pki_types::{CertificateDer, PrivateKeyDer};
        let _ = rustls::crypto::ring::default_provider().install_default();
        let certs = CertificateDer::pem_file_iter(cert)
            .expect("certificate file")
            .collect::<Result<Vec<_>, _>>()
            .expect("certificates");
        let key = PrivateKeyDer::from_pem_file(key).expect("key");
        let config = rustls::ServerConfig::builder()
            .with_no_client_auth()
            .with_single_cert(certs, key)
            .expect("server configuration");
        Self::listen(behaviour, Some(Arc::new(config)))
    }

    fn listen(behaviour: Behaviour, tls: Option<Arc<rustls::ServerConfig>>) -> Caster {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = listener.local_addr().expect("address").port();
        let connections = Arc::new(Mutex::new(Vec::new()));
        let seen = connections.clone();
        std::thread::spawn(move || {
            for stream in listener.incoming() {
                let Ok(stream) = stream else { continue };
                let behaviour = behaviour.clone();
                let seen = seen.clone();
                let tls = tls.clone();
                std::thread::spawn(move || match tls {
                    None => {
                        let lines = stream.try_clone().ok();
                        serve(stream, lines, behaviour, seen);
                    }
                    Some(config) => {
                        // What a TLS client sends after its request is not read (GGAs wait
                        // in the socket's buffer).
                        let Ok(server) = rustls::ServerConnection::new(config) else {
                            return;
                        };
                        serve(
                            rustls::StreamOwned::new(server, stream),
                            None,
                            behaviour,
                            seen,
                        );
                    }
                });
            }
        });
        Caster { port, connections }
    }

    /// `ntrip://rover:s3cret@127.0.0.1:PORT/MOUNT`.
    pub fn url(&self) -> String {
        format!("ntrip://rover:s3cret@127.0.0.1:{}/MOUNT", self.port)
    }

    /// Every connection so far.
    pub fn connections(&self) -> Vec<Connection> {
        self.connections.lock().unwrap().clone()
    }

    /// Waits until `n` connections have come, at most `wait`.
    pub fn wait_connections(&self, n: usize, wait: Duration) -> Vec<Connection> {
        let until = Instant::now() + wait;
        loop {
            let c = self.connections();
            if c.len() >= n || Instant::now() > until {
                return c;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// Serves one client on `stream`; `lines`, a second handle on a plain connection, reads
/// what the client sends after its request.
fn serve(
    mut stream: impl Read + Write,
    lines: Option<TcpStream>,
    behaviour: Behaviour,
    seen: Arc<Mutex<Vec<Connection>>>,
) {
    let at = Instant::now();
    let index = {
        let mut s = seen.lock().unwrap();
        s.push(Connection {
            at,
            request: String::new(),
            lines: Vec::new(),
        });
        s.len() - 1
    };
    if matches!(behaviour, Behaviour::Close) {
        return;
    }
    // The request head, up to its blank line.
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") && head.len() < 8192 {
        match stream.read(&mut byte) {
            Ok(1) => head.push(byte[0]),
            _ => return,
        }
    }
    let request = String::from_utf8_lossy(&head).into_owned();
    seen.lock().unwrap()[index].request = request.clone();
    // The sourcetable: one mountpoint, MOUNT, which wants GGA.
    if request.starts_with("GET / ") {
        let _ = stream.write_all(
            b"SOURCETABLE 200 OK\r\nContent-Type: text/plain\r\n\r\n\
              STR;MOUNT;Test;RTCM 3.3;1004(1),1005(10);2;GPS;TEST;DEU;48.10;11.50;1;0;chassisd test caster;none;B;N;9600;\r\n\
              ENDSOURCETABLE\r\n",
        );
        let _ = stream.flush();
        return;
    }
    // What the client sends from now on, line by line.
    if let Some(mut reader) = lines {
        let seen = seen.clone();
        std::thread::spawn(move || {
            let mut line = Vec::new();
            let mut buf = [0u8; 512];
            while let Ok(n) = reader.read(&mut buf) {
                if n == 0 {
                    return;
                }
                for &b in &buf[..n] {
                    line.push(b);
                    if b == b'\n' {
                        let text = String::from_utf8_lossy(&line).trim_end().to_owned();
                        seen.lock().unwrap()[index]
                            .lines
                            .push((Instant::now(), text));
                        line.clear();
                    }
                }
            }
        });
    }
    match behaviour {
        Behaviour::Stream {
            head,
            body,
            chunks,
            every,
            repeat,
        } => {
            if stream.write_all(head.as_bytes()).is_err() || stream.flush().is_err() {
                return;
            }
            let mut at = if repeat || index == 0 { 0 } else { body.len() };
            let mut sizes = chunks.iter().cycle();
            while at < body.len() {
                let n = (*sizes.next().unwrap_or(&512)).min(body.len() - at);
                if stream.write_all(&body[at..at + n]).is_err() || stream.flush().is_err() {
                    return;
                }
                at += n;
                std::thread::sleep(every);
            }
            std::thread::sleep(Duration::from_secs(600));
        }
        Behaviour::Silent { head } => {
            let _ = stream.write_all(head.as_bytes());
            std::thread::sleep(Duration::from_secs(600));
        }
        Behaviour::Unauthorized => {
            let _ = stream.write_all(
                b"HTTP/1.1 401 Unauthorized\r\nWWW-Authenticate: Basic realm=\"MOUNT\"\r\n\r\n",
            );
        }
        Behaviour::Close => {}
    }
}

/// A pty master's reader: every byte chassisd writes to the receiver's port, kept.
pub struct PortReader {
    bytes: Arc<Mutex<Vec<u8>>>,
}

impl PortReader {
    /// Reads `master` from a thread of its own until the test ends; a master whose slave is
    /// not open yet reads as an error, and is tried again.
    pub fn start(mut master: std::fs::File) -> PortReader {
        let bytes = Arc::new(Mutex::new(Vec::new()));
        let kept = bytes.clone();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            loop {
                match master.read(&mut buf) {
                    Ok(0) | Err(_) => std::thread::sleep(Duration::from_millis(20)),
                    Ok(n) => kept.lock().unwrap().extend_from_slice(&buf[..n]),
                }
            }
        });
        PortReader { bytes }
    }

    /// Everything read so far.
    pub fn bytes(&self) -> Vec<u8> {
        self.bytes.lock().unwrap().clone()
    }

    /// Waits until at least `n` bytes have come (or `wait` passes); returns them all.
    pub fn wait_len(&self, n: usize, wait: Duration) -> Vec<u8> {
        let until = Instant::now() + wait;
        while self.bytes.lock().unwrap().len() < n && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(50));
        }
        self.bytes()
    }
}
