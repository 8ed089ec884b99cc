//! A silent MQTT client for `chassisd record`: it subscribes to the vehicle's command topics
//! and records what arrives, and publishes nothing (no `online`, no last will, no replies),
//! so a recorder never answers for the vehicle.

use std::time::Duration;

use rumqttc::{AsyncClient, Event, Packet, QoS};
use tokio::sync::mpsc;

use crate::api::mqtt::MQTT_SOURCE;
use crate::config::mqtt::MqttConfig;
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::links::mqtt::{client_options, low_latency};
use crate::vehicle::LinkState;

/// Requests rumqttc queues between the client handle and its event loop.
const CLIENT_QUEUE: usize = 16;
/// First reconnect delay.
const FIRST_BACKOFF: Duration = Duration::from_millis(100);

/// Starts the observer; commands and link events go to `records` as source `mqtt`.
pub fn spawn(
    config: &MqttConfig,
    vehicle: &str,
    topics: Vec<String>,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
) -> Result<(), crate::runtime::error::RuntimeError> {
    let client_id = format!("{}-recorder", config.base_client_id(vehicle));
    let (client, mut events) = AsyncClient::new(client_options(config, client_id)?, CLIENT_QUEUE);
    events.set_network_options(low_latency());
    let broker = format!("{}:{}", config.host, config.port);
    let reconnect_max = config.reconnect_max();
    tokio::spawn(async move {
        let link = |state| Record {
            t: clock.now(),
            source: MQTT_SOURCE.into(),
            payload: Payload::Link(state),
        };
        let mut connected = false;
        let mut said = false;
        let mut backoff = FIRST_BACKOFF;
        loop {
            let record = match events.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    connected = true;
                    said = false;
                    backoff = FIRST_BACKOFF;
                    let filters = topics
                        .iter()
                        .map(|t| rumqttc::SubscribeFilter::new(t.clone(), QoS::AtLeastOnce));
                    if let Err(e) = client.try_subscribe_many(filters) {
                        tracing::error!(error = %e, "MQTT subscribe failed");
                    }
                    link(LinkState::Up)
                }
                // A retained message is an old command, not one sent during the recording.
                Ok(Event::Incoming(Packet::SubAck(ack))) => {
                    let refused = crate::runtime::links::mqtt::refused_subscriptions(&ack);
                    if refused > 0 {
                        tracing::error!(
                            refused,
                            ?topics,
                            "MQTT broker refused subscriptions; those commands are not recorded"
                        );
                    } else {
                        tracing::info!(%broker, ?topics, "MQTT: recording the vehicle's commands");
                    }
                    continue;
                }
                Ok(Event::Incoming(Packet::Publish(p))) if !p.retain => Record {
                    t: clock.now(),
                    source: MQTT_SOURCE.into(),
                    payload: Payload::Command {
                        topic: p.topic,
                        payload: p.payload,
                    },
                },
                Ok(_) => continue,
                Err(e) => {
                    let was_connected = std::mem::replace(&mut connected, false);
                    // Said once per outage, not on every retry.
                    if was_connected || !said {
                        tracing::warn!(%broker, error = %e, "MQTT: no connection; retrying");
                        said = true;
                    }
                    if was_connected && records.send(link(LinkState::Down)).await.is_err() {
                        return;
                    }
                    tokio::time::sleep(backoff).await;
                    backoff = (backoff * 2).min(reconnect_max.max(FIRST_BACKOFF));
                    continue;
                }
            };
            if records.send(record).await.is_err() {
                return;
            }
        }
    });
    Ok(())
}
