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
//!
//! Each command is a handler in `commands/`, found in `commands::COMMANDS` by its `cmd`; the
//! message's body is checked once here, and failures are [`RtkError`]s.

mod commands;
mod error;
pub mod status;

use serde::Serialize;
use serde_json::Value;

use super::log_budget::{self, LogBudget, SharedBudget};
use super::mqtt::{CoreAccess, Dialect, Handled, Publish};
use super::request_body;
use super::trajectory::{self, TrajectoryStore};
use crate::time::Timestamp;
use crate::vehicle::VehicleStatus;
use commands::{Answered, Context};
pub use error::RtkError;
pub use status::BaseStatus;

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

    /// Answers `cmd` on `feedback`: `<cmd>_success`, or `<cmd>_failse` with the reason.
    fn feedback(
        &self,
        cmd: &str,
        result: Result<(), &RtkError>,
        out: &mut Vec<Publish>,
    ) -> Handled {
        let reason = result.err().map(ToString::to_string);
        let suffix = if result.is_ok() { "success" } else { "failse" };
        let body = Feedback {
            cmd: format!("{cmd}_{suffix}"),
            cmd_type: "feedback",
            message: reason.as_deref(),
        };
        let json = serde_json::to_string(&body).unwrap_or_default();
        if let Some(reason) = &reason {
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

    /// An `mqtt_control` message: its command found, checked for its type, handled and
    /// answered (a message whose command cannot be read as `mqtt_control`).
    fn control(
        &mut self,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Publish>,
    ) -> Handled {
        let message = match request_body::fields(payload, self.max_payload) {
            Ok(message) => message,
            Err(e) => return self.feedback(MQTT_CONTROL, Err(&e.into()), out),
        };
        let Some(cmd) = message.get("cmd").and_then(Value::as_str) else {
            return self.feedback(MQTT_CONTROL, Err(&RtkError::NoCommand), out);
        };
        let command = match commands::find(cmd) {
            Ok(command) => command,
            Err(e) => return self.feedback(&safe_cmd(cmd), Err(&e), out),
        };
        let cmd_type = message.get("cmd_type").and_then(Value::as_str);
        if cmd_type != Some(command.cmd_type) {
            let e = RtkError::WrongType {
                cmd: command.cmd,
                expected: command.cmd_type,
                given: cmd_type.map_or("absent".to_owned(), |t| format!("{t:?}")),
            };
            return self.feedback(command.cmd, Err(&e), out);
        }
        let mut cx = Context {
            core,
            store: self.store.as_mut(),
            max_payload: self.max_payload,
            out,
        };
        match (command.handle)(&message, &mut cx) {
            Ok(Answered::Feedback) => self.feedback(command.cmd, Ok(()), out),
            Ok(Answered::Published) => Handled::Taken,
            Err(e) => self.feedback(command.cmd, Err(&e), out),
        }
    }
}

/// A command name fit to echo back in a feedback `cmd`: printable and short.
fn safe_cmd(cmd: &str) -> String {
    cmd.chars()
        .filter(|c| c.is_ascii_alphanumeric() || *c == '_')
        .take(64)
        .collect()
}

/// The dialect when `[mqtt.rtk]` is configured; it takes the trajectory store.
pub fn from_setup(setup: &mut super::mqtt::DialectSetup<'_>) -> Option<Box<dyn Dialect>> {
    setup.mqtt.rtk.as_ref()?;
    let store = setup
        .trajectories
        .take()
        .unwrap_or_else(|| Box::new(trajectory::MemoryStore::default()));
    Some(Box::new(RtkDialect::new(
        store,
        setup
            .mqtt
            .max_payload(crate::config::mqtt::DialectName::Rtk),
    )))
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
            let e = RtkError::NotWritten {
                what: failed.what,
                reason: failed.reason,
            };
            self.feedback(failed.command, Err(&e), out);
        }
    }
}
