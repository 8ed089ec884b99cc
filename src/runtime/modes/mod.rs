//! The ways of running: each wires the drivers and links it needs to the engine (or, for
//! `record`, to the recorder alone).

pub mod can_sim;
pub mod check;
pub mod listen;
pub mod live;
pub mod sim;
pub mod sim_fast;

/// Says what the zones do, and what they do not do yet.
fn log_zones(config: &crate::config::VehicleConfig) {
    if let Some(z) = &config.zones {
        tracing::warn!(
            zones = z.set.zones().len(),
            "zones: every motion's way is checked before it starts and the braking way every \
             tick, and autonomous work waits on the GNSS gate; edits over ROS1 and the \
             WebSocket are not built yet"
        );
    }
}

use crate::engine::EngineOutput;
use crate::runtime::links::{mqtt, ros1, websocket};

/// Handles the engine outputs that go the same way in live mode and in the simulation:
/// what the WebSocket server sees of them, what the ROS1 node publishes to it, messages to
/// the MQTT link, events and command answers to the log. Returns the others (status lines
/// and frames), which each mode routes itself.
pub(crate) fn forward_common(
    output: EngineOutput,
    mqtt: Option<&mqtt::MqttSender>,
    ros1: Option<&mut ros1::Ros1Link>,
    websocket: Option<&mut websocket::WebsocketLink>,
) -> Option<EngineOutput> {
    if let Some(link) = websocket {
        link.see(&output);
    }
    let output = match ros1 {
        Some(link) => link.take(output)?,
        None => output,
    };
    match output {
        EngineOutput::Publish(message) => {
            if let Some(link) = mqtt {
                link.send(message);
            }
        }
        EngineOutput::Event(event) => tracing::info!("{event}"),
        EngineOutput::CommandResult {
            source,
            topic,
            result: Ok(()),
            ..
        } => tracing::info!(%source, %topic, "command accepted"),
        EngineOutput::CommandResult {
            source,
            topic,
            result: Err(reason),
            ..
        } => tracing::warn!(%source, %topic, %reason, "command refused"),
        other => return Some(other),
    }
    None
}
