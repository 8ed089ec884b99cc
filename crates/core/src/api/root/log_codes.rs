//! The `/log` event codes: the spec's, with the numbers it left out or repeated resolved.

/// A `/log` event code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LogCode {
    /// Key.
    pub key: &'static str,
    /// Value.
    pub code: u32,
    /// ERROR, WARNING or NOTIFY.
    pub level: &'static str,
    /// Module.
    pub module: &'static str,
    /// What it means.
    pub text: &'static str,
}

const fn log(
    key: &'static str,
    code: u32,
    level: &'static str,
    module: &'static str,
    text: &'static str,
) -> LogCode {
    LogCode {
        key,
        code,
        level,
        module,
        text,
    }
}

/// Every `/log` code, with the numbers the spec left out or repeated resolved.
pub const LOG_CODES: [LogCode; 18] = [
    log(
        "LOCALIZATION_ERROR",
        100,
        "ERROR",
        "localization",
        "localization lost",
    ),
    log("GPS_ERROR", 101, "ERROR", "localization", "GNSS fix lost"),
    log(
        "RTK_CORRECTIONS_LOST",
        102,
        "ERROR",
        "localization",
        "RTK corrections stopped",
    ),
    log(
        "RTK_CORRECTIONS_RESTORED",
        103,
        "NOTIFY",
        "localization",
        "RTK corrections arriving again",
    ),
    log("LOW_BATTERY", 200, "WARNING", "battery", "battery low"),
    log("FULL_BATTERY", 201, "NOTIFY", "battery", "battery full"),
    log(
        "RECHARGE_ERROR",
        202,
        "ERROR",
        "battery",
        "recharging failed",
    ),
    log(
        "VIRTUAL_WALL",
        300,
        "WARNING",
        "navigation",
        "entered a virtual wall",
    ),
    log(
        "NO_CHASSIS_FEEDBACK",
        400,
        "ERROR",
        "chassis",
        "no feedback from the chassis",
    ),
    log(
        "NODE_NOT_RESPONDING",
        401,
        "ERROR",
        "chassis",
        "a drive node does not respond",
    ),
    log(
        "CONTROL_LINK_LOST",
        402,
        "ERROR",
        "chassis",
        "control heartbeat lost: stopped",
    ),
    log(
        "OBSTACLE_DETECTED",
        500,
        "WARNING",
        "obstacle",
        "obstacle detected",
    ),
    log(
        "OBSTACLE_STOP",
        501,
        "WARNING",
        "obstacle",
        "stopped for an obstacle",
    ),
    log(
        "OBSTACLE_DETOUR",
        502,
        "NOTIFY",
        "obstacle",
        "going around an obstacle",
    ),
    log(
        "OBSTACLE_AVOIDANCE_FAILED",
        503,
        "ERROR",
        "obstacle",
        "obstacle avoidance failed",
    ),
    log(
        "MAP_LOAD_FAILED",
        600,
        "ERROR",
        "navigation",
        "navigation map failed to load",
    ),
    log(
        "SAFETY_STOP",
        403,
        "ERROR",
        "chassis",
        "drive fault: stopped",
    ),
    log(
        "EMERGENCY_STOP",
        404,
        "ERROR",
        "chassis",
        "emergency stop: stopped",
    ),
];

pub(super) fn log_code(key: &str) -> Option<&'static LogCode> {
    LOG_CODES.iter().find(|c| c.key == key)
}
