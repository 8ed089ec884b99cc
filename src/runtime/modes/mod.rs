//! The ways of running: each wires the drivers and links it needs to the engine (or, for
//! `record`, to the recorder alone).

pub mod can_sim;
pub mod check;
pub mod listen;
pub mod live;
pub mod sim;
pub mod sim_fast;

/// Says what the zones do, once at start.
fn log_zones(config: &crate::config::VehicleConfig) {
    if let Some(z) = &config.zones {
        tracing::info!(
            zones = z.set.zones().len(),
            "zones: every motion's way is checked before it starts and the braking way every \
             tick, autonomous work runs only while the GNSS gate is open; ROS1 /set_shape and /set_region \
             edit them, the WebSocket's /zones and /safety_envelope and the live page show them"
        );
    }
}

use crate::engine::EngineOutput;
use crate::runtime::links::{mqtt, ros1, websocket};
use crate::runtime::zones_writer::ZonesWriter;

/// The writer of the zones file, when the configuration names one.
fn zones_writer(config: &crate::config::VehicleConfig) -> Option<ZonesWriter> {
    let file = config.zones.as_ref()?.file.clone()?;
    match ZonesWriter::start(file) {
        Ok(w) => Some(w),
        Err(e) => {
            tracing::error!(error = %e, "cannot start the zones writer: edits are not kept");
            None
        }
    }
}

/// Handles the engine outputs that go the same way in live mode and in the simulation:
/// what the WebSocket server sees of them, what the ROS1 node publishes to it, messages to
/// the MQTT link, events and command answers to the log. Returns the others (status lines
/// and frames), which each mode routes itself.
pub(crate) fn forward_common(
    output: EngineOutput,
    mqtt: Option<&mqtt::MqttSender>,
    ros1: Option<&mut ros1::Ros1Link>,
    websocket: Option<&mut websocket::WebsocketLink>,
    zones: Option<&ZonesWriter>,
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
        EngineOutput::ZonesChanged(text) => match zones {
            Some(writer) => writer.write(text),
            None => tracing::warn!("the zones changed, but they have no file to be written to"),
        },
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
