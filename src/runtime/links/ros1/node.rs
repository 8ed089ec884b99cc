//! The node's life: connect to the master (retrying while it is away), advertise, subscribe
//! and serve; publish what the engine feeds; and watch the master, rebuilding every
//! registration when it has forgotten the node (a restarted rosmaster keeps none, and a
//! roslibrust node does not register again by itself).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use roslibrust::ros1::{MasterClient, NodeHandle, ServiceServer};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinSet;

use super::messages::{self, geometry_msgs, map_msgs, std_msgs};
use super::{Answer, Feed, Ros1Queues};
use crate::api::ros1;
use crate::api::ros1::adapter::{Point, RegionRequest, Ros1Request, ShapeRequest};
use crate::api::ros1::messages::ImuNoise;
use crate::api::ros1::odometry::OdometryNoise;
use crate::api::ros1::publisher::{self, Advertised, Messages, Publishing};
use crate::config::ros1::Ros1Config;
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::links::command_rate::{CommandRate, RateReport};
use crate::runtime::outage_log::{OutageLog, Say};
use crate::vehicle::Pose2D;

/// How often the master is asked whether it still knows the node.
const WATCH_EVERY: Duration = Duration::from_secs(1);
/// The longest wait between connection attempts.
const RETRY_MAX: Duration = Duration::from_secs(5);
/// Requests that may wait for the engine's answer at once; more are refused as busy.
const MAX_PENDING: usize = 64;
/// How long a service call waits for the engine's answer.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(2);
/// How long a request keeps its place while no answer comes (one lost on the way, which the
/// queues' sizes rule out, must not hold a place for ever).
const FORGET_AFTER: Duration = Duration::from_secs(10);
/// Messages queued per subscribed topic in roslibrust before the oldest go.
const SUBSCRIBER_QUEUE: usize = 16;
/// Why `/robot_ssh` and `/set_wifi` answer no.
const DISABLED: &str = "disabled for security";

/// What the node is built from.
#[derive(Debug, Clone)]
pub struct Ros1Spec {
    /// `[ros1]`.
    pub config: Ros1Config,
    /// The vehicle's name (`/navi_info`).
    pub vehicle: String,
    /// The odometry's noise (`/raw_odom`'s covariance).
    pub odometry_noise: OdometryNoise,
    /// The IMU's noise (`/imu/data`'s covariances).
    pub imu_noise: ImuNoise,
}

/// One request waiting for the engine's answer.
struct Pending {
    /// Who waits (a service call); `None` for a topic's message.
    waiter: Option<std::sync::mpsc::SyncSender<Result<(), String>>>,
    /// Whether it starts a motion (announced on the navigation topic once accepted).
    starts_motion: bool,
    /// Whether it is the charging action.
    charging: bool,
    /// Whether it edits the zones (answered on `/androidmsg_virtualmapstatus`).
    edits_zones: bool,
    /// When it went to the engine.
    sent: Instant,
}

/// The requests waiting for the engine's answer, by the id each was recorded with.
#[derive(Default)]
struct Waiting {
    last_id: u64,
    by_id: HashMap<u64, Pending>,
}

/// Hands requests to the engine; their answers come back by id.
#[derive(Clone)]
struct Requests {
    records: mpsc::Sender<Record>,
    clock: RecordClock,
    waiting: Arc<Mutex<Waiting>>,
}

impl Requests {
    /// Sends `request`; a `waiter` gets the engine's answer.
    fn submit(
        &self,
        request: Ros1Request,
        waiter: Option<std::sync::mpsc::SyncSender<Result<(), String>>>,
    ) -> Result<(), String> {
        // The lock spans the send, so an answer never comes before its request waits.
        let mut waiting = self
            .waiting
            .lock()
            .map_err(|_| "the ROS1 node's request queue is broken".to_owned())?;
        let id = if request.awaits_answer() {
            waiting.by_id.retain(|_, p| p.sent.elapsed() < FORGET_AFTER);
            if waiting.by_id.len() >= MAX_PENDING {
                return Err(format!(
                    "busy: {MAX_PENDING} requests already wait for the vehicle"
                ));
            }
            waiting.last_id += 1;
            Some(waiting.last_id)
        } else {
            None
        };
        let record = Record {
            t: self.clock.now(),
            source: ros1::SOURCE.into(),
            payload: Payload::Command {
                topic: request.name().to_owned(),
                payload: request.encode(id),
            },
        };
        self.records
            .try_send(record)
            .map_err(|_| "the vehicle's command queue is full".to_owned())?;
        if let Some(id) = id {
            let entry = Pending {
                waiter,
                starts_motion: request.starts_motion(),
                charging: request.is_charging(),
                edits_zones: request.edits_zones(),
                sent: Instant::now(),
            };
            waiting.by_id.insert(id, entry);
        }
        Ok(())
    }

    /// Sends `request` and waits for the engine's answer (on a blocking thread: roslibrust
    /// runs service callbacks there).
    fn call(&self, request: Ros1Request) -> Result<(), String> {
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        self.submit(request, Some(tx))?;
        rx.recv_timeout(ANSWER_TIMEOUT)
            .unwrap_or_else(|_| Err("the vehicle did not answer in time".to_owned()))
    }
}

/// Starts the node; it runs until the runtime ends. Requests go to `records`.
pub fn spawn(
    spec: Ros1Spec,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
    queues: Ros1Queues,
) {
    tokio::spawn(crate::runtime::panics::or_report_down(
        "ROS1 node",
        run(spec, clock, records, queues),
    ));
}

/// The registered graph: dropping it unregisters everything (the node handle goes last).
struct Graph {
    /// Every topic of `api::ros1::publisher::advertised`.
    publishers: Vec<TopicPublisher>,
    _services: Vec<ServiceServer>,
    _subscribers: JoinSet<()>,
    node: NodeHandle,
}

impl Graph {
    /// Publishes each message on its topic.
    async fn publish(&self, messages: Messages) {
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
        topic: &Advertised,
    ) -> Result<Self, roslibrust::ros1::NodeError> {
        let descriptor = messages::MESSAGE_REGISTRY
            .get(topic.msg_type)
            .ok_or_else(|| {
                roslibrust::ros1::NodeError::IoError(std::io::Error::other(format!(
                    "{}: no interface {} in src/api/ros1/interfaces",
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

/// The node's state between messages: what is due to publish, and `/get_position`'s answer.
struct State {
    publishing: Publishing,
    position: watch::Sender<Option<Pose2D>>,
}

impl State {
    /// The messages `item` makes due (published when the node is registered).
    fn on_feed(&mut self, item: &Feed) -> Messages {
        if let Feed::Poses(_, report) = item {
            self.position.send_replace(publisher::position(report));
        }
        let mut out = Vec::new();
        self.publishing.on_feed(item, &mut out);
        out
    }
}

async fn run(
    spec: Ros1Spec,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
    queues: Ros1Queues,
) {
    let Ros1Queues {
        mut feed,
        mut answers,
    } = queues;
    let requests = Requests {
        records,
        clock,
        waiting: Arc::new(Mutex::new(Waiting::default())),
    };
    let (position, position_rx) = watch::channel(None);
    let mut state = State {
        publishing: Publishing::new(spec.odometry_noise, spec.imu_noise),
        position,
    };
    let mut outage = OutageLog::default();
    let mut outage_start: Option<Instant> = None;
    let mut retry = Duration::from_millis(250);
    // Where the ports listen is said once, not at every registration.
    let mut said_where = false;
    let mut watch = tokio::time::interval(WATCH_EVERY);
    watch.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        // Connect and register everything, keeping up with the engine meanwhile.
        let building = build(&spec, &requests, &position_rx);
        tokio::pin!(building);
        let graph = loop {
            tokio::select! {
                graph = &mut building => break graph,
                Some(item) = feed.recv() => drop(state.on_feed(&item)),
                Some(answer) = answers.recv() => {
                    answer_pending(&requests, &mut state, answer, None).await;
                }
            }
        };
        let graph = match graph {
            Ok(graph) => graph,
            Err(e) => {
                let start = *outage_start.get_or_insert_with(Instant::now);
                match outage.failed(start.elapsed()) {
                    Say::First => tracing::warn!(
                        master = %spec.config.master_uri,
                        error = %e,
                        "ROS master unreachable; retrying"
                    ),
                    Say::Still(attempts) => tracing::warn!(
                        master = %spec.config.master_uri,
                        attempts,
                        error = %e,
                        "ROS master still unreachable"
                    ),
                    Say::Quiet => tracing::debug!(error = %e, "ROS master unreachable"),
                }
                // The engine's feed is kept up with while waiting, so nothing piles up.
                let pause = tokio::time::sleep(retry);
                tokio::pin!(pause);
                loop {
                    tokio::select! {
                        () = &mut pause => break,
                        Some(item) = feed.recv() => drop(state.on_feed(&item)),
                        Some(answer) = answers.recv() => {
                            answer_pending(&requests, &mut state, answer, None).await;
                        }
                    }
                }
                retry = (retry * 2).min(RETRY_MAX);
                continue;
            }
        };
        let uri = graph.node.get_client_uri().await.unwrap_or_default();
        keep_to_advertised(&spec.config.master_uri, &uri, &mut said_where).await;
        tracing::info!(
            master = %spec.config.master_uri,
            node = %spec.config.node_name,
            %uri,
            "ROS1 node registered"
        );
        outage = OutageLog::default();
        outage_start = None;
        retry = Duration::from_millis(250);
        // The latched status codes again, for the new registrations.
        let mut latched = Vec::new();
        state.publishing.latched(&mut latched);
        graph.publish(latched).await;
        let master = MasterClient::new(
            spec.config.master_uri.as_str(),
            uri.as_str(),
            format!("{}_watch", spec.config.node_name),
        )
        .await
        .ok();
        let mut master_away = false;
        loop {
            tokio::select! {
                Some(item) = feed.recv() => graph.publish(state.on_feed(&item)).await,
                Some(answer) = answers.recv() => {
                    answer_pending(&requests, &mut state, answer, Some(&graph)).await;
                }
                _ = watch.tick() => {
                    match still_registered(master.as_ref(), &spec.config.master_uri, &spec.config.node_name, &uri).await {
                        Registration::Known => {
                            if master_away {
                                tracing::info!("ROS master back; the node is still registered");
                                master_away = false;
                            }
                        }
                        Registration::MasterAway => {
                            if !master_away {
                                tracing::warn!(master = %spec.config.master_uri, "ROS master unreachable; publishing goes on to connected subscribers");
                                master_away = true;
                            }
                        }
                        Registration::Forgotten => {
                            tracing::warn!(master = %spec.config.master_uri, "the ROS master does not know the node (restarted?): registering again");
                            break;
                        }
                    }
                }
            }
        }
        drop(graph);
    }
}

/// Keeps the node's ports (roslibrust's listeners on 0.0.0.0) to the address the node
/// advertises in `uri`, when one is configured (see `bind`); says where they listen once.
async fn keep_to_advertised(master_uri: &str, uri: &str, said: &mut bool) {
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

/// Gives the engine's `answer` to the request it names.
async fn answer_pending(
    requests: &Requests,
    state: &mut State,
    Answer { request, result }: Answer,
    graph: Option<&Graph>,
) {
    let entry = match requests.waiting.lock() {
        Ok(mut w) => w.by_id.remove(&request),
        Err(_) => None,
    };
    let Some(entry) = entry else {
        return;
    };
    let answer = result;
    if answer.is_ok() && entry.starts_motion {
        let mut codes = Vec::new();
        state
            .publishing
            .on_request_accepted(entry.charging, &mut codes);
        if let Some(graph) = graph {
            graph.publish(codes).await;
        }
    }
    if entry.edits_zones {
        let mut codes = Vec::new();
        state.publishing.on_zone_edit(answer.is_ok(), &mut codes);
        if let Some(graph) = graph {
            graph.publish(codes).await;
        }
    }
    if let Some(waiter) = entry.waiter {
        // A caller that timed out is gone; its answer goes nowhere.
        let _ = waiter.try_send(answer);
    }
}

/// Whether the master still knows the node.
enum Registration {
    Known,
    MasterAway,
    Forgotten,
}

async fn still_registered(
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
        Ok(()) => true,
        Err(reason) => {
            tracing::warn!(%reason, "{name} refused");
            false
        }
    }
}

/// Connects and registers every publisher, subscriber and service.
async fn build(
    spec: &Ros1Spec,
    requests: &Requests,
    position: &watch::Receiver<Option<Pose2D>>,
) -> Result<Graph, roslibrust::ros1::NodeError> {
    let node = NodeHandle::new(&spec.config.master_uri, &spec.config.node_name).await?;
    let mut publishers = Vec::new();
    for topic in publisher::advertised() {
        publishers.push(TopicPublisher::advertise(&node, &topic).await?);
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
                .map(|()| map_msgs::SetNaviCmdResponse {})
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
    let p = position.clone();
    services.push(
        node.advertise_service::<map_msgs::GetPosition, _>(
            "/get_position",
            move |_: map_msgs::GetPositionRequest| match *p.borrow() {
                Some(pose) => Ok(map_msgs::GetPositionResponse {
                    pose: geometry_msgs::Point32 {
                        x: pose.x as f32,
                        y: pose.y as f32,
                        z: 0.0,
                    },
                }),
                None => Err(anyhow::anyhow!(
                    "the vehicle is not located yet (no GNSS fix or INIT_POSITION)"
                )),
            },
        )
        .await?,
    );
    let info = ros1::navi_info(&spec.vehicle);
    services.push(
        node.advertise_service::<map_msgs::AboutRobot, _>(
            "/navi_info",
            move |_: map_msgs::AboutRobotRequest| {
                Ok(map_msgs::AboutRobotResponse {
                    status: 0,
                    nav_info: info.clone(),
                })
            },
        )
        .await?,
    );
    services.push(
        node.advertise_service::<map_msgs::RobotSsh, _>(
            "/robot_ssh",
            |request: map_msgs::RobotSshRequest| {
                let shown: String = request.instruction.chars().take(200).collect();
                tracing::warn!(instruction = ?shown, "/robot_ssh refused: {DISABLED}");
                Ok(map_msgs::RobotSshResponse {
                    status: 1,
                    data: DISABLED.to_owned(),
                })
            },
        )
        .await?,
    );
    services.push(
        node.advertise_service::<map_msgs::SetWifi, _>(
            "/set_wifi",
            |request: map_msgs::SetWifiRequest| {
                let shown: String = request.wifi_name.chars().take(64).collect();
                tracing::warn!(wifi = ?shown, "/set_wifi refused: {DISABLED} (no network manager integration)");
                Err(anyhow::anyhow!(
                    "{DISABLED}: chassisd has no network manager integration"
                ))
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
    let mut rate = CommandRate::new(rate_hz, burst);
    while let Some(message) = subscriber.next().await {
        let message = match message {
            Ok(m) => m,
            Err(e) => {
                tracing::warn!(topic, error = %e, "ROS1 message refused");
                continue;
            }
        };
        let now = Instant::now();
        let (admitted, report) = rate.admit(topic, now);
        match report.or_else(|| rate.due_summary(now)) {
            Some(RateReport::Started(_)) => tracing::warn!(
                topic,
                limit_hz = rate_hz,
                burst,
                "ROS1 messages over the rate limit are dropped; a summary follows every 5 s while it lasts"
            ),
            Some(RateReport::Summary(counts)) => {
                let dropped: u64 = counts.iter().map(|(_, n)| n).sum();
                tracing::warn!(
                    topic,
                    dropped,
                    "ROS1 messages dropped over the rate limit in the last 5 s"
                );
            }
            None => {}
        }
        if !admitted {
            continue;
        }
        let request = to_request(message).and_then(|r| requests.submit(r, None));
        if let Err(reason) = request {
            tracing::warn!(topic, %reason, "ROS1 message refused");
        }
    }
}
