//! The node's graph in its own process: roslibrust's node handle, its publishers, the
//! subscribers and services that take requests, and the master watched. Requests go up to
//! chassisd (see [`super::pipe`]); a service caller waits for the vehicle's answer.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use roslibrust::ros1::{MasterClient, NodeHandle, ServiceServer};
use tokio::sync::mpsc;
use tokio::task::JoinSet;

use super::messages::{self, geometry_msgs, map_msgs, std_msgs};
use super::pipe::{FromNode, NodeSettings, Verdict};
use crate::api::ros1::adapter::{Point, RegionRequest, Ros1Request, ShapeRequest};
use crate::api::ros1::topics::{self, Topic};
use crate::runtime::links::command_rate::{CommandRate, RateReport};

/// How often the master is asked whether it still knows the node.
pub const WATCH_EVERY: Duration = Duration::from_secs(1);
/// Service calls that may wait for the vehicle's answer at once; more are refused as busy.
const MAX_PENDING: usize = 64;
/// How long a service call waits for the vehicle's answer.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(2);
/// How long a call keeps its place while no answer comes.
const FORGET_AFTER: Duration = Duration::from_secs(10);
/// Messages queued per subscribed topic in roslibrust before the oldest go.
const SUBSCRIBER_QUEUE: usize = 16;
/// Service calls waiting for the vehicle's answer, by call number.
#[derive(Default)]
struct Calls {
    last: u64,
    by_call: HashMap<u64, (std::sync::mpsc::SyncSender<Verdict>, Instant)>,
}

/// A rate limit and its settings: `ros1.command_rate_hz` and `ros1.command_burst`.
struct Limit {
    rate: CommandRate,
    rate_hz: f64,
    burst: u32,
}

impl Limit {
    fn new((rate_hz, burst): (f64, u32)) -> Self {
        Self {
            rate: CommandRate::new(rate_hz, burst),
            rate_hz,
            burst,
        }
    }

    /// Whether a message or call on `name` is within its rate now. Those beyond it are
    /// `left` ("dropped", "refused"): logged once when it starts on a name, then summed up
    /// every 5 s while it lasts.
    fn admit(&mut self, name: &str, what: &str, left: &str) -> bool {
        let now = Instant::now();
        let (admitted, report) = self.rate.admit(name, now);
        match report.or_else(|| self.rate.due_summary(now)) {
            Some(RateReport::Started(_)) => tracing::warn!(
                name,
                limit_hz = self.rate_hz,
                burst = self.burst,
                "ROS1 {what} over the rate limit are {left}; a summary follows every 5 s while it lasts"
            ),
            Some(RateReport::Summary(counts)) => {
                let count: u64 = counts.iter().map(|(_, n)| n).sum();
                tracing::warn!(
                    count,
                    "ROS1 {what} {left} over the rate limit in the last 5 s"
                );
            }
            None => {}
        }
        admitted
    }
}

/// Hands requests up to chassisd; answers come back by call number.
#[derive(Clone)]
pub struct Requests {
    up: mpsc::Sender<FromNode>,
    calls: Arc<Mutex<Calls>>,
    /// Service calls within their rate per service, as topics' messages are: a client that
    /// polls a query as fast as it can is refused beyond the rate, and never holds the
    /// places every other caller waits in.
    service_rate: Arc<Mutex<Limit>>,
}

impl Requests {
    /// Requests that go up through `up`; service calls within `rate` (per second, burst).
    pub fn new(up: mpsc::Sender<FromNode>, rate: (f64, u32)) -> Self {
        Self {
            up,
            calls: Arc::new(Mutex::new(Calls::default())),
            service_rate: Arc::new(Mutex::new(Limit::new(rate))),
        }
    }

    /// Sends `request` up; a `waiter` gets the vehicle's answer.
    fn submit(
        &self,
        request: Ros1Request,
        waiter: Option<std::sync::mpsc::SyncSender<Verdict>>,
    ) -> Result<(), String> {
        let mut calls = self
            .calls
            .lock()
            .map_err(|_| "the ROS1 node's request queue is broken".to_owned())?;
        let call = match waiter {
            Some(waiter) => {
                calls
                    .by_call
                    .retain(|_, (_, at)| at.elapsed() < FORGET_AFTER);
                if calls.by_call.len() >= MAX_PENDING {
                    return Err(format!(
                        "busy: {MAX_PENDING} requests already wait for the vehicle"
                    ));
                }
                calls.last += 1;
                let call = calls.last;
                calls.by_call.insert(call, (waiter, Instant::now()));
                Some(call)
            }
            None => None,
        };
        let message = FromNode::Request { call, request };
        if serde_json::to_string(&message).map_or(true, |l| l.len() >= super::pipe::MAX_LINE) {
            call.map(|c| calls.by_call.remove(&c));
            return Err(format!(
                "the request is over {} MiB",
                super::pipe::MAX_LINE >> 20
            ));
        }
        self.up.try_send(message).map_err(|_| {
            call.map(|c| calls.by_call.remove(&c));
            "the vehicle's command queue is full".to_owned()
        })
    }

    /// Sends `request` and waits for the vehicle's answer (on a blocking thread: roslibrust
    /// runs service callbacks there).
    fn call(&self, request: Ros1Request) -> Verdict {
        let service = request.name();
        let admitted = self
            .service_rate
            .lock()
            .map_err(|_| "the ROS1 node's rate limit is broken".to_owned())?
            .admit(service, "service calls", "refused");
        if !admitted {
            return Err(format!(
                "refused: {service} is called more often than ros1.command_rate_hz allows"
            ));
        }
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        self.submit(request, Some(tx))?;
        rx.recv_timeout(ANSWER_TIMEOUT)
            .unwrap_or_else(|_| Err("the vehicle did not answer in time".to_owned()))
    }

    /// The vehicle's answer to call `call`; a caller that timed out is gone.
    pub fn answer(&self, call: u64, result: Verdict) {
        let waiter = match self.calls.lock() {
            Ok(mut calls) => calls.by_call.remove(&call),
            Err(_) => None,
        };
        if let Some((waiter, _)) = waiter {
            let _ = waiter.try_send(result);
        }
    }
}

/// The registered graph: dropping it unregisters everything (the node handle goes last).
pub struct Graph {
    /// Every topic of `api::ros1::topics::TOPICS`.
    publishers: Vec<TopicPublisher>,
    _services: Vec<ServiceServer>,
    _subscribers: JoinSet<()>,
    pub node: NodeHandle,
}

impl Graph {
    /// Publishes each message on its topic.
    pub async fn publish(&self, messages: Vec<(String, serde_json::Value)>) {
        for (topic, msg) in messages {
            if let Some(p) = self.publishers.iter().find(|p| p.name == topic) {
                p.publish(&msg).await;
            }
        }
    }
}

/// One advertised topic: its type's generated definition, its JSON serialised through that
/// type.
struct TopicPublisher {
    name: &'static str,
    latched: bool,
    descriptor: &'static roslibrust::MessageDescriptor,
    publisher: roslibrust::ros1::PublisherAny,
}

impl TopicPublisher {
    async fn advertise(
        node: &NodeHandle,
        topic: &Topic,
    ) -> Result<Self, roslibrust::ros1::NodeError> {
        let descriptor = messages::MESSAGE_REGISTRY
            .get(topic.msg_type)
            .ok_or_else(|| {
                roslibrust::ros1::NodeError::IoError(std::io::Error::other(format!(
                    "{}: no interface {} in crates/core/src/api/ros1/interfaces",
                    topic.name, topic.msg_type
                )))
            })?;
        let publisher = node
            .advertise_any(
                topic.name,
                descriptor.ros_type_name,
                descriptor.definition,
                topic.queue,
                topic.latched,
            )
            .await?;
        Ok(Self {
            name: topic.name,
            latched: topic.latched,
            descriptor,
            publisher,
        })
    }

    /// Publishes `msg`, checked field by field against the type (some 20 µs a message,
    /// `cargo bench --bench ros1`: skipped while nobody subscribes; latched topics are
    /// kept, for the subscriber that comes).
    async fn publish(&self, msg: &serde_json::Value) {
        if !self.latched && !self.publisher.has_connected_clients() {
            return;
        }
        match messages::wire(self.descriptor, msg) {
            Ok(bytes) => {
                if let Err(e) = self.publisher.publish(bytes).await {
                    tracing::debug!(topic = self.name, error = %e, "ROS1 publish failed");
                }
            }
            // A message of chassisd's own not fitting its type: a fault to show, not hide.
            Err(e) => tracing::error!(topic = self.name, error = %e, "ROS1 message not built"),
        }
    }
}

/// Keeps the node's ports (roslibrust's listeners on 0.0.0.0) to the address the node
/// advertises in `uri`, when one is configured (see `bind`); says where they listen once.
pub async fn keep_to_advertised(master_uri: &str, uri: &str, said: &mut bool) {
    let host = uri
        .strip_prefix("http://")
        .and_then(|rest| rest.rsplit_once(':'))
        .map_or("", |(host, _)| host);
    let allowed = super::bind::allowed(host, super::bind::master_on_loopback(master_uri)).await;
    let outcome = allowed.as_ref().map(super::bind::restrict);
    if std::mem::replace(said, true) {
        return;
    }
    match (allowed, outcome) {
        (Some(allowed), Some(Ok(ports))) => {
            tracing::info!(
                ?allowed,
                ports,
                "ROS1 node: its ports take connections to these addresses only"
            );
        }
        (_, Some(Err(e))) => {
            tracing::warn!(error = %e, "ROS1 node: its ports could not be kept to its address; they listen on every interface")
        }
        _ => tracing::warn!(
            %host,
            "ROS1 node: its ports listen on every interface (set ROS_IP to the address other nodes reach it at to keep them to it)"
        ),
    }
}

/// Whether the master still knows the node.
pub enum Registration {
    Known,
    MasterAway,
    Forgotten,
}

pub async fn still_registered(
    master: Option<&MasterClient>,
    master_uri: &str,
    name: &str,
    uri: &str,
) -> Registration {
    let fresh;
    let master = match master {
        Some(m) => m,
        None => match MasterClient::new(master_uri, uri, format!("{name}_watch")).await {
            Ok(m) => {
                fresh = m;
                &fresh
            }
            Err(_) => return Registration::MasterAway,
        },
    };
    match master.lookup_node(name).await {
        Ok(known) if known == uri => Registration::Known,
        Ok(other) => {
            // Another node took the name; the master told this one to shut down. Registering
            // again would fight it, so the node stays as it is and says so.
            tracing::error!(name, other = %other, "another ROS node took this node's name");
            Registration::Known
        }
        Err(roslibrust::ros1::RosMasterError::MasterError(_)) => Registration::Forgotten,
        Err(_) => Registration::MasterAway,
    }
}

/// The points of a ROS request as the adapter records them.
fn points(points: &[geometry_msgs::Point]) -> Vec<Point> {
    points
        .iter()
        .map(|p| Point {
            x: p.x,
            y: p.y,
            z: p.z,
        })
        .collect()
}

/// Hands a zone edit to the engine: whether it was made (a refusal is logged with its
/// reason; the status code goes out on `/androidmsg_virtualmapstatus` with the answer).
fn zone_edit_made(requests: &Requests, request: Ros1Request) -> bool {
    let name = request.name();
    match requests.call(request) {
        Ok(_) => true,
        Err(reason) => {
            tracing::warn!(%reason, "{name} refused");
            false
        }
    }
}

/// Connects and registers every publisher, subscriber and service.
pub async fn build(
    spec: &NodeSettings,
    requests: &Requests,
) -> Result<Graph, roslibrust::ros1::NodeError> {
    let node = NodeHandle::new(&spec.config.master_uri, &spec.config.node_name).await?;
    let mut publishers = Vec::new();
    for topic in topics::TOPICS {
        publishers.push(TopicPublisher::advertise(&node, topic).await?);
    }
    let mut subscribers = JoinSet::new();
    let rate = (spec.config.command_rate_hz, spec.config.command_burst);
    let cmd_vel = node
        .subscribe::<geometry_msgs::Twist>("/cmd_vel", SUBSCRIBER_QUEUE)
        .await?;
    subscribers.spawn(forward(cmd_vel, "/cmd_vel", requests.clone(), rate, |t| {
        Ok(Ros1Request::CmdVel {
            linear: [t.linear.x, t.linear.y, t.linear.z],
            angular: [t.angular.x, t.angular.y, t.angular.z],
        })
    }));
    let navi_stop = node
        .subscribe::<std_msgs::Int16>("/navi_stop", SUBSCRIBER_QUEUE)
        .await?;
    subscribers.spawn(forward(
        navi_stop,
        "/navi_stop",
        requests.clone(),
        rate,
        |m| Ros1Request::navi_stop(m.data),
    ));
    let autocharge = node
        .subscribe::<std_msgs::Int16>("/autocharge", SUBSCRIBER_QUEUE)
        .await?;
    subscribers.spawn(forward(
        autocharge,
        "/autocharge",
        requests.clone(),
        rate,
        |m| Ros1Request::autocharge(m.data),
    ));

    let mut services = Vec::new();
    let r = requests.clone();
    services.push(
        node.advertise_service::<map_msgs::SetNaviCmd, _>(
            "/set_navi_cmd",
            move |request: map_msgs::SetNaviCmdRequest| {
                r.call(Ros1Request::SetNaviCmd {
                    cmd: request.cmd,
                    distance: request.distance,
                })
                .map(|_| map_msgs::SetNaviCmdResponse {})
                .map_err(|reason| {
                    tracing::warn!(%reason, "/set_navi_cmd refused");
                    // roslibrust's service callbacks answer with its ServiceError,
                    // which is an anyhow::Error.
                    anyhow::anyhow!(reason)
                })
            },
        )
        .await?,
    );
    let r = requests.clone();
    services.push(
        node.advertise_service::<map_msgs::SetShape, _>(
            "/set_shape",
            move |request: map_msgs::SetShapeRequest| {
                let request = Ros1Request::SetShape(ShapeRequest {
                    kind: request.r#type,
                    shape_id: request.r#shapeId,
                    points: points(&request.points),
                    radius: request.radius,
                    closed: request.closed,
                });
                Ok(map_msgs::SetShapeResponse {
                    success: zone_edit_made(&r, request),
                })
            },
        )
        .await?,
    );
    let r = requests.clone();
    services.push(
        node.advertise_service::<map_msgs::SetRegion, _>(
            "/set_region",
            move |request: map_msgs::SetRegionRequest| {
                let request = Ros1Request::SetRegion(RegionRequest {
                    kind: request.r#type,
                    shape_id: request.r#shapeId,
                    points: points(&request.points),
                    points2: points(&request.points2),
                    start_waits: points(&request.r#startPointWaits),
                    end_waits: points(&request.r#endPointWaits),
                    radius: request.radius,
                    closed: request.closed,
                });
                Ok(map_msgs::SetRegionResponse {
                    success: zone_edit_made(&r, request),
                })
            },
        )
        .await?,
    );
    // The queries and the refused services go through the engine too: recorded, and
    // answered there (api::ros1::queries).
    let r = requests.clone();
    services.push(
        node.advertise_service::<map_msgs::GetPosition, _>(
            "/get_position",
            move |_: map_msgs::GetPositionRequest| {
                let at = r
                    .call(Ros1Request::GetPosition)
                    .map_err(anyhow::Error::msg)?;
                let coordinate = |key: &str| {
                    at.as_ref()
                        .and_then(|at| at.get(key))
                        .and_then(serde_json::Value::as_f64)
                        .ok_or_else(|| anyhow::anyhow!("the vehicle's answer has no {key}"))
                };
                Ok(map_msgs::GetPositionResponse {
                    pose: geometry_msgs::Point32 {
                        x: coordinate("x")? as f32,
                        y: coordinate("y")? as f32,
                        z: 0.0,
                    },
                })
            },
        )
        .await?,
    );
    let r = requests.clone();
    services.push(
        node.advertise_service::<map_msgs::AboutRobot, _>(
            "/navi_info",
            move |_: map_msgs::AboutRobotRequest| {
                let about = r.call(Ros1Request::NaviInfo).map_err(anyhow::Error::msg)?;
                Ok(map_msgs::AboutRobotResponse {
                    status: 0,
                    nav_info: about
                        .as_ref()
                        .and_then(serde_json::Value::as_str)
                        .unwrap_or_default()
                        .to_owned(),
                })
            },
        )
        .await?,
    );
    let r = requests.clone();
    services.push(
        node.advertise_service::<map_msgs::RobotSsh, _>(
            "/robot_ssh",
            move |request: map_msgs::RobotSshRequest| {
                // The spec's answer to a refusal is status 1 with the reason.
                let data = match r.call(Ros1Request::robot_ssh(&request.instruction)) {
                    Ok(_) => String::new(),
                    Err(reason) => reason,
                };
                Ok(map_msgs::RobotSshResponse { status: 1, data })
            },
        )
        .await?,
    );
    let r = requests.clone();
    services.push(
        node.advertise_service::<map_msgs::SetWifi, _>(
            "/set_wifi",
            move |request: map_msgs::SetWifiRequest| {
                // The password stays here: only the network's name goes up, to be recorded.
                r.call(Ros1Request::set_wifi(&request.wifi_name))
                    .map(|_| map_msgs::SetWifiResponse {})
                    .map_err(anyhow::Error::msg)
            },
        )
        .await?,
    );
    Ok(Graph {
        publishers,
        _services: services,
        _subscribers: subscribers,
        node,
    })
}

/// Turns a subscribed topic's messages into requests, within its rate.
async fn forward<T, F>(
    mut subscriber: roslibrust::ros1::Subscriber<T>,
    topic: &'static str,
    requests: Requests,
    (rate_hz, burst): (f64, u32),
    to_request: F,
) where
    T: roslibrust::RosMessageType,
    F: Fn(T) -> Result<Ros1Request, String> + Send + 'static,
{
    let mut limit = Limit::new((rate_hz, burst));
    while let Some(message) = subscriber.next().await {
        let message = match message {
            Ok(m) => m,
            Err(e) => {
                tracing::warn!(topic, error = %e, "ROS1 message refused");
                continue;
            }
        };
        if !limit.admit(topic, "messages", "dropped") {
            continue;
        }
        let request = to_request(message).and_then(|r| requests.submit(r, None));
        if let Err(reason) = request {
            tracing::warn!(topic, %reason, "ROS1 message refused");
        }
    }
}
