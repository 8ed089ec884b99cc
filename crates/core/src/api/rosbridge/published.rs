//! The topics the server publishes from the status ticks, each with its rate and its
//! message (JSON of its ROS 2 type, [`super::messages`]; where the ROS1 node publishes the
//! same std_msgs message, the ROS1 adapter's). The server publishes them by this
//! table, so a new one is a line here, its entry in [`super::topics::TOPICS`] and its
//! message. The latched topics ([`super::topics::LATCHED`]) go out when what they carry
//! changes: [`Latches`] tells the server when.

use std::sync::Arc;

use serde_json::Value;

use super::topics::{
    BATTERY_STATE, DIAGNOSTICS, DRIVE_MODE, PLAN, POSE, SAFETY_ENVELOPE, TF, WHEEL_SPEEDS, ZONES,
};
use super::{envelope, messages};
use crate::api::ros1::messages as ros1;
use crate::control::MotionId;
use crate::vehicle::VehicleStatus;
use crate::zones::local::ZoneOutline;

/// One topic published from the status ticks.
#[derive(Debug, Clone, Copy)]
pub struct StatusTopic {
    /// Its name, one of [`super::topics::TOPICS`].
    pub name: &'static str,
    /// Status ticks (10 Hz) from one message to the next.
    pub every: u64,
    /// Its message for a status; `None` when there is nothing to say.
    pub build: fn(&VehicleStatus) -> Option<Value>,
}

/// Every topic the server publishes from the status ticks.
pub const STATUS_TOPICS: &[StatusTopic] = &[
    StatusTopic {
        name: POSE,
        every: 1,
        build: messages::pose,
    },
    StatusTopic {
        name: TF,
        every: 1,
        build: messages::tf,
    },
    StatusTopic {
        name: WHEEL_SPEEDS,
        every: 1,
        build: ros1::wheel_speeds,
    },
    StatusTopic {
        name: SAFETY_ENVELOPE,
        every: 1,
        build: |status| status.envelope.as_ref().map(super::envelope::status),
    },
    StatusTopic {
        name: BATTERY_STATE,
        every: 10,
        build: messages::battery_state,
    },
    StatusTopic {
        name: DIAGNOSTICS,
        every: 10,
        build: |status| Some(messages::diagnostics(status)),
    },
    StatusTopic {
        name: DRIVE_MODE,
        every: 10,
        build: ros1::drive_mode,
    },
];

/// What the latched topics last carried (`None`: nothing sent yet).
#[derive(Debug, Default)]
pub struct Latches {
    /// The motion whose path `/plan` carried (`Some(None)`: no motion).
    plan: Option<Option<MotionId>>,
    /// The zones `/zones` carried, the same `Arc` until they change.
    zones: Option<Option<Arc<[ZoneOutline]>>>,
}

impl Latches {
    /// The latched topics whose content `status` changes (all of them the first time), with
    /// their messages.
    pub fn changed(&mut self, status: &VehicleStatus) -> Vec<(&'static str, Value)> {
        let mut changed = Vec::new();
        let plan = status.plan.as_ref().map(|p| p.id);
        if self.plan != Some(plan) {
            self.plan = Some(plan);
            let points = status.plan.as_ref().map_or(&[][..], |p| &p.points[..]);
            changed.push((PLAN, messages::path(status.time, points)));
        }
        let zones = status.envelope.as_ref().and_then(|e| e.zones.clone());
        let same = |last: &Option<Arc<[ZoneOutline]>>| match (last, &zones) {
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            (a, b) => a.is_none() && b.is_none(),
        };
        if !self.zones.as_ref().is_some_and(same) {
            let outlines = zones.as_deref().unwrap_or(&[]);
            changed.push((ZONES, envelope::zones(status.time, outlines)));
            self.zones = Some(zones);
        }
        changed
    }
}

/// The topics due at the `tick`th status tick (counted from 1).
pub fn due(tick: u64) -> impl Iterator<Item = &'static StatusTopic> {
    STATUS_TOPICS
        .iter()
        .filter(move |t| tick.is_multiple_of(t.every.max(1)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::rosbridge::topics::{Flow, find};

    #[test]
    fn every_status_topic_is_a_published_topic_at_its_rate() {
        for t in STATUS_TOPICS {
            let topic = find(t.name).expect("in the topic table");
            assert_eq!(
                topic.flow,
                Flow::Published(10.0 / t.every as f64),
                "{}",
                t.name
            );
        }
        assert_eq!(due(1).count(), 4);
        assert_eq!(due(10).count(), 7);
    }

    #[test]
    fn latched_topics_go_out_first_and_then_only_when_they_change() {
        use crate::vehicle::envelope::EnvelopeStatus;
        let mut latches = Latches::default();
        let mut status = VehicleStatus::default();
        let names =
            |c: Vec<(&'static str, Value)>| c.into_iter().map(|(n, _)| n).collect::<Vec<_>>();
        assert_eq!(names(latches.changed(&status)), [PLAN, ZONES]);
        assert!(latches.changed(&status).is_empty());
        let outlines: Arc<[ZoneOutline]> = Vec::new().into();
        status.envelope = Some(EnvelopeStatus {
            gate_closed: None,
            zones: Some(outlines.clone()),
            nearest: None,
            footprint_m: 0.5,
            sigma_m: None,
            braking_m: 0.0,
        });
        assert_eq!(names(latches.changed(&status)), [ZONES]);
        // A status carrying the same zones (a clone of the Arc) sends nothing.
        assert!(latches.changed(&status.clone()).is_empty());
        // Zones drawn again (an edit) go out, even when they look the same.
        if let Some(e) = &mut status.envelope {
            e.zones = Some(Vec::new().into());
        }
        assert_eq!(names(latches.changed(&status)), [ZONES]);
    }

    /// The topic's message for `status`.
    fn message(name: &str, status: &VehicleStatus) -> Option<Value> {
        let topic = STATUS_TOPICS.iter().find(|t| t.name == name)?;
        (topic.build)(status)
    }

    #[test]
    fn wheel_speeds_are_left_then_right() {
        let mut status = VehicleStatus::default();
        assert!(
            message(WHEEL_SPEEDS, &status).is_none(),
            "no drive train, no speeds"
        );
        status.chassis = Some(crate::vehicle::chassis::ChassisStatus {
            odometry: crate::vehicle::chassis::WheelOdometry {
                left_mps: -0.1,
                right_mps: 0.3,
                ..Default::default()
            },
            ..Default::default()
        });
        let msg = message(WHEEL_SPEEDS, &status).unwrap();
        assert_eq!(msg["data"], serde_json::json!([-0.1, 0.3]));
        assert_eq!(msg["layout"]["dim"][0]["label"], "left_right");
    }

    #[test]
    fn the_drive_mode_is_named() {
        use crate::vehicle::chassis::DriveMode;
        let mut status = VehicleStatus::default();
        assert!(
            message(DRIVE_MODE, &status).is_none(),
            "no drive train, no mode"
        );
        status.mode = Some(DriveMode::Navigation);
        assert_eq!(
            message(DRIVE_MODE, &status),
            Some(serde_json::json!({"data": "navigation"}))
        );
    }
}
