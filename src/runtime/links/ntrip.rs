//! The NTRIP client: one task that keeps a connection to a caster, sends the rover's position
//! as GGA, and hands the correction stream on as `rtcm` records (the bytes as the caster sent
//! them, de-chunked), with link-state records when a stream starts and ends. It never gives
//! up and never storms the caster: [`crate::ntrip::backoff`] decides when to connect.
//!
//! The task frames the stream itself only to know that it is alive: a connection that
//! delivers no valid RTCM 3 frame for `timeout` is dropped, and only a connection that
//! delivered frames resets the back-off. What reaches a receiver is framed again downstream.

use std::time::Duration;

use bytes::Bytes;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, watch};
use tokio::time::{Instant, sleep_until, timeout};

use crate::devices::gnss::encode::GgaFix;
use crate::devices::gnss::rtcm::RtcmFramer;
pub use crate::ntrip::NtripSpec;
use crate::ntrip::backoff::Backoff;
use crate::ntrip::chunked::{ChunkError, Dechunker};
use crate::ntrip::request::request;
use crate::ntrip::response::{Head, HeadError, MAX_HEAD, Status, parse_head};
use crate::ntrip::sourcetable::{self, MAX_TABLE};
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::error::RuntimeError;
use crate::vehicle::LinkState;

/// Source name of the corrections in records.
pub const SOURCE: &str = crate::engine::CORRECTIONS_SOURCE;
/// The GGA interval used when the configuration sends none and the caster's table says the
/// mountpoint needs one.
const GGA_WHEN_WANTED: Duration = Duration::from_secs(10);
/// Read buffer, bytes.
const READ_BUFFER: usize = 4096;
/// What to do about refused credentials (the client's log and `check` say it alike).
const CREDENTIALS_FIX: &str = "check the user and the password (or password_file)";
/// Mountpoints named in a "not found" report, at most.
const LISTED: usize = 12;

/// What the task reports to whoever watches (`check`, diagnostics).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ClientState {
    /// Connected and streaming.
    pub streaming: bool,
    /// Connects so far.
    pub attempts: u64,
    /// Why the last connection ended or failed, with the fix.
    pub last_error: Option<String>,
    /// Valid frames over every connection.
    pub frames: u64,
    /// Bytes dropped by the liveness framer.
    pub invalid_bytes: u64,
    /// GGA sentences sent.
    pub ggas_sent: u64,
}

/// The engine is gone: the task ends.
struct Closed;

/// What a connection works with.
struct Link<'a> {
    spec: &'a NtripSpec,
    clock: &'a RecordClock,
    tx: &'a mpsc::Sender<Record>,
    position: &'a watch::Receiver<Option<GgaFix>>,
    state: &'a watch::Sender<ClientState>,
}

/// How a connection ended.
struct Ended {
    reason: String,
    delivered: bool,
}

impl Ended {
    fn failed(reason: impl Into<String>) -> Self {
        Self {
            reason: reason.into(),
            delivered: false,
        }
    }
}

/// Runs until the receiving side of `tx` closes. `position` holds the rover's latest fix for
/// the GGA (or the fallback position before the first).
pub async fn run(
    spec: NtripSpec,
    clock: RecordClock,
    tx: mpsc::Sender<Record>,
    position: watch::Receiver<Option<GgaFix>>,
    state: watch::Sender<ClientState>,
) {
    let start = Instant::now();
    let mut backoff = Backoff::new();
    let mut spec = spec;
    if spec.gga_interval.is_none() {
        // The table says whether the mountpoint needs the rover's position (a virtual
        // reference station sends nothing without it).
        backoff.connecting(start.elapsed());
        if let Ok(table) = mountpoints(&spec).await
            && table
                .iter()
                .any(|s| s.mountpoint == spec.url.mountpoint && s.wants_gga)
        {
            tracing::warn!(caster = %spec.url, interval_s = GGA_WHEN_WANTED.as_secs(),
                "the caster's table says this mountpoint needs the rover's position (nmea=1): \
                 sending GGA although gga_interval_s = 0");
            spec.gga_interval = Some(GGA_WHEN_WANTED);
        }
    }
    loop {
        let at = backoff.next_connect(start.elapsed());
        sleep_until(start + at).await;
        backoff.connecting(start.elapsed());
        state.send_modify(|s| s.attempts += 1);
        let link = Link {
            spec: &spec,
            clock: &clock,
            tx: &tx,
            position: &position,
            state: &state,
        };
        let ended = match session(&link).await {
            Ok(e) => e,
            Err(Closed) => return,
        };
        state.send_modify(|s| {
            s.streaming = false;
            s.last_error = Some(ended.reason.clone());
        });
        let wait = backoff.ended(start.elapsed(), ended.delivered);
        if ended.delivered || Backoff::worth_logging(backoff.failures()) {
            tracing::warn!(caster = %spec.url, reason = %ended.reason,
                failures = backoff.failures(), retry_in_s = wait.as_secs(),
                "NTRIP connection ended; reconnecting");
        } else {
            tracing::debug!(caster = %spec.url, reason = %ended.reason, "NTRIP connect failed");
        }
        if tx.is_closed() {
            return;
        }
    }
}

async fn send(
    tx: &mpsc::Sender<Record>,
    clock: &RecordClock,
    payload: Payload,
) -> Result<(), Closed> {
    let record = Record {
        t: clock.now(),
        source: SOURCE.into(),
        payload,
    };
    tx.send(record).await.map_err(|_| Closed)
}

/// A connection to a caster: TCP, or TLS over it.
trait CasterStream: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send {}

impl<T: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send> CasterStream for T {}

type Conn = Box<dyn CasterStream>;

/// Connects (with TLS for `ntrips://`) and writes the request for the mountpoint (or the
/// table).
async fn open(spec: &NtripSpec, sourcetable: bool) -> Result<Conn, String> {
    let address = spec.url.address();
    let tcp = match timeout(spec.timeout, TcpStream::connect(&address)).await {
        Ok(Ok(s)) => s,
        Ok(Err(e)) => return Err(format!("cannot connect to {address}: {e}")),
        Err(_) => {
            return Err(format!(
                "no answer from {address} within {} s",
                spec.timeout.as_secs()
            ));
        }
    };
    let _ = tcp.set_nodelay(true);
    let mut stream: Conn = match (spec.url.tls, &spec.tls) {
        (false, _) => Box::new(tcp),
        (true, None) => return Err("ntrips:// without a TLS configuration".into()),
        (true, Some(config)) => {
            let name = rustls::pki_types::ServerName::try_from(spec.url.host.clone())
                .map_err(|e| format!("{:?} is no name for TLS: {e}", spec.url.host))?;
            let connector = tokio_rustls::TlsConnector::from(config.clone());
            match timeout(spec.timeout, connector.connect(name, tcp)).await {
                Ok(Ok(tls)) => Box::new(tls),
                Ok(Err(e)) => {
                    return Err(format!(
                        "TLS with {address} failed: {e} (is it a TLS port? is its \
                         certificate's authority trusted, or named as {}?)",
                        spec.ca_setting
                    ));
                }
                Err(_) => {
                    return Err(format!(
                        "no TLS handshake with {address} within {} s",
                        spec.timeout.as_secs()
                    ));
                }
            }
        }
    };
    let text = request(&spec.url, spec.version, sourcetable);
    stream
        .write_all(text.as_bytes())
        .await
        .map_err(|e| format!("cannot send the request to {address}: {e}"))?;
    Ok(stream)
}

/// Reads the head; the bytes after it stay in `buf`.
async fn read_head(stream: &mut Conn, buf: &mut Vec<u8>, limit: Duration) -> Result<Head, String> {
    let deadline = Instant::now() + limit;
    loop {
        match parse_head(buf) {
            Ok(Some(head)) => {
                buf.drain(..head.length);
                return Ok(head);
            }
            Ok(None) => {}
            Err(HeadError::NotAStatus(line)) => {
                return Err(format!(
                    "the server is no NTRIP caster (it answered {line:?}): check the host and port"
                ));
            }
            Err(e @ HeadError::TooLong) => return Err(e.to_string()),
        }
        let mut chunk = [0u8; READ_BUFFER];
        let n = match tokio::time::timeout_at(deadline, stream.read(&mut chunk)).await {
            Ok(Ok(0)) => return Err("the caster closed the connection before answering".into()),
            Ok(Ok(n)) => n,
            Ok(Err(e)) => return Err(format!("reading the caster's answer: {e}")),
            Err(_) => {
                return Err(format!(
                    "the caster did not answer within {} s",
                    limit.as_secs()
                ));
            }
        };
        buf.extend_from_slice(&chunk[..n]);
        if buf.len() > MAX_HEAD + READ_BUFFER {
            return Err(HeadError::TooLong.to_string());
        }
    }
}

/// A response's body as it arrives: de-chunked when the caster chunks it (NTRIP 2.0).
struct Body(Option<Dechunker>);

impl Body {
    fn of(head: &Head) -> Self {
        Self(head.chunked.then(Dechunker::new))
    }

    /// Moves the body's bytes among `raw` (emptied) to the end of `body`.
    fn take(&mut self, raw: &mut Vec<u8>, body: &mut Vec<u8>) -> Result<(), ChunkError> {
        match &mut self.0 {
            Some(d) => d.push(raw, body)?,
            None => body.append(raw),
        }
        raw.clear();
        Ok(())
    }

    /// The caster ended a chunked body.
    fn is_done(&self) -> bool {
        self.0.as_ref().is_some_and(Dechunker::is_done)
    }
}

/// Why the caster's table could not be had: it did not answer, or answered otherwise.
struct NoTable {
    /// The caster answered (a status other than its table, or a broken table).
    answered: bool,
    why: String,
}

impl std::fmt::Display for NoTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.why)
    }
}

/// The caster's mountpoints (for a report), or why they cannot be had.
async fn mountpoints(spec: &NtripSpec) -> Result<Vec<sourcetable::Stream>, NoTable> {
    let unreachable = |why: String| NoTable {
        answered: false,
        why,
    };
    let mut stream = open(spec, true).await.map_err(unreachable)?;
    let mut buf = Vec::new();
    let head = read_head(&mut stream, &mut buf, spec.timeout)
        .await
        .map_err(unreachable)?;
    let answered = |why: String| NoTable {
        answered: true,
        why,
    };
    match &head.status {
        Status::Sourcetable | Status::Icy | Status::Http => {}
        Status::Error(code, reason) => {
            return Err(answered(format!(
                "the caster answered {code} {reason} instead of its table"
            )));
        }
    }
    let deadline = Instant::now() + spec.timeout;
    let mut body = Vec::new();
    let mut decoder = Body::of(&head);
    let mut pending = std::mem::take(&mut buf);
    loop {
        decoder
            .take(&mut pending, &mut body)
            .map_err(|e| answered(format!("the table's body: {e}")))?;
        let text = String::from_utf8_lossy(&body);
        if sourcetable::is_complete(&text) || body.len() > MAX_TABLE {
            return Ok(sourcetable::parse(&text));
        }
        let mut chunk = [0u8; READ_BUFFER];
        match tokio::time::timeout_at(deadline, stream.read(&mut chunk)).await {
            Ok(Ok(0)) | Err(_) => return Ok(sourcetable::parse(&text)),
            Ok(Ok(n)) => pending = chunk[..n].to_vec(),
            Ok(Err(e)) => return Err(answered(format!("reading the table: {e}"))),
        }
    }
}

/// Why the mountpoint was refused, with the caster's list.
async fn not_found(spec: &NtripSpec) -> String {
    let mount = &spec.url.mountpoint;
    match mountpoints(spec).await {
        Ok(list) if list.is_empty() => {
            format!("the caster has no mountpoint {mount:?}, and its table lists none")
        }
        Ok(list) => {
            let names: Vec<&str> = list
                .iter()
                .take(LISTED)
                .map(|s| s.mountpoint.as_str())
                .collect();
            let more = list.len().saturating_sub(LISTED);
            format!(
                "the caster has no mountpoint {mount:?}; it has {}{}: fix the URL's mountpoint",
                names.join(", "),
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            )
        }
        Err(e) => format!("the caster has no mountpoint {mount:?} (its table: {e})"),
    }
}

/// One connection, from connect to its end.
async fn session(link: &Link<'_>) -> Result<Ended, Closed> {
    let Link {
        spec,
        clock,
        tx,
        state,
        ..
    } = *link;
    let mut stream = match open(spec, false).await {
        Ok(s) => s,
        Err(e) => return Ok(Ended::failed(e)),
    };
    let mut buf = Vec::new();
    let head = match read_head(&mut stream, &mut buf, spec.timeout).await {
        Ok(h) => h,
        Err(e) => return Ok(Ended::failed(e)),
    };
    match &head.status {
        Status::Icy | Status::Http => {}
        Status::Error(code @ (401 | 403), reason) => {
            return Ok(Ended::failed(format!(
                "the caster refused the credentials ({code} {reason}): {CREDENTIALS_FIX}"
            )));
        }
        // NTRIP 1.0 casters answer an unknown mountpoint with their table.
        Status::Error(404, _) | Status::Sourcetable => {
            return Ok(Ended::failed(not_found(spec).await));
        }
        Status::Error(code, reason) => {
            return Ok(Ended::failed(format!(
                "the caster answered {code} {reason}"
            )));
        }
    }
    if let Some(encoding) = &head.content_encoding {
        return Ok(Ended::failed(format!(
            "the caster sends its stream in {encoding} content encoding, which chassisd does \
             not decode: use the mountpoint without compression"
        )));
    }
    send(tx, clock, Payload::Link(LinkState::Up)).await?;
    state.send_modify(|s| s.streaming = true);
    let ended = stream_corrections(link, &mut stream, head, buf).await;
    send(tx, clock, Payload::Link(LinkState::Down)).await?;
    ended
}

async fn stream_corrections(
    link: &Link<'_>,
    stream: &mut Conn,
    head: Head,
    first: Vec<u8>,
) -> Result<Ended, Closed> {
    let Link {
        spec,
        clock,
        tx,
        position,
        state,
    } = *link;
    let mut decoder = Body::of(&head);
    let mut framer = RtcmFramer::new();
    let mut delivered = false;
    let mut last_valid = Instant::now();
    // The first GGA at once: a virtual reference station sends nothing before it.
    let mut next_gga = spec.gga_interval.map(|_| Instant::now());
    let mut pending = first;
    let mut chunk = vec![0u8; READ_BUFFER];
    loop {
        if !pending.is_empty() {
            let mut body = Vec::with_capacity(pending.len());
            if let Err(e) = decoder.take(&mut pending, &mut body) {
                return Ok(Ended {
                    reason: format!("the caster's chunked stream broke: {e}"),
                    delivered,
                });
            }
            let before = framer.stats().frames;
            framer.push(&body, |_, _| {});
            let stats = framer.stats();
            if stats.frames > before {
                delivered = true;
                last_valid = Instant::now();
            }
            let (frames, invalid) = (stats.frames - before, stats.invalid_bytes);
            state.send_modify(|s| {
                s.frames += frames;
                s.invalid_bytes = invalid;
            });
            if !body.is_empty() {
                send(tx, clock, Payload::Serial(Bytes::from(body))).await?;
            }
            if decoder.is_done() {
                return Ok(Ended {
                    reason: "the caster ended its stream".into(),
                    delivered,
                });
            }
        }
        let silent_until = last_valid + spec.timeout;
        let gga_at = next_gga.unwrap_or(silent_until + Duration::from_secs(3600));
        tokio::select! {
            read = stream.read(&mut chunk) => match read {
                Ok(0) => return Ok(Ended { reason: "the caster closed the connection".into(), delivered }),
                Ok(n) => pending.extend_from_slice(&chunk[..n]),
                Err(e) => return Ok(Ended { reason: format!("reading the stream: {e}"), delivered }),
            },
            () = sleep_until(gga_at), if next_gga.is_some() => {
                let fix = *position.borrow();
                if let Some(fix) = fix {
                    let sentence = fix.gga();
                    if let Err(e) = stream.write_all(sentence.as_bytes()).await {
                        return Ok(Ended { reason: format!("sending the GGA: {e}"), delivered });
                    }
                    state.send_modify(|s| s.ggas_sent += 1);
                }
                next_gga = spec.gga_interval.map(|i| gga_at + i);
            }
            () = sleep_until(silent_until) => {
                return Ok(Ended {
                    reason: format!("no valid RTCM 3 frame for {} s", spec.timeout.as_secs()),
                    delivered,
                });
            }
        }
    }
}

/// The running client of `[ntrip]`, as the engine's loop holds it.
pub struct CorrectionsClient {
    position: watch::Sender<Option<GgaFix>>,
    state: watch::Receiver<ClientState>,
    /// The fallback position, sent until the receiver has a fix.
    fallback: Option<GgaFix>,
}

impl CorrectionsClient {
    /// Hands the receiver's latest fix to the GGA (the fallback stays until there is one).
    pub fn update_position(&self, fix: Option<&crate::devices::gnss::GnssFix>) {
        let Some(gga) = fix.and_then(GgaFix::from_fix) else {
            return;
        };
        self.position.send_if_modified(|p| {
            let changed = *p != Some(gga);
            *p = Some(gga);
            changed
        });
    }

    /// What the client reports.
    pub fn state(&self) -> ClientState {
        self.state.borrow().clone()
    }

    /// The position sent before the first fix.
    pub fn fallback(&self) -> Option<GgaFix> {
        self.fallback
    }
}

/// Starts the client of `[ntrip]` (the password file is read now). Its records go to `tx`.
pub fn spawn(
    config: &crate::config::ntrip::NtripConfig,
    clock: RecordClock,
    tx: mpsc::Sender<Record>,
) -> Result<CorrectionsClient, RuntimeError> {
    let spec = config.spec().map_err(RuntimeError::Failed)?;
    let fallback = config
        .fallback_position
        .map(|p| GgaFix::fallback(p.lat, p.lon, p.height));
    let (position, position_rx) = watch::channel(fallback);
    let (state_tx, state) = watch::channel(ClientState::default());
    tracing::info!(caster = %spec.url, version = ?spec.version,
        gga_interval_s = spec.gga_interval.map(|d| d.as_secs_f64()),
        "NTRIP client starting");
    tokio::spawn(crate::runtime::panics::restarting(
        "NTRIP client",
        move || {
            run(
                spec.clone(),
                clock,
                tx.clone(),
                position_rx.clone(),
                state_tx.clone(),
            )
        },
    ));
    Ok(CorrectionsClient {
        position,
        state,
        fallback,
    })
}

/// One step of `chassisd check`'s probe of the caster: what was probed, and ok with what
/// was seen, or the reason and the fix.
pub type ProbeStep = (&'static str, Result<String, (String, String)>);

/// `chassisd check`'s probe: the caster reachable, the mountpoint in its table, the
/// credentials accepted, valid frames arriving (within `spec.timeout`, GGA sent first).
pub async fn probe(spec: &NtripSpec, position: Option<GgaFix>) -> Vec<ProbeStep> {
    const REACHABLE: &str = "caster reachable";
    const LISTED_STEP: &str = "mountpoint in the table";
    const AUTH: &str = "credentials accepted";
    const FRAMES: &str = "frames arriving";
    let not_probed = |why: &str| Err((format!("not probed: {why}"), "fix the step above".into()));
    let mut steps = Vec::new();
    let table = match mountpoints(spec).await {
        Ok(t) => Ok(t),
        // It answered, without its table (401 for a table behind the login, or none): the
        // mountpoint is probed on.
        Err(e) if e.answered => Err(e.why),
        Err(e) => {
            let e = e.why;
            steps.push((
                REACHABLE,
                Err((
                    e,
                    format!(
                        "check the host and port ({}) and this computer's network",
                        spec.url.address()
                    ),
                )),
            ));
            for what in [LISTED_STEP, AUTH, FRAMES] {
                steps.push((what, not_probed("the caster is not reachable")));
            }
            return steps;
        }
    };
    let mount = &spec.url.mountpoint;
    let withheld = table.is_err();
    let table = match table {
        Ok(table) => table,
        Err(why) => {
            steps.push((REACHABLE, Ok(format!("{} answers", spec.url.address()))));
            steps.push((
                LISTED_STEP,
                Err((
                    why,
                    format!(
                        "a 401 or 403: {CREDENTIALS_FIX}; otherwise the caster keeps its table \
                         to itself, and the mountpoint is tried below"
                    ),
                )),
            ));
            Vec::new()
        }
    };
    let listed = table.iter().find(|s| &s.mountpoint == mount);
    let wants_gga = listed.is_some_and(|s| s.wants_gga);
    if !withheld {
        steps.push((
            REACHABLE,
            Ok(format!(
                "{} answers, {} mountpoints listed",
                spec.url.address(),
                table.len()
            )),
        ));
        steps.push((
            LISTED_STEP,
            match listed {
                Some(s) => Ok(format!(
                    "{mount}{}",
                    if s.wants_gga { " (wants GGA)" } else { "" }
                )),
                None => Err((
                    not_found(spec).await,
                    "fix the URL's mountpoint (some casters list only a few: then this may be \
                     right)"
                        .into(),
                )),
            },
        ));
    }
    let mut stream = match open(spec, false).await {
        Ok(s) => s,
        Err(e) => {
            steps.push((AUTH, Err((e, "check the caster's address".into()))));
            steps.push((FRAMES, not_probed("no connection")));
            return steps;
        }
    };
    let mut buf = Vec::new();
    let head = match read_head(&mut stream, &mut buf, spec.timeout).await {
        Ok(h) => h,
        Err(e) => {
            steps.push((AUTH, Err((e, "check the host and port".into()))));
            steps.push((FRAMES, not_probed("no answer")));
            return steps;
        }
    };
    match &head.status {
        Status::Icy => steps.push((AUTH, Ok("ICY 200 OK (NTRIP 1.0)".into()))),
        Status::Http => steps.push((AUTH, Ok("HTTP 200 (NTRIP 2.0)".into()))),
        Status::Error(code @ (401 | 403), reason) => {
            steps.push((
                AUTH,
                Err((
                    format!("the caster refused the credentials ({code} {reason})"),
                    CREDENTIALS_FIX.into(),
                )),
            ));
            steps.push((FRAMES, not_probed("not authenticated")));
            return steps;
        }
        other => {
            let (answer, fix) = match other {
                Status::Error(code @ 500.., reason) => (
                    format!("{code} {reason}"),
                    "the caster is failing or busy: try again later, or ask its operator",
                ),
                Status::Error(code, reason) => (
                    format!("{code} {reason}"),
                    "fix the URL's mountpoint (the caster's table lists them)",
                ),
                _ => (
                    "its table instead".into(),
                    "fix the URL's mountpoint (the caster's table lists them)",
                ),
            };
            steps.push((
                AUTH,
                Err((
                    format!("the caster did not serve the mountpoint: it answered {answer}"),
                    fix.into(),
                )),
            ));
            steps.push((FRAMES, not_probed("no stream")));
            return steps;
        }
    }
    if let Some(fix) = position.filter(|_| wants_gga || spec.gga_interval.is_some()) {
        let _ = stream.write_all(fix.gga().as_bytes()).await;
    }
    let mut decoder = Body::of(&head);
    let mut framer = RtcmFramer::new();
    let deadline = Instant::now() + spec.timeout;
    let mut pending = buf;
    let mut chunk = vec![0u8; READ_BUFFER];
    let mut body = Vec::new();
    loop {
        if decoder.take(&mut pending, &mut body).is_err() {
            break;
        }
        framer.push(&body, |_, _| {});
        body.clear();
        if framer.stats().frames >= 3 {
            break;
        }
        match tokio::time::timeout_at(deadline, stream.read(&mut chunk)).await {
            Ok(Ok(n)) if n > 0 => pending.extend_from_slice(&chunk[..n]),
            _ => break,
        }
    }
    let stats = framer.stats();
    steps.push((
        FRAMES,
        if stats.frames > 0 {
            let types: Vec<String> = stats.by_type.keys().map(u16::to_string).collect();
            Ok(format!(
                "{} valid RTCM 3 frames (messages {})",
                stats.frames,
                types.join(", ")
            ))
        } else {
            Err((
                format!(
                    "no valid RTCM 3 frame within {} s ({} bytes dropped)",
                    spec.timeout.as_secs(),
                    stats.invalid_bytes
                ),
                if position.is_none() {
                    "a virtual reference station sends nothing before a GGA: set \
                     ntrip.fallback_position"
                        .into()
                } else {
                    "check that the base station is up, and the mountpoint's format (RTCM 3)".into()
                },
            ))
        },
    ));
    steps
}

/// What `chassisd ntrip` did.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FetchReport {
    /// Valid frames written.
    pub frames: u64,
    /// Their bytes.
    pub bytes: u64,
    /// Frames per message number.
    pub by_type: std::collections::BTreeMap<u16, u64>,
    /// Bytes dropped (outside frames, or in frames whose CRC failed).
    pub invalid_bytes: u64,
    /// Connects.
    pub attempts: u64,
    /// GGA sentences sent.
    pub ggas_sent: u64,
    /// Why the last connection ended, if one did.
    pub last_error: Option<String>,
}

/// Runs the client for `duration` (or until interrupted) and writes every valid frame, whole
/// and in order, to `out`: `chassisd ntrip`, a str2str of chassisd's own client.
pub async fn fetch(
    spec: NtripSpec,
    position: Option<GgaFix>,
    mut out: Box<dyn tokio::io::AsyncWrite + Unpin + Send>,
    duration: Option<Duration>,
) -> std::io::Result<FetchReport> {
    let (tx, mut rx) = mpsc::channel::<Record>(64);
    let (_position_tx, position_rx) = watch::channel(position);
    let (state_tx, state_rx) = watch::channel(ClientState::default());
    let clock = RecordClock::start();
    let client = tokio::spawn(run(spec, clock, tx, position_rx, state_tx));
    let mut framer = RtcmFramer::new();
    let end = duration.map(|d| Instant::now() + d);
    let stopped = async {
        match end {
            Some(end) => sleep_until(end).await,
            None => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    };
    tokio::pin!(stopped);
    loop {
        tokio::select! {
            record = rx.recv() => {
                let Some(record) = record else { break };
                if let Payload::Serial(bytes) = record.payload {
                    let mut whole = Vec::with_capacity(bytes.len());
                    framer.push(&bytes, |frame, _| whole.extend_from_slice(frame));
                    out.write_all(&whole).await?;
                    out.flush().await?;
                }
            }
            () = &mut stopped => break,
        }
    }
    client.abort();
    let s = framer.stats();
    let state = state_rx.borrow().clone();
    Ok(FetchReport {
        frames: s.frames,
        bytes: s.frame_bytes,
        by_type: s.by_type.clone(),
        invalid_bytes: s.invalid_bytes,
        attempts: state.attempts,
        ggas_sent: state.ggas_sent,
        last_error: state.last_error,
    })
}
