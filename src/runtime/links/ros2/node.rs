//! chassisd's side of the ROS 2 node: it starts the node's own process ([`super::child`]),
//! hands it every message to publish (built by `api::ros2::publisher` from the engine's
//! feed), takes what it hears to the engine as records (each topic held to
//! `ros2.command_rate_hz`), and decides the action's goals: the engine's answer accepts or
//! rejects one, the status ticks give its feedback, its motion's end its result. When that
//! process ends (a limit reached by a hostile peer, a panic, a kill), it is logged and
//! started again; the engine and the drives never wait for it.

use std::collections::HashMap;
use std::path::Path;
use std::time::{Duration, Instant};

use serde_json::Value;
use tokio::sync::mpsc;

use super::pipe::{FromNode, MAX_LINE, NodeSettings, ToNode};
use super::{Control, Ros2Queues};
use crate::api::adapter::Answer;
use crate::api::log_budget::{self, LogBudget, SharedBudget};
use crate::api::ros1::messages::ImuNoise;
use crate::api::ros1::odometry::OdometryNoise;
use crate::api::ros2::messages::Mounts;
use crate::api::ros2::navigate::Navigation;
use crate::api::ros2::publisher::{Feed, Messages, Publishing, Settings};
use crate::api::ros2::topics::TAKEN;
use crate::api::ros2::{self, NAVIGATE_TO_POSE, NAVIGATE_TO_POSE_CANCEL};
use crate::api::rosbridge::messages::goal_from_pose_stamped;
use crate::config::VehicleConfig;
use crate::config::ros2::Ros2Config;
use crate::record::{Payload, Record};
use crate::runtime::child_process;
use crate::runtime::clock::RecordClock;
use crate::runtime::error::RuntimeError;
use crate::runtime::links::child_pipes::ChildPipes;
use crate::runtime::links::command_rate::{CommandRate, RateReport};

/// The hidden subcommand that runs [`super::child::main`].
pub const CHILD_COMMAND: &str = "ros2-child";
/// Goals that may wait for the engine's answer at once; more are rejected as busy.
const MAX_PENDING: usize = 16;
/// How long a goal keeps its place while no answer comes.
const FORGET_AFTER: Duration = Duration::from_secs(10);
/// Lines waiting for the node's process before new ones are dropped (some 2 s of poses).
const DOWN_QUEUE: usize = 512;
/// The first wait before a restart; doubled while restarts keep failing.
const FIRST_BACKOFF: Duration = Duration::from_millis(250);
/// The longest wait between restarts.
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// A process that lived this long resets the back-off.
const STABLE_AFTER: Duration = Duration::from_secs(30);
/// Status ticks (10 Hz) between two feedbacks of a goal: 5 Hz.
const FEEDBACK_EVERY: u64 = 2;

/// Refused requests' log lines (a peer may be refused as fast as it publishes).
static REFUSED: SharedBudget = SharedBudget::new(LogBudget::new());

/// What the node is built from.
#[derive(Debug, Clone)]
pub struct Ros2Spec {
    /// The node process's settings.
    pub node: NodeSettings,
    /// What its messages are built with.
    pub publishing: Settings,
}

/// The node's spec for a vehicle: its noise figures come from the configuration (the
/// localiser's odometry and gyro noise, the IMU's), its mounts from the receiver's antenna
/// and the IMU's mounting.
pub fn settings(config: &VehicleConfig, ros2: Ros2Config) -> Result<Ros2Spec, RuntimeError> {
    let joining = super::interface::resolve(&ros2, Path::new("[ros2]"))
        .map_err(|e| RuntimeError::Failed(e.to_string()))?;
    let localizer = crate::config::localization::localizer_config(config);
    let (accel_mps2, orientation_deg) = config.imu.as_ref().map_or((0.05, 1.0), |imu| {
        (imu.accel_noise_mps2, imu.orientation_noise_deg)
    });
    let antenna = config
        .gnss
        .as_ref()
        .map_or([0.0; 3], |g| [g.antenna.x, g.antenna.y, g.antenna.z]);
    let imu = config.imu.as_ref().map(|imu| {
        let q = imu.mounting().rotation;
        [q.i, q.j, q.k, q.w]
    });
    Ok(Ros2Spec {
        publishing: Settings {
            odometry_noise: OdometryNoise::from_localizer(&localizer, config.imu.is_some()),
            imu_noise: ImuNoise {
                gyro_rps: localizer.gyro_sigma,
                accel_mps2,
                orientation_rad: orientation_deg.to_radians(),
            },
            mounts: Mounts { antenna, imu },
            frames: ros2.frames.clone(),
            odom_rate_hz: ros2.odom_rate_hz,
        },
        node: NodeSettings {
            config: ros2,
            joining,
        },
    })
}

/// A goal waiting for the engine's answer.
struct PendingGoal {
    /// The node process (by its start number) and its number for the goal.
    goal: (u64, u64),
    /// Where to, in `map`.
    target: (f64, f64),
    sent: Instant,
}

/// What the node's task keeps: the requests in flight, the goals under way and where their
/// answers go.
struct Requests {
    records: mpsc::Sender<Record>,
    clock: RecordClock,
    rate: CommandRate,
    last_id: u64,
    pending: HashMap<u64, PendingGoal>,
    navigation: Navigation,
    /// The goals under way, by the id each was recorded with: their process and number.
    goals: HashMap<u64, (u64, u64)>,
    status_ticks: u64,
}

impl Requests {
    /// Records `msg` taken on `topic` (with `id` when its answer is awaited).
    fn record(&mut self, topic: &str, id: Option<u64>, msg: &Value) -> Result<(), String> {
        let record = Record {
            t: self.clock.now(),
            source: ros2::SOURCE.into(),
            payload: Payload::Command {
                topic: topic.to_owned(),
                payload: ros2::adapter::encode(id, msg),
            },
        };
        self.records
            .try_send(record)
            .map_err(|_| "the vehicle's command queue is full".to_owned())
    }

    /// Whether a message on `topic` may pass its rate; says so in the log when not.
    fn admit(&mut self, topic: &str) -> bool {
        let (admitted, report) = self.rate.admit(topic, Instant::now());
        log_rate(report);
        admitted
    }

    /// A goal of process `number`: recorded for the engine, or refused now with the reason.
    fn goal(&mut self, number: u64, goal: u64, msg: &Value) -> Result<(), String> {
        self.pending.retain(|_, p| p.sent.elapsed() < FORGET_AFTER);
        if self.pending.len() >= MAX_PENDING {
            return Err(format!(
                "busy: {MAX_PENDING} goals already wait for the vehicle"
            ));
        }
        if !self.admit(NAVIGATE_TO_POSE) {
            return Err(format!(
                "over ros2.command_rate_hz goals on {NAVIGATE_TO_POSE}"
            ));
        }
        let pose = msg.get("pose").unwrap_or(&Value::Null);
        let (x, y, _) = goal_from_pose_stamped(pose)
            .map_err(|reason| format!("{NAVIGATE_TO_POSE}: {reason}"))?;
        self.last_id += 1;
        let id = self.last_id;
        self.record(NAVIGATE_TO_POSE, Some(id), msg)?;
        self.pending.insert(
            id,
            PendingGoal {
                goal: (number, goal),
                target: (x, y),
                sent: Instant::now(),
            },
        );
        Ok(())
    }

    /// Its client asks to cancel goal `goal` of process `number`: the vehicle stops when
    /// it is the one under way.
    fn cancel(&mut self, number: u64, goal: u64) {
        let Some((&id, _)) = self.goals.iter().find(|(_, g)| **g == (number, goal)) else {
            return;
        };
        if self.navigation.cancel(id)
            && let Err(reason) = self.record(NAVIGATE_TO_POSE_CANCEL, None, &serde_json::json!({}))
        {
            tracing::warn!(%reason, "ROS 2 node: a goal's cancel was not taken");
        }
    }
}

/// Logs what the rate limiter says, once and then in summaries.
fn log_rate(report: Option<RateReport>) {
    match report {
        Some(RateReport::Started(topic)) => {
            tracing::warn!(%topic, "ROS 2 messages over ros2.command_rate_hz: dropped (a summary follows every 5 s)")
        }
        Some(RateReport::Summary(counts)) => {
            tracing::warn!(?counts, "ROS 2 messages dropped over ros2.command_rate_hz")
        }
        None => {}
    }
}

/// The running node process.
struct NodeProcess {
    /// Its start number (1 for the first).
    number: u64,
    pipes: ChildPipes<FromNode>,
    ready: bool,
    dropped: u64,
}

impl NodeProcess {
    /// Sends `message` if the process keeps up; otherwise it is dropped and counted.
    fn send(&mut self, message: &ToNode) {
        let Ok(line) = serde_json::to_string(message) else {
            return;
        };
        if self.pipes.down.try_send(line).is_err() {
            self.dropped += 1;
            if self.dropped.is_power_of_two() {
                tracing::warn!(
                    dropped = self.dropped,
                    "ROS 2 node's process behind: messages dropped"
                );
            }
        }
    }

    fn publish(&mut self, messages: Messages) {
        if !self.ready || messages.is_empty() {
            return;
        }
        let messages = messages
            .into_iter()
            .map(|(topic, msg)| (topic.to_owned(), msg))
            .collect();
        self.send(&ToNode::Publish { messages });
    }
}

/// Starts the node; it runs until the runtime ends. Requests go to `records`.
pub fn spawn(
    spec: Ros2Spec,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
    queues: Ros2Queues,
) {
    tokio::spawn(crate::runtime::panics::or_report_down(
        "ROS 2 node",
        run(spec, clock, records, queues),
    ));
}

async fn run(
    spec: Ros2Spec,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
    queues: Ros2Queues,
) {
    let Ros2Queues {
        mut feed,
        mut control,
    } = queues;
    let exe = match child_process::self_exe("ROS 2 node") {
        Ok(exe) => exe,
        Err(e) => {
            tracing::error!(error = %e, "ROS 2 node not started");
            return;
        }
    };
    let Ok(settings) = serde_json::to_string(&spec.node) else {
        tracing::error!("ROS 2 node not started: its settings cannot be written");
        return;
    };
    let config = &spec.node.config;
    let rate = CommandRate::new(config.command_rate_hz, config.command_burst).with_known_topics(
        TAKEN
            .iter()
            .map(|t| t.name.to_owned())
            .chain([NAVIGATE_TO_POSE.to_owned()]),
    );
    let mut publishing = Publishing::new(spec.publishing.clone());
    let mut requests = Requests {
        records,
        clock,
        rate,
        last_id: 0,
        pending: HashMap::new(),
        navigation: Navigation::default(),
        goals: HashMap::new(),
        status_ticks: 0,
    };
    let mut backoff = FIRST_BACKOFF;
    let mut number = 0;
    loop {
        number += 1;
        match ChildPipes::start(
            &exe,
            CHILD_COMMAND,
            &settings,
            DOWN_QUEUE,
            MAX_LINE,
            "ROS 2 node",
        )
        .await
        {
            Ok(pipes) => {
                let node = NodeProcess {
                    number,
                    pipes,
                    ready: false,
                    dropped: 0,
                };
                let lived = serve(
                    node,
                    &mut feed,
                    &mut control,
                    &mut publishing,
                    &mut requests,
                )
                .await;
                if lived > STABLE_AFTER {
                    backoff = FIRST_BACKOFF;
                }
            }
            Err(e) => tracing::error!(error = %e, "ROS 2 node's process not started; trying again"),
        }
        idle(
            backoff,
            &mut feed,
            &mut control,
            &mut publishing,
            &mut requests,
        )
        .await;
        backoff = (backoff * 2).min(MAX_BACKOFF);
    }
}

/// Serves the engine and the node's process until it ends; how long it lived.
async fn serve(
    mut node: NodeProcess,
    feed: &mut mpsc::Receiver<Feed>,
    control: &mut mpsc::Receiver<Control>,
    publishing: &mut Publishing,
    requests: &mut Requests,
) -> Duration {
    let mut summaries = tokio::time::interval(crate::runtime::links::command_rate::SUMMARY_EVERY);
    let status = loop {
        tokio::select! {
            Some(item) = feed.recv() => {
                let messages = on_feed(publishing, requests, &item, Some(&mut node));
                node.publish(messages);
            }
            Some(item) = control.recv() => on_control(requests, publishing, item, Some(&mut node)),
            message = node.pipes.up.recv() => match message {
                Some(FromNode::Ready) => {
                    node.ready = true;
                    let mut once = Vec::new();
                    publishing.on_ready(requests.clock.now(), &mut once);
                    node.publish(once);
                }
                Some(FromNode::Message { topic, msg }) => {
                    if requests.admit(&topic)
                        && let Err(reason) = requests.record(&topic, None, &msg)
                        && let Some(left_out) = log_budget::allow(&REFUSED, requests.clock.now())
                    {
                        tracing::warn!(%topic, %reason, left_out, "ROS 2 message not taken");
                    }
                }
                Some(FromNode::Goal { goal, msg }) => {
                    if let Err(reason) = requests.goal(node.number, goal, &msg) {
                        refuse_goal(&mut node, publishing, requests.clock.now(), goal, reason);
                    }
                }
                Some(FromNode::Cancel { goal }) => requests.cancel(node.number, goal),
                None => break node.pipes.child.wait().await,
            },
            _ = summaries.tick() => log_rate(requests.rate.due_summary(Instant::now())),
            status = node.pipes.child.wait() => break status,
        }
    };
    let lived = node.pipes.started.elapsed();
    let why = match status {
        Ok(s) => child_process::describe_exit(s, &[]),
        Err(e) => format!("cannot be waited for: {e}"),
    };
    tracing::error!(
        reason = %why,
        lived_s = lived.as_secs_f64(),
        process = node.number,
        "ROS 2 node's process ended; starting it again"
    );
    lived
}

/// Rejects goal `goal` for `reason`: the action protocol carries no reason, so it goes to
/// `/rosout` and the log.
fn refuse_goal(
    node: &mut NodeProcess,
    publishing: &mut Publishing,
    now: crate::time::Timestamp,
    goal: u64,
    reason: String,
) {
    let text = format!("{NAVIGATE_TO_POSE}: goal rejected: {reason}");
    if let Some(left_out) = log_budget::allow(&REFUSED, now) {
        tracing::warn!(%reason, left_out, "ROS 2 goal rejected");
    }
    let mut messages = Vec::new();
    publishing.on_feed(&Feed::Event(text), &mut messages);
    node.publish(messages);
    node.send(&ToNode::Goal {
        goal,
        verdict: Err(reason),
    });
}

/// The messages `item` makes due, and each goal's feedback at a status tick.
fn on_feed(
    publishing: &mut Publishing,
    requests: &mut Requests,
    item: &Feed,
    node: Option<&mut NodeProcess>,
) -> Messages {
    let mut out = Vec::new();
    publishing.on_feed(item, &mut out);
    if let Feed::Status(status) = item {
        requests.status_ticks += 1;
        if requests.status_ticks.is_multiple_of(FEEDBACK_EVERY)
            && let Some(node) = node
        {
            for (id, msg) in requests.navigation.feedback(status) {
                if let Some(&(number, goal)) = requests.goals.get(&id)
                    && number == node.number
                {
                    node.send(&ToNode::Feedback { goal, msg });
                }
            }
        }
    }
    out
}

/// Acts on an answer or a motion's end: a goal accepted or rejected, a goal ended.
fn on_control(
    requests: &mut Requests,
    publishing: &mut Publishing,
    item: Control,
    node: Option<&mut NodeProcess>,
) {
    match item {
        Control::Answer(Answer {
            request: Some(id),
            result,
            ..
        }) => {
            let Some(pending) = requests.pending.remove(&id) else {
                return;
            };
            if result.is_ok() {
                requests
                    .navigation
                    .accepted(id, pending.target, requests.clock.now());
                requests.goals.insert(id, pending.goal);
                // Those the navigation no longer keeps (a motion's end never heard) go too.
                let navigation = &requests.navigation;
                requests.goals.retain(|id, _| navigation.is_active(*id));
            }
            let Some(node) = node else {
                return;
            };
            let (number, goal) = pending.goal;
            if number != node.number {
                return;
            }
            match result {
                Ok(()) => node.send(&ToNode::Goal {
                    goal,
                    verdict: Ok(()),
                }),
                Err(reason) => refuse_goal(node, publishing, requests.clock.now(), goal, reason),
            }
        }
        Control::Answer(_) => {}
        Control::MotionEnded(result) => {
            let Some(ended) = requests.navigation.ended(&result) else {
                return;
            };
            let Some((number, goal)) = requests.goals.remove(&ended.goal) else {
                return;
            };
            if let Some(node) = node
                && number == node.number
            {
                node.send(&ToNode::Ended {
                    goal,
                    status: ended.status,
                    result: ended.result,
                });
            }
        }
    }
}

/// Waits `pause` with no node process, keeping up with the engine meanwhile so nothing
/// piles up.
async fn idle(
    pause: Duration,
    feed: &mut mpsc::Receiver<Feed>,
    control: &mut mpsc::Receiver<Control>,
    publishing: &mut Publishing,
    requests: &mut Requests,
) {
    let pause = tokio::time::sleep(pause);
    tokio::pin!(pause);
    loop {
        tokio::select! {
            () = &mut pause => return,
            Some(item) = feed.recv() => drop(on_feed(publishing, requests, &item, None)),
            Some(item) = control.recv() => on_control(requests, publishing, item, None),
        }
    }
}
