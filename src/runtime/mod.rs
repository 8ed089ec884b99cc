//! The async edges of live mode: drivers that move bytes, and the task that owns the engine.

pub mod broker;
pub mod can;
pub mod can_sim;
pub mod check;
pub mod clock;
pub mod command_rate;
pub mod drivers;
pub mod heap;
pub mod host;
pub mod input_lines;
pub mod journal;
pub mod listen;
pub mod live;
pub mod lossy;
pub mod mqtt;
pub mod mqtt_observe;
pub mod notify;
pub mod ntrip;
pub mod outage_log;
pub mod panics;
pub mod recorder;
pub mod ros1;
pub mod serial;
pub mod serial_tx;
pub mod sim;
pub mod sim_fast;
pub mod status_out;
pub mod trajectory_writer;
pub mod websocket;

use crate::engine::EngineOutput;

/// Handles the engine outputs that go the same way in live mode and in the simulation:
/// what the WebSocket server sees of them, what the ROS1 node publishes to it, messages to
/// the MQTT link, events and command answers to the log. Returns the others (status lines
/// and frames), which each mode routes itself.
fn forward_common(
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
        } => tracing::info!(%source, %topic, "command accepted"),
        EngineOutput::CommandResult {
            source,
            topic,
            result: Err(reason),
        } => tracing::warn!(%source, %topic, %reason, "command refused"),
        other => return Some(other),
    }
    None
}
