//! The native ROS 2 node: chassisd joins a DDS domain itself (ros2-client on RustDDS), with
//! no ROS installation on the vehicle. What its topics and action mean is `api::ros2`; this
//! module moves the messages.
//!
//! The node runs in a process of its own (`child`, started and restarted by `node`), so
//! that what a DDS peer sends (discovery of any number of participants, malformed RTPS,
//! oversized samples) costs that process, at most its limits, never the one that holds the
//! control loop. The engine's task hands the node what it publishes through a [`Ros2Link`],
//! which never blocks. The node's requests go to the engine as command records of the
//! source `ros2`, so a recording keeps them and replays without DDS.

#[cfg(feature = "ros2")]
pub mod child;
#[cfg(feature = "ros2")]
pub mod interface;
#[cfg(feature = "ros2")]
pub mod messages;
#[cfg(feature = "ros2")]
mod node;
#[cfg(feature = "ros2")]
pub mod pipe;
#[cfg(feature = "ros2")]
pub mod wire;

use tokio::sync::mpsc;

use crate::api::adapter::Answer;
use crate::api::ros2::SOURCE;
use crate::api::ros2::publisher::Feed;
use crate::engine::EngineOutput;

#[cfg(feature = "ros2")]
pub use node::{CHILD_COMMAND, spawn};

/// Feed items waiting for the node before the newest are dropped (some 2 s of poses).
const FEED_QUEUE: usize = 512;
/// Answers and motion ends waiting for the node: more than the requests it lets wait.
const CONTROL_QUEUE: usize = 256;

/// What decides a goal's fate, which the node must not lose.
#[derive(Debug, Clone)]
pub enum Control {
    /// The engine's answer to a request of the node's.
    Answer(Answer),
    /// A motion ended (a goal of the action's, perhaps).
    MotionEnded(crate::control::MotionResult),
}

/// The engine task's end of the node's queues: sending never blocks, and what does not fit
/// is dropped and counted (the node publishes the next pose instead).
pub struct Ros2Link {
    feed: mpsc::Sender<Feed>,
    control: mpsc::Sender<Control>,
    dropped: u64,
}

/// The node's end.
pub struct Ros2Queues {
    /// What to publish from.
    pub feed: mpsc::Receiver<Feed>,
    /// Answers and motion ends.
    pub control: mpsc::Receiver<Control>,
}

impl Ros2Link {
    /// A link and the node's end of it.
    pub fn new() -> (Self, Ros2Queues) {
        let (feed, feed_rx) = mpsc::channel(FEED_QUEUE);
        let (control, control_rx) = mpsc::channel(CONTROL_QUEUE);
        (
            Self {
                feed,
                control,
                dropped: 0,
            },
            Ros2Queues {
                feed: feed_rx,
                control: control_rx,
            },
        )
    }

    /// Looks at an engine output on its way elsewhere and takes what the node needs.
    pub fn see(&mut self, output: &EngineOutput) {
        let control = match output {
            EngineOutput::MotionEnded(result) => Control::MotionEnded(result.clone()),
            EngineOutput::CommandResult {
                source,
                topic,
                request: Some(request),
                result,
                data,
            } if source == SOURCE => Control::Answer(Answer {
                topic: topic.clone(),
                request: Some(*request),
                result: result.clone(),
                data: data.clone(),
            }),
            other => return self.feed(other),
        };
        // The queue is longer than the requests the node lets wait, and motions end seldom.
        if self.control.try_send(control).is_err() {
            tracing::error!("ROS 2 node: an answer or a motion's end was lost");
        }
    }

    fn feed(&mut self, output: &EngineOutput) {
        let item = match output {
            EngineOutput::Poses(t, report) => Feed::Poses(*t, *report),
            EngineOutput::Imu(sample) => Feed::Imu(*sample),
            EngineOutput::Fix(t, fix) => Feed::Fix(*t, fix.clone()),
            EngineOutput::Status(status) => Feed::Status(status.clone()),
            EngineOutput::Event(event) => Feed::Event(event.to_string()),
            _ => return,
        };
        if self.feed.try_send(item).is_err() {
            self.dropped += 1;
            if self.dropped.is_power_of_two() {
                tracing::warn!(dropped = self.dropped, "ROS 2 node behind: feed dropped");
            }
        }
    }
}

/// The recording's entry for the node's requests.
pub fn source_meta() -> crate::record::SourceMeta {
    crate::record::SourceMeta::commands(SOURCE, &format!("{SOURCE}.log"))
}

/// Starts the node of `ros2` for a vehicle of `config` whose engine is `engine` (it then
/// emits the poses, samples and fixes the node publishes); the node's requests go to
/// `records`.
#[cfg(feature = "ros2")]
pub fn start(
    engine: &mut crate::engine::Engine,
    config: &crate::config::VehicleConfig,
    ros2: crate::config::ros2::Ros2Config,
    clock: crate::runtime::clock::RecordClock,
    records: mpsc::Sender<crate::record::Record>,
) -> Result<Ros2Link, crate::runtime::error::RuntimeError> {
    let settings = node::settings(config, ros2)?;
    engine.emit_poses();
    let (link, queues) = Ros2Link::new();
    spawn(settings, clock, records, queues);
    Ok(link)
}

/// Without the `ros2` feature there is no node to start.
#[cfg(not(feature = "ros2"))]
pub fn start(
    _: &mut crate::engine::Engine,
    _: &crate::config::VehicleConfig,
    _: crate::config::ros2::Ros2Config,
    _: crate::runtime::clock::RecordClock,
    _: mpsc::Sender<crate::record::Record>,
) -> Result<Ros2Link, crate::runtime::error::RuntimeError> {
    Err(crate::runtime::error::RuntimeError::Failed(
        "this chassisd was built without the ros2 feature".into(),
    ))
}
