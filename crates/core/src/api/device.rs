//! Dialect `device` (device-mqtt-api.md, `device/{serial_number}/...`): `goal`,
//! `start_mapping`, `stop_mapping` and `use_map`, each answered on `<topic>/ack` as
//! `{"msg_id", "timestamp" (Unix s), "success", "code"?, "message"?, "data"?}`.
//!
//! `goal` drives to `data.x`, `data.y` (m, the map frame: east and north of the datum, as the
//! status pose) and the heading whose quaternion z is `data.z` (sin(yaw / 2): the example's
//! 0.7071 is 90°, counter-clockwise from east; `w` = cos(yaw / 2) may be given too). A `z`
//! outside −1..1 is refused rather than read as an angle. It is answered once, when it ends:
//! success, 3001 when cancelled (a new goal, a stop, a velocity command, a mode switch) or
//! 3002 when it failed, with the result in `message`; a goal refused at once (not located,
//! latched) gets 3002 with the reason.
//!
//! Codes: 3001 goal cancelled (and, for start_mapping, already mapping), 3002 goal failed,
//! 3003 not available in this driver, 4000 a malformed or invalid request, 4004 an unknown
//! command, 4013 a payload over the size limit. Mapping belongs to the navigation stack above
//! this driver: unless `mapping_forward` names where that stack listens, mapping requests are
//! refused with 3003; with it, they are passed on as they came and its acks relayed back.
//!
//! Two safety commands extend the spec in its own shape: `estop` (`data: {"engaged": bool}`)
//! engages or releases the software emergency stop, and `reset` (`data: {}`) re-arms a latched
//! stop once its cause has cleared; a refusal answers 3002 with the reason.

use std::collections::VecDeque;

use serde::Serialize;
use serde_json::Value;

use super::log_budget::{self, LogBudget, SharedBudget};
use super::mqtt::{CoreAccess, Dialect, Handled, Publish};
use crate::control::goal::GoalPose;
use crate::control::{MotionResult, MotionTag, Outcome};
use crate::fusion::planar::wrap;
use crate::time::Timestamp;
use crate::vehicle::{Command, VehicleStatus};

/// Goal cancelled (or: already mapping).
pub const CANCELLED: u32 = 3001;
/// Goal failed.
pub const FAILED: u32 = 3002;
/// Not available in this driver.
pub const NOT_AVAILABLE: u32 = 3003;
/// Malformed or invalid request.
pub const BAD_REQUEST: u32 = 4000;
/// Unknown command.
pub const UNKNOWN: u32 = 4004;
/// Payload too large.
pub const TOO_LARGE: u32 = 4013;

/// Commands that go to the navigation stack when one is configured.
const MAPPING: [&str; 3] = ["start_mapping", "stop_mapping", "use_map"];

/// Commands chassisd carries out itself. Each is a command topic: it has a rate bucket of
/// its own (an e-stop never waits behind invented topics) and the embedded broker keeps it
/// for chassisd's commands (no client's last will may release an e-stop).
const OWN_COMMANDS: [&str; 3] = ["goal", "estop", "reset"];

#[derive(Serialize)]
struct Ack<'a> {
    msg_id: &'a Value,
    timestamp: u64,
    success: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    code: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    message: Option<&'a str>,
}

/// Goals answered at their end at most: the oldest request is forgotten beyond this (a
/// goal replaced by another ends at once, so only a flood could pile them up).
const MAX_PENDING_GOALS: usize = 16;

/// The `device` dialect.
pub struct DeviceDialect {
    prefix: String,
    forward: Option<String>,
    max_payload: usize,
    /// The number of the last goal it started.
    next_goal: u64,
    /// Goals under way or ended but not yet answered: number and `msg_id`.
    goals: VecDeque<(u64, Value)>,
}

impl DeviceDialect {
    /// The dialect of `serial_number`; mapping requests go to `forward` when set.
    pub fn new(serial_number: &str, forward: Option<String>, max_payload: usize) -> Self {
        Self {
            prefix: format!("device/{serial_number}/"),
            forward,
            max_payload,
            next_goal: 0,
            goals: VecDeque::new(),
        }
    }

    fn ack(
        &self,
        t: Timestamp,
        command: &str,
        msg_id: &Value,
        failure: Option<(u32, &str)>,
        out: &mut Vec<Publish>,
    ) -> Handled {
        if let Some((code, reason)) = failure {
            static REFUSALS: SharedBudget = SharedBudget::new(LogBudget::new());
            if let Some(left_out) = log_budget::allow(&REFUSALS, t) {
                tracing::warn!(dialect = "device", %command, code, %reason, refusals_not_logged = left_out, "request refused");
            }
        }
        self.publish_ack(t, command, msg_id, failure, out);
        if failure.is_some() {
            Handled::Refused
        } else {
            Handled::Taken
        }
    }

    /// Publishes an ack (a goal's end, which the core has logged already).
    fn publish_ack(
        &self,
        t: Timestamp,
        command: &str,
        msg_id: &Value,
        failure: Option<(u32, &str)>,
        out: &mut Vec<Publish>,
    ) {
        let body = Ack {
            msg_id,
            timestamp: t.as_micros() / 1_000_000,
            success: failure.is_none(),
            code: failure.map(|f| f.0),
            message: failure.map(|f| f.1),
        };
        let json = serde_json::to_string(&body).unwrap_or_default();
        out.push(Publish::reply(
            format!("{}{command}/ack", self.prefix),
            json,
        ));
    }
}

/// The dialect when `[mqtt.device]` is configured.
pub fn from_setup(setup: &mut super::mqtt::DialectSetup<'_>) -> Option<Box<dyn Dialect>> {
    let d = setup.mqtt.device.as_ref()?;
    Some(Box::new(DeviceDialect::new(
        &d.serial_number,
        d.mapping_forward.clone(),
        setup.mqtt.max_payload,
    )))
}

impl Dialect for DeviceDialect {
    fn name(&self) -> &'static str {
        "device"
    }

    fn subscriptions(&self) -> Vec<String> {
        let mut topics = vec![format!("{}+", self.prefix)];
        if let Some(f) = &self.forward {
            topics.extend(MAPPING.iter().map(|c| format!("{f}/{c}/ack")));
        }
        topics
    }

    fn command_topics(&self) -> Vec<String> {
        let mut topics: Vec<String> = MAPPING
            .iter()
            .chain(&OWN_COMMANDS)
            .map(|c| format!("{}{c}", self.prefix))
            .collect();
        if let Some(f) = &self.forward {
            topics.extend(MAPPING.iter().map(|c| format!("{f}/{c}/ack")));
        }
        topics
    }

    fn topics(&self) -> Vec<String> {
        let mut topics = self.command_topics();
        topics.extend(
            MAPPING
                .iter()
                .chain(&OWN_COMMANDS)
                .map(|c| format!("{}{c}/ack", self.prefix)),
        );
        if let Some(f) = &self.forward {
            topics.extend(MAPPING.iter().map(|c| format!("{f}/{c}")));
        }
        topics
    }

    fn owns(&self, topic: &str) -> bool {
        let own = topic
            .strip_prefix(&self.prefix)
            .is_some_and(|rest| !rest.is_empty() && !rest.contains('/'));
        own || self.forwarded_ack(topic).is_some()
    }

    fn on_message(
        &mut self,
        t: Timestamp,
        topic: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) -> Handled {
        // The navigation stack's answer to a forwarded request: relayed as it is.
        if let Some(command) = self.forwarded_ack(topic) {
            out.push(Publish::reply(
                format!("{}{command}/ack", self.prefix),
                payload.to_vec(),
            ));
            return Handled::Taken;
        }
        let command = topic.strip_prefix(&self.prefix).unwrap_or(topic).to_owned();
        if payload.len() > self.max_payload {
            let reason = format!(
                "payload of {} bytes exceeds {}",
                payload.len(),
                self.max_payload
            );
            return self.ack(t, &command, &Value::Null, Some((TOO_LARGE, &reason)), out);
        }
        let request: Value = match serde_json::from_slice(payload) {
            Ok(v @ Value::Object(_)) => v,
            Ok(_) => {
                let reason = "the request must be a JSON object";
                return self.ack(t, &command, &Value::Null, Some((BAD_REQUEST, reason)), out);
            }
            Err(e) => {
                let reason = format!("malformed JSON: {e}");
                return self.ack(t, &command, &Value::Null, Some((BAD_REQUEST, &reason)), out);
            }
        };
        let msg_id = request.get("msg_id").cloned().unwrap_or(Value::Null);
        if !msg_id.is_string() {
            let reason = "msg_id must be a string";
            return self.ack(t, &command, &msg_id, Some((BAD_REQUEST, reason)), out);
        }
        match command.as_str() {
            "goal" => match parse_goal(&request["data"]) {
                Err(reason) => self.ack(t, &command, &msg_id, Some((BAD_REQUEST, &reason)), out),
                Ok(goal) => {
                    self.next_goal += 1;
                    let tag = MotionTag {
                        owner: "device",
                        id: self.next_goal,
                    };
                    match core.command(Command::Goal {
                        goal,
                        tag: Some(tag),
                    }) {
                        // Answered when it ends, as the spec's acks are.
                        Ok(()) => {
                            if self.goals.len() == MAX_PENDING_GOALS {
                                self.goals.pop_front();
                            }
                            self.goals.push_back((tag.id, msg_id));
                            Handled::Taken
                        }
                        Err(e) => {
                            let reason = e.to_string();
                            self.ack(t, &command, &msg_id, Some((FAILED, &reason)), out)
                        }
                    }
                }
            },
            "estop" => {
                let failure = match request["data"].get("engaged").and_then(Value::as_bool) {
                    None => Some((BAD_REQUEST, "data needs a boolean engaged".to_owned())),
                    Some(engaged) => core
                        .command(Command::EmergencyStop { engaged })
                        .err()
                        .map(|e| (FAILED, e.to_string())),
                };
                let failure = failure.as_ref().map(|(c, m)| (*c, m.as_str()));
                self.ack(t, &command, &msg_id, failure, out)
            }
            "reset" => {
                let failure = core
                    .command(Command::Reset)
                    .err()
                    .map(|e| (FAILED, e.to_string()));
                let failure = failure.as_ref().map(|(c, m)| (*c, m.as_str()));
                self.ack(t, &command, &msg_id, failure, out)
            }
            c if MAPPING.contains(&c) => match &self.forward {
                Some(f) => {
                    out.push(Publish::reply(format!("{f}/{c}"), payload.to_vec()));
                    Handled::Taken
                }
                None => self.ack(
                    t,
                    &command,
                    &msg_id,
                    Some((
                        NOT_AVAILABLE,
                        "not available: mapping belongs to the navigation stack, and no \
                         mqtt.device.mapping_forward is configured",
                    )),
                    out,
                ),
            },
            _ => {
                let reason = format!("unknown command {command:?}");
                self.ack(t, &command, &msg_id, Some((UNKNOWN, &reason)), out)
            }
        }
    }

    fn on_status(
        &mut self,
        _status: &VehicleStatus,
        _core: &mut dyn CoreAccess,
        _out: &mut Vec<Publish>,
    ) {
    }

    fn on_motion_ended(&mut self, t: Timestamp, result: &MotionResult, out: &mut Vec<Publish>) {
        let Some(tag) = result.tag else {
            return;
        };
        let Some(at) = self.goals.iter().position(|(id, _)| *id == tag.id) else {
            return;
        };
        let Some((_, msg_id)) = self.goals.remove(at) else {
            return;
        };
        let message = result.to_string();
        let failure = match &result.outcome {
            Outcome::Succeeded => None,
            Outcome::Cancelled(_) => Some((CANCELLED, message.as_str())),
            Outcome::TimedOut | Outcome::Aborted(_) => Some((FAILED, message.as_str())),
        };
        self.publish_ack(t, "goal", &msg_id, failure, out);
    }
}

/// A goal's `data`: `x`, `y` in the map frame (m, east and north of the datum) and `z`, the
/// z of the heading's quaternion (sin(yaw / 2), so 0.7071 is 90°), with `w` (cos(yaw / 2))
/// optional. A `z` outside −1..1 is refused, not read as radians.
fn parse_goal(data: &Value) -> Result<GoalPose, String> {
    let number = |k: &str| {
        data.get(k)
            .and_then(Value::as_f64)
            .filter(|v| v.is_finite())
    };
    let (Some(x), Some(y), Some(z)) = (number("x"), number("y"), number("z")) else {
        return Err(
            "data needs finite numbers x, y (m, map frame) and z (the heading's \
                    quaternion z)"
                .to_owned(),
        );
    };
    let yaw = match data.get("w") {
        None => {
            if !(-1.0..=1.0).contains(&z) {
                return Err(format!(
                    "z {z} is outside -1..1: z is the quaternion z of the heading \
                     (sin(yaw/2); 0.7071 is 90°), not an angle"
                ));
            }
            2.0 * z.asin()
        }
        Some(w) => {
            let Some(w) = w.as_f64().filter(|w| w.is_finite()) else {
                return Err("w must be a finite number".to_owned());
            };
            if (z.hypot(w) - 1.0).abs() > 0.01 {
                return Err(format!(
                    "z {z} and w {w} are not a unit quaternion of a heading"
                ));
            }
            2.0 * z.atan2(w)
        }
    };
    Ok(GoalPose {
        x,
        y,
        yaw: wrap(yaw),
    })
}

impl DeviceDialect {
    /// The mapping command whose forwarded ack arrives on `topic`.
    fn forwarded_ack(&self, topic: &str) -> Option<&'static str> {
        let rest = topic
            .strip_prefix(self.forward.as_deref()?)?
            .strip_prefix('/')?;
        let command = rest.strip_suffix("/ack")?;
        MAPPING.into_iter().find(|c| *c == command)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::chassis::CommandRejected;

    struct NoCore;
    impl CoreAccess for NoCore {
        fn pose_report(&self) -> crate::vehicle::PoseReport {
            crate::vehicle::PoseReport::default()
        }

        fn command(&mut self, _: Command) -> Result<(), CommandRejected> {
            Ok(())
        }
    }

    fn send(d: &mut DeviceDialect, topic: &str, payload: &str) -> Vec<Publish> {
        let mut out = Vec::new();
        let t = Timestamp::from_micros(1_757_403_776_000_000);
        assert!(d.owns(topic), "{topic}");
        d.on_message(t, topic, payload.as_bytes(), &mut NoCore, &mut out);
        out
    }

    #[test]
    fn mapping_is_forwarded_and_its_acks_relayed_when_configured() {
        let mut d = DeviceDialect::new("SN1", Some("nav/SN1".into()), 1 << 20);
        assert_eq!(
            d.subscriptions(),
            [
                "device/SN1/+",
                "nav/SN1/start_mapping/ack",
                "nav/SN1/stop_mapping/ack",
                "nav/SN1/use_map/ack"
            ]
        );
        let request = r#"{"msg_id":"uuid-789","timestamp":1757403776,"data":{}}"#;
        let out = send(&mut d, "device/SN1/start_mapping", request);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].topic, "nav/SN1/start_mapping");
        assert_eq!(out[0].payload, request.as_bytes());
        let ack = r#"{"msg_id":"uuid-789","timestamp":1757403777,"success":true,"data":{}}"#;
        let out = send(&mut d, "nav/SN1/start_mapping/ack", ack);
        assert_eq!(out[0].topic, "device/SN1/start_mapping/ack");
        assert_eq!(out[0].payload, ack.as_bytes());
        // Its own ack topics are not commands.
        assert!(!d.owns("device/SN1/start_mapping/ack"));
    }

    /// The safety commands are command topics like the goal, with their acks: the link
    /// rate-limits them apart from invented topics, and the broker reserves them.
    #[test]
    fn estop_and_reset_are_command_topics() {
        let d = DeviceDialect::new("SN1", None, 1 << 20);
        let commands = d.command_topics();
        for c in ["goal", "estop", "reset", "start_mapping"] {
            assert!(
                commands.contains(&format!("device/SN1/{c}")),
                "{c}: {commands:?}"
            );
            assert!(d.topics().contains(&format!("device/SN1/{c}/ack")), "{c}");
        }
    }

    /// Every error ack is a refusal the run counts; a taken goal or a forward is not.
    #[test]
    fn error_acks_are_refusals() {
        let mut d = DeviceDialect::new("SN1", None, 1 << 20);
        let t = Timestamp::from_micros(1_757_403_776_000_000);
        let mut handled = |topic: &str, payload: &str| {
            d.on_message(t, topic, payload.as_bytes(), &mut NoCore, &mut Vec::new())
        };
        let goal = r#"{"msg_id":"a","timestamp":1757403776,"data":{"x":1,"y":2,"z":0}}"#;
        assert_eq!(handled("device/SN1/goal", goal), Handled::Taken);
        for (topic, payload) in [
            ("device/SN1/goal", r#"{"data":{"x":1,"y":2,"z":0}}"#),
            ("device/SN1/goal", "{"),
            ("device/SN1/goal", r#"{"msg_id":"b","data":{"x":1}}"#),
            ("device/SN1/start_mapping", r#"{"msg_id":"c","data":{}}"#),
            ("device/SN1/fly", r#"{"msg_id":"d","data":{}}"#),
        ] {
            assert_eq!(handled(topic, payload), Handled::Refused, "{payload}");
        }
    }

    #[test]
    fn goal_headings_are_quaternion_z_and_nothing_else() {
        let yaw = |data: &str| parse_goal(&serde_json::from_str(data).unwrap()).map(|g| g.yaw);
        let close = |r: Result<f64, String>, deg: f64| {
            let got = r.unwrap();
            assert!(
                wrap(got - deg.to_radians()).abs() < 1e-4,
                "{}° for {deg}°",
                got.to_degrees()
            );
        };
        close(yaw(r#"{"x":1.23,"y":4.56,"z":0.7071}"#), 90.0);
        close(yaw(r#"{"x":0,"y":0,"z":0}"#), 0.0);
        close(yaw(r#"{"x":0,"y":0,"z":-1}"#), -180.0);
        close(
            yaw(r#"{"x":0,"y":0,"z":0.7071,"w":-0.7071}"#),
            270.0 - 360.0,
        );
        for bad in [
            r#"{"x":0,"y":0,"z":1.57}"#,
            r#"{"x":0,"y":0,"z":0.5,"w":0.5}"#,
            r#"{"x":0,"y":0}"#,
            r#"{"x":"1","y":0,"z":0}"#,
            r#"{"x":0,"y":0,"z":0,"w":"1"}"#,
        ] {
            assert!(yaw(bad).is_err(), "{bad}");
        }
        let e = yaw(r#"{"x":0,"y":0,"z":1.57}"#).unwrap_err();
        assert!(e.contains("not an angle"), "{e}");
    }

    #[test]
    fn without_a_navigation_stack_mapping_is_refused_with_3003() {
        let mut d = DeviceDialect::new("SN1", None, 1 << 20);
        let out = send(
            &mut d,
            "device/SN1/use_map",
            r#"{"msg_id":"m1","timestamp":1,"data":{"filename":"uuid-3301.yaml"}}"#,
        );
        let ack: Value = serde_json::from_slice(&out[0].payload).unwrap();
        assert_eq!(out[0].topic, "device/SN1/use_map/ack");
        assert_eq!(ack["success"], false);
        assert_eq!(ack["code"], NOT_AVAILABLE);
        assert_eq!(ack["msg_id"], "m1");
        assert_eq!(ack["timestamp"], 1_757_403_776);
    }
}
