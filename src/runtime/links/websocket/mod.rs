//! The rosbridge v2 server (`[websocket]`, `--websocket ADDR`): WebSocket clients subscribe
//! to the vehicle's ROS topics and publish `/cmd_vel` and `/goal_pose`, with no ROS
//! installation. What the topics mean is `api::rosbridge`; this module moves them.
//!
//! Three parts. The engine's task hands the server what it publishes through a
//! [`WebsocketLink`], which never waits (a full queue drops the newest, counted). One server
//! task owns every client's subscriptions and fills each client's bounded queue. Each
//! connection has a task of its own that writes its queue to the socket and reads its
//! operations: a client that does not read loses its oldest messages and slows nobody.
//! Commands go to the engine as records of the source `websocket`, so a recording keeps
//! them and the engine's answer comes back to the client that sent them.

mod handshakes;
pub mod hub;
mod serve;
mod slots;

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use crate::runtime::error::{RuntimeError, io};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Extension, Query, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde_json::Value;
use tokio::sync::mpsc;

use self::hub::{Client, ClientQueue};
use self::serve::{Held, Limits};
use self::slots::{AUTH_WINDOW, Slot, Slots};
use crate::api::ros1::odometry::OdometryNoise;
use crate::api::rosbridge::ops::{self, Level};
use crate::api::rosbridge::publisher::{ControlTicks, Published, Publishing, odometry_every};
use crate::api::rosbridge::session::{Action, token_matches};
use crate::api::rosbridge::{SOURCE, adapter};
use crate::config::websocket::WebsocketConfig;
use crate::engine::{Engine, EngineOutput};
use crate::fusion::odometry::OdomPose;
use crate::record::{Payload, Record, SourceMeta};
use crate::runtime::clock::RecordClock;
use crate::runtime::links::command_rate::CommandRate;
use crate::runtime::refusals::Refusals;
use crate::time::Timestamp;
use crate::vehicle::VehicleStatus;

/// Feed items waiting for the server task before the newest are dropped (some 2 s).
const FEED_QUEUE: usize = 256;
/// Client events waiting for the server task.
const EVENT_QUEUE: usize = 1024;
/// Commands sent to the engine and not answered yet, at most.
const PENDING_ANSWERS: usize = 1024;

/// What the engine's outputs give the server.
#[derive(Debug, Clone)]
enum Feed {
    Status(Box<VehicleStatus>),
    /// A control tick's number, time and `odom` pose, when a topic publishes it.
    Odometry(u64, Timestamp, OdomPose),
    Answer(crate::api::adapter::Answer),
    Event(String),
}

/// The engine task's end: sending never blocks, and what does not fit is dropped and
/// counted (the next status or pose follows soon).
pub struct WebsocketLink {
    feed: mpsc::Sender<Feed>,
    ticks: ControlTicks,
    dropped: u64,
}

impl WebsocketLink {
    /// Looks at an engine output on its way elsewhere and takes what the topics need.
    pub fn see(&mut self, output: &EngineOutput) {
        let item = match output {
            EngineOutput::Status(s) => Feed::Status(s.clone()),
            EngineOutput::Poses(t, report) => match self.ticks.next(report) {
                Some((tick, odom)) => Feed::Odometry(tick, *t, odom),
                None => return,
            },
            EngineOutput::CommandResult {
                source,
                topic,
                request: Some(request),
                result,
                data,
            } if source == SOURCE => Feed::Answer(crate::api::adapter::Answer {
                topic: topic.clone(),
                request: Some(*request),
                result: result.clone(),
                data: data.clone(),
            }),
            EngineOutput::Event(event) => Feed::Event(event.to_string()),
            _ => return,
        };
        if self.feed.try_send(item).is_err() {
            self.dropped += 1;
            if self.dropped.is_power_of_two() {
                tracing::warn!(
                    dropped = self.dropped,
                    "websocket: the server is not keeping up; feed dropped"
                );
            }
        }
    }
}

/// The recording's entry for the clients' commands.
pub fn source_meta() -> SourceMeta {
    SourceMeta::commands(SOURCE, &format!("{SOURCE}.log"))
}

/// What the server task hears from connections.
enum Event {
    Connected(u64, Arc<ClientQueue>, Slot),
    Op(u64, String),
    /// The client's [`AUTH_WINDOW`] is over.
    AuthDeadline(u64),
    Gone(u64),
}

/// What every connection shares.
struct Shared {
    events: mpsc::Sender<Event>,
    token: Option<String>,
    /// Web pages allowed besides chassisd's own (`websocket.allowed_origins`).
    allowed_origins: Vec<String>,
    /// The clients' places.
    slots: Arc<Slots>,
    refusals: Arc<Refusals>,
    client_queue: usize,
    next_id: AtomicUsize,
}

/// Starts the server of `config` for a vehicle whose engine is `engine` (it then emits the
/// poses `/odom` needs); the clients' commands go to `records`.
pub fn start(
    engine: &mut Engine,
    vehicle: &crate::config::VehicleConfig,
    config: WebsocketConfig,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
) -> Result<WebsocketLink, RuntimeError> {
    let address = config.address().ok_or_else(|| {
        RuntimeError::Failed(format!(
            "websocket.bind {:?} is not an address",
            config.bind
        ))
    })?;
    let listener = listen(address).map_err(io(format!("websocket: cannot listen on {address}")))?;
    if let Ok(local) = listener.local_addr() {
        crate::runtime::listeners::own(local.port());
    }
    engine.emit_poses();
    let localizer = crate::config::localization::localizer_config(vehicle);
    let noise = OdometryNoise::from_localizer(&localizer, vehicle.imu.is_some());
    let (feed_tx, feed_rx) = mpsc::channel(FEED_QUEUE);
    let (events_tx, events_rx) = mpsc::channel(EVENT_QUEUE);
    let refusals = Refusals::start("websocket", serve::REASONS);
    let slots = Arc::new(Slots::new(config.max_clients));
    let shared = Arc::new(Shared {
        events: events_tx,
        token: config.token.clone(),
        allowed_origins: config.allowed_origins.clone(),
        slots: slots.clone(),
        refusals: refusals.clone(),
        client_queue: config.client_queue,
        next_id: AtomicUsize::new(1),
    });
    let server = Server {
        clients: BTreeMap::new(),
        places: BTreeMap::new(),
        rates: BTreeMap::new(),
        command_rate_hz: config.command_rate_hz,
        pending: BTreeMap::new(),
        last_request: 0,
        publishing: Publishing::new(noise, odometry_every(config.odom_rate_hz)),
        latched: BTreeMap::new(),
        token: config.token.clone(),
        slots,
        refusals: refusals.clone(),
        clock,
        records,
    };
    tokio::spawn(crate::runtime::panics::or_report_down(
        "websocket server",
        server.run(feed_rx, events_rx),
    ));
    let router = axum::Router::new()
        .route("/", axum::routing::get(root))
        .route("/connection", axum::routing::get(connection_check))
        .route(
            "/roslib.min.js",
            axum::routing::get(|| async { page(ROSLIB, "text/javascript; charset=utf-8") }),
        )
        .with_state(shared);
    let page = format!("http://{address}/");
    tracing::info!(%address, %page, token = config.token.is_some(), "websocket: rosbridge v2 server listening; the live page is at the same address over http");
    // Both kinds of places, authenticated or not.
    let limits = Limits::new(2 * config.max_clients, refusals);
    tokio::spawn(serve::serve(listener, router, limits));
    Ok(WebsocketLink {
        feed: feed_tx,
        ticks: ControlTicks::new(odometry_every(config.odom_rate_hz)),
        dropped: 0,
    })
}

/// The kernel's send buffer of each client's socket, bytes (inherited from the listener).
/// Fixed instead of autotuned (up to 4 MB on Linux): a client that stops reading then backs
/// up within a second of messages, and its own queue, bounded and counted, takes over.
/// Plenty for a dashboard on Wi-Fi: 64 KiB per 100 ms round trip is 640 KB/s.
const CLIENT_SEND_BUFFER: usize = 64 * 1024;

/// A listening socket on `address` whose accepted sockets get [`CLIENT_SEND_BUFFER`].
fn listen(address: std::net::SocketAddr) -> std::io::Result<tokio::net::TcpListener> {
    let socket = socket2::Socket::new(
        socket2::Domain::for_address(address),
        socket2::Type::STREAM,
        None,
    )?;
    socket.set_reuse_address(true)?;
    socket.set_send_buffer_size(CLIENT_SEND_BUFFER)?;
    socket.bind(&address.into())?;
    socket.listen(128)?;
    socket.set_nonblocking(true)?;
    tokio::net::TcpListener::from_std(socket.into())
}

/// The live page: a plain `GET /` (a WebSocket upgrade of `/` is a rosbridge client).
const PAGE: &str = include_str!("page/index.html");
/// roslibjs 1.4.1 from npm (`roslib`), vendored: the vehicle has no internet.
const ROSLIB: &str = include_str!("page/roslib.min.js");
/// The page may load only from chassisd itself and talk only to it.
const CONTENT_POLICY: &str = "default-src 'none'; script-src 'self' 'unsafe-inline'; \
     style-src 'unsafe-inline'; connect-src 'self'; img-src 'self' data:; base-uri 'none'; \
     form-action 'none'";

/// A static file with the page's content policy.
fn page(body: &'static str, content_type: &'static str) -> Response {
    (
        [
            (axum::http::header::CONTENT_TYPE, content_type),
            (axum::http::header::CONTENT_SECURITY_POLICY, CONTENT_POLICY),
            (axum::http::header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

/// What a WebSocket client is let in as: with the token (or none is set), or still to
/// present it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Entry {
    Authenticated,
    Waiting,
}

/// Who the client of a request would be let in as, or its refusal as an HTTP answer (an
/// Origin of another page, a wrong token), counted.
fn admission(
    shared: &Shared,
    peer: std::net::SocketAddr,
    query: &BTreeMap<String, String>,
    headers: &axum::http::HeaderMap,
) -> Result<Entry, (StatusCode, &'static str)> {
    let header = |name| headers.get(name).and_then(|v| v.to_str().ok());
    if let Some(origin) = header(axum::http::header::ORIGIN)
        && !origin_allowed(
            origin,
            header(axum::http::header::HOST),
            &shared.allowed_origins,
        )
    {
        shared.refusals.count("foreign_origin", Some(peer));
        return Err((
            StatusCode::FORBIDDEN,
            "chassisd: WebSocket connections from other web pages are refused; add the \
             page's origin to websocket.allowed_origins to let it in",
        ));
    }
    match (shared.token.as_deref(), query.get("token")) {
        (None, _) => Ok(Entry::Authenticated),
        (Some(token), Some(given)) if token_matches(Some(token), given) => Ok(Entry::Authenticated),
        (Some(_), Some(_)) => {
            shared.refusals.count("bad_token", Some(peer));
            Err((
                StatusCode::UNAUTHORIZED,
                "chassisd: wrong token (websocket.token): open the page as /?token=TOKEN with \
                 the configured one",
            ))
        }
        (Some(_), None) => Ok(Entry::Waiting),
    }
}

/// The answer to a client refused for want of a place of `entry`'s kind.
fn no_place(entry: Entry) -> Response {
    let text = match entry {
        Entry::Authenticated => {
            "chassisd: too many WebSocket clients (websocket.max_clients); close another \
             page or client, or raise the limit"
        }
        Entry::Waiting => {
            "chassisd: too many WebSocket clients waiting to authenticate; connect with \
             ?token=TOKEN"
        }
    };
    (StatusCode::SERVICE_UNAVAILABLE, text).into_response()
}

/// `GET /`: a WebSocket upgrade becomes a rosbridge client. With a token set, a wrong
/// `?token=` is refused here, and a client without one gets a place of those waiting to
/// authenticate, never an authenticated client's.
async fn root(
    State(shared): State<Arc<Shared>>,
    Extension(held): Extension<Held>,
    Query(query): Query<BTreeMap<String, String>>,
    headers: axum::http::HeaderMap,
    ws: Option<WebSocketUpgrade>,
) -> Response {
    let Some(ws) = ws else {
        return page(PAGE, "text/html; charset=utf-8");
    };
    let entry = match admission(&shared, held.peer, &query, &headers) {
        Ok(entry) => entry,
        Err(refused) => return refused.into_response(),
    };
    let slot = match entry {
        Entry::Authenticated => shared.slots.authenticated().ok_or("full"),
        Entry::Waiting => shared
            .slots
            .unauthenticated(held.peer.ip())
            .ok_or("unauthenticated_full"),
    };
    let slot = match slot {
        Ok(slot) => slot,
        Err(reason) => {
            shared.refusals.count(reason, Some(held.peer));
            return no_place(entry);
        }
    };
    ws.max_message_size(ops::MAX_MESSAGE + 1024)
        .on_upgrade(move |socket| connection(socket, shared, slot, held))
}

/// `GET /connection`: what a WebSocket client with the same address, Origin and `?token=`
/// would meet now, in words, without taking a place: a browser learns nothing of a refused
/// handshake, so the live page asks here why it could not connect.
async fn connection_check(
    State(shared): State<Arc<Shared>>,
    Extension(held): Extension<Held>,
    Query(query): Query<BTreeMap<String, String>>,
    headers: axum::http::HeaderMap,
) -> Response {
    let entry = match admission(&shared, held.peer, &query, &headers) {
        Ok(entry) => entry,
        Err(refused) => return refused.into_response(),
    };
    if !shared
        .slots
        .has_room(entry == Entry::Authenticated, held.peer.ip())
    {
        return no_place(entry);
    }
    match entry {
        Entry::Authenticated => (
            StatusCode::OK,
            "chassisd: a WebSocket client would be let in now",
        )
            .into_response(),
        // Let in to authenticate, which the page does only by its address.
        Entry::Waiting => (
            StatusCode::UNAUTHORIZED,
            "chassisd: this server wants its token (websocket.token): open the page as \
             /?token=TOKEN",
        )
            .into_response(),
    }
}

/// One client: its queue to the socket, its operations to the server task.
/// `_held` keeps the connection's descriptor and place in the server's total.
async fn connection(mut socket: WebSocket, shared: Arc<Shared>, slot: Slot, _held: Held) {
    let id = shared.next_id.fetch_add(1, Ordering::Relaxed) as u64;
    let queue = Arc::new(ClientQueue::new(shared.client_queue));
    // Only a client still to authenticate has a deadline; the server task judges it.
    let mut deadline_due = slot.is_unauthenticated();
    let deadline = tokio::time::sleep(AUTH_WINDOW);
    tokio::pin!(deadline);
    if shared
        .events
        .send(Event::Connected(id, queue.clone(), slot))
        .await
        .is_ok()
    {
        loop {
            tokio::select! {
                () = &mut deadline, if deadline_due => {
                    deadline_due = false;
                    if shared.events.send(Event::AuthDeadline(id)).await.is_err() {
                        break;
                    }
                }
                message = socket.recv() => match message {
                    Some(Ok(Message::Text(text))) => {
                        // A client flooding the server task waits here alone.
                        if shared.events.send(Event::Op(id, text)).await.is_err() {
                            break;
                        }
                    }
                    Some(Ok(Message::Binary(_))) => queue.push(
                        None,
                        ops::status(Level::Error, None, "binary messages are not taken: send JSON text"),
                    ),
                    Some(Err(e)) => {
                        // A message over the limit (or a broken frame): say why, then close.
                        let text = format!(
                            "closing: {e} (messages are limited to {} bytes)",
                            ops::MAX_MESSAGE
                        );
                        let _ = socket.send(Message::Text(ops::status(Level::Error, None, &text))).await;
                        let _ = socket.send(close_frame(1009, "message too big or malformed")).await;
                        break;
                    }
                    Some(Ok(Message::Close(_))) | None => break,
                    Some(Ok(_)) => {}
                },
                () = queue.ready.notified() => {
                    let mut failed = false;
                    for text in queue.take() {
                        if socket.send(Message::Text(text)).await.is_err() {
                            failed = true;
                            break;
                        }
                    }
                    if failed {
                        break;
                    }
                    if queue.is_closing() {
                        let _ = socket.send(close_frame(1008, "authentication failed")).await;
                        break;
                    }
                }
            }
        }
        let _ = shared.events.send(Event::Gone(id)).await;
    }
}

/// A Close frame with `code` and `reason`.
fn close_frame(code: u16, reason: &'static str) -> Message {
    Message::Close(Some(axum::extract::ws::CloseFrame {
        code,
        reason: reason.into(),
    }))
}

/// The server task's state.
struct Server {
    clients: BTreeMap<u64, Client>,
    /// Each client's place, given back when it goes.
    places: BTreeMap<u64, Slot>,
    /// Where places come from (a client that authenticates takes an authenticated one).
    slots: Arc<Slots>,
    refusals: Arc<Refusals>,
    /// Each client's publishing rate limit.
    rates: BTreeMap<u64, CommandRate>,
    command_rate_hz: f64,
    /// Who sent each command the engine has not answered yet, by the command's id.
    pending: BTreeMap<u64, u64>,
    /// The id of the last command sent.
    last_request: u64,
    /// What is published when (`api::rosbridge::publisher`).
    publishing: Publishing,
    /// The last message of each latched topic, sent to a new subscriber at once.
    latched: BTreeMap<&'static str, String>,
    token: Option<String>,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
}

impl Server {
    async fn run(mut self, mut feed: mpsc::Receiver<Feed>, mut events: mpsc::Receiver<Event>) {
        loop {
            tokio::select! {
                item = feed.recv() => match item {
                    Some(item) => self.on_feed(item),
                    None => return,
                },
                event = events.recv() => match event {
                    Some(Event::Connected(id, queue, slot)) => {
                        // Operators only: those still to authenticate are counted, never
                        // logged one by one.
                        let authenticated = !slot.is_unauthenticated();
                        if authenticated {
                            tracing::info!(client = id, "websocket: client connected");
                        }
                        self.clients.insert(id, Client::new(queue, authenticated));
                        self.places.insert(id, slot);
                        self.rates.insert(id, CommandRate::new(self.command_rate_hz, self.command_rate_hz.ceil() as u32));
                    }
                    Some(Event::Op(id, text)) => self.on_op(id, &text),
                    Some(Event::AuthDeadline(id)) => self.on_auth_deadline(id),
                    Some(Event::Gone(id)) => {
                        if let Some(client) = self.clients.remove(&id)
                            && client.session.authenticated
                        {
                            tracing::info!(client = id, dropped = client.queue.dropped(), "websocket: client gone");
                        }
                        self.places.remove(&id);
                        self.rates.remove(&id);
                    }
                    None => return,
                },
            }
        }
    }

    /// Offers `msg` on `topic` to every client due for it; a latched topic's is kept for
    /// the next subscribers.
    fn publish(&mut self, published: Published, now: Instant) {
        let Published {
            topic,
            msg,
            latched,
        } = published;
        let text = ops::publish(topic, &msg);
        for client in self.clients.values_mut() {
            client.offer(topic, &text, now);
        }
        if latched {
            self.latched.insert(topic, text);
        }
    }

    fn on_feed(&mut self, item: Feed) {
        let now = Instant::now();
        let clients = &self.clients;
        // A message nobody is due for is not built.
        let wanted = |topic: &str| clients.values().any(|c| c.wants(topic, now));
        let mut out = Vec::new();
        match item {
            Feed::Status(status) => self.publishing.on_status(&status, wanted, &mut out),
            Feed::Odometry(tick, t, pose) => {
                self.publishing
                    .on_odometry(tick, t, &pose, wanted, &mut out);
            }
            Feed::Event(text) => {
                let t = self.clock.now();
                self.publishing.on_event(t, &text, wanted, &mut out);
            }
            Feed::Answer(answer) => {
                let Some(id) = answer.request.and_then(|r| self.pending.remove(&r)) else {
                    return;
                };
                let topic = answer.topic;
                if let (Some(client), Err(reason)) = (self.clients.get(&id), answer.result) {
                    client.status(
                        Level::Error,
                        ops::status(Level::Error, None, &format!("{topic}: refused: {reason}")),
                    );
                }
            }
        }
        for message in out {
            self.publish(message, now);
        }
    }

    fn on_op(&mut self, id: u64, text: &str) {
        let now = Instant::now();
        let Some(client) = self.clients.get_mut(&id) else {
            return;
        };
        let mut publishes = Vec::new();
        let was_authenticated = client.session.authenticated;
        let failures = client.session.auth_failures();
        for action in client.session.on_op(text, now, self.token.as_deref()) {
            match action {
                Action::Status(level, text) => client.status(level, text),
                Action::Answer(text) => client.answer(text),
                Action::Close => client.queue.close(),
                Action::SubscribedToLatched(topic) => {
                    if let Some(text) = self.latched.get(topic) {
                        client.offer(topic, text, now);
                    }
                }
                Action::Publish {
                    name,
                    topic,
                    msg,
                    id: op_id,
                } => publishes.push((name, topic, msg, op_id)),
            }
        }
        if client.session.auth_failures() > failures {
            self.refusals.count("wrong_token", None);
        }
        if !was_authenticated && client.session.authenticated {
            self.on_authenticated(id);
        }
        for (name, topic, msg, op_id) in publishes {
            self.command(id, op_id.as_deref(), name, &topic, &msg);
        }
    }

    /// Client `id` presented the token: it moves to an authenticated client's place, or
    /// goes when none is free.
    fn on_authenticated(&mut self, id: u64) {
        let Some(client) = self.clients.get(&id) else {
            return;
        };
        match self.slots.authenticated() {
            // The place it waited in goes back.
            Some(slot) => {
                tracing::info!(client = id, "websocket: client authenticated");
                drop(self.places.insert(id, slot));
            }
            None => {
                self.refusals.count("full", None);
                client.status(
                    Level::Error,
                    ops::status(
                        Level::Error,
                        None,
                        "too many WebSocket clients (websocket.max_clients): the connection closes",
                    ),
                );
                client.queue.close();
            }
        }
    }

    /// Client `id`'s time to authenticate is over: it goes unless it has.
    fn on_auth_deadline(&mut self, id: u64) {
        let Some(client) = self.clients.get(&id) else {
            return;
        };
        if client.session.authenticated {
            return;
        }
        self.refusals.count("auth_timeout", None);
        let text = format!(
            "authentication: not done within {} s: the connection closes",
            AUTH_WINDOW.as_secs()
        );
        client.status(Level::Error, ops::status(Level::Error, None, &text));
        client.queue.close();
    }

    /// A client's checked `publish` on `name`: a command for the engine, within the
    /// client's rate.
    fn command(
        &mut self,
        id: u64,
        op_id: Option<&str>,
        name: &'static str,
        topic: &str,
        msg: &Value,
    ) {
        let Some(client) = self.clients.get(&id) else {
            return;
        };
        let refuse = |reason: &str| {
            client.status(
                Level::Error,
                ops::status(Level::Error, op_id, &format!("publish: {reason}")),
            );
        };
        let now = Instant::now();
        if let Some(rate) = self.rates.get_mut(&id)
            && !rate.admit(name, now).0
        {
            return client.status(
                Level::Warning,
                ops::status(
                    Level::Warning,
                    op_id,
                    &format!(
                        "publish: {topic} over websocket.command_rate_hz ({}/s); dropped",
                        self.command_rate_hz
                    ),
                ),
            );
        }
        let request = self.last_request + 1;
        let record = Record {
            t: self.clock.now(),
            source: SOURCE.into(),
            payload: Payload::Command {
                topic: name.into(),
                payload: adapter::encode(request, msg),
            },
        };
        if self.records.try_send(record).is_err() {
            return refuse(&format!("{topic}: the vehicle's queue is full; dropped"));
        }
        self.last_request = request;
        if self.pending.len() >= PENDING_ANSWERS {
            // The oldest: an answer lost on the way must not hold a place for ever.
            self.pending.pop_first();
        }
        self.pending.insert(request, id);
    }
}

/// Whether a browser page from `origin` may open a WebSocket: chassisd's own page (the
/// origin of the address the browser asked for, when that is an IP address or
/// `localhost`: a name could be an attacker's that resolves here, DNS rebinding), or a
/// page in `allowed`. Clients that send no Origin are not browsers and are not asked.
fn origin_allowed(origin: &str, host: Option<&str>, allowed: &[String]) -> bool {
    if allowed.iter().any(|a| a.eq_ignore_ascii_case(origin)) {
        return true;
    }
    let Some(host) = host else {
        return false;
    };
    let name = match host.rsplit_once(':') {
        // An IPv6 literal keeps its brackets: [::1]:9090.
        Some((name, port)) if port.chars().all(|c| c.is_ascii_digit()) => name,
        _ => host,
    };
    let literal = name.eq_ignore_ascii_case("localhost")
        || name.parse::<std::net::IpAddr>().is_ok()
        || name
            .strip_prefix('[')
            .and_then(|n| n.strip_suffix(']'))
            .is_some_and(|n| n.parse::<std::net::Ipv6Addr>().is_ok());
    literal && origin.eq_ignore_ascii_case(&format!("http://{host}"))
}
