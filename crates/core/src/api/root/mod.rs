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
//!
//! Each command is a file of `commands/`, found in `commands::COMMANDS` by its topic and
//! `messageType`; the request's body is checked once here, and failures are [`RootError`]s
//! whose codes are chosen by matching.

mod commands;
mod error;
mod heartbeat;
mod log_codes;
mod reports;

use serde::Serialize;
use serde_json::{Value, json};

use super::log_budget::{self, LogBudget, SharedBudget};
use super::mqtt::{CoreAccess, Dialect, Handled, Publish};
use super::request_body;
use crate::control::mission::MissionEvent;
use crate::time::Timestamp;
use crate::vehicle::VehicleStatus;
use commands::{Context, Done, Missions};
pub use error::{INVALID, NOT_AVAILABLE, OK, REFUSED, RootError, UNKNOWN_TYPE};
use heartbeat::Heartbeats;
pub use log_codes::{LOG_CODES, LogCode};
use reports::{REPORTS, Reports};

/// Whom an answer goes to: the request's topic base, messageId and messageType.
struct Request<'a> {
    base: &'a str,
    /// The spec's name for its command, once found (for the log).
    name: Option<&'static str>,
    id: &'a Value,
    kind: &'a Value,
}

#[derive(Serialize)]
struct AckData<'a> {
    code: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    message: Option<&'a str>,
}

/// The `root` dialect.
pub struct RootDialect {
    prefix: String,
    max_payload: usize,
    heartbeats: Heartbeats,
    reports: Reports,
    missions: Missions,
}

impl RootDialect {
    /// The dialect of vehicle `vehicle_id`. Heartbeats feed the core's control-link
    /// watchdog; with `heartbeat_client`, only those whose `clientId` is that.
    pub fn new(vehicle_id: &str, heartbeat_client: Option<String>, max_payload: usize) -> Self {
        Self {
            prefix: format!("/root/{vehicle_id}/"),
            max_payload,
            heartbeats: Heartbeats::new(heartbeat_client),
            reports: Reports::default(),
            missions: Missions::default(),
        }
    }

    fn topic(&self, rest: &str) -> String {
        format!("{}{rest}", self.prefix)
    }

    /// Publishes the answer on `{base}/{suffix}`: done, or the failure's code and reason.
    fn answer(
        &self,
        t: Timestamp,
        to: &Request<'_>,
        suffix: &str,
        outcome: Result<(), &RootError>,
        out: &mut Vec<Publish>,
    ) -> Handled {
        let reason = outcome.err().map(ToString::to_string);
        let code = outcome.err().map_or(OK, RootError::code);
        if let Some(reason) = &reason {
            static REFUSALS: SharedBudget = SharedBudget::new(LogBudget::new());
            if let Some(left_out) = log_budget::allow(&REFUSALS, t) {
                tracing::warn!(dialect = "root", topic = %to.base, command = to.name.unwrap_or("?"), code, %reason, refusals_not_logged = left_out, "request refused");
            }
        }
        let body = json!({
            "messageId": to.id,
            "timestamp": timestamp(t),
            "messageType": to.kind,
            "data": AckData { code, message: reason.as_deref() },
        });
        out.push(Publish::reply(
            self.topic(&format!("{}/{suffix}", to.base)),
            body.to_string(),
        ));
        if outcome.is_ok() {
            Handled::Taken
        } else {
            Handled::Refused
        }
    }

    /// A `.../set` message on `base` (e.g. `cmd/navigation`): its command found and handled,
    /// and answered.
    fn set(
        &mut self,
        t: Timestamp,
        base: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) -> Handled {
        let null = Value::Null;
        let fields = match request_body::fields(payload, self.max_payload) {
            Ok(fields) => fields,
            Err(e) => {
                let unknown = Request {
                    base,
                    name: None,
                    id: &null,
                    kind: &null,
                };
                return self.answer(t, &unknown, "ack", Err(&e.into()), out);
            }
        };
        let mut to = Request {
            base,
            name: None,
            id: fields.get("messageId").unwrap_or(&null),
            kind: fields.get("messageType").unwrap_or(&null),
        };
        let data = fields.get("data").unwrap_or(&null);
        let mut cx = Context {
            core,
            message_id: to.id,
            missions: &mut self.missions,
        };
        let done = to
            .kind
            .as_u64()
            .ok_or_else(|| RootError::invalid("messageType must be a number"))
            .and_then(|kind| commands::find(base, kind))
            .and_then(|command| {
                to.name = Some(command.name);
                (command.handle)(data, &mut cx)
            });
        match done {
            Ok(done) => {
                self.answer(t, &to, "ack", Ok(()), out);
                if done == Done::Finished {
                    self.answer(t, &to, "notify", Ok(()), out);
                }
                Handled::Taken
            }
            Err(e) => self.answer(t, &to, "ack", Err(&e), out),
        }
    }
}

/// The `{base}/set` topics the dialect acts on (others get an "unknown" answer).
fn set_bases() -> Vec<&'static str> {
    let mut bases = commands::bases();
    bases.push("heartbeat");
    bases
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
        setup
            .mqtt
            .max_payload(crate::config::mqtt::DialectName::Root),
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
        let Some((message_id, data)) = self.missions.progress(id, event) else {
            return;
        };
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
        set_bases()
            .iter()
            .map(|base| self.topic(&format!("{base}/set")))
            .collect()
    }

    fn topics(&self) -> Vec<String> {
        let answers = set_bases().into_iter().flat_map(|base| {
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
            if self.heartbeats.beat(payload, self.max_payload, core) {
                out.push(Publish::reply(
                    self.topic("heartbeat/notify"),
                    json!({ "timestamp": timestamp(t) }).to_string(),
                ));
            }
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
        self.reports.on_status(&self.prefix, status, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::test_core::CommandLog as FakeCore;
    use crate::vehicle::Command;
    use crate::vehicle::chassis::CommandRejected;

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
        core.refuse_next = Some(CommandRejected::NotReady("left".into()));
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
        core.refuse_next = Some(CommandRejected::NotFinite);
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
