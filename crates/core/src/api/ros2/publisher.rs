//! What the ROS 2 node publishes, sans-IO: from each item the engine feeds it (poses every
//! control tick, IMU samples, the receiver's solutions, status ticks, events) the messages
//! due, as JSON of their types with their topics, by the table of [`super::topics`], with
//! the frame ids `[ros2.frames]` names. The node's process serialises them; it decides
//! nothing.

use std::collections::BTreeMap;

use serde_json::Value;

use super::messages::{GNSS_FRAME, IMU_FRAME, Mounts};
use super::topics::{LATCHED, Publish, TOPICS};
use crate::api::ros1::messages::ImuNoise;
use crate::api::ros1::odometry::OdometryNoise;
use crate::api::rosbridge::messages::{BASE_FRAME, MAP_FRAME, ODOM_FRAME};
use crate::api::rosbridge::publisher::{Published, Publishing as StatePublishing, odometry_every};
use crate::api::rosbridge::topics::Publish as State;
use crate::config::ros2::Ros2Frames;
use crate::devices::gnss::GnssFix;
use crate::devices::imu::ImuSample;
use crate::time::Timestamp;
use crate::vehicle::{PoseReport, VehicleStatus};

/// What the engine's outputs give the node.
#[derive(Debug, Clone)]
pub enum Feed {
    /// The poses at a control tick.
    Poses(Timestamp, PoseReport),
    /// An IMU sample, in the vehicle frame.
    Imu(ImuSample),
    /// The receiver's solution after a sentence, at the time the sentence came.
    Fix(Timestamp, Box<GnssFix>),
    /// A status tick.
    Status(Box<VehicleStatus>),
    /// One of the engine's events, as the log says it.
    Event(String),
}

/// Messages due, each with its topic.
pub type Messages = Vec<(&'static str, Value)>;

/// What the node's messages are built with.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The odometry's noise (`/odom`'s covariance).
    pub odometry_noise: OdometryNoise,
    /// The IMU's noise (`/imu/data`'s covariances).
    pub imu_noise: ImuNoise,
    /// Where the sensors sit (`/tf_static`).
    pub mounts: Mounts,
    /// The frame ids.
    pub frames: Ros2Frames,
    /// `/odom`'s rate, Hz.
    pub odom_rate_hz: f64,
}

/// What the publishers keep between messages.
#[derive(Debug)]
pub struct Publishing {
    state: StatePublishing,
    settings: Settings,
    /// The frames renamed, when `[ros2.frames]` renames any.
    renames: Vec<(&'static str, String)>,
    control_ticks: u64,
    /// What the last `/fix` came from: the position report's time of day and receipt, and
    /// the quality.
    last_fix: Option<FixKey>,
    /// The latest time the feed carried (events are stamped with it).
    now: Option<Timestamp>,
    /// The last message of each latched topic, for a node that joins again.
    latched: BTreeMap<&'static str, Value>,
}

/// What tells one of the receiver's solutions from the next: a sentence that only adds to a
/// solution (RMC after GGA, GST) leaves it the same.
type FixKey = (
    Option<chrono::NaiveTime>,
    Option<Timestamp>,
    crate::devices::gnss::FixQuality,
);

impl Publishing {
    /// Publishing with `settings`.
    pub fn new(settings: Settings) -> Self {
        let odom_every = odometry_every(settings.odom_rate_hz);
        let topics = TOPICS.iter().filter_map(|t| match t.publish {
            Publish::State(State::Odometry { build, .. }) => Some((
                t.name,
                State::Odometry {
                    every: odom_every,
                    build,
                },
            )),
            Publish::State(state) => Some((t.name, state)),
            Publish::Imu(_) | Publish::Fix(_) | Publish::Static(_) => None,
        });
        let defaults = [
            (MAP_FRAME, &settings.frames.map),
            (ODOM_FRAME, &settings.frames.odom),
            (BASE_FRAME, &settings.frames.base),
            (GNSS_FRAME, &settings.frames.gnss),
            (IMU_FRAME, &settings.frames.imu),
        ];
        let renames = defaults
            .into_iter()
            .filter(|(from, to)| from != to)
            .map(|(from, to)| (from, to.clone()))
            .collect();
        Self {
            state: StatePublishing::with_topics(settings.odometry_noise, topics),
            settings,
            renames,
            control_ticks: 0,
            last_fix: None,
            now: None,
            latched: BTreeMap::new(),
        }
    }

    /// What a node that is (again) on its domain at `t` publishes first: the topics
    /// published once, and every latched topic's last message (the node may have missed it,
    /// or be a new process: its writers keep nothing of the last one's).
    pub fn on_ready(&mut self, t: Timestamp, out: &mut Messages) {
        let start = out.len();
        for topic in TOPICS {
            if let Publish::Static(build) = topic.publish {
                out.push((topic.name, build(t, &self.settings.mounts)));
            }
        }
        self.rename(&mut out[start..]);
        out.extend(
            self.latched
                .iter()
                .map(|(&topic, msg)| (topic, msg.clone())),
        );
    }

    /// The messages `item` makes due.
    pub fn on_feed(&mut self, item: &Feed, out: &mut Messages) {
        let start = out.len();
        let mut state = Vec::new();
        match item {
            Feed::Poses(t, report) => {
                self.now = Some(*t);
                self.control_ticks += 1;
                if let Some(odom) = &report.odom {
                    self.state
                        .on_odometry(self.control_ticks, *t, odom, |_| true, &mut state);
                }
            }
            Feed::Imu(sample) => {
                for topic in TOPICS {
                    if let Publish::Imu(build) = topic.publish {
                        out.push((topic.name, build(sample, &self.settings.imu_noise)));
                    }
                }
            }
            Feed::Fix(t, fix) => {
                let key = (fix.utc_time, fix.position.map(|p| p.rx), fix.quality);
                if self.last_fix != Some(key) {
                    self.last_fix = Some(key);
                    for topic in TOPICS {
                        if let Publish::Fix(build) = topic.publish {
                            out.push((topic.name, build(*t, fix)));
                        }
                    }
                }
            }
            Feed::Status(status) => {
                self.now = Some(status.time);
                self.state.on_status(status, |_| true, &mut state);
            }
            Feed::Event(text) => {
                if let Some(t) = self.now {
                    self.state.on_event(t, text, |_| true, &mut state);
                }
            }
        }
        out.extend(
            state
                .into_iter()
                .map(|Published { topic, msg, .. }| (topic, msg)),
        );
        self.rename(&mut out[start..]);
        for (topic, msg) in &out[start..] {
            if super::topics::find(topic).is_some_and(|t| t.qos == LATCHED) {
                self.latched.insert(topic, msg.clone());
            }
        }
    }

    /// Gives the messages' frame ids the names `[ros2.frames]` chose.
    fn rename(&self, messages: &mut [(&'static str, Value)]) {
        if self.renames.is_empty() {
            return;
        }
        for (_, msg) in messages {
            rename_frames(msg, &self.renames);
        }
    }
}

/// Renames every `frame_id` and `child_frame_id` of `msg` (at any depth: a path's poses, an
/// array's markers, a TF message's transforms) that `renames` names.
fn rename_frames(msg: &mut Value, renames: &[(&'static str, String)]) {
    match msg {
        Value::Object(fields) => {
            for (key, value) in fields.iter_mut() {
                if let ("frame_id" | "child_frame_id", Value::String(frame)) =
                    (key.as_str(), &mut *value)
                {
                    if let Some((_, to)) = renames.iter().find(|(from, _)| from == frame) {
                        frame.clone_from(to);
                    }
                } else {
                    rename_frames(value, renames);
                }
            }
        }
        Value::Array(items) => {
            for item in items {
                rename_frames(item, renames);
            }
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::gnss::{FixQuality, GeoPosition, Timed};
    use crate::fusion::odometry::OdomPose;
    use crate::vehicle::Localization;

    fn settings(frames: Ros2Frames) -> Settings {
        Settings {
            odometry_noise: OdometryNoise {
                speed: (0.01, 0.01),
                yaw_rate: 0.01,
            },
            imu_noise: ImuNoise {
                gyro_rps: 0.01,
                accel_mps2: 0.05,
                orientation_rad: 0.02,
            },
            mounts: Mounts {
                antenna: [0.2, 0.0, 1.0],
                imu: None,
            },
            frames,
            odom_rate_hz: 50.0,
        }
    }

    fn poses(t: Timestamp) -> Feed {
        Feed::Poses(
            t,
            PoseReport {
                odom: Some(OdomPose {
                    v: 0.5,
                    ..Default::default()
                }),
                map: None,
                frames: None,
                localization: Localization::Uninitialized,
            },
        )
    }

    fn topics(out: &Messages) -> Vec<&'static str> {
        out.iter().map(|(topic, _)| *topic).collect()
    }

    #[test]
    fn odometry_at_its_rate_and_the_static_frames_once() {
        let mut p = Publishing::new(settings(Ros2Frames::default()));
        let mut out = Vec::new();
        p.on_ready(Timestamp::from_nanos(1), &mut out);
        assert_eq!(topics(&out), ["/tf_static"]);
        out.clear();
        for n in 1..=100u64 {
            p.on_feed(&poses(Timestamp::from_micros(n * 10_000)), &mut out);
        }
        assert_eq!(topics(&out), vec!["/odom"; 50], "50 Hz of a 100 Hz loop");
        assert_eq!(out[0].1["header"]["frame_id"], "odom");
        assert_eq!(out[0].1["child_frame_id"], "base_link");
    }

    /// The fields of a ROS1 or ROS 2 message that both carry: a header's stamp becomes
    /// nanoseconds, its seq (ROS1 only) goes.
    fn shared_fields(msg: &Value) -> Value {
        let mut msg = msg.clone();
        if let Some(header) = msg.get_mut("header").and_then(Value::as_object_mut) {
            let stamp = &header["stamp"];
            let secs = stamp
                .get("sec")
                .or(stamp.get("secs"))
                .and_then(Value::as_i64);
            let nanos = stamp
                .get("nanosec")
                .or(stamp.get("nsecs"))
                .and_then(Value::as_i64);
            let ns = secs.zip(nanos).map(|(s, n)| s * 1_000_000_000 + n);
            header.insert("stamp".into(), ns.into());
            header.remove("seq");
        }
        if let Some(transforms) = msg.get_mut("transforms").and_then(Value::as_array_mut) {
            for t in transforms {
                *t = shared_fields(t);
            }
        }
        msg
    }

    #[test]
    fn odom_and_tf_carry_what_the_ros1_nodes_carry_for_the_same_poses() {
        use crate::api::ros1::publisher::{Feed as Ros1Feed, Publishing as Ros1Publishing};
        use crate::vehicle::{FrameTree, Pose2D};
        let settings = Settings {
            odom_rate_hz: 100.0,
            ..settings(Ros2Frames::default())
        };
        let mut ros2 = Publishing::new(settings.clone());
        let mut ros1 = Ros1Publishing::new(settings.odometry_noise, settings.imu_noise);
        let (mut out2, mut out1) = (Vec::new(), Vec::new());
        let mut tf_pairs = Vec::new();
        // 3 s along a curve; the map frame set after the first second.
        for n in 1..=300u64 {
            let t = Timestamp::from_micros(n * 10_000);
            let k = n as f64 * 0.01;
            let odom = OdomPose {
                x: 0.5 * k,
                y: 0.05 * k * k,
                yaw: 0.2 * k,
                v: 0.5,
                w: 0.2,
            };
            let frames = (n > 100).then_some(FrameTree {
                map_to_odom: Pose2D {
                    x: 3.0,
                    y: -1.0,
                    yaw: 0.3,
                },
                odom_to_base: Pose2D {
                    x: odom.x,
                    y: odom.y,
                    yaw: odom.yaw,
                },
            });
            let report = PoseReport {
                odom: Some(odom),
                map: None,
                frames,
                localization: Localization::Good,
            };
            ros2.on_feed(&Feed::Poses(t, report), &mut out2);
            ros1.on_feed(&Ros1Feed::Poses(t, report), &mut out1);
            if n % 10 == 0 {
                let status = VehicleStatus {
                    time: t,
                    odom: Some(odom),
                    frames,
                    ..Default::default()
                };
                let start = out2.len();
                ros2.on_feed(&Feed::Status(Box::new(status)), &mut out2);
                let tf2 = out2[start..].iter().find(|(topic, _)| *topic == "/tf");
                let tf1 = crate::api::ros1::messages::tf(t, &report);
                tf_pairs.push((
                    tf2.map(|(_, m)| shared_fields(m)),
                    tf1.map(|m| shared_fields(&m)),
                ));
            }
        }
        let odom2: Vec<Value> = out2
            .iter()
            .filter(|(topic, _)| *topic == "/odom")
            .map(|(_, m)| shared_fields(m))
            .collect();
        let odom1: Vec<Value> = out1
            .iter()
            .filter(|(topic, _)| *topic == "/raw_odom")
            .map(|(_, m)| shared_fields(m))
            .collect();
        assert_eq!(odom2.len(), 300);
        assert_eq!(odom2, odom1, "/odom against ROS1's /raw_odom");
        assert_eq!(tf_pairs.len(), 30);
        for (tf2, tf1) in tf_pairs {
            assert!(tf2.is_some());
            assert_eq!(tf2, tf1, "/tf against ROS1's");
        }
    }

    #[test]
    fn a_fix_goes_out_once_per_solution() {
        let mut p = Publishing::new(settings(Ros2Frames::default()));
        let rx = Timestamp::from_nanos(5_000_000_000);
        let fix = GnssFix {
            quality: FixQuality::RtkFixed,
            position: Some(Timed {
                rx,
                value: GeoPosition {
                    latitude_deg: 1.0,
                    longitude_deg: 2.0,
                    altitude_msl_m: Some(3.0),
                    geoid_separation_m: None,
                    ellipsoid_height_m: None,
                },
            }),
            ..Default::default()
        };
        let mut out = Vec::new();
        // GGA, then RMC and GST of the same epoch: one message.
        for _ in 0..3 {
            p.on_feed(&Feed::Fix(rx, Box::new(fix)), &mut out);
        }
        assert_eq!(topics(&out), ["/fix"]);
        let mut lost = fix;
        lost.quality = FixQuality::Invalid;
        p.on_feed(&Feed::Fix(rx, Box::new(lost)), &mut out);
        assert_eq!(topics(&out), ["/fix", "/fix"], "the loss is news");
        assert_eq!(out[1].1["status"]["status"], -1);
    }

    #[test]
    fn the_configured_frames_replace_rep_105s_names_everywhere() {
        let frames = Ros2Frames {
            base: "base_footprint".into(),
            gnss: "gps".into(),
            ..Default::default()
        };
        let mut p = Publishing::new(settings(frames));
        let mut out = Vec::new();
        p.on_ready(Timestamp::from_nanos(1), &mut out);
        let transform = &out[0].1["transforms"][0];
        assert_eq!(transform["header"]["frame_id"], "base_footprint");
        assert_eq!(transform["child_frame_id"], "gps");
        out.clear();
        p.on_feed(&poses(Timestamp::from_nanos(20_000_000)), &mut out);
        p.on_feed(&poses(Timestamp::from_nanos(30_000_000)), &mut out);
        assert_eq!(out[0].1["child_frame_id"], "base_footprint");
        assert_eq!(out[0].1["header"]["frame_id"], "odom", "not renamed");
    }

    #[test]
    fn a_node_ready_again_gets_the_latched_topics_last_messages() {
        let mut p = Publishing::new(settings(Ros2Frames::default()));
        let mut out = Vec::new();
        let status = VehicleStatus {
            time: Timestamp::from_nanos(1_000_000_000),
            ..Default::default()
        };
        p.on_feed(&Feed::Status(Box::new(status.clone())), &mut out);
        assert!(topics(&out).contains(&"/zones"), "{:?}", topics(&out));
        // Unchanged: not published again on the next status.
        out.clear();
        p.on_feed(&Feed::Status(Box::new(status)), &mut out);
        assert!(!topics(&out).contains(&"/zones"));
        // A node process that joins (again) gets them all the same.
        out.clear();
        p.on_ready(Timestamp::from_nanos(2_000_000_000), &mut out);
        assert_eq!(topics(&out), ["/tf_static", "/plan", "/zones"]);
    }

    #[test]
    fn events_go_to_rosout_stamped_with_the_feeds_time() {
        let mut p = Publishing::new(settings(Ros2Frames::default()));
        let mut out = Vec::new();
        p.on_feed(&Feed::Event("before any time".into()), &mut out);
        assert!(out.is_empty(), "no time to stamp it with yet");
        p.on_feed(&poses(Timestamp::from_nanos(2_500_000_000)), &mut out);
        out.clear();
        p.on_feed(&Feed::Event("drive up".into()), &mut out);
        assert_eq!(topics(&out), ["/rosout"]);
        assert_eq!(out[0].1["msg"], "drive up");
        assert_eq!(out[0].1["stamp"]["sec"], 2);
    }
}
