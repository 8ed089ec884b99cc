//! `heartbeat/set`: the control link's heartbeat. A heartbeat is a JSON object (the spec's
//! example, trailing comma and all); it is answered, and it feeds the core's control-link
//! watchdog when it comes from the client followed (or from anyone, when none is named).
//! Anything else is neither: garbage must not arm the watchdog that then stops an operator who
//! sends only DRIVE.

use serde_json::{Map, Value};

use crate::api::mqtt::CoreAccess;
use crate::vehicle::Command;

/// Whose heartbeats count, and how many were not heartbeats at all.
pub(super) struct Heartbeats {
    /// Only heartbeats naming this `clientId` feed the watchdog.
    client: Option<String>,
    /// Heartbeats ignored because they were not JSON objects.
    malformed: u64,
}

impl Heartbeats {
    /// Heartbeats from `client`, or from anyone.
    pub(super) fn new(client: Option<String>) -> Self {
        Self {
            client,
            malformed: 0,
        }
    }

    /// A heartbeat's payload of at most `max` bytes: whether it is one (and is answered).
    pub(super) fn beat(&mut self, payload: &[u8], max: usize, core: &mut dyn CoreAccess) -> bool {
        let Some(beat) = (payload.len() <= max).then(|| object(payload)).flatten() else {
            self.malformed += 1;
            if self.malformed.is_power_of_two() {
                tracing::warn!(
                    count = self.malformed,
                    "root heartbeat ignored: not a JSON object (neither answered nor counted)"
                );
            }
            return false;
        };
        let sender = beat.get("clientId").and_then(Value::as_str);
        if self.client.as_deref().is_none_or(|c| sender == Some(c)) {
            let _ = core.command(Command::ControlHeartbeat);
        }
        true
    }
}

/// A heartbeat's payload as a JSON object. The spec's own example ends its object with a
/// comma (`{"timestamp": "...",}`), which JSON forbids; that one comma is forgiven.
fn object(payload: &[u8]) -> Option<Map<String, Value>> {
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
