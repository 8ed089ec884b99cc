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
//! Three commands extend the spec in its own shape: `estop` (`data: {"engaged": bool}`)
//! engages or releases the software emergency stop, `reset` (`data: {}`) re-arms a latched
//! stop once its cause has cleared, and `cancel` (`data: {}`) ends the goal under way without
//! latching; a refusal answers 3002 with the reason.
//!
//! Each command is a file of `commands/`, found in `commands::COMMANDS` by its name; the
//! request's body and `msg_id` are checked once here, and failures are [`DeviceError`]s whose
//! codes are chosen by matching.

mod commands;
mod error;

use serde::Serialize;
use serde_json::Value;

use super::log_budget::{self, LogBudget, SharedBudget};
use super::mqtt::{CoreAccess, Dialect, Handled, Publish};
use super::request_body;
use crate::control::MotionResult;
use crate::time::Timestamp;
use crate::vehicle::VehicleStatus;
use commands::{Answered, Context, Goals};
pub use error::{BAD_REQUEST, CANCELLED, DeviceError, FAILED, NOT_AVAILABLE, TOO_LARGE, UNKNOWN};

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

/// The `device` dialect.
pub struct DeviceDialect {
    prefix: String,
    forward: Option<String>,
    max_payload: usize,
    goals: Goals,
}

impl DeviceDialect {
    /// The dialect of `serial_number`; mapping requests go to `forward` when set.
    pub fn new(serial_number: &str, forward: Option<String>, max_payload: usize) -> Self {
        Self {
            prefix: format!("device/{serial_number}/"),
            forward,
            max_payload,
            goals: Goals::default(),
        }
    }

    /// Answers a request to `command` now: done, or why not (logged within a budget).
    fn ack(
        &self,
        t: Timestamp,
        command: &str,
        msg_id: &Value,
        outcome: Result<(), &DeviceError>,
        out: &mut Vec<Publish>,
    ) -> Handled {
        if let Err(e) = outcome {
            static REFUSALS: SharedBudget = SharedBudget::new(LogBudget::new());
            if let Some(left_out) = log_budget::allow(&REFUSALS, t) {
                tracing::warn!(dialect = "device", %command, code = e.code(), reason = %e, refusals_not_logged = left_out, "request refused");
            }
        }
        self.publish_ack(t, command, msg_id, outcome, out);
        if outcome.is_ok() {
            Handled::Taken
        } else {
            Handled::Refused
        }
    }

    /// Publishes an ack (a goal's end, which the core has logged already).
    fn publish_ack(
        &self,
        t: Timestamp,
        command: &str,
        msg_id: &Value,
        outcome: Result<(), &DeviceError>,
        out: &mut Vec<Publish>,
    ) {
        let message = outcome.err().map(ToString::to_string);
        let body = Ack {
            msg_id,
            timestamp: t.as_micros() / 1_000_000,
            success: outcome.is_ok(),
            code: outcome.err().map(DeviceError::code),
            message: message.as_deref(),
        };
        let json = serde_json::to_string(&body).unwrap_or_default();
        out.push(Publish::reply(
            format!("{}{command}/ack", self.prefix),
            json,
        ));
    }

    /// The mapping command whose forwarded ack arrives on `topic`.
    fn forwarded_ack(&self, topic: &str) -> Option<&'static str> {
        let rest = topic
            .strip_prefix(self.forward.as_deref()?)?
            .strip_prefix('/')?;
        let command = rest.strip_suffix("/ack")?;
        commands::mapping().find(|c| *c == command)
    }

    /// The topics of the commands chassisd carries out (`own`) or passes on, under the
    /// dialect's prefix and with `suffix` after them.
    fn own_topics(&self, own: bool, suffix: &str) -> impl Iterator<Item = String> {
        commands::COMMANDS
            .iter()
            .filter(move |c| c.own == own)
            .map(move |c| format!("{}{}{suffix}", self.prefix, c.name))
    }

    /// The navigation stack's topics for the mapping requests, with `suffix`.
    fn forwarded_topics(&self, suffix: &str) -> Vec<String> {
        let Some(f) = &self.forward else {
            return Vec::new();
        };
        commands::mapping()
            .map(|c| format!("{f}/{c}{suffix}"))
            .collect()
    }
}

/// The dialect when `[mqtt.device]` is configured.
pub fn from_setup(setup: &mut super::mqtt::DialectSetup<'_>) -> Option<Box<dyn Dialect>> {
    let d = setup.mqtt.device.as_ref()?;
    Some(Box::new(DeviceDialect::new(
        &d.serial_number,
        d.mapping_forward.clone(),
        setup
            .mqtt
            .max_payload(crate::config::mqtt::DialectName::Device),
    )))
}

impl Dialect for DeviceDialect {
    fn name(&self) -> &'static str {
        "device"
    }

    fn subscriptions(&self) -> Vec<String> {
        let mut topics = vec![format!("{}+", self.prefix)];
        topics.extend(self.forwarded_topics("/ack"));
        topics
    }

    /// Each command is a command topic: it has a rate bucket of its own (an e-stop never
    /// waits behind invented topics) and the embedded broker keeps it for chassisd's commands
    /// (no client's last will may release an e-stop).
    fn command_topics(&self) -> Vec<String> {
        let mut topics: Vec<String> = self.own_topics(false, "").collect();
        topics.extend(self.own_topics(true, ""));
        topics.extend(self.forwarded_topics("/ack"));
        topics
    }

    fn topics(&self) -> Vec<String> {
        let mut topics = self.command_topics();
        topics.extend(self.own_topics(false, "/ack"));
        topics.extend(self.own_topics(true, "/ack"));
        topics.extend(self.forwarded_topics(""));
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
        let name = topic.strip_prefix(&self.prefix).unwrap_or(topic);
        let fields = match request_body::fields(payload, self.max_payload) {
            Ok(fields) => fields,
            Err(e) => return self.ack(t, name, &Value::Null, Err(&e.into()), out),
        };
        let null = Value::Null;
        let msg_id = fields.get("msg_id").unwrap_or(&null);
        if !msg_id.is_string() {
            let e = DeviceError::bad("msg_id must be a string");
            return self.ack(t, name, msg_id, Err(&e), out);
        }
        let data = fields.get("data").unwrap_or(&null);
        let handled = commands::find(name).and_then(|command| {
            let mut cx = Context {
                core,
                command: command.name,
                msg_id,
                payload,
                goals: &mut self.goals,
                forward: self.forward.as_deref(),
                out,
            };
            (command.handle)(data, &mut cx)
        });
        match handled {
            Ok(Answered::Now) => self.ack(t, name, msg_id, Ok(()), out),
            Ok(Answered::AtItsEnd | Answered::Elsewhere) => Handled::Taken,
            Err(e) => self.ack(t, name, msg_id, Err(&e), out),
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
        if let Some((msg_id, outcome)) = self.goals.ended(result) {
            self.publish_ack(t, "goal", &msg_id, outcome.as_ref().map(|_| ()), out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::test_core::CommandLog;

    fn send(d: &mut DeviceDialect, topic: &str, payload: &str) -> Vec<Publish> {
        let mut out = Vec::new();
        let t = Timestamp::from_micros(1_757_403_776_000_000);
        assert!(d.owns(topic), "{topic}");
        d.on_message(
            t,
            topic,
            payload.as_bytes(),
            &mut CommandLog::default(),
            &mut out,
        );
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
        for c in ["goal", "estop", "reset", "cancel", "start_mapping"] {
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
            d.on_message(
                t,
                topic,
                payload.as_bytes(),
                &mut CommandLog::default(),
                &mut Vec::new(),
            )
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
