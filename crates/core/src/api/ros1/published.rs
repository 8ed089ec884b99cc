//! The topics the node publishes from the status ticks, each whole here: its name, its ROS
//! type, its rate and its message as JSON (the fields as the type names them). The node
//! advertises each with the type's definition, generated from `interfaces/`, and serialises
//! the JSON through that type, which checks every field; so a topic, even of a new type,
//! needs only its interface files and a line in [`STATUS_TOPICS`].

use serde_json::{Value, json};

use crate::vehicle::VehicleStatus;
use crate::vehicle::chassis::DriveMode;

/// One topic published from the status ticks.
#[derive(Debug, Clone, Copy)]
pub struct StatusTopic {
    /// Its name.
    pub name: &'static str,
    /// Its ROS type (`package/Type`), one of `interfaces/`.
    pub msg_type: &'static str,
    /// Status ticks (10 Hz) from one message to the next.
    pub every: u64,
    /// The message for a status and the sequence number of its header; `None` when there is
    /// nothing to say.
    pub build: fn(&VehicleStatus, u32) -> Option<Value>,
}

/// Every topic the node publishes from the status ticks.
pub const STATUS_TOPICS: &[StatusTopic] = &[
    StatusTopic {
        name: "/wheel_speeds",
        msg_type: "std_msgs/Float64MultiArray",
        every: 1,
        build: |status, _| wheel_speeds(status),
    },
    StatusTopic {
        name: "/drive_mode",
        msg_type: "std_msgs/String",
        every: 10,
        build: |status, _| drive_mode(status),
    },
];

/// `/wheel_speeds`: the left and the right wheel's measured surface speed, m/s (forward
/// positive), at 10 Hz; nothing without a drive train. The rosbridge server publishes the
/// same message (std_msgs keeps its fields in ROS 2).
pub fn wheel_speeds(status: &VehicleStatus) -> Option<Value> {
    let odometry = status.chassis.as_ref()?.odometry;
    Some(json!({
        "layout": {
            "dim": [{"label": "left_right", "size": 2, "stride": 2}],
            "data_offset": 0,
        },
        "data": [odometry.left_mps, odometry.right_mps],
    }))
}

/// `/drive_mode`: who may drive, `manual` (velocity commands) or `navigation` (autonomous
/// moves only), at 1 Hz; nothing without a drive train. Rosbridge publishes it too.
pub fn drive_mode(status: &VehicleStatus) -> Option<Value> {
    let mode = match status.mode? {
        DriveMode::Manual => "manual",
        DriveMode::Navigation => "navigation",
    };
    Some(json!({ "data": mode }))
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

    #[test]
    fn wheel_speeds_are_left_then_right() {
        let mut status = VehicleStatus::default();
        assert!(wheel_speeds(&status).is_none(), "no drive train, no speeds");
        status.chassis = Some(crate::vehicle::chassis::ChassisStatus {
            odometry: crate::vehicle::chassis::WheelOdometry {
                left_mps: 0.25,
                right_mps: 0.5,
                ..Default::default()
            },
            ..Default::default()
        });
        let msg = wheel_speeds(&status).unwrap();
        assert_eq!(msg["data"], json!([0.25, 0.5]));
        assert_eq!(msg["layout"]["dim"][0]["size"], 2);
        assert_eq!(due(1).count(), 1);
        assert_eq!(due(10).count(), STATUS_TOPICS.len());
    }

    #[test]
    fn the_drive_mode_is_named() {
        let mut status = VehicleStatus::default();
        assert!(drive_mode(&status).is_none(), "no drive train, no mode");
        status.mode = Some(DriveMode::Navigation);
        assert_eq!(drive_mode(&status), Some(json!({"data": "navigation"})));
        status.mode = Some(DriveMode::Manual);
        assert_eq!(drive_mode(&status), Some(json!({"data": "manual"})));
    }
}
