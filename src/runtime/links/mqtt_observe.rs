//! A silent MQTT client for `chassisd record`: it subscribes to the vehicle's command topics
//! and records what arrives, and publishes nothing (no `online`, no last will, no replies),
//! so a recorder never answers for the vehicle.

use rumqttc::{AsyncClient, Event, Packet, QoS};
use tokio::sync::mpsc;

use crate::config::mqtt::MqttLinkConfig;
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::links::backoff::{Backoff, BrokerWalk};
use crate::runtime::links::mqtt::{client_options_at, low_latency};
use crate::vehicle::LinkState;

/// Requests rumqttc queues between the client handle and its event loop.
const CLIENT_QUEUE: usize = 16;
/// Starts the observer of one link; commands and link events go to `records` as the
/// link's source (`mqtt` for the one-link form's).
pub fn spawn(
    config: &MqttLinkConfig,
    vehicle: &str,
    topics: Vec<String>,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
) -> Result<(), crate::runtime::error::RuntimeError> {
    let client_id = format!("{}-recorder", config.base_client_id(vehicle));
    let brokers = config
        .brokers()
        .into_iter()
        .map(|b| {
            Ok((
                b.to_string(),
                client_options_at(config, &b, client_id.clone())?,
            ))
        })
        .collect::<Result<Vec<_>, crate::runtime::error::RuntimeError>>()?;
    let (client, mut events) = AsyncClient::new(brokers[0].1.clone(), CLIENT_QUEUE);
    events.set_network_options(low_latency());
    let mut backoff = Backoff::new(
        config.reconnect_min(),
        config.reconnect_max(),
        crate::secret::unguessable(),
    );
    let source = config.source();
    tokio::spawn(async move {
        let link = |state| Record {
            t: clock.now(),
            source: source.clone(),
            payload: Payload::Link(state),
        };
        let mut connected = false;
        let mut said = false;
        let mut walk = BrokerWalk::new(brokers.len());
        loop {
            let broker = &brokers[walk.current()].0;
            let record = match events.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    connected = true;
                    said = false;
                    backoff.reset();
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
                    source: source.clone(),
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
                    if !was_connected {
                        walk.attempt_failed();
                        events.mqtt_options = brokers[walk.current()].1.clone();
                    }
                    tokio::time::sleep(backoff.next_wait()).await;
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
