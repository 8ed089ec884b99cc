//! Dialect `root` (root-mqtt-api.rst, `/root/{vehicleId}/...`).
//!
//! Commands arrive on `.../set` topics and are answered on the matching `.../ack` with the same
//! `messageId` and `messageType`: `"data": {"code": 0}` when done, else a non-zero code and a
//! `message`. Codes: 1 invalid request (malformed JSON, wrong types, out-of-range values,
//! oversized payload), 2 unknown `messageType` (or one sent on the wrong topic), 3 not
//! available in this driver, 4 refused by the vehicle (the reason says why). An action that
//! takes effect later ends with a `.../notify` in the ack's shape.
//!
//! Resolutions of the spec's gaps (documented in docs/protocols/root.md):
//! - navigation general is published on `report/navigation/general` (the spec reuses
//!   `report/chassis/general`, the chassis report's topic);
//! - the `/log` codes that share 200 become LOW_BATTERY 200, FULL_BATTERY 201,
//!   RECHARGE_ERROR 202, and the unnumbered ones get 300, 400, 401, 500–503 and 600; events go
//!   to `log/notify`;
//! - timestamps are UTC, `%Y-%m-%d %H:%M:%S`;
//! - INIT_POSITION's seven numbers are x, y, z and the orientation quaternion x, y, z, w.

use serde::Serialize;
use serde_json::{Value, json};

use super::log_budget::{self, LogBudget, SharedBudget};
use super::mqtt::{CoreAccess, Dialect, Handled, Publish};
use crate::control::mission::{MAX_STEPS, MissionEvent, MissionStep};
use crate::control::{MotionTag, Outcome};
use crate::devices::bms::ChargeState;
use crate::geodesy::Geodetic;
use crate::time::Timestamp;
use crate::vehicle::{Command, DriveMode, Localization, VehicleStatus, chassis::status_bits};

/// Done.
pub const OK: u32 = 0;
/// Invalid request.
pub const INVALID: u32 = 1;
/// Unknown messageType.
pub const UNKNOWN_TYPE: u32 = 2;
/// Not available in this driver.
pub const NOT_AVAILABLE: u32 = 3;
/// Refused by the vehicle.
pub const REFUSED: u32 = 4;

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

fn log_code(key: &str) -> Option<&'static LogCode> {
    LOG_CODES.iter().find(|c| c.key == key)
}

/// Report periods, in status ticks (100 ms).
const LOCALIZATION_EVERY: u64 = 2;
const CHASSIS_EVERY: u64 = 2;
const BATTERY_EVERY: u64 = 10;
const USAGE_EVERY: u64 = 10;
const OBSTACLE_EVERY: u64 = 10;
const NAVIGATION_EVERY: u64 = 10;
/// Below this state of charge LOW_BATTERY is raised, %.
const LOW_BATTERY_PERCENT: f64 = 20.0;

/// Whom an answer goes to: the request's topic base, messageId and messageType.
struct Request<'a> {
    base: &'a str,
    id: &'a Value,
    kind: &'a Value,
}

#[derive(Serialize)]
struct AckData<'a> {
    code: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    message: Option<&'a str>,
}

/// `cmd/chassis` ESTOP (an extension): `data` 1 engages the software e-stop, 0 releases it.
pub const ESTOP: u64 = 101;
/// `cmd/chassis` RESET (an extension): re-arms a latched stop once its cause has cleared.
pub const RESET: u64 = 102;

/// The `root` dialect.
pub struct RootDialect {
    prefix: String,
    max_payload: usize,
    /// Only heartbeats naming this `clientId` feed the control-link watchdog.
    heartbeat_client: Option<String>,
    /// Heartbeats ignored because they were not JSON objects.
    malformed_heartbeats: u64,
    ticks: u64,
    previous: Option<VehicleStatus>,
    /// RTK_CORRECTIONS_LOST went out, and no RESTORED since.
    corrections_lost: bool,
    /// Missions under way or recently ended: their tag id and `messageId`, for notifies.
    missions: std::collections::VecDeque<(u64, Value)>,
    last_mission: u64,
}

/// Mission `messageId`s kept for their notifies.
const MAX_PENDING_MISSIONS: usize = 16;

impl RootDialect {
    /// The dialect of vehicle `vehicle_id`. Heartbeats feed the core's control-link
    /// watchdog; with `heartbeat_client`, only those whose `clientId` is that.
    pub fn new(vehicle_id: &str, heartbeat_client: Option<String>, max_payload: usize) -> Self {
        Self {
            prefix: format!("/root/{vehicle_id}/"),
            max_payload,
            heartbeat_client,
            malformed_heartbeats: 0,
            ticks: 0,
            previous: None,
            corrections_lost: false,
            missions: std::collections::VecDeque::new(),
            last_mission: 0,
        }
    }

    /// MISSION: parses the steps and starts them, tagged so that progress is notified with
    /// the request's `messageId`.
    fn start_mission(
        &mut self,
        data: &Value,
        id: &Value,
        core: &mut dyn CoreAccess,
    ) -> Result<(), (u32, String)> {
        let steps = mission(data)?;
        self.last_mission += 1;
        let tag = MotionTag {
            owner: "root",
            id: self.last_mission,
        };
        core.command(Command::Mission {
            steps: std::sync::Arc::new(steps),
            tag: Some(tag),
        })
        .map_err(|e| refusal(&e))?;
        if self.missions.len() >= MAX_PENDING_MISSIONS {
            self.missions.pop_front();
        }
        self.missions.push_back((tag.id, id.clone()));
        Ok(())
    }

    fn topic(&self, rest: &str) -> String {
        format!("{}{rest}", self.prefix)
    }

    fn answer(
        &self,
        t: Timestamp,
        to: &Request<'_>,
        suffix: &str,
        outcome: Result<(), (u32, &str)>,
        out: &mut Vec<Publish>,
    ) -> Handled {
        let handled = if outcome.is_ok() {
            Handled::Taken
        } else {
            Handled::Refused
        };
        let (code, message) = match outcome {
            Ok(()) => (OK, None),
            Err((code, reason)) => {
                static REFUSALS: SharedBudget = SharedBudget::new(LogBudget::new());
                if let Some(left_out) = log_budget::allow(&REFUSALS, t) {
                    tracing::warn!(dialect = "root", topic = %to.base, code, %reason, refusals_not_logged = left_out, "request refused");
                }
                (code, Some(reason))
            }
        };
        let body = json!({
            "messageId": to.id,
            "timestamp": timestamp(t),
            "messageType": to.kind,
            "data": AckData { code, message },
        });
        out.push(Publish::reply(
            self.topic(&format!("{}/{suffix}", to.base)),
            body.to_string(),
        ));
        handled
    }

    fn event(&self, t: Timestamp, key: &str, detail: &str, out: &mut Vec<Publish>) {
        let Some(code) = log_code(key) else { return };
        tracing::warn!(dialect = "root", key, code = code.code, %detail, "event");
        let body = json!({
            "timestamp": timestamp(t),
            "data": {
                "code": code.code,
                "key": code.key,
                "level": code.level,
                "module": code.module,
                "message": if detail.is_empty() { code.text.to_owned() } else { format!("{}: {detail}", code.text) },
            }
        });
        out.push(Publish::reply(self.topic("log/notify"), body.to_string()));
    }

    /// A `.../set` message on `base` (e.g. `cmd/navigation`).
    fn set(
        &mut self,
        t: Timestamp,
        base: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) -> Handled {
        let null = Value::Null;
        let unknown = Request {
            base,
            id: &null,
            kind: &null,
        };
        if payload.len() > self.max_payload {
            let reason = format!(
                "payload of {} bytes exceeds {}",
                payload.len(),
                self.max_payload
            );
            return self.answer(t, &unknown, "ack", Err((INVALID, &reason)), out);
        }
        let request: Value = match serde_json::from_slice(payload) {
            Ok(v @ Value::Object(_)) => v,
            Ok(_) => {
                let reason = "the request must be a JSON object";
                return self.answer(t, &unknown, "ack", Err((INVALID, reason)), out);
            }
            Err(e) => {
                let reason = format!("malformed JSON: {e}");
                return self.answer(t, &unknown, "ack", Err((INVALID, &reason)), out);
            }
        };
        let id = request.get("messageId").cloned().unwrap_or(Value::Null);
        let kind = request.get("messageType").cloned().unwrap_or(Value::Null);
        let data = request.get("data").unwrap_or(&null);
        let outcome = match (base, kind.as_u64()) {
            (_, None) => Err((INVALID, "messageType must be a number".to_owned())),
            ("cmd/navigation", Some(0)) => self.init_position(t, data, core),
            ("cmd/navigation", Some(1)) => core
                .command(Command::Pause)
                .map_err(|e| (REFUSED, e.to_string())),
            ("cmd/navigation", Some(2)) => core
                .command(Command::Continue)
                .map_err(|e| (REFUSED, e.to_string())),
            ("cmd/navigation", Some(5)) => self.start_mission(data, &id, core),
            ("cmd/navigation", Some(6)) => match data.as_u64() {
                Some(0) => core
                    .command(Command::SetMode(DriveMode::Navigation))
                    .map_err(|e| (REFUSED, e.to_string())),
                Some(1) => core
                    .command(Command::SetMode(DriveMode::Manual))
                    .map_err(|e| (REFUSED, e.to_string())),
                _ => Err((
                    INVALID,
                    "data must be 0 (navigation) or 1 (manual)".to_owned(),
                )),
            },
            ("cmd/map", Some(3 | 4)) => match data.get("name").and_then(Value::as_str) {
                Some(_) => Err((
                    NOT_AVAILABLE,
                    "not available: mapping belongs to the navigation stack above this driver"
                        .to_owned(),
                )),
                None => Err((INVALID, "data.name must be a string".to_owned())),
            },
            ("cmd/chassis", Some(100)) => drive(data, core),
            ("cmd/chassis", Some(ESTOP)) => match data.as_u64() {
                Some(n @ (0 | 1)) => core
                    .command(Command::EmergencyStop { engaged: n == 1 })
                    .map_err(|e| (REFUSED, e.to_string())),
                _ => Err((INVALID, "data must be 1 (engage) or 0 (release)".to_owned())),
            },
            ("cmd/chassis", Some(RESET)) => core
                .command(Command::Reset)
                .map_err(|e| (REFUSED, e.to_string())),
            ("setting/map", Some(0)) => match data.as_str() {
                Some(_) => Err((
                    NOT_AVAILABLE,
                    "not available: maps belong to the navigation stack above this driver"
                        .to_owned(),
                )),
                None => Err((INVALID, "data must be the map's name".to_owned())),
            },
            ("setting/navigation", Some(100)) => set_lng_lat(data, core),
            (_, Some(n)) => Err((
                UNKNOWN_TYPE,
                format!("messageType {n} is not taken on {base}/set"),
            )),
        };
        let to = Request {
            base,
            id: &id,
            kind: &kind,
        };
        match outcome {
            Ok(()) => {
                self.answer(t, &to, "ack", Ok(()), out);
                // INIT_POSITION is an action the protocol reports the end of.
                if base == "cmd/navigation" && kind.as_u64() == Some(0) {
                    self.answer(t, &to, "notify", Ok(()), out);
                }
                Handled::Taken
            }
            Err((code, reason)) => self.answer(t, &to, "ack", Err((code, &reason)), out),
        }
    }

    fn init_position(
        &self,
        _t: Timestamp,
        data: &Value,
        core: &mut dyn CoreAccess,
    ) -> Result<(), (u32, String)> {
        let numbers: Option<Vec<f64>> = data
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect());
        let Some([x, y, _z, qx, qy, qz, qw]) = numbers
            .filter(|n| data.as_array().is_some_and(|a| a.len() == n.len()))
            .and_then(|n| <[f64; 7]>::try_from(n).ok())
        else {
            return Err((
                INVALID,
                "data must be [x, y, z, qx, qy, qz, qw]: a position and an orientation quaternion"
                    .to_owned(),
            ));
        };
        let norm = (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
        if ![x, y, qx, qy, qz, qw].iter().all(|v| v.is_finite()) || !(0.5..=1.5).contains(&norm) {
            return Err((
                INVALID,
                "values must be finite, the quaternion of unit length".to_owned(),
            ));
        }
        let yaw = (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz));
        core.command(Command::SetPose { x, y, yaw })
            .map_err(|e| refusal(&e))
    }

    fn reports(&mut self, s: &VehicleStatus, out: &mut Vec<Publish>) {
        let t = s.time;
        let stamp = timestamp(t);
        let tick = self.ticks;
        let publish = |topic: &str, data: Value, out: &mut Vec<Publish>| {
            out.push(Publish::telemetry(
                self.topic(topic),
                json!({ "timestamp": stamp, "data": data }).to_string(),
            ));
        };
        if tick.is_multiple_of(LOCALIZATION_EVERY) {
            let (sin, cos) = (s.pose.yaw / 2.0).sin_cos();
            let status = match s.localization {
                Localization::Good => 0,
                Localization::Uninitialized => 1,
                Localization::Lost => 2,
            };
            publish(
                "report/navigation/localization",
                json!({
                    "pose": [[s.pose.x, s.pose.y, 0.0], [0.0, 0.0, sin, cos]],
                    "scan": [],
                    "status": status,
                }),
                out,
            );
        }
        if tick.is_multiple_of(OBSTACLE_EVERY) {
            // No obstacle sensor is driven: nothing seen, at no distance.
            publish(
                "report/navigation/obstacle",
                json!({ "obstacle": [], "distance": -1.0, "angle": 0.0 }),
                out,
            );
        }
        if tick.is_multiple_of(BATTERY_EVERY)
            && let Some(b) = &s.battery
        {
            let r = &b.reading;
            publish(
                "report/chassis/battery",
                json!({
                    "charged": r.charge_state == Some(ChargeState::Charging),
                    "percentage": r.soc_pct.unwrap_or(0.0),
                    "voltage": r.voltage_v.unwrap_or(0.0),
                    "current": r.current_a.unwrap_or(0.0),
                    "temperature": r.temperature_c.unwrap_or(0.0),
                }),
                out,
            );
        }
        if tick.is_multiple_of(USAGE_EVERY)
            && let Some(h) = &s.host
        {
            publish(
                "report/navigation/usage",
                json!({ "cpu": round1(h.cpu), "memory": round1(h.memory) }),
                out,
            );
        }
        if tick.is_multiple_of(CHASSIS_EVERY) {
            let (linear, angular) = s.chassis.as_ref().map_or((0.0, 0.0), |c| (c.vx, c.wz));
            publish(
                "report/chassis/general",
                json!({ "linear": linear, "angular": angular }),
                out,
            );
        }
        if tick.is_multiple_of(NAVIGATION_EVERY) {
            let moving = s
                .chassis
                .as_ref()
                .is_some_and(|c| c.status_bits & status_bits::MOVING != 0);
            publish(
                "report/navigation/general",
                json!({
                    "mapping": false,
                    "moving": moving,
                    "mode": match s.mode {
                        Some(DriveMode::Navigation) => "navigation",
                        Some(DriveMode::Manual) => "manual",
                        None => "none",
                    },
                }),
                out,
            );
        }
    }

    /// `/log` events for what changed since the last status.
    fn events(&mut self, s: &VehicleStatus, out: &mut Vec<Publish>) {
        let Some(p) = self.previous.take() else {
            self.previous = Some(s.clone());
            return;
        };
        let t = s.time;
        if p.localization == Localization::Good && s.localization == Localization::Lost {
            self.event(t, "LOCALIZATION_ERROR", "", out);
        }
        if p.gnss.ok && !s.gnss.ok {
            self.event(t, "GPS_ERROR", "", out);
        }
        if let (Some(before), Some(now)) = (&p.corrections, &s.corrections) {
            if before.fresh && !now.fresh {
                let detail = format!("no valid frame for {:.0} s", now.stale_after_s);
                self.event(t, "RTK_CORRECTIONS_LOST", &detail, out);
                self.corrections_lost = true;
            }
            if !before.fresh && now.fresh && self.corrections_lost {
                self.event(t, "RTK_CORRECTIONS_RESTORED", "", out);
                self.corrections_lost = false;
            }
        }
        let soc = |st: &VehicleStatus| {
            st.battery
                .as_ref()
                .filter(|b| !b.stale)
                .and_then(|b| b.reading.soc_pct)
        };
        if let (Some(before), Some(now)) = (soc(&p), soc(s)) {
            if before >= LOW_BATTERY_PERCENT && now < LOW_BATTERY_PERCENT {
                self.event(t, "LOW_BATTERY", &format!("{now:.0} %"), out);
            }
            if before < 100.0 && now >= 100.0 {
                self.event(t, "FULL_BATTERY", "", out);
            }
        }
        let bits = |st: &VehicleStatus| st.chassis.as_ref().map_or(0, |c| c.status_bits);
        let rose = |bit: u32| bits(&p) & bit == 0 && bits(s) & bit != 0;
        if rose(status_bits::BUS_DOWN) {
            self.event(t, "NO_CHASSIS_FEEDBACK", "CAN interface down", out);
        }
        if rose(status_bits::HEARTBEAT_LOST) {
            self.event(t, "NODE_NOT_RESPONDING", "drive heartbeat lost", out);
        }
        if rose(status_bits::CONTROL_LINK_LOST) {
            self.event(t, "CONTROL_LINK_LOST", "", out);
        }
        let reason = || {
            s.chassis
                .as_ref()
                .and_then(|c| c.stop_reason.clone())
                .unwrap_or_default()
        };
        if rose(status_bits::FAULT) {
            self.event(t, "SAFETY_STOP", &reason(), out);
        }
        if rose(status_bits::ESTOP) {
            self.event(t, "EMERGENCY_STOP", &reason(), out);
        }
        self.previous = Some(s.clone());
    }
}

/// `MISSION` data: an array of `{action, parameters}` steps.
///
/// - MOVE_TO_POSITION and COVERAGE: `path` `[x0, y0, x1, y1, ...]`, m in the map frame,
///   followed in order (the vehicle drives to the first point first);
/// - WAIT: `seconds` ≥ 0;
/// - OPEN_CUTTER and CLOSE_CUTTER: `cutter` true and false (optional; it must match);
/// - CHARGING: `time`, s charged before the step is done (0: done once charging).
pub(crate) fn mission(data: &Value) -> Result<Vec<MissionStep>, (u32, String)> {
    const ACTIONS: [&str; 6] = [
        "MOVE_TO_POSITION",
        "WAIT",
        "OPEN_CUTTER",
        "CLOSE_CUTTER",
        "COVERAGE",
        "CHARGING",
    ];
    let Some(steps) = data.as_array() else {
        return Err((INVALID, "data must be an array of steps".to_owned()));
    };
    if steps.is_empty() {
        return Err((INVALID, "a mission needs at least one step".to_owned()));
    }
    if steps.len() > MAX_STEPS {
        return Err((
            INVALID,
            format!(
                "a mission has at most {MAX_STEPS} steps, this one {}: split it",
                steps.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(steps.len());
    for (i, step) in steps.iter().enumerate() {
        let action = step.get("action").and_then(Value::as_str).unwrap_or("");
        let Some(parameters) = step.get("parameters").filter(|p| p.is_object()) else {
            return Err((
                INVALID,
                format!(
                    "step {i}: needs an action (one of {}) and parameters",
                    ACTIONS.join(", ")
                ),
            ));
        };
        let bad = |what: &str| (INVALID, format!("step {i} ({action}): {what}"));
        let seconds = |key: &str| {
            parameters
                .get(key)
                .and_then(Value::as_f64)
                .filter(|s| (0.0..=86_400.0).contains(s))
                .ok_or_else(|| {
                    bad(&format!(
                        "{key} must be a number of seconds from 0 to 86400"
                    ))
                })
        };
        let path = || {
            let values: Option<Vec<f64>> = parameters
                .get("path")
                .and_then(Value::as_array)
                .and_then(|a| a.iter().map(Value::as_f64).collect());
            let values = values
                .ok_or_else(|| bad("path must be an array of numbers [x0, y0, x1, y1, ...]"))?;
            super::path_points(&values).map_err(|e| bad(&e))
        };
        let cutter = |want: bool| match parameters.get("cutter") {
            None => Ok(MissionStep::Cutter(want)),
            Some(v) if v.as_bool() == Some(want) => Ok(MissionStep::Cutter(want)),
            Some(_) => Err(bad(&format!("cutter must be {want} (or absent)"))),
        };
        out.push(match action {
            "MOVE_TO_POSITION" => MissionStep::MoveTo(path()?),
            "COVERAGE" => MissionStep::Coverage(path()?),
            "WAIT" => MissionStep::Wait(seconds("seconds")?),
            "OPEN_CUTTER" => cutter(true)?,
            "CLOSE_CUTTER" => cutter(false)?,
            "CHARGING" => MissionStep::Charge(seconds("time")?),
            _ => {
                return Err((
                    INVALID,
                    format!(
                        "step {i}: action {action:?} is not one of {}",
                        ACTIONS.join(", ")
                    ),
                ));
            }
        });
    }
    Ok(out)
}

/// The `{base}/set` topics the dialect acts on (others get an "unknown" answer).
const SET_BASES: [&str; 6] = [
    "cmd/navigation",
    "cmd/map",
    "cmd/chassis",
    "setting/map",
    "setting/navigation",
    "heartbeat",
];

/// The report topics the dialect publishes.
const REPORTS: [&str; 6] = [
    "report/navigation/localization",
    "report/navigation/obstacle",
    "report/chassis/battery",
    "report/navigation/usage",
    "report/chassis/general",
    "report/navigation/general",
];

/// A heartbeat's payload as a JSON object. The spec's own example ends its object with a
/// comma (`{"timestamp": "...",}`), which JSON forbids; that one comma is forgiven.
fn heartbeat_object(payload: &[u8]) -> Option<serde_json::Map<String, Value>> {
    if let Ok(Value::Object(map)) = serde_json::from_slice(payload) {
        return Some(map);
    }
    let text = std::str::from_utf8(payload).ok()?.trim_end();
    let body = text.strip_suffix('}')?.trim_end().strip_suffix(',')?;
    match serde_json::from_str(&format!("{body}}}")) {
        Ok(Value::Object(map)) => Some(map),
        _ => None,
    }
}

/// The reply code of a command the core refused: a wrong value is the request's fault
/// (INVALID), anything else the vehicle's state (REFUSED).
fn refusal(e: &crate::vehicle::chassis::CommandRejected) -> (u32, String) {
    let code = if e.is_bad_value() { INVALID } else { REFUSED };
    (code, e.to_string())
}

/// `DRIVE`: `{"linear": m/s, "angular": rad/s}`.
fn drive(data: &Value, core: &mut dyn CoreAccess) -> Result<(), (u32, String)> {
    let (Some(linear), Some(angular)) = (
        data.get("linear").and_then(Value::as_f64),
        data.get("angular").and_then(Value::as_f64),
    ) else {
        return Err((
            INVALID,
            "data needs numbers linear (m/s) and angular (rad/s)".to_owned(),
        ));
    };
    core.command(Command::Velocity {
        vx: linear,
        wz: angular,
    })
    .map_err(|e| refusal(&e))
}

/// `SET_LNG_LAT`: `[longitude, latitude, height]`, degrees and metres.
fn set_lng_lat(data: &Value, core: &mut dyn CoreAccess) -> Result<(), (u32, String)> {
    let values: Option<Vec<f64>> = data
        .as_array()
        .filter(|a| a.len() == 3)
        .and_then(|a| a.iter().map(Value::as_f64).collect());
    let Some([lon_deg, lat_deg, h_m]) = values.and_then(|v| <[f64; 3]>::try_from(v).ok()) else {
        return Err((
            INVALID,
            "data must be [longitude, latitude, height]".to_owned(),
        ));
    };
    // The core judges the place (latitude, longitude, height ranges) for every channel.
    core.command(Command::SetDatum(Geodetic {
        lat_deg,
        lon_deg,
        h_m,
    }))
    .map_err(|e| refusal(&e))
}

fn round1(v: f64) -> f64 {
    (v * 10.0).round() / 10.0
}

/// `%Y-%m-%d %H:%M:%S`, UTC.
pub fn timestamp(t: Timestamp) -> String {
    chrono::DateTime::from_timestamp_micros(t.as_micros() as i64)
        .map(|d| d.format("%Y-%m-%d %H:%M:%S").to_string())
        .unwrap_or_default()
}

/// The dialect when `[mqtt.root]` is configured.
pub fn from_setup(setup: &mut super::mqtt::DialectSetup<'_>) -> Option<Box<dyn Dialect>> {
    let r = setup.mqtt.root.as_ref()?;
    Some(Box::new(RootDialect::new(
        &r.vehicle_id,
        r.heartbeat_client_id.clone(),
        setup.mqtt.max_payload,
    )))
}

impl Dialect for RootDialect {
    fn on_mission_event(
        &mut self,
        t: Timestamp,
        id: u64,
        event: &MissionEvent,
        out: &mut Vec<Publish>,
    ) {
        let Some((_, message_id)) = self.missions.iter().find(|(m, _)| *m == id).cloned() else {
            return;
        };
        let data = match event {
            MissionEvent::StepStarted(step, action) => {
                json!({"code": OK, "step": step, "action": action, "state": "started"})
            }
            MissionEvent::StepDone(step, action) => {
                json!({"code": OK, "step": step, "action": action, "state": "done"})
            }
            MissionEvent::Ended(Outcome::Succeeded) => json!({"code": OK}),
            MissionEvent::Ended(other) => {
                json!({"code": REFUSED, "message": format!("mission {other}")})
            }
        };
        if matches!(event, MissionEvent::Ended(_)) {
            self.missions.retain(|(m, _)| *m != id);
        }
        let body = json!({
            "messageId": message_id,
            "timestamp": timestamp(t),
            "messageType": 5,
            "data": data,
        });
        out.push(Publish::reply(
            self.topic("cmd/navigation/notify"),
            body.to_string(),
        ));
    }

    fn name(&self) -> &'static str {
        "root"
    }

    fn subscriptions(&self) -> Vec<String> {
        vec![self.topic("+/+/set"), self.topic("heartbeat/set")]
    }

    fn command_topics(&self) -> Vec<String> {
        SET_BASES
            .iter()
            .map(|base| self.topic(&format!("{base}/set")))
            .collect()
    }

    fn topics(&self) -> Vec<String> {
        let answers = SET_BASES.iter().flat_map(|base| {
            ["set", "ack", "notify"].map(|end| self.topic(&format!("{base}/{end}")))
        });
        let reports = REPORTS.iter().map(|r| self.topic(r));
        answers
            .chain(reports)
            .chain([self.topic("log/notify")])
            .collect()
    }

    fn owns(&self, topic: &str) -> bool {
        topic
            .strip_prefix(&self.prefix)
            .and_then(|rest| rest.strip_suffix("/set"))
            .is_some_and(|base| base == "heartbeat" || base.split('/').count() == 2)
    }

    fn on_message(
        &mut self,
        t: Timestamp,
        topic: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) -> Handled {
        let base = topic
            .strip_prefix(&self.prefix)
            .and_then(|rest| rest.strip_suffix("/set"))
            .unwrap_or_default()
            .to_owned();
        if base == "heartbeat" {
            // A heartbeat is a JSON object (the spec's example, trailing comma and all); it
            // is answered, and it feeds the watchdog when it comes from the client followed
            // (or from anyone, when none is named). Anything else is neither: garbage must
            // not arm the watchdog that then stops an operator who sends only DRIVE.
            let Some(beat) = (payload.len() <= self.max_payload)
                .then(|| heartbeat_object(payload))
                .flatten()
            else {
                self.malformed_heartbeats += 1;
                if self.malformed_heartbeats.is_power_of_two() {
                    tracing::warn!(
                        count = self.malformed_heartbeats,
                        "root heartbeat ignored: not a JSON object (neither answered nor counted)"
                    );
                }
                return Handled::Taken;
            };
            let sender = beat.get("clientId").and_then(Value::as_str);
            if self
                .heartbeat_client
                .as_deref()
                .is_none_or(|c| sender == Some(c))
            {
                let _ = core.command(Command::ControlHeartbeat);
            }
            out.push(Publish::reply(
                self.topic("heartbeat/notify"),
                json!({ "timestamp": timestamp(t) }).to_string(),
            ));
            return Handled::Taken;
        }
        self.set(t, &base, payload, core, out)
    }

    fn on_status(
        &mut self,
        status: &VehicleStatus,
        _core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) {
        self.reports(status, out);
        self.events(status, out);
        self.ticks += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::chassis::CommandRejected;

    /// The core as a recorder of commands, answering each with a chosen result.
    #[derive(Default)]
    struct FakeCore {
        commands: Vec<Command>,
        refuse_with: Option<CommandRejected>,
    }

    impl CoreAccess for FakeCore {
        fn pose_report(&self) -> crate::vehicle::PoseReport {
            crate::vehicle::PoseReport::default()
        }

        fn command(&mut self, command: Command) -> Result<(), CommandRejected> {
            self.commands.push(command);
            match self.refuse_with.take() {
                Some(e) => Err(e),
                None => Ok(()),
            }
        }
    }

    const T: Timestamp = Timestamp::from_micros(1_767_225_600_000_000);

    fn dialect() -> RootDialect {
        RootDialect::new("v1", None, 4096)
    }

    /// Sends `payload` on `topic`; the publishes it caused, as (topic, JSON).
    fn send(
        d: &mut RootDialect,
        core: &mut FakeCore,
        topic: &str,
        payload: &str,
    ) -> Vec<(String, Value)> {
        let mut out = Vec::new();
        assert!(d.owns(topic), "{topic}");
        d.on_message(T, topic, payload.as_bytes(), core, &mut out);
        out.into_iter()
            .map(|p| (p.topic, serde_json::from_slice(&p.payload).expect("JSON")))
            .collect()
    }

    fn only_ack(out: &[(String, Value)], topic: &str) -> Value {
        assert_eq!(out.len(), 1, "{out:?}");
        assert_eq!(out[0].0, topic);
        out[0].1.clone()
    }

    #[test]
    fn rtk_corrections_going_stale_and_back_are_logged_with_their_codes() {
        use crate::vehicle::corrections::CorrectionsStatus;
        let (mut d, mut core) = (dialect(), FakeCore::default());
        let status = |fresh: bool| VehicleStatus {
            time: T,
            corrections: Some(CorrectionsStatus {
                connected: true,
                age_s: Some(if fresh { 1.0 } else { 11.0 }),
                fresh,
                frames: 10,
                bytes: 1000,
                stale_after_s: 10.0,
            }),
            ..Default::default()
        };
        let mut logs = Vec::new();
        // Never fresh yet: nothing; fresh; stale (102); still stale; fresh again (103).
        for fresh in [false, true, false, false, true, true] {
            let mut out = Vec::new();
            d.on_status(&status(fresh), &mut core, &mut out);
            logs.extend(
                out.into_iter()
                    .filter(|p| p.topic.ends_with("/log/notify"))
                    .map(|p| serde_json::from_slice::<Value>(&p.payload).expect("JSON")),
            );
        }
        let codes: Vec<i64> = logs
            .iter()
            .filter_map(|l| l["data"]["code"].as_i64())
            .collect();
        assert_eq!(codes, [102, 103], "{logs:?}");
        assert_eq!(logs[0]["data"]["key"], "RTK_CORRECTIONS_LOST");
        assert!(
            logs[0]["data"]["message"]
                .as_str()
                .unwrap_or_default()
                .contains("10 s")
        );
    }

    #[test]
    fn drive_becomes_a_velocity_command_and_is_acknowledged() {
        let (mut d, mut core) = (dialect(), FakeCore::default());
        let out = send(
            &mut d,
            &mut core,
            "/root/v1/cmd/chassis/set",
            r#"{"messageId": 7, "timestamp": "x", "messageType": 100, "data": {"linear": 0.3, "angular": -0.1}}"#,
        );
        let ack = only_ack(&out, "/root/v1/cmd/chassis/ack");
        assert_eq!(ack["messageId"], 7);
        assert_eq!(ack["messageType"], 100);
        assert_eq!(ack["data"]["code"], OK);
        assert_eq!(ack["timestamp"], "2026-01-01 00:00:00");
        assert!(matches!(
            core.commands.as_slice(),
            [Command::Velocity { vx, wz }] if *vx == 0.3 && *wz == -0.1
        ));
    }

    #[test]
    fn the_cores_refusal_is_answered_with_its_code_and_reason() {
        let (mut d, mut core) = (dialect(), FakeCore::default());
        core.refuse_with = Some(CommandRejected::NotReady("left".into()));
        let out = send(
            &mut d,
            &mut core,
            "/root/v1/cmd/chassis/set",
            r#"{"messageId": 1, "messageType": 100, "data": {"linear": 0.1, "angular": 0}}"#,
        );
        let ack = only_ack(&out, "/root/v1/cmd/chassis/ack");
        assert_eq!(ack["data"]["code"], REFUSED);
        assert!(
            ack["data"]["message"].as_str().unwrap().contains("left"),
            "{ack}"
        );
        // Values out of range are the request's fault, not the vehicle's.
        core.refuse_with = Some(CommandRejected::NotFinite);
        let out = send(
            &mut d,
            &mut core,
            "/root/v1/cmd/chassis/set",
            r#"{"messageId": 2, "messageType": 100, "data": {"linear": 1e300, "angular": 0}}"#,
        );
        assert_eq!(
            only_ack(&out, "/root/v1/cmd/chassis/ack")["data"]["code"],
            INVALID
        );
    }

    #[test]
    fn malformed_requests_reach_no_core_and_get_invalid() {
        let (mut d, mut core) = (dialect(), FakeCore::default());
        for payload in [
            "not json",
            "[1, 2]",
            r#"{"messageId": 3, "messageType": "drive", "data": {}}"#,
            r#"{"messageId": 4, "messageType": 100, "data": {"linear": "fast"}}"#,
        ] {
            let out = send(&mut d, &mut core, "/root/v1/cmd/chassis/set", payload);
            let ack = only_ack(&out, "/root/v1/cmd/chassis/ack");
            assert_eq!(ack["data"]["code"], INVALID, "{payload}: {ack}");
            assert!(ack["data"]["message"].is_string(), "{ack}");
        }
        let big = format!(
            r#"{{"messageId": 5, "messageType": 100, "pad": "{}"}}"#,
            "x".repeat(5000)
        );
        let out = send(&mut d, &mut core, "/root/v1/cmd/chassis/set", &big);
        assert_eq!(
            only_ack(&out, "/root/v1/cmd/chassis/ack")["data"]["code"],
            INVALID
        );
        assert!(core.commands.is_empty(), "{:?}", core.commands);
    }

    #[test]
    fn an_unknown_message_type_gets_code_two_and_its_own_id() {
        let (mut d, mut core) = (dialect(), FakeCore::default());
        let out = send(
            &mut d,
            &mut core,
            "/root/v1/cmd/chassis/set",
            r#"{"messageId": "abc", "messageType": 999, "data": {}}"#,
        );
        let ack = only_ack(&out, "/root/v1/cmd/chassis/ack");
        assert_eq!(ack["data"]["code"], UNKNOWN_TYPE);
        assert_eq!(ack["messageId"], "abc");
        assert!(core.commands.is_empty());
    }

    #[test]
    fn heartbeats_feed_the_watchdog_only_from_the_named_client() {
        let mut core = FakeCore::default();
        let mut d = RootDialect::new("v1", Some("operator".into()), 4096);
        let out = send(
            &mut d,
            &mut core,
            "/root/v1/heartbeat/set",
            r#"{"clientId": "someone"}"#,
        );
        assert_eq!(out[0].0, "/root/v1/heartbeat/notify");
        assert!(
            core.commands.is_empty(),
            "another client's heartbeat does not count"
        );
        send(
            &mut d,
            &mut core,
            "/root/v1/heartbeat/set",
            r#"{"clientId": "operator"}"#,
        );
        assert!(matches!(
            core.commands.as_slice(),
            [Command::ControlHeartbeat]
        ));
        // Without a named client, any JSON object counts, the spec's trailing comma too.
        let (mut d, mut core) = (dialect(), FakeCore::default());
        let out = send(
            &mut d,
            &mut core,
            "/root/v1/heartbeat/set",
            "{\n  \"timestamp\": \"2026-01-01 00:00:00\",\n}",
        );
        assert_eq!(out.len(), 1);
        assert!(matches!(
            core.commands.as_slice(),
            [Command::ControlHeartbeat]
        ));
    }

    #[test]
    fn a_heartbeat_that_is_not_a_json_object_is_neither_answered_nor_counted() {
        let (mut d, mut core) = (dialect(), FakeCore::default());
        for garbage in [
            "garbage not json",
            "beat",
            "[1, 2]",
            "7",
            "{\"a\": 1,,}",
            "",
        ] {
            let out = send(&mut d, &mut core, "/root/v1/heartbeat/set", garbage);
            assert!(out.is_empty(), "{garbage:?} answered");
        }
        assert!(core.commands.is_empty());
    }

    #[test]
    fn init_position_is_acknowledged_then_notified_with_the_yaw_of_its_quaternion() {
        let (mut d, mut core) = (dialect(), FakeCore::default());
        let (s, c) = (std::f64::consts::FRAC_PI_4 / 2.0).sin_cos();
        let out = send(
            &mut d,
            &mut core,
            "/root/v1/cmd/navigation/set",
            &format!(
                r#"{{"messageId": 9, "messageType": 0, "data": [1.0, 2.0, 0.0, 0.0, 0.0, {s}, {c}]}}"#
            ),
        );
        let topics: Vec<&str> = out.iter().map(|(t, _)| t.as_str()).collect();
        assert_eq!(
            topics,
            [
                "/root/v1/cmd/navigation/ack",
                "/root/v1/cmd/navigation/notify"
            ]
        );
        let [Command::SetPose { x, y, yaw }] = core.commands.as_slice() else {
            panic!("{:?}", core.commands)
        };
        assert_eq!((*x, *y), (1.0, 2.0));
        assert!((yaw - std::f64::consts::FRAC_PI_4).abs() < 1e-12, "{yaw}");
    }

    #[test]
    fn topics_of_other_vehicles_and_shapes_are_not_owned() {
        let d = dialect();
        assert!(!d.owns("/root/v2/cmd/chassis/set"));
        assert!(!d.owns("/root/v1/cmd/chassis/ack"));
        assert!(!d.owns("/root/v1/a/b/c/set"));
        assert!(d.owns("/root/v1/setting/navigation/set"));
    }
}
