//! chassisd's side of the node: it starts the node's own process ([`super::child`]), hands it
//! every message to publish (built here, from the engine's feed), takes its requests to the
//! engine as records, and gives their answers back. When that process ends (a limit reached
//! by a hostile peer, a panic in roslibrust, a kill), it is logged and started again; the
//! engine and the drives never wait for it.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use tokio::process::Child;
use tokio::sync::mpsc;

use super::pipe::{FromNode, MAX_LINE, NodeSettings, ToNode};
use super::{Answer, Feed, Ros1Queues};
use crate::api::log_budget::{self, LogBudget, SharedBudget};
use crate::api::ros1;
use crate::api::ros1::adapter::Ros1Request;
use crate::api::ros1::messages::ImuNoise;
use crate::api::ros1::odometry::OdometryNoise;
use crate::api::ros1::publisher::{Messages, Publishing};
use crate::config::ros1::Ros1Config;
use crate::record::{Payload, Record};
use crate::runtime::child_process;
use crate::runtime::clock::RecordClock;
use crate::runtime::links::child_pipes::ChildPipes;

/// The hidden subcommand that runs [`super::child::main`].
pub const CHILD_COMMAND: &str = "ros1-child";
/// Requests that may wait for the engine's answer at once; more are refused as busy.
const MAX_PENDING: usize = 64;
/// How long a request keeps its place while no answer comes (one lost on the way, which the
/// queues' sizes rule out, must not hold a place for ever).
const FORGET_AFTER: Duration = Duration::from_secs(10);
/// Lines waiting for the node's process before new ones are dropped (some 2 s of poses).
const DOWN_QUEUE: usize = 256;
/// The first wait before a restart; doubled while restarts keep failing.
const FIRST_BACKOFF: Duration = Duration::from_millis(250);
/// The longest wait between restarts.
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// A process that lived this long resets the back-off.
const STABLE_AFTER: Duration = Duration::from_secs(30);

/// Refused requests' log lines (a caller may refuse itself as fast as it calls).
static REFUSED: SharedBudget = SharedBudget::new(LogBudget::new());

/// What the node is built from.
#[derive(Debug, Clone)]
pub struct Ros1Spec {
    /// `[ros1]`.
    pub config: Ros1Config,
    /// The odometry's noise (`/raw_odom`'s covariance).
    pub odometry_noise: OdometryNoise,
    /// The IMU's noise (`/imu/data`'s covariances).
    pub imu_noise: ImuNoise,
}

/// One request waiting for the engine's answer.
struct Pending {
    /// The node process (by its start number) and call that waits, if one does.
    call: Option<(u64, u64)>,
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
struct Requests {
    records: mpsc::Sender<Record>,
    clock: RecordClock,
    last_id: u64,
    by_id: HashMap<u64, Pending>,
}

impl Requests {
    /// Hands `request` to the engine; `call` is who waits for its answer.
    fn submit(&mut self, request: &Ros1Request, call: Option<(u64, u64)>) -> Result<(), String> {
        let id = if request.awaits_answer() {
            self.by_id.retain(|_, p| p.sent.elapsed() < FORGET_AFTER);
            if self.by_id.len() >= MAX_PENDING {
                return Err(format!(
                    "busy: {MAX_PENDING} requests already wait for the vehicle"
                ));
            }
            self.last_id += 1;
            Some(self.last_id)
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
            self.by_id.insert(
                id,
                Pending {
                    call,
                    starts_motion: request.starts_motion(),
                    charging: request.is_charging(),
                    edits_zones: request.edits_zones(),
                    sent: Instant::now(),
                },
            );
        }
        Ok(())
    }
}

/// The running node process and the ends of its pipes.
struct NodeProcess {
    /// Its start number (1 for the first).
    number: u64,
    child: Child,
    down: mpsc::Sender<String>,
    up: mpsc::Receiver<FromNode>,
    started: Instant,
    registered: bool,
    dropped: u64,
}

impl NodeProcess {
    /// Sends `message` if the process keeps up; otherwise it is dropped and counted.
    fn send(&mut self, message: &ToNode) {
        let Ok(line) = serde_json::to_string(message) else {
            return;
        };
        if self.down.try_send(line).is_err() {
            self.dropped += 1;
            if self.dropped.is_power_of_two() {
                tracing::warn!(
                    dropped = self.dropped,
                    "ROS1 node's process behind: messages dropped"
                );
            }
        }
    }

    fn publish(&mut self, messages: Messages) {
        if !self.registered || messages.is_empty() {
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
    let exe = match child_process::self_exe("ROS1 node") {
        Ok(exe) => exe,
        Err(e) => {
            tracing::error!(error = %e, "ROS1 node not started");
            return;
        }
    };
    let settings = NodeSettings {
        config: spec.config.clone(),
    };
    let Ok(settings) = serde_json::to_string(&settings) else {
        tracing::error!("ROS1 node not started: its settings cannot be written");
        return;
    };
    let mut publishing = Publishing::new(spec.odometry_noise, spec.imu_noise);
    let mut requests = Requests {
        records,
        clock,
        last_id: 0,
        by_id: HashMap::new(),
    };
    let mut backoff = FIRST_BACKOFF;
    let mut number = 0;
    loop {
        number += 1;
        match start(&exe, &settings, number).await {
            Ok(node) => {
                let lived = serve(
                    node,
                    &mut feed,
                    &mut answers,
                    &mut publishing,
                    &mut requests,
                )
                .await;
                if lived > STABLE_AFTER {
                    backoff = FIRST_BACKOFF;
                }
            }
            Err(e) => tracing::error!(error = %e, "ROS1 node's process not started; trying again"),
        }
        idle(
            backoff,
            &mut feed,
            &mut answers,
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
    answers: &mut mpsc::Receiver<Answer>,
    publishing: &mut Publishing,
    requests: &mut Requests,
) -> Duration {
    let status = loop {
        tokio::select! {
            Some(item) = feed.recv() => {
                let messages = on_feed(publishing, &item);
                node.publish(messages);
            }
            Some(answer) = answers.recv() => {
                answer_pending(requests, publishing, answer, Some(&mut node));
            }
            message = node.up.recv() => match message {
                Some(FromNode::Registered) => {
                    node.registered = true;
                    // The latched status codes again, for the new registrations.
                    let mut latched = Vec::new();
                    publishing.latched(&mut latched);
                    node.publish(latched);
                }
                Some(FromNode::Request { call, request }) => {
                    let request = request.kept();
                    let result = requests.submit(&request, call.map(|c| (node.number, c)));
                    if let Err(reason) = &result
                        && let Some(left_out) = log_budget::allow(&REFUSED, requests.clock.now())
                    {
                        tracing::warn!(request = request.name(), %reason, left_out, "ROS1 request refused");
                    }
                    // A refusal, or a request the engine does not answer, is answered now.
                    if let Some(call) = call
                        && (result.is_err() || !request.awaits_answer())
                    {
                        node.send(&ToNode::Answer { call, result: result.map(|()| None) });
                    }
                }
                None => break node.child.wait().await,
            },
            status = node.child.wait() => break status,
        }
    };
    let lived = node.started.elapsed();
    let why = match status {
        Ok(s) => child_process::describe_exit(
            s,
            &[(
                super::child::EXIT_DESCRIPTORS,
                "peers' connections held all its descriptors",
            )],
        ),
        Err(e) => format!("cannot be waited for: {e}"),
    };
    tracing::error!(
        reason = %why,
        lived_s = lived.as_secs_f64(),
        process = node.number,
        "ROS1 node's process ended; starting it again (it registers anew)"
    );
    lived
}

/// The messages `item` makes due.
fn on_feed(publishing: &mut Publishing, item: &Feed) -> Messages {
    let mut out = Vec::new();
    publishing.on_feed(item, &mut out);
    out
}

/// Waits `pause` with no node process, keeping up with the engine meanwhile so nothing
/// piles up.
async fn idle(
    pause: Duration,
    feed: &mut mpsc::Receiver<Feed>,
    answers: &mut mpsc::Receiver<Answer>,
    publishing: &mut Publishing,
    requests: &mut Requests,
) {
    let pause = tokio::time::sleep(pause);
    tokio::pin!(pause);
    loop {
        tokio::select! {
            () = &mut pause => return,
            Some(item) = feed.recv() => drop(on_feed(publishing, &item)),
            Some(answer) = answers.recv() => answer_pending(requests, publishing, answer, None),
        }
    }
}

/// Starts node process `number` and hands it its settings.
async fn start(
    exe: &std::path::Path,
    settings: &str,
    number: u64,
) -> Result<NodeProcess, std::io::Error> {
    let ChildPipes {
        child,
        down,
        up,
        started,
    } = ChildPipes::start(
        exe,
        CHILD_COMMAND,
        settings,
        DOWN_QUEUE,
        MAX_LINE,
        "ROS1 node",
    )
    .await?;
    Ok(NodeProcess {
        number,
        child,
        down,
        up,
        started,
        registered: false,
        dropped: 0,
    })
}

/// Gives the engine's `answer` to the request it names.
fn answer_pending(
    requests: &mut Requests,
    publishing: &mut Publishing,
    Answer {
        request,
        result,
        data,
    }: Answer,
    node: Option<&mut NodeProcess>,
) {
    let Some(entry) = requests.by_id.remove(&request) else {
        return;
    };
    let mut codes = Vec::new();
    if result.is_ok() && entry.starts_motion {
        publishing.on_request_accepted(entry.charging, &mut codes);
    }
    if entry.edits_zones {
        publishing.on_zone_edit(result.is_ok(), &mut codes);
    }
    let Some(node) = node else {
        return;
    };
    node.publish(codes);
    // A caller of an earlier process is gone with it.
    if let Some((number, call)) = entry.call
        && number == node.number
    {
        node.send(&ToNode::Answer {
            call,
            result: result.map(|()| data),
        });
    }
}
