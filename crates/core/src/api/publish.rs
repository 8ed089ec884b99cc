//! A message for the MQTT broker, as the dialects and the engine hand it to the link.

use bytes::Bytes;

/// Delivery guarantee of a publication.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Qos {
    /// Telemetry: at most once; dropped first when the broker is away.
    AtMostOnce,
    /// Replies and events: at least once; kept while the broker is away.
    AtLeastOnce,
}

/// One message to publish.
#[derive(Debug, Clone, PartialEq)]
pub struct Publish {
    /// Topic.
    pub topic: String,
    /// Payload (JSON).
    pub payload: Bytes,
    /// Delivery guarantee.
    pub qos: Qos,
    /// Retained by the broker.
    pub retain: bool,
    /// The dialect that publishes it (`rtk`, `root`, `device`): the runtime sends it on the
    /// link that carries that dialect. `None`: a link's own message.
    pub dialect: Option<&'static str>,
}

impl Publish {
    /// The bytes of its MQTT PUBLISH packet, at most: fixed header (up to five bytes), topic
    /// with its length, packet id, payload.
    pub fn packet_len(&self) -> usize {
        5 + 2 + self.topic.len() + 2 + self.payload.len()
    }

    /// Telemetry: QoS 0, not retained.
    pub fn telemetry(topic: impl Into<String>, payload: impl Into<Bytes>) -> Self {
        Self {
            topic: topic.into(),
            payload: payload.into(),
            qos: Qos::AtMostOnce,
            retain: false,
            dialect: None,
        }
    }

    /// A reply or event: QoS 1, not retained.
    pub fn reply(topic: impl Into<String>, payload: impl Into<Bytes>) -> Self {
        Self {
            qos: Qos::AtLeastOnce,
            ..Self::telemetry(topic, payload)
        }
    }
}
