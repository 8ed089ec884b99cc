//! The native ROS1 node: chassisd joins a ROS1 graph itself (roslibrust speaks XML-RPC and
//! TCPROS), with no ROS installation on the vehicle. What its topics and services mean is
//! `api::ros1`; this module moves the messages.
//!
//! The node runs in a process of its own (`child`, started and restarted by `node`), so
//! that what a ROS peer sends costs that process, at most its limits, never the one that
//! holds the control loop. The engine's task hands the node what it publishes through a
//! [`Ros1Link`], which never blocks: poses every control tick, IMU samples, the status, motion and mission ends, and
//! the answers to the node's own requests. The node's requests go to the engine as command
//! records of the source `ros1`, so a recording keeps them and replays without ROS.

#[cfg(feature = "ros1")]
mod bind;
#[cfg(feature = "ros1")]
pub mod child;
#[cfg(feature = "ros1")]
mod graph;
#[cfg(feature = "ros1")]
pub mod messages;
#[cfg(feature = "ros1")]
mod node;
#[cfg(feature = "ros1")]
pub mod pipe;

use tokio::sync::mpsc;

use crate::api::ros1::SOURCE;
use crate::engine::EngineOutput;

pub use crate::api::ros1::messages::ImuNoise;
#[cfg(feature = "ros1")]
pub use node::{CHILD_COMMAND, Ros1Spec, spawn};

/// Feed items waiting for the node before the newest are dropped (some 2 s of poses).
const FEED_QUEUE: usize = 256;
/// Answers waiting for the node: more than the requests it may have in flight.
const ANSWER_QUEUE: usize = 256;

pub use crate::api::ros1::publisher::Feed;

/// The engine task's end of the node's queues: sending never blocks, and what does not fit
/// is dropped and counted (the node publishes the next pose instead).
pub struct Ros1Link {
    feed: mpsc::Sender<Feed>,
    answers: mpsc::Sender<Answer>,
    dropped: u64,
}

/// The node's end.
pub struct Ros1Queues {
    /// What to publish.
    pub feed: mpsc::Receiver<Feed>,
    /// The engine's answers to the requests the node gave an id.
    pub answers: mpsc::Receiver<Answer>,
}

/// The engine's answer to the node's request `request`.
#[derive(Debug, Clone)]
pub struct Answer {
    /// The id the node gave the request.
    pub request: u64,
    /// Accepted, or why not.
    pub result: Result<(), String>,
    /// What a query asked for.
    pub data: Option<serde_json::Value>,
}

impl Ros1Link {
    /// A link and the node's end of it.
    pub fn new() -> (Self, Ros1Queues) {
        let (feed, feed_rx) = mpsc::channel(FEED_QUEUE);
        let (answers, answers_rx) = mpsc::channel(ANSWER_QUEUE);
        (
            Self {
                feed,
                answers,
                dropped: 0,
            },
            Ros1Queues {
                feed: feed_rx,
                answers: answers_rx,
            },
        )
    }

    fn send(&mut self, item: Feed) {
        if self.feed.try_send(item).is_err() {
            self.dropped += 1;
            if self.dropped.is_power_of_two() {
                tracing::warn!(dropped = self.dropped, "ROS1 node behind: poses dropped");
            }
        }
    }

    /// Takes what the node needs from `output`; returns the output when others want it too
    /// (statuses, motion ends, command answers), `None` when it was the node's alone.
    pub fn take(&mut self, output: EngineOutput) -> Option<EngineOutput> {
        match output {
            EngineOutput::Poses(t, report) => self.send(Feed::Poses(t, report)),
            EngineOutput::Imu(sample) => self.send(Feed::Imu(sample)),
            EngineOutput::Mission { tag, event } => self.send(Feed::Mission { tag, event }),
            EngineOutput::Status(status) => {
                self.send(Feed::Status(status.clone()));
                return Some(EngineOutput::Status(status));
            }
            EngineOutput::MotionEnded(result) => {
                self.send(Feed::MotionEnded(result.clone()));
                return Some(EngineOutput::MotionEnded(result));
            }
            EngineOutput::CommandResult {
                source,
                topic,
                request: Some(request),
                result,
                data,
            } if source == SOURCE => {
                // Every request with an id gets exactly one answer; the queue is longer
                // than the requests the node lets wait, so it never overflows.
                let answer = Answer {
                    request,
                    result: result.clone(),
                    data: data.clone(),
                };
                if self.answers.try_send(answer).is_err() {
                    tracing::error!("ROS1 node: an answer was lost; its caller times out");
                }
                return Some(EngineOutput::CommandResult {
                    source,
                    topic,
                    request: Some(request),
                    result,
                    data,
                });
            }
            other => return Some(other),
        }
        None
    }
}

/// The node's spec for a vehicle: its noise figures come from the configuration (the
/// localiser's odometry and gyro noise, the IMU's accelerometer and orientation noise).
#[cfg(feature = "ros1")]
pub fn spec_for(
    config: &crate::config::VehicleConfig,
    ros1: crate::config::ros1::Ros1Config,
) -> Ros1Spec {
    let localizer = crate::config::localization::localizer_config(config);
    let (accel_mps2, orientation_deg) = config.imu.as_ref().map_or((0.05, 1.0), |imu| {
        (imu.accel_noise_mps2, imu.orientation_noise_deg)
    });
    Ros1Spec {
        config: ros1,
        odometry_noise: crate::api::ros1::odometry::OdometryNoise::from_localizer(
            &localizer,
            config.imu.is_some(),
        ),
        imu_noise: ImuNoise {
            gyro_rps: localizer.gyro_sigma,
            accel_mps2,
            orientation_rad: orientation_deg.to_radians(),
        },
    }
}

/// The recording's entry for the node's commands.
pub fn source_meta() -> crate::record::SourceMeta {
    crate::record::SourceMeta::commands(SOURCE, &format!("{SOURCE}.log"))
}

/// Starts the node of `ros1` for a vehicle of `config` whose engine is `engine` (it then
/// emits the poses the node publishes); the node's requests go to `records`.
#[cfg(feature = "ros1")]
pub fn start(
    engine: &mut crate::engine::Engine,
    config: &crate::config::VehicleConfig,
    ros1: crate::config::ros1::Ros1Config,
    clock: crate::runtime::clock::RecordClock,
    records: mpsc::Sender<crate::record::Record>,
) -> Result<Ros1Link, crate::runtime::error::RuntimeError> {
    engine.emit_poses();
    let (link, queues) = Ros1Link::new();
    spawn(spec_for(config, ros1), clock, records, queues);
    Ok(link)
}

/// Without the `ros1` feature there is no node to start.
#[cfg(not(feature = "ros1"))]
pub fn start(
    _: &mut crate::engine::Engine,
    _: &crate::config::VehicleConfig,
    _: crate::config::ros1::Ros1Config,
    _: crate::runtime::clock::RecordClock,
    _: mpsc::Sender<crate::record::Record>,
) -> Result<Ros1Link, crate::runtime::error::RuntimeError> {
    Err(crate::runtime::error::RuntimeError::Failed(
        "this chassisd was built without the ros1 feature".into(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn answer(source: &str, request: Option<u64>, result: Result<(), String>) -> EngineOutput {
        EngineOutput::CommandResult {
            source: source.into(),
            topic: "/set_navi_cmd".into(),
            request,
            result,
            data: None,
        }
    }

    #[test]
    fn the_node_gets_its_own_answers_by_id_and_no_others() {
        let (mut link, mut queues) = Ros1Link::new();
        // Answered out of order, one refused: each keeps its id.
        for output in [
            answer(SOURCE, Some(2), Err("cmd must be 1 to 5".into())),
            answer(SOURCE, None, Ok(())),
            answer("websocket", Some(7), Ok(())),
            answer(SOURCE, Some(1), Ok(())),
        ] {
            assert!(link.take(output).is_some(), "answers go on to the log too");
        }
        let mut got = Vec::new();
        while let Ok(a) = queues.answers.try_recv() {
            got.push((a.request, a.result.is_ok()));
        }
        assert_eq!(got, [(2, false), (1, true)]);
    }
}
