//! What several of the server's messages are built from: a ROS 2 header, and a
//! diagnostic_msgs/DiagnosticStatus with its levels.

use serde_json::{Value, json};

use crate::api::ros1::ros_time;
use crate::time::Timestamp;

/// diagnostic_msgs/DiagnosticStatus levels.
pub const OK: u8 = 0;
pub const WARN: u8 = 1;
pub const ERROR: u8 = 2;

/// A std_msgs/Header of ROS 2: the stamp as `sec` and `nanosec`, no `seq`.
pub fn header(t: Timestamp, frame: &str) -> Value {
    let (sec, nanosec) = ros_time(t);
    json!({"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame})
}

/// One part's diagnostic status, named `chassisd: NAME`.
pub fn diagnostic(level: u8, name: &str, message: &str, values: &[(&str, String)]) -> Value {
    json!({
        "level": level,
        "name": format!("chassisd: {name}"),
        "message": message,
        "hardware_id": "",
        "values": values
            .iter()
            .map(|(k, v)| json!({"key": k, "value": v}))
            .collect::<Vec<_>>(),
    })
}
