//! What the node publishes, sans-IO: the topics it advertises, and from each item the
//! engine feeds it (poses every control tick, IMU samples, status ticks, motion ends,
//! mission progress) the messages due, as JSON of their types with their topics. The node
//! advertises [`advertised`] and serialises what [`Publishing`] returns; it decides nothing.

use std::time::Duration;

use serde_json::Value;

use super::messages::{self, ImuNoise};
use super::odometry::{OdometryNoise, OdometryUncertainty};
use super::published;
use super::status::{StatusTopics, Topic};
use crate::control::MotionTag;
use crate::control::mission::MissionEvent;
use crate::devices::imu::ImuSample;
use crate::time::Timestamp;
use crate::vehicle::{Localization, Pose2D, PoseReport, VehicleStatus};

/// `/tracked_pose`'s and `/tf`'s period (15 Hz).
const TRACKED_POSE_PERIOD: Duration = Duration::from_nanos(1_000_000_000 / 15);

/// What the engine's outputs give the node.
#[derive(Debug, Clone)]
pub enum Feed {
    /// The poses at a control tick.
    Poses(Timestamp, PoseReport),
    /// An IMU sample, in the vehicle frame.
    Imu(ImuSample),
    /// A status tick.
    Status(Box<VehicleStatus>),
    /// A motion ended.
    MotionEnded(crate::control::MotionResult),
    /// A mission made progress.
    Mission {
        /// Who asked.
        tag: Option<MotionTag>,
        /// What happened.
        event: MissionEvent,
    },
}

/// A topic the node advertises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Advertised {
    /// Its name.
    pub name: &'static str,
    /// Its ROS type, one of `interfaces/`.
    pub msg_type: &'static str,
    /// Messages kept for a slow subscriber.
    pub queue: usize,
    /// Latched: a new subscriber gets the last message at once.
    pub latched: bool,
}

/// Every topic the node publishes.
pub fn advertised() -> Vec<Advertised> {
    let plain = |name, msg_type| Advertised {
        name,
        msg_type,
        queue: 10,
        latched: false,
    };
    let mut topics = vec![
        plain("/raw_odom", "nav_msgs/Odometry"),
        plain("/imu/data", "sensor_msgs/Imu"),
        plain("/tracked_pose", "geometry_msgs/PoseStamped"),
        plain("/tf", "tf2_msgs/TFMessage"),
    ];
    topics.extend(
        published::STATUS_TOPICS
            .iter()
            .map(|t| plain(t.name, t.msg_type)),
    );
    topics.extend(Topic::ALL.iter().map(|t| Advertised {
        name: t.name(),
        msg_type: "std_msgs/Int16",
        queue: 1,
        latched: true,
    }));
    topics
}

/// Messages due, each with its topic.
pub type Messages = Vec<(&'static str, Value)>;

/// What the publishers keep between messages.
#[derive(Debug)]
pub struct Publishing {
    odometry: OdometryUncertainty,
    imu_noise: ImuNoise,
    status: StatusTopics,
    next_tracked_pose: Option<Timestamp>,
    seq: u32,
    imu_seq: u32,
    status_ticks: u64,
}

impl Publishing {
    /// Publishing with these noise figures (the covariances of `/raw_odom` and `/imu/data`).
    pub fn new(odometry: OdometryNoise, imu_noise: ImuNoise) -> Self {
        Self {
            odometry: OdometryUncertainty::new(odometry),
            imu_noise,
            status: StatusTopics::default(),
            next_tracked_pose: None,
            seq: 0,
            imu_seq: 0,
            status_ticks: 0,
        }
    }

    /// The messages `item` makes due.
    pub fn on_feed(&mut self, item: &Feed, out: &mut Messages) {
        let mut codes = Vec::new();
        match item {
            Feed::Poses(t, report) => self.on_poses(*t, report, out),
            Feed::Imu(sample) => {
                self.imu_seq = self.imu_seq.wrapping_add(1);
                out.push((
                    "/imu/data",
                    messages::imu(sample, self.imu_seq, &self.imu_noise),
                ));
            }
            Feed::Status(status) => {
                self.status_ticks += 1;
                for topic in published::due(self.status_ticks) {
                    if let Some(msg) = (topic.build)(status, self.status_ticks as u32) {
                        out.push((topic.name, msg));
                    }
                }
                self.status.on_status(status, &mut codes);
            }
            Feed::MotionEnded(result) => self.status.on_motion_ended(result, &mut codes),
            Feed::Mission { tag, event } => self.status.on_mission(*tag, event, &mut codes),
        }
        push_codes(codes, out);
    }

    fn on_poses(&mut self, t: Timestamp, report: &PoseReport, out: &mut Messages) {
        if let Some(odom) = report.odom {
            let covariance = self.odometry.update(t, &odom);
            self.seq = self.seq.wrapping_add(1);
            out.push((
                "/raw_odom",
                messages::odometry(t, self.seq, &odom, &covariance),
            ));
        }
        // `/tracked_pose` and `/tf` at 15 Hz.
        let due = self.next_tracked_pose.is_none_or(|next| t >= next);
        if !due || (report.map.is_none() && report.odom.is_none()) {
            return;
        }
        // One period on from the last message (the first one's included).
        let next = self
            .next_tracked_pose
            .unwrap_or(t)
            .saturating_add(TRACKED_POSE_PERIOD);
        // Late by more than a period (a pause in the feed): start again from now.
        self.next_tracked_pose = Some(if next < t {
            t.saturating_add(TRACKED_POSE_PERIOD)
        } else {
            next
        });
        if let Some((pose, _)) = report.map {
            out.push(("/tracked_pose", messages::pose_stamped(t, self.seq, &pose)));
        }
        if let Some(tf) = messages::tf(t, report) {
            out.push(("/tf", tf));
        }
    }

    /// A request that starts a motion was accepted (the charging action, or a move): the
    /// codes that announce it.
    pub fn on_request_accepted(&mut self, charging: bool, out: &mut Messages) {
        let mut codes = Vec::new();
        self.status.on_request_accepted(charging, &mut codes);
        push_codes(codes, out);
    }

    /// An edit of the zones was answered (made or refused).
    pub fn on_zone_edit(&mut self, made: bool, out: &mut Messages) {
        let mut codes = Vec::new();
        self.status.on_zone_edit(made, &mut codes);
        push_codes(codes, out);
    }

    /// The latched codes as they stand, for a new registration.
    pub fn latched(&self, out: &mut Messages) {
        push_codes(self.status.current(), out);
    }
}

fn push_codes(codes: Vec<(Topic, i16)>, out: &mut Messages) {
    out.extend(
        codes
            .into_iter()
            .map(|(topic, code)| (topic.name(), messages::code(code))),
    );
}

/// `/get_position`'s answer: the map pose when located, else none.
pub fn position(report: &PoseReport) -> Option<Pose2D> {
    match (report.localization, report.map) {
        (Localization::Good | Localization::Lost, Some((pose, _))) => Some(pose),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::odometry::OdomPose;

    fn publishing() -> Publishing {
        let noise = OdometryNoise {
            speed: (0.01, 0.01),
            yaw_rate: 0.01,
        };
        let imu = ImuNoise {
            gyro_rps: 0.01,
            accel_mps2: 0.05,
            orientation_rad: 0.02,
        };
        Publishing::new(noise, imu)
    }

    #[test]
    fn odometry_every_tick_and_the_tracked_pose_at_15_hz() {
        let mut p = publishing();
        let report = PoseReport {
            odom: Some(OdomPose::default()),
            map: None,
            frames: None,
            localization: Localization::Uninitialized,
        };
        let mut out = Vec::new();
        for tick in 0..100u64 {
            let t = Timestamp::from_micros(1_000_000 + tick * 10_000);
            p.on_feed(&Feed::Poses(t, report), &mut out);
        }
        let count = |name: &str| out.iter().filter(|(t, _)| *t == name).count();
        assert_eq!(count("/raw_odom"), 100);
        assert_eq!(
            count("/tf"),
            15,
            "odom→base_link alone before the vehicle is placed"
        );
        assert_eq!(
            count("/tracked_pose"),
            0,
            "nothing in map before it is placed"
        );
        let seqs: Vec<u64> = out
            .iter()
            .filter(|(t, _)| *t == "/raw_odom")
            .map(|(_, m)| m["header"]["seq"].as_u64().unwrap())
            .collect();
        assert_eq!(seqs.first(), Some(&1));
        assert_eq!(seqs.last(), Some(&100));
    }

    #[test]
    fn every_topic_is_advertised_once() {
        let topics = advertised();
        let mut names: Vec<&str> = topics.iter().map(|t| t.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), topics.len());
        assert!(
            topics
                .iter()
                .filter(|t| t.latched)
                .all(|t| t.msg_type == "std_msgs/Int16")
        );
    }
}
