//! The ROS 2 node's own process (`chassisd ros2-child`, started by chassisd, never by
//! hand). Everything a DDS peer reaches runs here: RustDDS's discovery, its RTPS readers
//! (which trust the sizes a peer announces: a fragmented sample may claim up to 4 GiB) and
//! the action server. In here that costs this process at most its limits ([`MEMORY_LIMIT`],
//! [`DESCRIPTOR_LIMIT`]), at a lower scheduling priority than the control loop's. Past a
//! limit the process ends, and chassisd starts a new one, which joins the domain again.
//!
//! Settings arrive as one JSON line on standard input; [`super::pipe`] says what follows
//! each way. Standard input's end means chassisd is gone, and so is this process.

use std::collections::HashMap;
use std::io::BufRead;
use std::sync::Arc;
use std::time::Duration;

use futures_util::StreamExt;
use ros2_client::action::{
    ActionServerQosPolicies, AsyncActionServer, CancelHandle, ExecutingGoalHandle, GoalEndStatus,
    NewGoalHandle,
};
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{
    ActionTypeName, Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher,
    QosProfile, ServiceMapping,
};
use serde_json::Value;
use tokio::sync::mpsc;

use super::messages::{cdr, decode, nav2_msgs};
use super::pipe::{FromNode, MAX_LINE, NodeSettings, ToNode};
use super::wire::{RawCdr, RawSeed};
use crate::api::adapter::MAX_REQUEST;
use crate::api::ros2::NAVIGATE_TO_POSE;
use crate::api::ros2::topics::{self, Qos, TAKEN, TOPICS};
use crate::config::ros2::Middleware;
use crate::runtime::child_process;
use crate::runtime::error::{RuntimeError, invalid, io};
use crate::runtime::links::child_pipes::{read_from_parent, write_to_parent};

/// The process's address space: RustDDS, its threads and socket buffers and the runtime
/// need some 150 MB of it; a peer's announced sample size beyond what is left fails its
/// allocation and ends the process.
pub const MEMORY_LIMIT: u64 = 768 << 20;
/// Descriptors the process may open: RustDDS's sockets and threads' few.
pub const DESCRIPTOR_LIMIT: u64 = 256;
/// The process's niceness: under load, the control loop's process runs first.
const NICENESS: libc::c_int = 5;
/// The runtime's worker threads (RustDDS runs its own event loop thread besides).
const WORKER_THREADS: usize = 2;
/// Lines waiting to go up before more are dropped.
const UP_QUEUE: usize = 256;
/// The longest settings line read.
const MAX_SETTINGS: u64 = 64 << 10;
/// Goals waiting for chassisd's verdict at once; more are rejected here.
const MAX_NEW_GOALS: usize = 16;
/// How long a finished goal's result waits for its client to ask for it.
const RESULT_WAIT: Duration = Duration::from_secs(10);
/// Results waiting to be sent before the oldest is dropped.
const RESULT_QUEUE: usize = 16;

type Goal = nav2_msgs::NavigateToPoseGoal;
type NavResult = nav2_msgs::NavigateToPoseResult;
type Feedback = nav2_msgs::NavigateToPoseFeedback;
type Server = AsyncActionServer<Goal, NavResult, Feedback>;

impl ros2_client::Message for Goal {}
impl ros2_client::Message for NavResult {}
impl ros2_client::Message for Feedback {}

/// The process's whole life; returns only on error (its end is an exit).
pub fn main() -> Result<(), RuntimeError> {
    child_process::end_on_panic("ROS 2 node");
    let mut line = String::new();
    std::io::Read::take(std::io::stdin().lock(), MAX_SETTINGS)
        .read_line(&mut line)
        .map_err(io("reading the ROS 2 node's settings"))?;
    let settings: NodeSettings = serde_json::from_str(&line)
        .map_err(invalid("the ROS 2 node's settings are not valid JSON"))?;
    confine()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(WORKER_THREADS)
        .thread_name("ros2-node")
        .enable_all()
        .build()
        .map_err(io("the ROS 2 node's runtime"))?;
    runtime.block_on(run(settings))
}

/// Lowers the process's limits and priority for good.
fn confine() -> Result<(), RuntimeError> {
    child_process::limit(libc::RLIMIT_AS, MEMORY_LIMIT)
        .map_err(io("limiting the ROS 2 node's memory"))?;
    child_process::limit(libc::RLIMIT_NOFILE, DESCRIPTOR_LIMIT)
        .map_err(io("limiting the ROS 2 node's descriptors"))?;
    // SAFETY: setpriority on this process only; a failure leaves the priority as it was.
    if unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, NICENESS) } != 0 {
        tracing::debug!("ROS 2 node: its priority could not be lowered");
    }
    Ok(())
}

/// A ROS 2 QoS profile of a table's. A reliable writer that a reader does not acknowledge
/// fails at once rather than wait: the process never stalls on one peer.
pub(crate) fn profile(qos: Qos) -> QosProfile {
    let base = QosProfile::publisher_default();
    let base = match qos.reliability {
        topics::Reliability::Reliable => base.reliability_reliable(WhenFull::Fail),
        topics::Reliability::BestEffort => base.reliability_best_effort(),
    };
    base.durability(match qos.durability {
        topics::Durability::Volatile => Durability::Volatile,
        topics::Durability::TransientLocal => Durability::TransientLocal,
    })
    .history(History::KeepLast {
        depth: usize::try_from(qos.depth).unwrap_or(usize::MAX),
    })
}

/// A topic's ROS 2 name under `namespace`: `/imu/data` under `/robot_1` is
/// `/robot_1/imu/data`.
pub(crate) fn name(namespace: &str, topic: &str) -> Result<Name, String> {
    let full = format!("{namespace}{topic}");
    let (space, base) = full.rsplit_once('/').unwrap_or(("", &full));
    let space = if space.is_empty() { "/" } else { space };
    Name::new(space, base).map_err(|e| format!("{full}: not a ROS 2 name: {e:?}"))
}

/// `package/msg/Type`'s parts.
pub(crate) fn type_name(msg_type: &str) -> MessageTypeName {
    let mut parts = msg_type.split('/');
    let package = parts.next().unwrap_or_default();
    let name = parts.next_back().unwrap_or_default();
    MessageTypeName::new(package, name)
}

/// The writers of the published topics, by the table's names.
struct Writers {
    by_topic: HashMap<&'static str, Writer>,
    failed: u64,
}

/// A published topic's writer.
struct Writer {
    msg_type: &'static str,
    publisher: Publisher<RawCdr>,
    /// Transient local: the last samples are kept for readers that join later.
    latched: bool,
}

impl Writers {
    fn create(node: &mut Node, namespace: &str) -> Result<Self, String> {
        let mut by_topic = HashMap::new();
        for topic in TOPICS {
            let qos = profile(topic.qos);
            let dds_topic = node
                .create_topic(
                    &name(namespace, topic.name)?,
                    type_name(topic.msg_type),
                    &qos,
                )
                .map_err(|e| format!("{}: {e:?}", topic.name))?;
            let publisher = node
                .create_publisher::<RawCdr>(&dds_topic, None)
                .map_err(|e| format!("{}: {e:?}", topic.name))?;
            let writer = Writer {
                msg_type: topic.msg_type,
                publisher,
                latched: topic.qos.durability == topics::Durability::TransientLocal,
            };
            by_topic.insert(topic.name, writer);
        }
        Ok(Self {
            by_topic,
            failed: 0,
        })
    }

    /// Serialises `msg` as its topic's type and writes it; a message its type refuses or
    /// a write that fails is counted and logged now and then. A volatile topic's message
    /// that no reader of `node`'s has matched is neither: it would go nowhere (the IMU's
    /// 100 Hz and the rest cost nothing until someone subscribes).
    fn publish(&mut self, node: &Node, topic: &str, msg: &Value) {
        let Some(writer) = self.by_topic.get(topic) else {
            return self.failed(topic, "not a topic of the node");
        };
        if !writer.latched && writer.publisher.get_subscription_count(node) == 0 {
            return;
        }
        let bytes = match cdr(writer.msg_type, msg) {
            Ok(bytes) => bytes,
            Err(e) => return self.failed(topic, &e),
        };
        if let Err(e) = writer.publisher.publish(RawCdr(bytes)) {
            self.failed(topic, &format!("{e:?}"));
        }
    }

    fn failed(&mut self, topic: &str, why: &str) {
        self.failed += 1;
        if self.failed.is_power_of_two() {
            tracing::warn!(%topic, why, failed = self.failed, "ROS 2 node: a message was not published");
        }
    }
}

/// Reads `taken` of the table into `up` as the JSON of its type, until the process ends.
/// RustDDS hands a reader every sample on its topic's name whatever the writer's type (a
/// TwistStamped to the Twist reader of `/cmd_vel` too), so each sample is decoded strictly
/// as the reader's type (every byte accounted for), and one of a sibling's type on the same
/// name is left to that sibling.
async fn read_topic(
    node: &mut Node,
    namespace: &str,
    taken: &'static topics::Taken,
    up: mpsc::Sender<FromNode>,
) -> Result<(), String> {
    let qos = profile(taken.qos);
    let dds_topic = node
        .create_topic(
            &name(namespace, taken.name)?,
            type_name(taken.msg_type),
            &qos,
        )
        .map_err(|e| format!("{}: {e:?}", taken.name))?;
    let reader = node
        .create_subscription::<Vec<u8>>(&dds_topic, Some(qos))
        .map_err(|e| format!("{}: {e:?}", taken.name))?;
    let siblings: Vec<&'static str> = TAKEN
        .iter()
        .filter(|t| t.name == taken.name && t.msg_type != taken.msg_type)
        .map(|t| t.msg_type)
        .collect();
    tokio::spawn(async move {
        let mut stream = Box::pin(reader.async_stream_seed(RawSeed));
        let (mut undecoded, mut oversized): (u64, u64) = (0, 0);
        while let Some(sample) = stream.next().await {
            // No request is this large (the engine refuses one over MAX_REQUEST): dropped
            // here, counted, and never carried to chassisd as a line of JSON.
            if let Ok((payload, _)) = &sample
                && payload.len() > MAX_REQUEST
            {
                oversized += 1;
                if oversized.is_power_of_two() {
                    tracing::warn!(
                        topic = taken.name,
                        bytes = payload.len(),
                        oversized,
                        "ROS 2 node: a sample larger than any request dropped"
                    );
                }
                continue;
            }
            let decoded = match sample {
                Ok((payload, _)) => match decode(taken.msg_type, &payload) {
                    Ok(msg) => Ok(msg),
                    Err(_) if siblings.iter().any(|t| decode(t, &payload).is_ok()) => continue,
                    Err(e) => Err(e),
                },
                Err(e) => Err(format!("{e:?}")),
            };
            match decoded {
                Ok(msg) => {
                    let message = FromNode::Message {
                        topic: taken.name.to_owned(),
                        msg,
                    };
                    // A full queue drops the message: chassisd is behind, the peer floods.
                    if let Err(mpsc::error::TrySendError::Closed(_)) = up.try_send(message) {
                        return;
                    }
                }
                Err(error) => {
                    undecoded += 1;
                    if undecoded.is_power_of_two() {
                        tracing::warn!(topic = taken.name, msg_type = taken.msg_type, %error, undecoded, "ROS 2 node: a sample not decoded");
                    }
                }
            }
        }
    });
    Ok(())
}

/// The node on its domain, or why not.
fn join(settings: &NodeSettings) -> Result<Node, String> {
    let mut builder = DomainParticipantBuilder::new(settings.joining.domain);
    if let Some(networks) = &settings.joining.networks {
        builder = builder.with_only_networks(networks.iter().copied());
    }
    let participant = builder
        .build()
        .map_err(|e| format!("DDS participant: {e:?}"))?;
    let context = Context::from_domain_participant(participant)
        .map_err(|e| format!("ROS 2 context: {e:?}"))?;
    let namespace = if settings.config.namespace.is_empty() {
        "/"
    } else {
        &settings.config.namespace
    };
    let node_name = NodeName::new(namespace, &settings.config.node_name)
        .map_err(|e| format!("node name: {e:?}"))?;
    context
        .new_node(node_name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| format!("ROS 2 node: {e:?}"))
}

/// The action server of `navigate_to_pose`.
fn action_server(node: &mut Node, settings: &NodeSettings) -> Result<Server, String> {
    let services = profile(topics::STATE);
    let qos = ActionServerQosPolicies {
        goal_service: services.clone(),
        result_service: services.clone(),
        cancel_service: services.clone(),
        feedback_publisher: services,
        // As rcl's: a client that joins later reads the goals' states.
        status_publisher: profile(topics::LATCHED),
    };
    let mapping = match settings.joining.middleware {
        Middleware::Cyclonedds => ServiceMapping::Cyclone,
        Middleware::Fastdds => ServiceMapping::Enhanced,
    };
    let server = node
        .create_action_server::<Goal, NavResult, Feedback>(
            mapping,
            &name(&settings.config.namespace, NAVIGATE_TO_POSE)?,
            &ActionTypeName::new("nav2_msgs", "NavigateToPose"),
            qos,
        )
        .map_err(|e| format!("{NAVIGATE_TO_POSE}: {e:?}"))?;
    Ok(AsyncActionServer::new(server))
}

async fn run(settings: NodeSettings) -> Result<(), RuntimeError> {
    let mut node = join(&settings).map_err(RuntimeError::Failed)?;
    let spinner = node
        .spinner()
        .map_err(|e| RuntimeError::Failed(format!("ROS 2 node's spinner: {e:?}")))?;
    tokio::spawn(spinner.spin());
    let (up_tx, up_rx) = mpsc::channel(UP_QUEUE);
    let (to_node_tx, mut to_node) = mpsc::channel(UP_QUEUE);
    tokio::spawn(write_to_parent(up_rx));
    tokio::spawn(read_from_parent::<ToNode>(
        to_node_tx,
        MAX_LINE,
        "ROS 2 node",
    ));
    let namespace = settings.config.namespace.clone();
    let mut writers = Writers::create(&mut node, &namespace).map_err(RuntimeError::Failed)?;
    let mut goals = Goals::default();
    let (new_goals, mut new_goals_rx) = mpsc::channel(MAX_NEW_GOALS);
    let (cancels, mut cancels_rx) = mpsc::channel(MAX_NEW_GOALS);
    let (results, results_rx) = mpsc::channel(RESULT_QUEUE);
    let server = if settings.config.accept_commands {
        for taken in TAKEN {
            read_topic(&mut node, &namespace, taken, up_tx.clone())
                .await
                .map_err(RuntimeError::Failed)?;
        }
        let server = Arc::new(action_server(&mut node, &settings).map_err(RuntimeError::Failed)?);
        tokio::spawn(receive_goals(server.clone(), new_goals));
        tokio::spawn(receive_cancels(server.clone(), cancels));
        tokio::spawn(send_results(server.clone(), results_rx));
        Some(server)
    } else {
        None
    };
    tracing::info!(
        domain = settings.joining.domain,
        middleware = ?settings.joining.middleware,
        node = %settings.config.node_name,
        namespace = %settings.config.namespace,
        accept_commands = settings.config.accept_commands,
        "ROS 2 node on its domain"
    );
    if up_tx.send(FromNode::Ready).await.is_err() {
        return Ok(());
    }
    loop {
        tokio::select! {
            Some(message) = to_node.recv() => match message {
                ToNode::Publish { messages } => {
                    for (topic, msg) in &messages {
                        writers.publish(&node, topic, msg);
                    }
                }
                ToNode::Goal { goal, verdict } => {
                    if let Some(server) = &server {
                        goals.decided(server, goal, verdict).await;
                    }
                }
                ToNode::Feedback { goal, msg } => {
                    if let Some(server) = &server {
                        goals.feedback(server, goal, msg).await;
                    }
                }
                ToNode::Ended { goal, status, result } => goals.ended(&results, goal, status, result),
            },
            Some(handle) = new_goals_rx.recv() => {
                let Some(server) = &server else { continue };
                goals.received(server, handle, &up_tx).await;
            }
            Some(cancel) = cancels_rx.recv() => {
                let Some(server) = &server else { continue };
                goals.cancel(server, cancel, &up_tx).await;
            }
        }
    }
}

/// The action's goals in this process, by the number it gave each.
#[derive(Default)]
struct Goals {
    last: u64,
    /// Received, waiting for chassisd's verdict.
    new: HashMap<u64, NewGoalHandle<Goal>>,
    /// Accepted and under way.
    executing: HashMap<u64, ExecutingGoalHandle<Goal>>,
}

impl Goals {
    /// A new goal: handed to chassisd, or rejected here when too many wait.
    async fn received(
        &mut self,
        server: &Server,
        handle: NewGoalHandle<Goal>,
        up: &mpsc::Sender<FromNode>,
    ) {
        let goal = server
            .get_new_goal(handle.clone())
            .map(serde_json::to_value);
        let Some(Ok(msg)) = goal else {
            return;
        };
        if self.new.len() >= MAX_NEW_GOALS {
            tracing::warn!("ROS 2 node: {MAX_NEW_GOALS} goals already wait; one rejected");
            let _ = server.reject_goal(handle).await;
            return;
        }
        self.last += 1;
        let number = self.last;
        if up.try_send(FromNode::Goal { goal: number, msg }).is_ok() {
            self.new.insert(number, handle);
        } else {
            let _ = server.reject_goal(handle).await;
        }
    }

    /// chassisd's verdict on goal `goal`.
    async fn decided(&mut self, server: &Server, goal: u64, verdict: Result<(), String>) {
        let Some(handle) = self.new.remove(&goal) else {
            return;
        };
        if verdict.is_err() {
            let _ = server.reject_goal(handle).await;
            return;
        }
        let started = match server.accept_goal(handle).await {
            Ok(accepted) => server.start_executing_goal(accepted).await,
            Err(e) => {
                tracing::warn!(error = ?e, "ROS 2 node: a goal could not be accepted");
                return;
            }
        };
        match started {
            Ok(executing) => {
                // At most as many under way as may wait: an end never heard costs a place.
                if self.executing.len() >= MAX_NEW_GOALS
                    && let Some(&oldest) = self.executing.keys().min()
                {
                    self.executing.remove(&oldest);
                }
                self.executing.insert(goal, executing);
            }
            Err(e) => tracing::warn!(error = ?e, "ROS 2 node: a goal could not start"),
        }
    }

    async fn feedback(&mut self, server: &Server, goal: u64, msg: Value) {
        let Some(handle) = self.executing.get(&goal) else {
            return;
        };
        match serde_json::from_value::<Feedback>(msg) {
            Ok(feedback) => {
                // A goal being cancelled takes no more feedback: that is not news.
                let _ = server.publish_feedback(handle.clone(), feedback).await;
            }
            Err(e) => tracing::warn!(error = %e, "ROS 2 node: feedback not of its type"),
        }
    }

    /// Goal `goal` ended: its result goes out when its client asks for it.
    fn ended(
        &mut self,
        results: &mpsc::Sender<(ExecutingGoalHandle<Goal>, GoalEndStatus, NavResult)>,
        goal: u64,
        status: i8,
        result: Value,
    ) {
        let Some(handle) = self.executing.remove(&goal) else {
            return;
        };
        let status = match status {
            crate::api::ros2::navigate::STATUS_SUCCEEDED => GoalEndStatus::Succeeded,
            crate::api::ros2::navigate::STATUS_CANCELED => GoalEndStatus::Canceled,
            _ => GoalEndStatus::Aborted,
        };
        match serde_json::from_value::<NavResult>(result) {
            Ok(result) => {
                if results.try_send((handle, status, result)).is_err() {
                    tracing::warn!("ROS 2 node: results wait for their clients; one dropped");
                }
            }
            Err(e) => tracing::warn!(error = %e, "ROS 2 node: a result not of its type"),
        }
    }

    /// A cancel request: the goals under way that it names are being cancelled, and
    /// chassisd is told.
    async fn cancel(&mut self, server: &Server, cancel: CancelHandle, up: &mpsc::Sender<FromNode>) {
        let named: Vec<(u64, ros2_client::action::GoalId)> = self
            .executing
            .iter()
            .map(|(&n, h)| (n, h.goal_id()))
            .filter(|(_, id)| cancel.contains_goal(id))
            .collect();
        if let Err(e) = server
            .respond_to_cancel_requests(&cancel, named.iter().map(|(_, id)| *id))
            .await
        {
            tracing::warn!(error = ?e, "ROS 2 node: a cancel request not answered");
        }
        for (goal, _) in named {
            let _ = up.try_send(FromNode::Cancel { goal });
        }
    }
}

/// Hands each new goal to the main loop.
async fn receive_goals(server: Arc<Server>, out: mpsc::Sender<NewGoalHandle<Goal>>) {
    loop {
        match server.receive_new_goal().await {
            Ok(handle) => {
                if out.send(handle).await.is_err() {
                    return;
                }
            }
            Err(e) => tracing::debug!(error = ?e, "ROS 2 node: a goal request not read"),
        }
    }
}

/// Hands each cancel request to the main loop.
async fn receive_cancels(server: Arc<Server>, out: mpsc::Sender<CancelHandle>) {
    loop {
        match server.receive_cancel_request().await {
            Ok(cancel) => {
                if out.send(cancel).await.is_err() {
                    return;
                }
            }
            Err(e) => tracing::debug!(error = ?e, "ROS 2 node: a cancel request not read"),
        }
    }
}

/// Sends each ended goal's result when its client asks, one at a time (ros2-client's result
/// server reads one request stream: two waiting at once could miss each other's), each
/// waiting at most [`RESULT_WAIT`].
async fn send_results(
    server: Arc<Server>,
    mut results: mpsc::Receiver<(ExecutingGoalHandle<Goal>, GoalEndStatus, NavResult)>,
) {
    while let Some((handle, status, result)) = results.recv().await {
        let sent = tokio::time::timeout(
            RESULT_WAIT,
            server.send_result_response(handle, status, result),
        )
        .await;
        match sent {
            Ok(Ok(())) => {}
            Ok(Err(e)) => tracing::warn!(error = ?e, "ROS 2 node: a result not sent"),
            Err(_) => tracing::warn!("ROS 2 node: a goal's client never asked for its result"),
        }
    }
}
