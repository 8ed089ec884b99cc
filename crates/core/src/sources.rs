//! The names of a recording's sources: the word each record carries to say where it came
//! from. They are the recording format's words (in `meta.toml`, in file names, in every
//! recording already made), so each is written once, here; the modules that own a source
//! name it by these constants.

/// The GNSS receiver: its bytes in, its corrections out (also the source of an imported
/// receiver log).
pub const GNSS: &str = "gnss";
/// The IMU's serial bytes.
pub const IMU: &str = "imu";
/// The host's load samples (topic `usage`).
pub const HOST: &str = "host";
/// Process events: the `shutdown` record where live mode stopped the drives on exit.
pub const PROCESS: &str = "process";
/// RTCM 3 corrections from an NTRIP caster, as it sent them.
pub const CORRECTIONS: &str = "rtcm";
/// The local command channel (`--commands-stdin`, calibration patterns).
pub const LOCAL_COMMANDS: &str = "stdin";
/// MQTT messages of every dialect.
pub const MQTT: &str = "mqtt";
/// The ROS1 node's requests.
pub const ROS1: &str = "ros1";
/// The ROS 2 node's requests.
pub const ROS2: &str = "ros2";
/// What rosbridge WebSocket clients publish and call.
pub const WEBSOCKET: &str = "websocket";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_is_distinct_and_a_plain_word() {
        let all = [
            GNSS,
            IMU,
            HOST,
            PROCESS,
            CORRECTIONS,
            LOCAL_COMMANDS,
            MQTT,
            ROS1,
            ROS2,
            WEBSOCKET,
        ];
        let mut seen = std::collections::BTreeSet::new();
        for name in all {
            assert!(seen.insert(name), "{name} twice");
            assert!(
                !name.is_empty()
                    && name
                        .bytes()
                        .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit()),
                "{name}: a file name part must be a plain word"
            );
        }
    }
}
