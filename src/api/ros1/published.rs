//! The topics the node publishes from the status ticks, each whole here: its name, its ROS
//! type, its rate and its message as JSON (the fields as the type names them). The node
//! advertises each with the type's definition, generated from `interfaces/`, and serialises
//! the JSON through that type, which checks every field; so a topic, even of a new type,
//! needs only its interface files and a line in [`STATUS_TOPICS`].

use serde_json::Value;

use crate::vehicle::VehicleStatus;

/// One topic published from the status ticks.
#[derive(Debug, Clone, Copy)]
pub struct StatusTopic {
    /// Its name.
    pub name: &'static str,
    /// Its ROS type (`package/Type`), one of `interfaces/`.
    pub msg_type: &'static str,
    /// Status ticks (10 Hz) from one message to the next.
    pub every: u64,
    /// The message for a status and the sequence number of its header; `None` when there is
    /// nothing to say.
    pub build: fn(&VehicleStatus, u32) -> Option<Value>,
}

/// Every topic the node publishes from the status ticks.
pub const STATUS_TOPICS: &[StatusTopic] = &[];

/// The topics due at the `tick`th status tick (counted from 1).
pub fn due(tick: u64) -> impl Iterator<Item = &'static StatusTopic> {
    STATUS_TOPICS
        .iter()
        .filter(move |t| tick.is_multiple_of(t.every.max(1)))
}
