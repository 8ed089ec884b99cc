//! What the node publishes, sans-IO: from each item the engine feeds it (poses every
//! control tick, IMU samples, status ticks, motion ends, mission progress) the messages due,
//! as JSON of their types with their topics, by the table of [`super::topics`]. The node
//! advertises that table and serialises what [`Publishing`] returns; it decides nothing.

use std::time::Duration;

use serde_json::Value;

use super::messages::{self, ImuNoise};
use super::odometry::{OdometryNoise, OdometryUncertainty};
use super::status::{StatusTopics, Topic};
use super::topics::{self, PoseTick, Publish, TOPICS};
use crate::control::MotionTag;
use crate::control::mission::MissionEvent;
use crate::devices::imu::ImuSample;
use crate::time::Timestamp;
use crate::vehicle::{Localization, Pose2D, PoseReport, VehicleStatus};

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

/// Messages due, each with its topic.
pub type Messages = Vec<(&'static str, Value)>;

/// What the publishers keep between messages.
#[derive(Debug)]
pub struct Publishing {
    odometry: OdometryUncertainty,
    imu_noise: ImuNoise,
    status: StatusTopics,
    /// When each topic of [`TOPICS`] published at most once a period is due next (`None`:
    /// not yet published; unused for the others).
    next_due: Vec<Option<Timestamp>>,
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
            next_due: vec![None; TOPICS.len()],
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
                for topic in TOPICS {
                    if let Publish::Imu(build) = topic.publish {
                        out.push((topic.name, build(sample, self.imu_seq, &self.imu_noise)));
                    }
                }
            }
            Feed::Status(status) => {
                self.status_ticks += 1;
                for topic in TOPICS {
                    if let Publish::Status { every, build } = topic.publish
                        && self.status_ticks.is_multiple_of(every.max(1))
                        && let Some(msg) = build(status, self.status_ticks as u32)
                    {
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
        // The odometry's covariance integrates every sample, and its sequence numbers
        // count them, whoever subscribes.
        let covariance = report.odom.map(|odom| {
            self.seq = self.seq.wrapping_add(1);
            self.odometry.update(t, &odom)
        });
        let tick = PoseTick {
            t,
            report,
            seq: self.seq,
            covariance,
        };
        for (topic, next_due) in TOPICS.iter().zip(&mut self.next_due) {
            let Publish::Poses { period, build } = topic.publish else {
                continue;
            };
            if let Some(period) = period
                && !due_at_most_every(next_due, period, t, report)
            {
                continue;
            }
            if let Some(msg) = build(&tick) {
                out.push((topic.name, msg));
            }
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

/// Whether a topic published at most once a `period`, next due at `next_due`, is due at
/// `t`; if so, when it is due next. A tick with no pose at all does not count.
fn due_at_most_every(
    next_due: &mut Option<Timestamp>,
    period: Duration,
    t: Timestamp,
    report: &PoseReport,
) -> bool {
    let due = next_due.is_none_or(|next| t >= next);
    if !due || (report.map.is_none() && report.odom.is_none()) {
        return false;
    }
    // One period on from the last message (the first one's included).
    let next = next_due.unwrap_or(t).saturating_add(period);
    // Late by more than a period (a pause in the feed): start again from now.
    *next_due = Some(if next < t {
        t.saturating_add(period)
    } else {
        next
    });
    true
}

fn push_codes(codes: Vec<(Topic, i16)>, out: &mut Messages) {
    out.extend(codes.into_iter().filter_map(|(code, data)| {
        topics::of_code(code).map(|topic| (topic.name, messages::code(data)))
    }));
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
    fn status_topics_at_their_rates_and_codes_on_their_topics() {
        let mut p = publishing();
        let status = VehicleStatus {
            chassis: Some(Default::default()),
            mode: Some(crate::vehicle::chassis::DriveMode::Manual),
            ..Default::default()
        };
        let mut out = Vec::new();
        for _ in 0..10 {
            p.on_feed(&Feed::Status(Box::new(status.clone())), &mut out);
        }
        let count = |name: &str| out.iter().filter(|(t, _)| *t == name).count();
        assert_eq!(count("/wheel_speeds"), 10);
        assert_eq!(count("/drive_mode"), 1);
        assert_eq!(count("/androidmsg_locationstatus"), 1, "once, on change");
        assert_eq!(
            out.iter().find(|(t, _)| *t == "/androidmsg_initstatus"),
            Some(&("/androidmsg_initstatus", serde_json::json!({"data": 12})))
        );
    }
}
