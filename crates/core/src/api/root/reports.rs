//! What the root dialect publishes from the status ticks: the `report/...` topics at their
//! rates, and the `/log` events for what changed since the last tick.

use serde_json::{Value, json};

use super::log_codes::log_code;
use super::timestamp;
use crate::api::mqtt::Publish;
use crate::devices::bms::ChargeState;
use crate::time::Timestamp;
use crate::vehicle::{DriveMode, Localization, VehicleStatus, chassis::status_bits};

/// Report periods, in status ticks (100 ms).
const LOCALIZATION_EVERY: u64 = 2;
const CHASSIS_EVERY: u64 = 2;
const BATTERY_EVERY: u64 = 10;
const USAGE_EVERY: u64 = 10;
const OBSTACLE_EVERY: u64 = 10;
const NAVIGATION_EVERY: u64 = 10;

/// Below this state of charge LOW_BATTERY is raised, %.
const LOW_BATTERY_PERCENT: f64 = 20.0;

/// The report topics the dialect publishes.
pub(super) const REPORTS: [&str; 6] = [
    "report/navigation/localization",
    "report/navigation/obstacle",
    "report/chassis/battery",
    "report/navigation/usage",
    "report/chassis/general",
    "report/navigation/general",
];

/// What the reports keep from one status tick to the next.
#[derive(Default)]
pub(super) struct Reports {
    ticks: u64,
    previous: Option<VehicleStatus>,
    /// RTK_CORRECTIONS_LOST went out, and no RESTORED since.
    corrections_lost: bool,
}

impl Reports {
    /// The reports due at this tick and the events since the last, on topics under `prefix`.
    pub(super) fn on_status(&mut self, prefix: &str, s: &VehicleStatus, out: &mut Vec<Publish>) {
        self.reports(prefix, s, out);
        self.events(prefix, s, out);
        self.ticks += 1;
    }

    fn reports(&self, prefix: &str, s: &VehicleStatus, out: &mut Vec<Publish>) {
        let t = s.time;
        let stamp = timestamp(t);
        let tick = self.ticks;
        let publish = |topic: &str, data: Value, out: &mut Vec<Publish>| {
            out.push(Publish::telemetry(
                format!("{prefix}{topic}"),
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
    fn events(&mut self, prefix: &str, s: &VehicleStatus, out: &mut Vec<Publish>) {
        let event = |key: &str, detail: &str, out: &mut Vec<Publish>| {
            log_event(prefix, s.time, key, detail, out)
        };
        let Some(p) = self.previous.take() else {
            self.previous = Some(s.clone());
            return;
        };
        if p.localization == Localization::Good && s.localization == Localization::Lost {
            event("LOCALIZATION_ERROR", "", out);
        }
        if p.gnss.ok && !s.gnss.ok {
            event("GPS_ERROR", "", out);
        }
        if let (Some(before), Some(now)) = (&p.corrections, &s.corrections) {
            if before.fresh && !now.fresh {
                let detail = format!("no valid frame for {:.0} s", now.stale_after_s);
                event("RTK_CORRECTIONS_LOST", &detail, out);
                self.corrections_lost = true;
            }
            if !before.fresh && now.fresh && self.corrections_lost {
                event("RTK_CORRECTIONS_RESTORED", "", out);
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
                event("LOW_BATTERY", &format!("{now:.0} %"), out);
            }
            if before < 100.0 && now >= 100.0 {
                event("FULL_BATTERY", "", out);
            }
        }
        let bits = |st: &VehicleStatus| st.chassis.as_ref().map_or(0, |c| c.status_bits);
        let rose = |bit: u32| bits(&p) & bit == 0 && bits(s) & bit != 0;
        if rose(status_bits::BUS_DOWN) {
            event("NO_CHASSIS_FEEDBACK", "CAN interface down", out);
        }
        if rose(status_bits::HEARTBEAT_LOST) {
            event("NODE_NOT_RESPONDING", "drive heartbeat lost", out);
        }
        if rose(status_bits::CONTROL_LINK_LOST) {
            event("CONTROL_LINK_LOST", "", out);
        }
        let reason = || {
            s.chassis
                .as_ref()
                .and_then(|c| c.stop_reason.clone())
                .unwrap_or_default()
        };
        if rose(status_bits::FAULT) {
            event("SAFETY_STOP", &reason(), out);
        }
        if rose(status_bits::ESTOP) {
            event("EMERGENCY_STOP", &reason(), out);
        }
        self.previous = Some(s.clone());
    }
}

/// The event `key` on `log/notify`, with `detail` after its text.
fn log_event(prefix: &str, t: Timestamp, key: &str, detail: &str, out: &mut Vec<Publish>) {
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
    out.push(Publish::reply(
        format!("{prefix}log/notify"),
        body.to_string(),
    ));
}

fn round1(v: f64) -> f64 {
    (v * 10.0).round() / 10.0
}
