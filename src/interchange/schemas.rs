//! The JSON schemas of the exported channels: Foxglove's well-known ones (by their names,
//! so its panels take them without configuration), ROS 2's message types where chassisd
//! already speaks them as JSON, and chassisd's own.

/// A channel's schema: its name (what a reader matches on) and its JSON Schema text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Schema {
    /// The name, e.g. `foxglove.LocationFix`.
    pub name: &'static str,
    /// The JSON Schema (draft-07).
    pub text: &'static str,
}

macro_rules! schema {
    ($name:literal, $file:literal) => {
        Schema {
            name: $name,
            text: include_str!(concat!("schemas/", $file)),
        }
    };
}

/// A WGS84 position with its covariance: a receiver's fix, the fused pose.
pub const LOCATION_FIX: Schema = schema!("foxglove.LocationFix", "LocationFix.json");
/// A pose in a frame: the map pose.
pub const POSE_IN_FRAME: Schema = schema!("foxglove.PoseInFrame", "PoseInFrame.json");
/// Poses in a frame: the plan.
pub const POSES_IN_FRAME: Schema = schema!("foxglove.PosesInFrame", "PosesInFrame.json");
/// The frame tree: map→odom→base_link.
pub const FRAME_TRANSFORMS: Schema = schema!("foxglove.FrameTransforms", "FrameTransforms.json");
/// The zones.
pub const GEOJSON: Schema = schema!("foxglove.GeoJSON", "GeoJSON.json");
/// The engine's events.
pub const LOG: Schema = schema!("foxglove.Log", "Log.json");
/// base_status of the rtk protocol.
pub const BASE_STATUS: Schema = schema!("chassisd.BaseStatus", "BaseStatus.json");
/// The battery.
pub const BATTERY_STATE: Schema = schema!("sensor_msgs/msg/BatteryState", "BatteryState.json");
/// The parts' health.
pub const DIAGNOSTIC_ARRAY: Schema = schema!(
    "diagnostic_msgs/msg/DiagnosticArray",
    "DiagnosticArray.json"
);
/// A serial chunk as read.
pub const SERIAL_CHUNK: Schema = schema!("chassisd.SerialChunk", "SerialChunk.json");
/// An NMEA sentence of a serial source.
pub const NMEA_SENTENCE: Schema = schema!("chassisd.NmeaSentence", "NmeaSentence.json");
/// A CAN frame.
pub const CAN_FRAME: Schema = schema!("chassisd.CanFrame", "CanFrame.json");
/// A command as it came.
pub const COMMAND: Schema = schema!("chassisd.Command", "Command.json");
/// A link going up or down.
pub const LINK_EVENT: Schema = schema!("chassisd.LinkEvent", "LinkEvent.json");
/// chassisd's answer to a command.
pub const COMMAND_RESULT: Schema = schema!("chassisd.CommandResult", "CommandResult.json");
/// A message chassisd published to its MQTT broker.
pub const MQTT_PUBLISH: Schema = schema!("chassisd.MqttPublish", "MqttPublish.json");

/// Every schema, for the documentation's table and the tests.
pub const ALL: &[Schema] = &[
    LOCATION_FIX,
    POSE_IN_FRAME,
    POSES_IN_FRAME,
    FRAME_TRANSFORMS,
    GEOJSON,
    LOG,
    BASE_STATUS,
    BATTERY_STATE,
    DIAGNOSTIC_ARRAY,
    SERIAL_CHUNK,
    NMEA_SENTENCE,
    CAN_FRAME,
    COMMAND,
    LINK_EVENT,
    COMMAND_RESULT,
    MQTT_PUBLISH,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_schema_is_json_titled_with_its_name() {
        for s in ALL {
            let v: serde_json::Value = serde_json::from_str(s.text).unwrap();
            assert_eq!(v["title"], s.name, "{}", s.name);
            assert_eq!(v["type"], "object", "{}", s.name);
        }
    }
}
