//! The node's life: connect to the master (retrying while it is away), advertise, subscribe
//! and serve; publish what the engine feeds; and watch the master, rebuilding every
//! registration when it has forgotten the node (a restarted rosmaster keeps none, and a
//! roslibrust node does not register again by itself).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use roslibrust::ros1::{MasterClient, NodeHandle, Publisher, ServiceServer};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinSet;

use super::messages::{self, geometry_msgs, map_msgs, nav_msgs, sensor_msgs, std_msgs, tf2_msgs};
use super::{Answer, Feed, Ros1Queues};
use crate::api::ros1;
use crate::api::ros1::adapter::Ros1Request;
use crate::api::ros1::odometry::{OdometryNoise, OdometryUncertainty};
use crate::api::ros1::published;
use crate::api::ros1::status::{StatusTopics, Topic};
use crate::config::ros1::Ros1Config;
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::links::command_rate::{CommandRate, RateReport};
use crate::runtime::outage_log::{OutageLog, Say};
use crate::vehicle::{Localization, Pose2D};

/// How often the master is asked whether it still knows the node.
const WATCH_EVERY: Duration = Duration::from_secs(1);
/// The longest wait between connection attempts.
const RETRY_MAX: Duration = Duration::from_secs(5);
/// `/tracked_pose`'s and `/tf`'s period (15 Hz).
const TRACKED_POSE_PERIOD: Duration = Duration::from_nanos(1_000_000_000 / 15);
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
    pub imu_noise: messages::ImuNoise,
}

/// One request waiting for the engine's answer.
struct Pending {
    /// Who waits (a service call); `None` for a topic's message.
    waiter: Option<std::sync::mpsc::SyncSender<Result<(), String>>>,
    /// Whether it starts a motion (announced on the navigation topic once accepted).
    starts_motion: bool,
    /// Whether it is the charging action.
    charging: bool,
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
    raw_odom: Publisher<nav_msgs::Odometry>,
    imu: Publisher<sensor_msgs::Imu>,
    tracked_pose: Publisher<geometry_msgs::PoseStamped>,
    tf: Publisher<tf2_msgs::TFMessage>,
    /// The topics of `api::ros1::published`, by name, each with its type.
    status_topics: Vec<StatusPublisher>,
    codes: Vec<(Topic, Publisher<std_msgs::Int16>)>,
    _services: Vec<ServiceServer>,
    _subscribers: JoinSet<()>,
    node: NodeHandle,
}

/// A topic of `api::ros1::published`: advertised with its type's generated definition, its
/// JSON serialised through that type.
struct StatusPublisher {
    name: &'static str,
    descriptor: &'static roslibrust::MessageDescriptor,
    publisher: roslibrust::ros1::PublisherAny,
}

impl StatusPublisher {
    async fn advertise(
        node: &NodeHandle,
        topic: &published::StatusTopic,
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
                10,
                false,
            )
            .await?;
        Ok(Self {
            name: topic.name,
            descriptor,
            publisher,
        })
    }

    /// Publishes `msg`, checked field by field against the type.
    async fn publish(&self, msg: &serde_json::Value) {
        match messages::wire(self.descriptor, msg) {
            Ok(bytes) => {
                if let Err(e) = self.publisher.publish(bytes).await {
                    tracing::debug!(topic = self.name, error = %e, "ROS1 publish failed");
                }
            }
            // The table's own message not fitting its type: a fault to show, not to hide.
            Err(e) => tracing::error!(topic = self.name, error = %e, "ROS1 message not built"),
        }
    }
}

/// What the publishers keep between messages.
struct Publishing {
    odometry: OdometryUncertainty,
    imu_noise: messages::ImuNoise,
    status: StatusTopics,
    /// Status ticks seen, for the rates of `api::ros1::published`.
    status_ticks: u64,
    next_tracked_pose: Option<crate::time::Timestamp>,
    seq: u32,
    imu_seq: u32,
    position: watch::Sender<Option<Pose2D>>,
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
    let mut publishing = Publishing {
        odometry: OdometryUncertainty::new(spec.odometry_noise),
        imu_noise: spec.imu_noise,
        status: StatusTopics::default(),
        next_tracked_pose: None,
        seq: 0,
        imu_seq: 0,
        status_ticks: 0,
        position,
    };
    let mut outage = OutageLog::default();
    let mut outage_start: Option<Instant> = None;
    let mut retry = Duration::from_millis(250);
    let mut watch = tokio::time::interval(WATCH_EVERY);
    watch.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        // Connect and register everything, keeping up with the engine meanwhile.
        let building = build(&spec, &requests, &position_rx);
        tokio::pin!(building);
        let graph = loop {
            tokio::select! {
                graph = &mut building => break graph,
                Some(item) = feed.recv() => publishing.absorb(&item),
                Some(answer) = answers.recv() => {
                    answer_pending(&requests, &mut publishing, answer, None).await;
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
                        Some(item) = feed.recv() => publishing.absorb(&item),
                        Some(answer) = answers.recv() => {
                            answer_pending(&requests, &mut publishing, answer, None).await;
                        }
                    }
                }
                retry = (retry * 2).min(RETRY_MAX);
                continue;
            }
        };
        let uri = graph.node.get_client_uri().await.unwrap_or_default();
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
        for (topic, code) in publishing.status.current() {
            publish_code(&graph, topic, code).await;
        }
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
                Some(item) = feed.recv() => publishing.publish(&graph, item).await,
                Some(answer) = answers.recv() => {
                    answer_pending(&requests, &mut publishing, answer, Some(&graph)).await;
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

/// Gives the engine's `answer` to the request it names.
async fn answer_pending(
    requests: &Requests,
    publishing: &mut Publishing,
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
        publishing
            .status
            .on_request_accepted(entry.charging, &mut codes);
        if let Some(graph) = graph {
            for (topic, code) in codes {
                publish_code(graph, topic, code).await;
            }
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

async fn publish_code(graph: &Graph, topic: Topic, code: i16) {
    if let Some((_, publisher)) = graph.codes.iter().find(|(t, _)| *t == topic)
        && let Err(e) = publisher.publish(&std_msgs::Int16 { data: code }).await
    {
        tracing::debug!(topic = topic.name(), error = %e, "ROS1 publish failed");
    }
}

impl Publishing {
    /// Keeps what the next registration needs while the node is not registered.
    fn absorb(&mut self, item: &Feed) {
        let mut codes = Vec::new();
        match item {
            Feed::Status(status) => {
                self.status_ticks += 1;
                self.status.on_status(status, &mut codes);
            }
            Feed::MotionEnded(result) => self.status.on_motion_ended(result, &mut codes),
            Feed::Mission { tag, event } => self.status.on_mission(*tag, event, &mut codes),
            Feed::Poses(_, report) => {
                self.position.send_replace(position(report));
            }
            Feed::Imu(_) => {}
        }
    }

    async fn publish(&mut self, graph: &Graph, item: Feed) {
        let mut codes = Vec::new();
        match item {
            Feed::Poses(t, report) => {
                self.position.send_replace(position(&report));
                if let Some(odom) = report.odom {
                    let covariance = self.odometry.update(t, &odom);
                    self.seq = self.seq.wrapping_add(1);
                    let message = messages::odometry(t, self.seq, &odom, &covariance);
                    if let Err(e) = graph.raw_odom.publish(&message).await {
                        tracing::debug!(error = %e, "/raw_odom publish failed");
                    }
                }
                // `/tracked_pose` and `/tf` at 15 Hz.
                let due = self.next_tracked_pose.is_none_or(|next| t >= next);
                if due && (report.map.is_some() || report.odom.is_some()) {
                    let next = self
                        .next_tracked_pose
                        .map_or(t, |n| n.saturating_add(TRACKED_POSE_PERIOD));
                    // Late by more than a period (a pause in the feed): start again from now.
                    self.next_tracked_pose = Some(if next < t {
                        t.saturating_add(TRACKED_POSE_PERIOD)
                    } else {
                        next
                    });
                    if let Some((pose, _)) = report.map {
                        let message = messages::pose_stamped(t, self.seq, &pose);
                        if let Err(e) = graph.tracked_pose.publish(&message).await {
                            tracing::debug!(error = %e, "/tracked_pose publish failed");
                        }
                    }
                    if let Some(message) = messages::tf(t, &report)
                        && let Err(e) = graph.tf.publish(&message).await
                    {
                        tracing::debug!(error = %e, "/tf publish failed");
                    }
                }
            }
            Feed::Imu(sample) => {
                self.imu_seq = self.imu_seq.wrapping_add(1);
                let message = messages::imu(&sample, self.imu_seq, &self.imu_noise);
                if let Err(e) = graph.imu.publish(&message).await {
                    tracing::debug!(error = %e, "/imu/data publish failed");
                }
            }
            Feed::Status(status) => {
                self.status_ticks += 1;
                self.status.on_status(&status, &mut codes);
                for topic in published::due(self.status_ticks) {
                    let Some(publisher) = graph.status_topics.iter().find(|p| p.name == topic.name)
                    else {
                        continue;
                    };
                    if let Some(msg) = (topic.build)(&status, self.status_ticks as u32) {
                        publisher.publish(&msg).await;
                    }
                }
            }
            Feed::MotionEnded(result) => self.status.on_motion_ended(&result, &mut codes),
            Feed::Mission { tag, event } => self.status.on_mission(tag, &event, &mut codes),
        }
        for (topic, code) in codes {
            publish_code(graph, topic, code).await;
        }
    }
}

/// `/get_position`'s answer: the map pose when located, else none.
fn position(report: &crate::vehicle::PoseReport) -> Option<Pose2D> {
    match (report.localization, report.map) {
        (Localization::Good | Localization::Lost, Some((pose, _))) => Some(pose),
        _ => None,
    }
}

/// Connects and registers every publisher, subscriber and service.
async fn build(
    spec: &Ros1Spec,
    requests: &Requests,
    position: &watch::Receiver<Option<Pose2D>>,
) -> Result<Graph, roslibrust::ros1::NodeError> {
    let node = NodeHandle::new(&spec.config.master_uri, &spec.config.node_name).await?;
    let raw_odom = node.advertise("/raw_odom", 10, false).await?;
    let imu = node.advertise("/imu/data", 10, false).await?;
    let tracked_pose = node.advertise("/tracked_pose", 10, false).await?;
    let tf = node.advertise("/tf", 10, false).await?;
    let mut status_topics = Vec::new();
    for topic in published::STATUS_TOPICS {
        status_topics.push(StatusPublisher::advertise(&node, topic).await?);
    }
    let mut codes = Vec::new();
    for topic in Topic::ALL {
        codes.push((topic, node.advertise(topic.name(), 1, true).await?));
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
        raw_odom,
        imu,
        tracked_pose,
        tf,
        status_topics,
        codes,
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
