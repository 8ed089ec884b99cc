//! The one shape every protocol takes in the engine. An adapter owns a command source of the
//! recordings (`mqtt`, `stdin`, `ros1`, `websocket`): it turns that source's requests into
//! typed core commands, and the core's answers, status ticks, motion ends and mission
//! progress into its protocol's replies. Adapters are sans-IO like the core; the runtime's
//! links only move bytes between their sockets and the engine, which resolves each source
//! to its adapter once, when it is built.
//!
//! A request that waits for its answer carries an id of its link's choosing, recorded with
//! it; the answer carries the same id back, so a link pairs answers with requests by id,
//! never by order.

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::api::publish::Publish;
use crate::control::mission::MissionEvent;
use crate::control::{MotionResult, MotionTag};
use crate::time::Timestamp;
use crate::vehicle::chassis::CommandRejected;
use crate::vehicle::{Command, PoseReport, VehicleStatus};

/// The core, as an adapter sees it: commands in, acceptance or a reason out; and what a
/// query reads.
pub trait CoreAccess {
    /// The `odom` pose and the map pose now.
    fn pose_report(&self) -> PoseReport;
    /// Hands `command` to the core at the current time.
    fn command(&mut self, command: Command) -> Result<(), CommandRejected>;
}

/// What an adapter sends out.
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// A message for the MQTT broker.
    Publish(Publish),
    /// The answer to one request.
    Answer(Answer),
}

/// The answer to one request: accepted, or why not.
#[derive(Debug, Clone, PartialEq)]
pub struct Answer {
    /// The request's topic, as recorded.
    pub topic: String,
    /// The request's id, when its link waits for the answer.
    pub request: Option<u64>,
    /// Accepted, or the reason it was refused.
    pub result: Result<(), String>,
    /// What a query asked for (a position, what the build is), as JSON; `None` for a
    /// command.
    pub data: Option<serde_json::Value>,
}

/// What became of a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Handled {
    /// Taken; any refusal went out in the protocol's own reply.
    Taken,
    /// Refused, and answered so.
    Refused,
    /// Not the adapter's to take (a topic none of its parts owns).
    NotOwned,
    /// A query answered: it read the vehicle and changed nothing, so it is no operator's
    /// command.
    Answered,
}

/// One protocol, as the engine drives it.
pub trait Adapter: Send {
    /// The command source it owns in recordings and the engine.
    fn source(&self) -> &'static str;
    /// A request of its source at `t`: decoded, handed to `core`, answered into `out`.
    fn on_request(
        &mut self,
        t: Timestamp,
        topic: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Reply>,
    ) -> Handled;
    /// A status tick: what is due, and acting on what the time says.
    fn on_status(
        &mut self,
        _status: &VehicleStatus,
        _core: &mut dyn CoreAccess,
        _out: &mut Vec<Reply>,
    ) {
    }
    /// A motion ended at `t` (whoever tagged it answers).
    fn on_motion_ended(&mut self, _t: Timestamp, _result: &MotionResult, _out: &mut Vec<Reply>) {}
    /// A mission made progress at `t` (whoever tagged it answers).
    fn on_mission_event(
        &mut self,
        _t: Timestamp,
        _tag: Option<MotionTag>,
        _event: &MissionEvent,
        _out: &mut Vec<Reply>,
    ) {
    }
}

/// A protocol's decoder: a recorded request's id (when its link waits for the answer) and
/// its core command, or why it is refused.
pub type Decode = fn(&str, &[u8]) -> (Option<u64>, Result<Command, String>);

/// The adapter of a protocol that only asks (it publishes nothing through the engine): its
/// source and its decoder; each request is answered with its id.
#[derive(Debug, Clone, Copy)]
pub struct RequestAdapter {
    source: &'static str,
    decode: Decode,
}

impl RequestAdapter {
    /// The adapter of `source`, whose requests `decode` reads.
    pub const fn new(source: &'static str, decode: Decode) -> Self {
        Self { source, decode }
    }
}

impl Adapter for RequestAdapter {
    fn source(&self) -> &'static str {
        self.source
    }

    fn on_request(
        &mut self,
        _t: Timestamp,
        topic: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Reply>,
    ) -> Handled {
        let (id, command) = (self.decode)(topic, payload);
        answer(topic, id, command, core, out)
    }
}

/// A ROS request as recorded: the message (rosbridge's JSON of its fields) and, when its
/// link waits for the answer, an id.
#[derive(Debug, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Envelope<T> {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    id: Option<u64>,
    msg: T,
}

/// The payload that records a ROS request: `{"id": ID, "msg": MESSAGE}`.
pub fn encode_request<T: Serialize>(id: Option<u64>, msg: &T) -> bytes::Bytes {
    // Serialising plain message structs cannot fail; an empty payload would be refused.
    serde_json::to_vec(&Envelope { id, msg })
        .unwrap_or_default()
        .into()
}

/// A recorded ROS request's id and message; `topic` names it in a refusal. A message that
/// does not decode keeps its id, so its link learns why.
pub fn decode_request<T: DeserializeOwned>(
    topic: &str,
    payload: &[u8],
) -> (Option<u64>, Result<T, String>) {
    if payload.len() > MAX_REQUEST {
        let why = format!(
            "{topic}: payload of {} bytes exceeds {MAX_REQUEST}",
            payload.len()
        );
        return (None, Err(why));
    }
    match serde_json::from_slice::<Envelope<serde_json::Value>>(payload) {
        Ok(e) => (
            e.id,
            serde_json::from_value(e.msg).map_err(|e| format!("{topic}: {e}")),
        ),
        Err(e) => (None, Err(format!("{topic}: {e}"))),
    }
}

/// Largest recorded ROS request, bytes: a pose or a twist is some 300, a `/set_shape` or
/// `/set_region` zone edit of some thousand points needs the room (the zones' own caps
/// apply after); rosbridge's message limit, so one size holds on both links.
pub const MAX_REQUEST: usize = 256 * 1024;

/// The answer a request gets from `core`, with the request's id.
pub fn answer(
    topic: &str,
    request: Option<u64>,
    command: Result<Command, String>,
    core: &mut dyn CoreAccess,
    out: &mut Vec<Reply>,
) -> Handled {
    let result = command.and_then(|c| core.command(c).map_err(|e| e.to_string()));
    let handled = if result.is_ok() {
        Handled::Taken
    } else {
        Handled::Refused
    };
    out.push(Reply::Answer(Answer {
        topic: topic.to_owned(),
        request,
        result,
        data: None,
    }));
    handled
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_round_trip_with_and_without_an_id() {
        let payload = encode_request(Some(7), &serde_json::json!({"data": 5}));
        assert_eq!(&payload[..], br#"{"id":7,"msg":{"data":5}}"#);
        let (id, msg) = decode_request::<serde_json::Value>("/x", &payload);
        assert_eq!((id, msg.unwrap()["data"].as_i64()), (Some(7), Some(5)));
        let payload = encode_request(None, &serde_json::json!({"data": 1}));
        assert_eq!(&payload[..], br#"{"msg":{"data":1}}"#);
    }

    #[test]
    fn broken_or_oversized_requests_are_refused_by_topic() {
        let (id, e) = decode_request::<serde_json::Value>("/x", b"{\"msg\":1,\"extra\":2}");
        assert!(id.is_none() && e.unwrap_err().starts_with("/x: unknown field"));
        // A message of the wrong shape keeps its id, so the link can answer it.
        let (id, e) = decode_request::<Vec<u8>>("/x", b"{\"id\":3,\"msg\":{}}");
        assert_eq!(id, Some(3));
        assert!(e.unwrap_err().starts_with("/x: invalid type"));
        let big = vec![b' '; MAX_REQUEST + 1];
        let (_, e) = decode_request::<serde_json::Value>("/x", &big);
        assert!(e.unwrap_err().contains("exceeds"));
    }
}
