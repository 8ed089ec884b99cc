//! Dialect `rtk` (rtk-mqtt-protocol.md, bare topics): `base_status` at 10 Hz, the
//! `mqtt_control` commands, their answers on `feedback`, and `trajectory_data`.
//!
//! Answers use the protocol's exact `cmd` strings (`<command>_success`, and its spelling
//! `<command>_failse`), with an added `message` key giving the reason of a failure. A message
//! whose command cannot be read is answered `mqtt_control_failse`; an unknown command
//! `<cmd>_failse`. `get_all_trajectory` answers with `trajectory_data` (an array, possibly
//! empty); the protocol has no success feedback for it.
//!
//! `start_task` follows the saved trajectory `name` from its point `id` (0-based index into
//! `data`) at up to `speed` m/s; `start_task_success` means the task started, and its end
//! shows in `base_status`'s `nav.status` (NAV_SUCCESS or NAV_ERROR, the reason in the log).
//! The points' latitude and longitude rule: they are placed in the map frame of the datum in
//! force when the task starts, so the path stays where it was recorded on the ground after
//! `init_rtk_data` or SET_LNG_LAT moved the frame; the stored `x`, `y`, `yaw` and `angle` are
//! kept as recorded and not driven on. `cancel_task` ends the motion under way and brings the
//! vehicle to rest (done when none is under way); it is also rtk's deliberate act that
//! re-arms a latched stop once its causes have cleared (rtk has no reset).

pub mod status;

use serde::Serialize;
use serde_json::Value;

use super::trajectory::{self, Trajectory, TrajectoryError, TrajectoryStore};
pub use status::BaseStatus;

use super::log_budget::{self, LogBudget, SharedBudget};
use super::mqtt::{CoreAccess, Dialect, Handled, Publish};
use crate::config::mqtt::packet_limit;
use crate::control::MotionTag;
use crate::time::Timestamp;
use crate::vehicle::chassis::CommandRejected;
use crate::vehicle::safety::Refusal;
use crate::vehicle::{Command, PathPoints, PathRequest, VehicleStatus};

/// Status topic.
pub const BASE_STATUS: &str = "base_status";
/// Command topic.
pub const MQTT_CONTROL: &str = "mqtt_control";
/// Answers.
pub const FEEDBACK: &str = "feedback";
/// Trajectory listing.
pub const TRAJECTORY_DATA: &str = "trajectory_data";

#[derive(Serialize)]
struct Feedback<'a> {
    cmd: String,
    cmd_type: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    message: Option<&'a str>,
}

/// The `rtk` dialect.
pub struct RtkDialect {
    store: Box<dyn TrajectoryStore>,
    max_payload: usize,
    /// The time of the message or status tick being handled (for the log's budget).
    now: Timestamp,
}

impl RtkDialect {
    /// A dialect keeping trajectories in `store`, refusing messages above `max_payload`.
    pub fn new(store: Box<dyn TrajectoryStore>, max_payload: usize) -> Self {
        Self {
            store,
            max_payload,
            now: Timestamp::default(),
        }
    }

    /// Replaces the trajectory store.
    pub fn set_store(&mut self, store: Box<dyn TrajectoryStore>) {
        self.store = store;
    }

    fn feedback(&self, cmd: &str, result: Result<(), String>, out: &mut Vec<Publish>) -> Handled {
        let (suffix, message) = match &result {
            Ok(()) => ("success", None),
            Err(m) => ("failse", Some(m.as_str())),
        };
        let body = Feedback {
            cmd: format!("{cmd}_{suffix}"),
            cmd_type: "feedback",
            message,
        };
        let json = serde_json::to_string(&body).unwrap_or_default();
        if let Err(reason) = &result {
            static REFUSALS: SharedBudget = SharedBudget::new(LogBudget::new());
            if let Some(left_out) = log_budget::allow(&REFUSALS, self.now) {
                tracing::warn!(dialect = "rtk", %cmd, %reason, refusals_not_logged = left_out, "command refused");
            }
        }
        out.push(Publish::reply(FEEDBACK, json));
        if result.is_ok() {
            Handled::Taken
        } else {
            Handled::Refused
        }
    }

    fn control(
        &mut self,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) -> Handled {
        if payload.len() > self.max_payload {
            let reason = format!(
                "payload of {} bytes exceeds {}",
                payload.len(),
                self.max_payload
            );
            return self.feedback(MQTT_CONTROL, Err(reason), out);
        }
        let message: Value = match serde_json::from_slice(payload) {
            Ok(v) => v,
            Err(e) => {
                return self.feedback(MQTT_CONTROL, Err(format!("malformed JSON: {e}")), out);
            }
        };
        let Some(cmd) = message.get("cmd").and_then(Value::as_str) else {
            return self.feedback(
                MQTT_CONTROL,
                Err("no \"cmd\" string in the message".into()),
                out,
            );
        };
        let cmd = cmd.to_owned();
        let expected_type = match cmd.as_str() {
            "get_all_trajectory"
            | "save_trajectory"
            | "delete_trajectory"
            | "delete_all_trajectory" => "trajectory_control",
            "start_task" | "cancel_task" | "init_rtk_data" => "task_control",
            _ => {
                let reason = format!("unknown command {cmd:?}");
                return self.feedback(&safe_cmd(&cmd), Err(reason), out);
            }
        };
        match message.get("cmd_type").and_then(Value::as_str) {
            Some(t) if t == expected_type => {}
            other => {
                let reason = format!(
                    "cmd_type must be {expected_type:?} for {cmd}, not {}",
                    other.map_or("absent".to_owned(), |t| format!("{t:?}"))
                );
                return self.feedback(&cmd, Err(reason), out);
            }
        }
        match cmd.as_str() {
            "get_all_trajectory" => match self.store.all() {
                Ok(all) => {
                    let json = serde_json::to_string(&all).unwrap_or_default();
                    let answer = Publish::reply(TRAJECTORY_DATA, json);
                    let limit = packet_limit(self.max_payload);
                    if answer.packet_len() > limit {
                        let points: usize = all.iter().map(|t| t.data.len()).sum();
                        let reason = format!(
                            "the {} trajectories stored ({points} points) make a trajectory_data of {} bytes, more than an MQTT packet may carry here ({limit} bytes: 4 × mqtt.max_payload); raise mqtt.max_payload, or delete trajectories",
                            all.len(),
                            answer.payload.len()
                        );
                        return self.feedback(&cmd, Err(reason), out);
                    }
                    out.push(answer);
                    Handled::Taken
                }
                Err(e) => self.feedback(&cmd, Err(e.to_string()), out),
            },
            "save_trajectory" => {
                let result = message
                    .get("data")
                    .ok_or_else(|| "no \"data\" object".to_owned())
                    .and_then(|d| {
                        Trajectory::deserialize_value(d).map_err(|e| format!("data: {e}"))
                    })
                    .and_then(|mut t| {
                        t.name = trajectory::canonical_name(&t.name).map_err(|e| e.to_string())?;
                        t.check().map_err(|e| e.to_string())?;
                        self.store.save(&t).map_err(|e| e.to_string())
                    });
                self.feedback(&cmd, result, out)
            }
            "delete_trajectory" => {
                let result = match message.get("name").and_then(Value::as_str) {
                    None => Err("no \"name\" string".to_owned()),
                    Some(name) => trajectory::canonical_name(name)
                        .and_then(|name| self.store.delete(&name))
                        .map_err(|e: TrajectoryError| e.to_string()),
                };
                self.feedback(&cmd, result, out)
            }
            "delete_all_trajectory" => {
                let result = self
                    .store
                    .delete_all()
                    .map(|_| ())
                    .map_err(|e| e.to_string());
                self.feedback(&cmd, result, out)
            }
            "start_task" => {
                let result = self.start_task(&message).and_then(|request| {
                    core.command(Command::FollowPath {
                        path: std::sync::Arc::new(request),
                        tag: Some(MotionTag {
                            owner: "rtk",
                            id: 0,
                        }),
                    })
                    .map_err(in_rtk_words)
                });
                self.feedback(&cmd, result, out)
            }
            "cancel_task" => {
                let result = match core.command(Command::CancelMotion) {
                    // Without drives no task can run: there is nothing to cancel.
                    Ok(()) | Err(CommandRejected::NoDrives) => Ok(()),
                    Err(e) => Err(e.to_string()),
                };
                // rtk has no velocity command and no reset: its deliberate stop is the act
                // that re-arms a latched stop whose causes have cleared. While one holds,
                // the task is still cancelled; the next start_task's refusal names the cause.
                if result.is_ok() {
                    let _ = core.command(Command::Reset);
                }
                self.feedback(&cmd, result, out)
            }
            _ => {
                let result = core
                    .command(Command::ZeroLocalFrame)
                    .map_err(|e| e.to_string());
                self.feedback(&cmd, result, out)
            }
        }
    }
}

/// A refusal as an rtk client can act on it: a latched stop is re-armed by `cancel_task`, as
/// rtk has neither a velocity command nor a reset.
fn in_rtk_words(refusal: CommandRejected) -> String {
    match refusal {
        CommandRejected::Safety(Refusal::Latched { reason, first }) => format!(
            "stopped ({reason}): {}send cancel_task to re-arm, then start_task again",
            first.map(|f| format!("{f}, then ")).unwrap_or_default()
        ),
        other => other.to_string(),
    }
}

impl RtkDialect {
    /// The path of a `start_task` message: the named trajectory from point `id` on.
    fn start_task(&mut self, message: &Value) -> Result<PathRequest, String> {
        let name = message
            .get("name")
            .and_then(Value::as_str)
            .ok_or("no \"name\" string")?;
        let id = match message.get("id") {
            None => 0,
            Some(v) => v
                .as_u64()
                .and_then(|id| usize::try_from(id).ok())
                .ok_or("\"id\" must be a point index (a whole number from 0)")?,
        };
        let speed = message
            .get("speed")
            .and_then(Value::as_f64)
            .ok_or("no \"speed\" number (m/s)")
            .map_err(str::to_owned)
            .and_then(crate::api::task_speed)?;
        let name = &trajectory::canonical_name(name).map_err(|e| e.to_string())?;
        let trajectory = self.store.get(name).map_err(|e| e.to_string())?;
        if id >= trajectory.data.len() {
            return Err(format!(
                "trajectory {name:?} has {} points; id {id} is past its end (ids count from 0)",
                trajectory.data.len()
            ));
        }
        Ok(PathRequest {
            points: PathPoints::Geodetic(
                trajectory.data[id..]
                    .iter()
                    .map(|p| (p.latitude, p.longitude))
                    .collect(),
            ),
            speed,
        })
    }
}

/// A command name fit to echo back in a feedback `cmd`: printable and short.
fn safe_cmd(cmd: &str) -> String {
    cmd.chars()
        .filter(|c| c.is_ascii_alphanumeric() || *c == '_')
        .take(64)
        .collect()
}

impl Trajectory {
    fn deserialize_value(v: &Value) -> Result<Self, serde_json::Error> {
        serde::Deserialize::deserialize(v)
    }
}

/// The dialect when `[mqtt.rtk]` is configured; it takes the trajectory store.
pub fn from_setup(setup: &mut super::mqtt::DialectSetup<'_>) -> Option<Box<dyn Dialect>> {
    setup.mqtt.rtk.as_ref()?;
    let store = setup
        .trajectories
        .take()
        .unwrap_or_else(|| Box::new(trajectory::MemoryStore::default()));
    Some(Box::new(RtkDialect::new(store, setup.mqtt.max_payload)))
}

impl Dialect for RtkDialect {
    fn name(&self) -> &'static str {
        "rtk"
    }

    fn subscriptions(&self) -> Vec<String> {
        vec![MQTT_CONTROL.to_owned()]
    }

    fn command_topics(&self) -> Vec<String> {
        vec![MQTT_CONTROL.to_owned()]
    }

    fn topics(&self) -> Vec<String> {
        [MQTT_CONTROL, FEEDBACK, TRAJECTORY_DATA, BASE_STATUS]
            .map(str::to_owned)
            .to_vec()
    }

    fn owns(&self, topic: &str) -> bool {
        topic == MQTT_CONTROL
    }

    fn on_message(
        &mut self,
        t: Timestamp,
        _topic: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) -> Handled {
        self.now = t;
        self.control(payload, core, out)
    }

    fn on_status(
        &mut self,
        status: &VehicleStatus,
        _core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) {
        self.now = status.time;
        out.push(Publish::telemetry(
            BASE_STATUS,
            BaseStatus::from_status(status).to_json(),
        ));
        // A change answered as done that did not reach the folder: the client hears it
        // failed, on the channel it asked on.
        for failed in self.store.failed_writes() {
            let reason = format!(
                "{}: kept in memory only, the trajectory folder's write failed ({}); it is lost \
                 at the next start",
                failed.what, failed.reason
            );
            self.feedback(failed.command, Err(reason), out);
        }
    }
}
