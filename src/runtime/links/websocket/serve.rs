//! The server's accept loop. Each connection is admitted within the process's descriptor
//! budget and the server's caps, or closed at once and counted; its HTTP exchange is served
//! by hyper with a header timeout and a deadline, after which only an upgraded WebSocket
//! lives on (its place is then the rosbridge client's, see `slots`). `axum::serve` has none
//! of these: 20,000 half-sent requests held every descriptor of the process.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use super::handshakes::{self, Handshakes};
use crate::runtime::descriptors;
use crate::runtime::links::per_address::{AddressPlace, PerAddress};
use crate::runtime::refusals::Refusals;

/// A request's head (request line and headers) must have arrived within this long of the
/// connection's start.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(5);
/// The whole HTTP exchange (the request, and the page or the upgrade's answer) must be over
/// within this long; a connection still in it is closed.
pub const HTTP_DEADLINE: Duration = Duration::from_secs(10);
/// Connections in their HTTP exchange at once; a new one beyond takes the oldest one's
/// place (see `handshakes`).
pub const MAX_HANDSHAKES: usize = 64;
/// Connections in their HTTP exchange at once from one address.
pub const HANDSHAKES_PER_ADDRESS: usize = 8;
/// The largest request head read, bytes (hyper's least): a token and an Origin fit many
/// times over.
const MAX_HEAD: usize = 8192;

/// Why a connection was refused or closed, as the summary names it.
pub const REASONS: &[&str] = &[
    "over_descriptors",
    "over_connections",
    "handshake_evicted",
    "over_address",
    "accept_failed",
    "header_timeout",
    "http_deadline",
    "malformed",
    "foreign_origin",
    "bad_token",
    "wrong_token",
    "full",
    "unauthenticated_full",
    "auth_timeout",
];

/// The server's caps.
pub struct Limits {
    /// Connections at once, in any phase.
    total: Arc<Semaphore>,
    handshakes: Arc<Handshakes>,
    per_address: Arc<PerAddress>,
    /// What was refused or closed.
    pub refusals: Arc<Refusals>,
}

impl Limits {
    /// Caps for a server of `places` WebSocket places (authenticated or not).
    pub fn new(places: usize, refusals: Arc<Refusals>) -> Self {
        Self {
            // Room for connections told to go that have not closed yet.
            total: Arc::new(Semaphore::new(places + 2 * MAX_HANDSHAKES)),
            handshakes: Handshakes::new(MAX_HANDSHAKES),
            per_address: PerAddress::new(HANDSHAKES_PER_ADDRESS),
            refusals,
        }
    }
}

/// What a connection holds for its whole life (the descriptor's permit and its place in the
/// total), and its peer; the request handler gets it, and an upgraded WebSocket keeps it.
#[derive(Clone)]
pub struct Held {
    /// Who connected.
    pub peer: SocketAddr,
    _life: Arc<(OwnedSemaphorePermit, OwnedSemaphorePermit)>,
}

/// What a connection holds during its HTTP exchange only.
struct Handshake {
    place: handshakes::Place,
    _address: AddressPlace,
}

/// Serves `router` on `listener` for ever.
pub async fn serve(listener: TcpListener, router: axum::Router, limits: Limits) {
    let router = router.layer(axum::middleware::map_response(one_request_per_connection));
    let refusals = limits.refusals.clone();
    loop {
        let (socket, peer) = match listener.accept().await {
            Ok(accepted) => accepted,
            Err(_) => {
                // Out of descriptors, most likely: wait rather than spin.
                refusals.count("accept_failed", None);
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        match admit(&limits, peer) {
            Ok((held, handshake)) => {
                // Each message goes out as it is written: with Nagle's algorithm a small
                // frame waits for the client's delayed acknowledgement of the last (up to
                // 40 ms at /odom's 100 Hz).
                let _ = socket.set_nodelay(true);
                let router = router.clone();
                let refusals = refusals.clone();
                tokio::spawn(async move {
                    let mut handshake = handshake;
                    let evicted = &mut handshake.place.evicted;
                    exchange(socket, router, held, evicted, refusals).await;
                    drop(handshake);
                });
            }
            Err(reason) => {
                refusals.count(reason, Some(peer));
                drop(socket);
            }
        }
    }
}

/// A new connection's permits, or the reason it is closed at once.
fn admit(limits: &Limits, peer: SocketAddr) -> Result<(Held, Handshake), &'static str> {
    let descriptor = descriptors::try_acquire().ok_or("over_descriptors")?;
    let total = (limits.total.clone().try_acquire_owned()).map_err(|_| "over_connections")?;
    let address = limits.per_address.take(peer.ip()).ok_or("over_address")?;
    let (place, evicted) = limits.handshakes.enter();
    if evicted {
        limits.refusals.count("handshake_evicted", None);
    }
    let held = Held {
        peer,
        _life: Arc::new((descriptor, total)),
    };
    Ok((
        held,
        Handshake {
            place,
            _address: address,
        },
    ))
}

/// Serves one connection's HTTP exchange, within [`HEADER_TIMEOUT`] and [`HTTP_DEADLINE`].
/// A newer connection taking its place (`evicted`) ends it at once.
async fn exchange(
    socket: TcpStream,
    router: axum::Router,
    held: Held,
    evicted: &mut tokio::sync::oneshot::Receiver<()>,
    refusals: Arc<Refusals>,
) {
    let peer = held.peer;
    let service = WithHeld {
        inner: TowerToHyperService::new(router),
        held,
    };
    let connection = hyper::server::conn::http1::Builder::new()
        .timer(TokioTimer::new())
        .header_read_timeout(HEADER_TIMEOUT)
        .max_buf_size(MAX_HEAD)
        .serve_connection(TokioIo::new(socket), service)
        .with_upgrades();
    let served = tokio::select! {
        served = tokio::time::timeout(HTTP_DEADLINE, connection) => served,
        // Counted where the place was taken.
        Ok(()) = evicted => return,
    };
    match served {
        Ok(Ok(())) => {}
        Ok(Err(e)) if e.is_timeout() => refusals.count("header_timeout", Some(peer)),
        Ok(Err(e)) if e.is_parse() || e.is_parse_too_large() => {
            refusals.count("malformed", Some(peer));
        }
        // The client left, or the socket failed: nothing of the server's to report.
        Ok(Err(_)) => {}
        Err(_) => refusals.count("http_deadline", Some(peer)),
    }
}

/// One request per connection: every answer but an upgrade's says `Connection: close`, and
/// hyper closes the connection after it (a kept-alive one would sit in its exchange until
/// the deadline). Not by turning hyper's keep-alive off: that adds `close` to the upgrade's
/// `Connection: upgrade` too, which strict WebSocket clients (tungstenite's, websocat)
/// refuse.
async fn one_request_per_connection(
    mut response: axum::response::Response,
) -> axum::response::Response {
    if response.status() != axum::http::StatusCode::SWITCHING_PROTOCOLS {
        response.headers_mut().insert(
            axum::http::header::CONNECTION,
            axum::http::HeaderValue::from_static("close"),
        );
    }
    response
}

/// The router, with the connection's [`Held`] in every request's extensions.
#[derive(Clone)]
struct WithHeld {
    inner: TowerToHyperService<axum::Router>,
    held: Held,
}

impl hyper::service::Service<hyper::Request<Incoming>> for WithHeld {
    type Response = <TowerToHyperService<axum::Router> as hyper::service::Service<
        hyper::Request<Incoming>,
    >>::Response;
    type Error = <TowerToHyperService<axum::Router> as hyper::service::Service<
        hyper::Request<Incoming>,
    >>::Error;
    type Future = <TowerToHyperService<axum::Router> as hyper::service::Service<
        hyper::Request<Incoming>,
    >>::Future;

    fn call(&self, mut request: hyper::Request<Incoming>) -> Self::Future {
        request.extensions_mut().insert(self.held.clone());
        self.inner.call(request)
    }
}
