//! The topics the server publishes from the status ticks, each with its rate and its
//! message (JSON of its ROS 2 type, [`super::messages`]; where the ROS1 node publishes the
//! same std_msgs message, the ROS1 adapter's). The server publishes them by this
//! table, so a new one is a line here, its entry in [`super::topics::TOPICS`] and its
//! message.

use serde_json::Value;

use super::messages;
use super::topics::{
    BATTERY_STATE, DIAGNOSTICS, DRIVE_MODE, POSE, SAFETY_ENVELOPE, TF, WHEEL_SPEEDS,
};
use crate::api::ros1::published as ros1;
use crate::vehicle::VehicleStatus;

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
