//! What the server publishes, sans-IO: from the status ticks, the control ticks' odometry
//! and the engine's events, the messages due by the table of [`super::topics`], each with
//! its topic. The server says only who wants which topic (a message nobody is due for is
//! not built) and carries the messages to them.

use serde_json::Value;

use super::latches::Latches;
use super::topics::{Flow, Publish, TOPICS};
use crate::api::ros1::odometry::{OdometryNoise, OdometryUncertainty};
use crate::fusion::odometry::OdomPose;
use crate::time::Timestamp;
use crate::vehicle::chassis::CONTROL_PERIOD;
use crate::vehicle::{PoseReport, VehicleStatus};

/// A message due on a topic.
#[derive(Debug, Clone, PartialEq)]
pub struct Published {
    /// Its topic.
    pub topic: &'static str,
    /// The message, as JSON of the topic's type.
    pub msg: Value,
    /// The topic is latched: the message goes to every subscriber and is kept for the next.
    pub latched: bool,
}

/// Control ticks (100 Hz, [`CONTROL_PERIOD`]) per odometry message at `rate_hz`: 1 at
/// 100 Hz, 2 at 50 Hz.
pub fn odometry_every(rate_hz: f64) -> u64 {
    let control_hz = 1.0 / CONTROL_PERIOD.as_secs_f64();
    (control_hz / rate_hz).round().clamp(1.0, u64::MAX as f64) as u64
}

/// Counts the control ticks on the engine's side, so only the odometry the topics publish
/// crosses to the server.
#[derive(Debug)]
pub struct ControlTicks {
    ticks: u64,
    every: u64,
}

impl ControlTicks {
    /// Ticks of which every `every`th carries odometry ([`odometry_every`]).
    pub fn new(every: u64) -> Self {
        Self {
            ticks: 0,
            every: every.max(1),
        }
    }

    /// The next control tick, whose poses are `report`: its number and its `odom` pose,
    /// when the odometry of that tick is published.
    pub fn next(&mut self, report: &PoseReport) -> Option<(u64, OdomPose)> {
        self.ticks += 1;
        let odom = report.odom?;
        self.ticks
            .is_multiple_of(self.every)
            .then_some((self.ticks, odom))
    }
}

/// What the publishers keep between messages.
#[derive(Debug)]
pub struct Publishing {
    /// The topics published, each with what makes it due.
    topics: Vec<(&'static str, Publish)>,
    odometry: OdometryUncertainty,
    status_ticks: u64,
    latches: Latches,
}

impl Publishing {
    /// Publishing the server's topics with the odometry's noise (`/odom`'s covariance),
    /// the odometry every `odometry_every`th control tick ([`odometry_every`]).
    pub fn new(noise: OdometryNoise, odometry_every: u64) -> Self {
        let topics = TOPICS.iter().filter_map(|t| match t.flow {
            Flow::Published(Publish::Odometry { build, .. }) => Some((
                t.name,
                Publish::Odometry {
                    every: odometry_every.max(1),
                    build,
                },
            )),
            Flow::Published(publish) => Some((t.name, publish)),
            Flow::Subscribed => None,
        });
        Self::with_topics(noise, topics)
    }

    /// Publishing `topics` (the ROS 2 node's, which builds the same messages).
    pub fn with_topics(
        noise: OdometryNoise,
        topics: impl IntoIterator<Item = (&'static str, Publish)>,
    ) -> Self {
        Self {
            topics: topics.into_iter().collect(),
            odometry: OdometryUncertainty::new(noise),
            status_ticks: 0,
            latches: Latches::default(),
        }
    }

    /// A status tick: the status topics due that someone `wanted` (the faster first, each
    /// rate in the table's order), then the latched ones whose content changed.
    pub fn on_status(
        &mut self,
        status: &VehicleStatus,
        mut wanted: impl FnMut(&'static str) -> bool,
        out: &mut Vec<Published>,
    ) {
        self.status_ticks += 1;
        let mut due: Vec<_> = self
            .topics
            .iter()
            .filter_map(|&(name, publish)| match publish {
                Publish::Status { every, build }
                    if self.status_ticks.is_multiple_of(every.max(1)) =>
                {
                    Some((every, name, build))
                }
                _ => None,
            })
            .collect();
        // Stable: each rate keeps the table's order.
        due.sort_by_key(|(every, ..)| *every);
        for (_, topic, build) in due {
            if wanted(topic)
                && let Some(msg) = build(status)
            {
                out.push(Published {
                    topic,
                    msg,
                    latched: false,
                });
            }
        }
        for &(topic, publish) in &self.topics {
            if let Publish::Latched(changed) = publish
                && let Some(msg) = changed(&mut self.latches, status)
            {
                out.push(Published {
                    topic,
                    msg,
                    latched: true,
                });
            }
        }
    }

    /// Control tick `tick`'s `odom` pose at `t` (one [`ControlTicks::next`] let through).
    pub fn on_odometry(
        &mut self,
        tick: u64,
        t: Timestamp,
        pose: &OdomPose,
        mut wanted: impl FnMut(&'static str) -> bool,
        out: &mut Vec<Published>,
    ) {
        // The covariance integrates every sample, subscribed or not.
        let covariance = self.odometry.update(t, pose);
        for &(topic, publish) in &self.topics {
            if let Publish::Odometry { every, build } = publish
                && tick.is_multiple_of(every.max(1))
                && wanted(topic)
            {
                out.push(Published {
                    topic,
                    msg: build(t, pose, &covariance),
                    latched: false,
                });
            }
        }
    }

    /// One of the engine's events, taken by the server at `t`.
    pub fn on_event(
        &mut self,
        t: Timestamp,
        text: &str,
        mut wanted: impl FnMut(&'static str) -> bool,
        out: &mut Vec<Published>,
    ) {
        for &(topic, publish) in &self.topics {
            if let Publish::Event(build) = publish
                && wanted(topic)
            {
                out.push(Published {
                    topic,
                    msg: build(t, text),
                    latched: false,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::chassis::{ChassisStatus, DriveMode};

    fn noise() -> OdometryNoise {
        OdometryNoise {
            speed: (0.01, 0.01),
            yaw_rate: 0.01,
        }
    }

    fn topics(out: &[Published]) -> Vec<&'static str> {
        out.iter().map(|m| m.topic).collect()
    }

    #[test]
    fn status_topics_at_their_rates_the_faster_first_then_the_latched() {
        let mut p = Publishing::new(noise(), 2);
        let status = VehicleStatus {
            chassis: Some(ChassisStatus::default()),
            mode: Some(DriveMode::Manual),
            ..Default::default()
        };
        let mut out = Vec::new();
        p.on_status(&status, |_| true, &mut out);
        // No pose, no envelope yet: the wheels, then the latched topics' first messages.
        assert_eq!(topics(&out), ["/wheel_speeds", "/plan", "/zones"]);
        let latched: Vec<_> = out.iter().filter(|m| m.latched).map(|m| m.topic).collect();
        assert_eq!(latched, ["/plan", "/zones"]);
        for _ in 2..10 {
            out.clear();
            p.on_status(&status, |_| true, &mut out);
            assert_eq!(topics(&out), ["/wheel_speeds"]);
        }
        out.clear();
        p.on_status(&status, |_| true, &mut out);
        assert_eq!(
            topics(&out),
            ["/wheel_speeds", "/diagnostics", "/drive_mode"]
        );
        out.clear();
        p.on_status(&status, |topic| topic != "/wheel_speeds", &mut out);
        assert!(
            out.is_empty(),
            "nobody wants the wheels: {:?}",
            topics(&out)
        );
    }

    #[test]
    fn odometry_every_other_control_tick_with_its_covariance_whoever_subscribes() {
        let mut ticks = ControlTicks::new(2);
        let mut p = Publishing::new(noise(), 2);
        let mut out = Vec::new();
        let mut report = PoseReport {
            odom: Some(OdomPose {
                v: 1.0,
                ..Default::default()
            }),
            map: None,
            frames: None,
            localization: crate::vehicle::Localization::Uninitialized,
        };
        for n in 1..=100u64 {
            if n == 50 {
                report.odom = None;
            }
            if let Some((tick, pose)) = ticks.next(&report) {
                let t = Timestamp::from_micros(n * 10_000);
                // Subscribed only after a while: the covariance grew meanwhile.
                p.on_odometry(tick, t, &pose, |_| n > 40, &mut out);
            }
        }
        assert_eq!(topics(&out), vec!["/odom"; 4], "ticks 42 to 48");
        let first = out[0].msg["pose"]["covariance"][0].as_f64().unwrap();
        assert!(
            first > 0.0,
            "the covariance integrated the unsubscribed ticks"
        );
    }

    #[test]
    fn odometry_rates_in_control_ticks() {
        assert_eq!(odometry_every(100.0), 1);
        assert_eq!(odometry_every(50.0), 2);
        assert_eq!(odometry_every(30.0), 3);
        assert_eq!(odometry_every(1.0), 100);
        assert_eq!(odometry_every(1000.0), 1, "no faster than the control loop");
    }

    #[test]
    fn the_tables_odometry_rate_is_the_configurations_default() {
        let every = TOPICS
            .iter()
            .find_map(|t| match t.flow {
                Flow::Published(Publish::Odometry { every, .. }) => Some(every),
                _ => None,
            })
            .unwrap();
        let default = crate::config::websocket::WebsocketConfig::default().odom_rate_hz;
        assert_eq!(every, odometry_every(default));
    }

    #[test]
    fn odometry_at_every_control_tick_at_100_hz() {
        let mut ticks = ControlTicks::new(odometry_every(100.0));
        let mut p = Publishing::new(noise(), odometry_every(100.0));
        let mut out = Vec::new();
        let report = PoseReport {
            odom: Some(OdomPose::default()),
            map: None,
            frames: None,
            localization: crate::vehicle::Localization::Uninitialized,
        };
        for n in 1..=10u64 {
            let (tick, pose) = ticks.next(&report).expect("every tick");
            p.on_odometry(
                tick,
                Timestamp::from_micros(n * 10_000),
                &pose,
                |_| true,
                &mut out,
            );
        }
        assert_eq!(topics(&out), vec!["/odom"; 10]);
    }

    #[test]
    fn events_go_to_rosout_when_wanted() {
        let mut p = Publishing::new(noise(), 2);
        let mut out = Vec::new();
        p.on_event(Timestamp::from_nanos(1), "drive up", |_| false, &mut out);
        assert!(out.is_empty());
        p.on_event(Timestamp::from_nanos(1), "drive up", |_| true, &mut out);
        assert_eq!(topics(&out), ["/rosout"]);
        assert_eq!(out[0].msg["msg"], "drive up");
    }
}
