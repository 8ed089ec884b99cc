//! One MQTT link (rumqttc): connects to its broker (or the next of its failover brokers),
//! reconnects with jittered back-off ([`super::backoff`]) and subscribes again, keeps a
//! retained `online` message with an `offline` last will, forwards incoming commands to the
//! engine as records of its own source, and publishes the messages of the dialects it
//! carries. Each link is a task of its own with its own queues and limits: one link down
//! never holds up another.
//!
//! Outgoing messages wait in two bounded queues while the broker is away: telemetry (QoS 0;
//! the oldest is dropped first) and replies and events (QoS 1; kept up to their own bound).
//! A reply stays ours until the broker acknowledges it: on a clean-session reconnect rumqttc
//! drops whatever it had not delivered, so the link queues those replies again itself.
//! The session is clean, so the broker keeps nothing for chassisd while it is away: a command
//! published during an outage is never executed later. Retained messages on command topics
//! are ignored for the same reason.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::runtime::error::{RuntimeError, io};
use bytes::Bytes;
use rumqttc::{
    AsyncClient, Event, EventLoop, LastWill, MqttOptions, NetworkOptions, Outgoing, Packet, QoS,
    TlsConfiguration, Transport,
};
use tokio::sync::mpsc;

use crate::api::log_budget::{self, LogBudget, SharedBudget};
use crate::api::mqtt::{Publish, Qos};
use crate::config::mqtt::{BrokerAddress, MqttLinkConfig};
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::runtime::links::backoff::{Backoff, BrokerWalk};
use crate::runtime::links::command_rate::{CommandRate, RateReport};
use crate::runtime::links::mqtt_echo::Echo;
use crate::runtime::links::mqtt_losses::{Losses, Tell};
use crate::vehicle::LinkState;

/// The budget of "retained command ignored" lines.
static RETAINED_IGNORED: SharedBudget = SharedBudget::new(LogBudget::new());

/// Messages from the engine waiting for the link task.
const HANDOFF: usize = 4096;
/// Requests rumqttc queues between the client handle and its event loop.
const CLIENT_QUEUE: usize = 256;

/// Hands messages to the link task.
#[derive(Clone)]
pub struct MqttSender {
    tx: mpsc::Sender<Publish>,
    dropped: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl MqttSender {
    /// Queues a message; never blocks. Only a stalled link task can refuse one: counted, and
    /// logged at the 1st, 2nd, 4th, 8th... drop, never once per message.
    pub fn send(&self, message: Publish) {
        if let Err(e) = self.tx.try_send(message) {
            let n = self
                .dropped
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
                + 1;
            if n.is_power_of_two() {
                tracing::error!(error = %e, dropped = n, "MQTT link task is not keeping up; messages dropped");
            }
        }
    }
}

/// Counters of the link.
#[derive(Debug, Default, Clone, Copy)]
struct Dropped {
    telemetry: u64,
    replies: u64,
    retained_commands: u64,
    /// Messages larger than a packet may be, never sent.
    oversized: u64,
}

/// The two outgoing queues, and the replies handed to rumqttc but not yet acknowledged.
struct Outbox {
    telemetry: VecDeque<Publish>,
    replies: VecDeque<Publish>,
    /// QoS 1 messages in rumqttc's request queue, in the order it will write them.
    handed: VecDeque<Publish>,
    /// QoS 1 messages written, by packet id, in the order written, awaiting their PubAck.
    unacked: VecDeque<(u16, Publish)>,
    telemetry_max: usize,
    replies_max: usize,
    /// The largest packet the broker takes from chassisd.
    packet_max: usize,
    dropped: Dropped,
}

impl Outbox {
    fn new(telemetry_max: usize, replies_max: usize, packet_max: usize) -> Self {
        Self {
            telemetry: VecDeque::new(),
            replies: VecDeque::new(),
            handed: VecDeque::new(),
            unacked: VecDeque::new(),
            telemetry_max,
            replies_max,
            packet_max,
            dropped: Dropped::default(),
        }
    }

    fn push(&mut self, message: Publish) {
        // The broker would end chassisd's session for it, and the reply, queued again on
        // the reconnect, would end the next one too.
        if message.packet_len() > self.packet_max {
            self.dropped.oversized += 1;
            if self.dropped.oversized.is_power_of_two() {
                tracing::error!(
                    topic = %message.topic,
                    bytes = message.packet_len(),
                    limit = self.packet_max,
                    dropped = self.dropped.oversized,
                    "MQTT message not sent: larger than a packet may be (4 × mqtt.max_payload, at least 1 MiB); raise mqtt.max_payload"
                );
            }
            return;
        }
        let (queue, max, dropped) = match message.qos {
            Qos::AtMostOnce => (
                &mut self.telemetry,
                self.telemetry_max,
                &mut self.dropped.telemetry,
            ),
            Qos::AtLeastOnce => (
                &mut self.replies,
                self.replies_max,
                &mut self.dropped.replies,
            ),
        };
        if queue.len() >= max {
            queue.pop_front();
            *dropped += 1;
            if dropped.is_power_of_two() {
                tracing::warn!(
                    telemetry = self.dropped.telemetry,
                    replies = self.dropped.replies,
                    "MQTT broker away: oldest queued messages dropped"
                );
            }
        }
        queue.push_back(message);
    }

    /// Hands queued messages to rumqttc while it takes them: telemetry first (at most a few
    /// status messages, whose period matters), then replies.
    fn flush(&mut self, client: &AsyncClient) {
        for qos in [Qos::AtMostOnce, Qos::AtLeastOnce] {
            while let Some(m) = self.queue(qos).pop_front() {
                if let Err(m) = self.hand(client, m) {
                    self.queue(qos).push_front(m);
                    return;
                }
            }
        }
    }

    /// The queue of messages sent at `qos`: telemetry, or replies and events.
    fn queue(&mut self, qos: Qos) -> &mut VecDeque<Publish> {
        match qos {
            Qos::AtMostOnce => &mut self.telemetry,
            Qos::AtLeastOnce => &mut self.replies,
        }
    }

    /// Gives one message to rumqttc, tracking a QoS 1 one until its PubAck; gives it back if
    /// rumqttc's queue is full.
    fn hand(&mut self, client: &AsyncClient, m: Publish) -> Result<(), Publish> {
        let qos = match m.qos {
            Qos::AtMostOnce => QoS::AtMostOnce,
            Qos::AtLeastOnce => QoS::AtLeastOnce,
        };
        if client
            .try_publish(m.topic.clone(), qos, m.retain, m.payload.clone())
            .is_err()
        {
            return Err(m);
        }
        if m.qos == Qos::AtLeastOnce {
            self.handed.push_back(m);
        }
        Ok(())
    }

    /// rumqttc wrote a publish with packet id `pkid` (0 for QoS 0).
    fn written(&mut self, pkid: u16) {
        if pkid != 0
            && let Some(m) = self.handed.pop_front()
        {
            self.unacked.push_back((pkid, m));
        }
    }

    /// The broker acknowledged packet `pkid`.
    fn acknowledged(&mut self, pkid: u16) {
        self.unacked.retain(|(id, _)| *id != pkid);
    }

    /// The connection broke: every reply not acknowledged goes back to the front of the
    /// queue, in its order (rumqttc forgets them on the clean-session reconnect).
    fn requeue_unacknowledged(&mut self) {
        let again: Vec<Publish> = self
            .unacked
            .drain(..)
            .map(|(_, m)| m)
            .chain(self.handed.drain(..))
            .collect();
        if !again.is_empty() {
            tracing::debug!(replies = again.len(), "unacknowledged replies queued again");
        }
        for m in again.into_iter().rev() {
            self.replies.push_front(m);
        }
    }
}

/// What the link needs to start.
pub struct MqttSpec {
    /// Brokers, identity and queues.
    pub config: MqttLinkConfig,
    /// Vehicle name (client id and status topic).
    pub vehicle: String,
    /// Topic filters to subscribe to.
    pub subscriptions: Vec<String>,
    /// The exact topics the dialects act on; others share one slow rate limit.
    pub command_topics: Vec<String>,
}

/// Starts the link task; incoming commands go to `records`.
pub fn spawn(
    spec: MqttSpec,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
) -> Result<MqttSender, RuntimeError> {
    let brokers = broker_options(&spec)?;
    let (tx, mut rx) = mpsc::channel(HANDOFF);
    tokio::spawn(async move {
        // An auxiliary task: after a panic (logged once by the hook) the link starts afresh
        // with a new connection; the queue of outgoing messages survives it.
        loop {
            let (client, mut eventloop) = AsyncClient::new(brokers[0].1.clone(), CLIENT_QUEUE);
            eventloop.set_network_options(low_latency());
            let link = run(
                &spec,
                &brokers,
                client,
                eventloop,
                &mut rx,
                clock,
                records.clone(),
            );
            match crate::runtime::panics::contain(link).await {
                Ok(LinkEnd::EngineGone) => return,
                Ok(LinkEnd::PollerLost) => {
                    tracing::error!(link = %spec.config.name, "MQTT link restarted: its event loop ended (a panic in it?)");
                }
                Err(()) => {
                    tracing::error!(link = %spec.config.name, "MQTT link restarted after a panic")
                }
            }
            tokio::time::sleep(Duration::from_secs(1)).await;
        }
    });
    Ok(MqttSender {
        tx,
        dropped: Default::default(),
    })
}

/// The client options for each of the link's brokers, in the order they are tried: id,
/// keep-alive, last will, credentials, TLS (its server name the broker's own).
fn broker_options(spec: &MqttSpec) -> Result<Vec<(BrokerAddress, MqttOptions)>, RuntimeError> {
    let c = &spec.config;
    let client_id = c.client_id(&spec.vehicle);
    c.brokers()
        .into_iter()
        .map(|broker| {
            let mut o = client_options_at(c, &broker, client_id.clone())?;
            o.set_last_will(LastWill::new(
                c.status_topic(&spec.vehicle),
                "offline",
                QoS::AtLeastOnce,
                true,
            ));
            Ok((broker, o))
        })
        .collect()
}

/// Commands and their acks are small packets that must not wait for Nagle's algorithm to
/// fill a segment (it held each DRIVE ack back about 40 ms).
pub fn low_latency() -> NetworkOptions {
    let mut n = NetworkOptions::new();
    n.set_tcp_nodelay(true);
    n
}

/// The options of any client of chassisd's on `broker`, one of link `c`'s, as `client_id`:
/// keep-alive, a clean session, packet sizes, credentials, TLS (its server name the
/// broker's own). No last will.
pub(crate) fn client_options_at(
    c: &MqttLinkConfig,
    broker: &BrokerAddress,
    client_id: String,
) -> Result<MqttOptions, RuntimeError> {
    let mut o = MqttOptions::new(client_id, broker.host.clone(), broker.port);
    o.set_keep_alive(c.keep_alive());
    o.set_clean_session(true);
    // Oversized commands get an error reply from their dialect; only far larger packets
    // are refused by the client itself (and cost a reconnect). The outbox never hands over
    // a larger one.
    o.set_max_packet_size(c.packet_limit(), c.packet_limit());
    if let (Some(user), password) = (&c.username, &c.password) {
        o.set_credentials(user.clone(), password.clone().unwrap_or_default());
    }
    if let Some(tls) = &c.tls {
        // rustls needs a process-wide crypto provider; ring is the one compiled in. A second
        // install (another link) is refused harmlessly.
        let _ = rustls::crypto::ring::default_provider().install_default();
        let read = |p: &str| {
            std::fs::read(p).map_err(io(format!("mqtt link {}: tls: cannot read {p}", c.name)))
        };
        let client_auth = match (&tls.client_cert_file, &tls.client_key_file) {
            (Some(cert), Some(key)) => Some((read(cert)?, read(key)?)),
            _ => None,
        };
        o.set_transport(Transport::tls_with_config(TlsConfiguration::Simple {
            ca: read(&tls.ca_file)?,
            alpn: None,
            client_auth,
        }));
    }
    Ok(o)
}

/// Why the link's loop ended.
enum LinkEnd {
    /// The engine is gone: nothing more to carry.
    EngineGone,
    /// The event loop's task ended: the link starts afresh.
    PollerLost,
}

async fn run(
    spec: &MqttSpec,
    brokers: &[(BrokerAddress, MqttOptions)],
    client: AsyncClient,
    eventloop: EventLoop,
    rx: &mut mpsc::Receiver<Publish>,
    clock: RecordClock,
    records: mpsc::Sender<Record>,
) -> LinkEnd {
    let c = &spec.config;
    let name = c.name.as_str();
    let mut broker = brokers[0].0.to_string();
    let status_topic = c.status_topic(&spec.vehicle);
    let mut outbox = Outbox::new(c.telemetry_queue, c.reply_queue, c.packet_limit());
    let mut rate = CommandRate::new(c.command_rate_hz, c.command_burst)
        .with_known_topics(spec.command_topics.iter().cloned());
    let mut connected = false;
    let mut last_failure: Option<String> = None;
    let mut losses = Losses::default();
    // Whether this session's connect and subscribe are worth an info line (not while
    // sessions keep being lost: those are summarised).
    let mut announce = true;
    let backoff = Backoff::new(
        c.reconnect_min(),
        c.reconnect_max(),
        crate::secret::unguessable(),
    );
    let mut events = Poller::spawn(eventloop, brokers.to_vec(), backoff);
    let mut echo = Echo::default();
    let source = c.source();
    let link = |state| Record {
        t: clock.now(),
        source: source.clone(),
        payload: Payload::Link(state),
    };
    loop {
        if let Some(report) = rate.due_summary(Instant::now()) {
            log_rate(&report, c);
        }
        if echo.overdue(Instant::now()) {
            tracing::error!(
                link = name,
                %broker,
                topic = %status_topic,
                "MQTT: the broker did not deliver the link's own `online` back within 5 s: its \
                 ACL probably denies the vehicle's topics, and the link's commands will not \
                 arrive (docs/fleet.md gives the ACLs)"
            );
        }
        if let Some(lost) = losses.due_summary(Instant::now()) {
            tracing::warn!(link = name, %broker, lost, "MQTT sessions lost in the last 5 s; reconnecting each time");
        }
        tokio::select! {
            event = events.next() => {
                let Some((at, event)) = event else { return LinkEnd::PollerLost };
                if let Some((address, _)) = brokers.get(at) {
                    broker = address.to_string();
                }
                match event {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    connected = true;
                    last_failure = None;
                    losses.connected(Instant::now());
                    if announce {
                        tracing::info!(link = name, %broker, client_id = %c.client_id(&spec.vehicle), "MQTT connected");
                    }
                    // The commands' topics, and the link's own status for its echo.
                    let qos = if c.command_qos == 0 { QoS::AtMostOnce } else { QoS::AtLeastOnce };
                    let filters = spec
                        .subscriptions
                        .iter()
                        .chain(std::iter::once(&status_topic))
                        .map(|f| rumqttc::SubscribeFilter::new(f.clone(), qos));
                    if let Err(e) = client.try_subscribe_many(filters) {
                        tracing::error!(link = name, error = %e, "MQTT subscribe failed");
                    }
                    // `online` goes first, tracked like a reply.
                    let online = Publish {
                        retain: true,
                        ..Publish::reply(status_topic.clone(), Bytes::from_static(b"online"))
                    };
                    if let Err(online) = outbox.hand(&client, online) {
                        outbox.replies.push_front(online);
                    }
                    outbox.flush(&client);
                    echo.sent(Instant::now());
                    if records.send(link(LinkState::Up)).await.is_err() {
                        return LinkEnd::EngineGone;
                    }
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    if p.topic == status_topic {
                        // Its own status: the echo (live, not the retained copy an earlier
                        // session left), never a command.
                        if !p.retain && p.payload.as_ref() == b"online" && echo.heard() {
                            tracing::info!(link = name, %broker, "MQTT: the broker now delivers the link's own status back");
                        }
                        continue;
                    }
                    if crate::runtime::panics::inject("mqtt") {
                        panic!("injected panic ({}=mqtt)", crate::runtime::panics::INJECT_PANIC);
                    }
                    if p.retain {
                        outbox.dropped.retained_commands += 1;
                        if let Some(left_out) = log_budget::allow(&RETAINED_IGNORED, clock.now()) {
                            tracing::warn!(topic = %p.topic, not_logged = left_out, "retained command ignored: commands must be live");
                        }
                        continue;
                    }
                    let (admitted, report) = rate.admit(&p.topic, Instant::now());
                    if let Some(report) = report {
                        log_rate(&report, c);
                    }
                    if !admitted {
                        continue;
                    }
                    let record = Record {
                        t: clock.now(),
                        source: source.clone(),
                        payload: Payload::Command { topic: p.topic, payload: p.payload },
                    };
                    if records.send(record).await.is_err() {
                        return LinkEnd::EngineGone;
                    }
                }
                Ok(Event::Incoming(Packet::SubAck(ack))) => {
                    let refused = refused_subscriptions(&ack);
                    if refused > 0 {
                        tracing::error!(link = name, %broker, refused, "MQTT broker refused subscriptions (its ACL?); the link's commands on them will not arrive");
                    } else if announce {
                        tracing::info!(link = name, topics = ?spec.subscriptions, "MQTT subscribed");
                    }
                }
                Ok(Event::Outgoing(outgoing)) => {
                    if let Outgoing::Publish(pkid) = outgoing {
                        outbox.written(pkid);
                    }
                    outbox.flush(&client);
                }
                Ok(Event::Incoming(Packet::PubAck(ack))) => outbox.acknowledged(ack.pkid),
                Ok(_) => {}
                Err(e) => {
                    outbox.requeue_unacknowledged();
                    echo.lost();
                    if connected {
                        connected = false;
                        let tell = losses.lost(Instant::now());
                        announce = tell == Tell::Lost;
                        log_loss(&tell, name, &broker, &e, &c.client_id(&spec.vehicle));
                        if records.send(link(LinkState::Down)).await.is_err() {
                            return LinkEnd::EngineGone;
                        }
                    } else {
                        // Say why once per cause (a wrong password or CA stays wrong), not
                        // on every retry.
                        let cause = e.to_string();
                        if last_failure.as_deref() != Some(cause.as_str()) {
                            tracing::warn!(link = name, %broker, error = %cause, "MQTT connect failed; retrying (on the next broker when the link lists more)");
                            last_failure = Some(cause);
                        } else {
                            tracing::debug!(link = name, %broker, error = %cause, "MQTT connect failed");
                        }
                    }
                }
            }},
            message = rx.recv() => {
                let Some(message) = message else { return LinkEnd::EngineGone };
                outbox.push(message);
                if connected {
                    outbox.flush(&client);
                }
            }
        }
    }
}

/// rumqttc's event loop, polled in a task of its own: `poll()` dropped halfway through a
/// connection attempt starts the attempt over, so a loop that also waits for outgoing
/// messages would cut every slow connection short (seen on a slow PC: five attempts in
/// 60 ms, each one taking the last one's place on the broker). The poller also waits out
/// the reconnect back-off and chooses the broker of the next attempt.
struct Poller {
    /// Each event with the index of the broker it came from.
    events: mpsc::Receiver<(usize, Result<Event, rumqttc::ConnectionError>)>,
    task: tokio::task::JoinHandle<()>,
}

impl Poller {
    /// Events waiting for the link before the poller waits.
    const QUEUE: usize = 64;

    fn spawn(
        mut eventloop: EventLoop,
        brokers: Vec<(BrokerAddress, MqttOptions)>,
        mut backoff: Backoff,
    ) -> Self {
        let (tx, events) = mpsc::channel(Self::QUEUE);
        let task = tokio::spawn(async move {
            let mut walk = BrokerWalk::new(brokers.len());
            let mut connected = false;
            loop {
                let at = walk.current();
                let event = eventloop.poll().await;
                let failed = event.is_err();
                if matches!(event, Ok(Event::Incoming(Packet::ConnAck(_)))) {
                    connected = true;
                    backoff.reset();
                }
                if tx.send((at, event)).await.is_err() {
                    return;
                }
                if failed {
                    // A lost session is tried again where it was; a failed attempt moves
                    // on to the next broker.
                    if !std::mem::take(&mut connected) {
                        walk.attempt_failed();
                    }
                    if let Some((_, options)) = brokers.get(walk.current())
                        && walk.current() != at
                    {
                        eventloop.mqtt_options = options.clone();
                    }
                    // rumqttc keeps a publish whose packet id collided across a lost
                    // connection, and then refuses every request of every later session
                    // until a "collision timeout" ends it: the link stayed wedged for good
                    // after a takeover. The link queues unacknowledged replies itself.
                    eventloop.state.collision = None;
                    tokio::time::sleep(backoff.next_wait()).await;
                }
            }
        });
        Self { events, task }
    }

    /// The next event; `None` when the poller ended (it never does by itself).
    async fn next(&mut self) -> Option<(usize, Result<Event, rumqttc::ConnectionError>)> {
        self.events.recv().await
    }
}

impl Drop for Poller {
    fn drop(&mut self) {
        // The link ended (or panicked): its connection goes with it.
        self.task.abort();
    }
}

/// How many of the filters a SubAck answers the broker refused.
pub(crate) fn refused_subscriptions(ack: &rumqttc::SubAck) -> usize {
    ack.return_codes
        .iter()
        .filter(|c| matches!(c, rumqttc::SubscribeReasonCode::Failure))
        .count()
}

/// A lost session, as [`Losses`] says to tell it.
fn log_loss(
    tell: &Tell,
    link: &str,
    broker: &str,
    error: &rumqttc::ConnectionError,
    client_id: &str,
) {
    match tell {
        Tell::Lost => {
            tracing::warn!(link, %broker, %error, "MQTT connection lost; reconnecting");
        }
        Tell::LikelyTakeover { cut_short } => tracing::error!(
            link,
            %broker,
            %error,
            cut_short,
            client_id,
            "MQTT: the broker keeps closing chassisd's session soon after it connects: another \
             client is probably connecting with chassisd's client id (MQTT gives an id to its \
             newest connection), or the broker's ACL refuses what the link publishes or \
             subscribes to (RabbitMQ and EMQX can close such a session; docs/fleet.md), or a \
             RabbitMQ cluster before 3.12 holds the link's subscription on a node that is down \
             (set command_qos = 0). Keep the link's client_id_suffix on, and have the broker's \
             ACL reserve the id (docs/security.md); further losses are summarised every 5 s"
        ),
        Tell::Quiet => tracing::debug!(link, %broker, %error, "MQTT connection lost again"),
    }
}

/// One line when a flood starts on a topic, then one per period while it lasts.
fn log_rate(report: &RateReport, c: &MqttLinkConfig) {
    match report {
        RateReport::Started(topic) => tracing::warn!(
            link = %c.name,
            %topic,
            limit_hz = c.command_rate_hz,
            burst = c.command_burst,
            "MQTT commands over the rate limit are refused unanswered; a summary follows every 5 s while it lasts"
        ),
        RateReport::Summary(counts) => {
            let refused: u64 = counts.iter().map(|(_, n)| n).sum();
            let topics = counts
                .iter()
                .map(|(t, n)| format!("{t}: {n}"))
                .collect::<Vec<_>>()
                .join(", ");
            tracing::warn!(link = %c.name, refused, %topics, "MQTT commands refused over the rate limit in the last 5 s");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outbox(telemetry_max: usize, replies_max: usize) -> Outbox {
        Outbox::new(telemetry_max, replies_max, 1 << 20)
    }

    fn topics(queue: &VecDeque<Publish>) -> Vec<&str> {
        queue.iter().map(|m| m.topic.as_str()).collect()
    }

    #[test]
    fn while_the_broker_is_away_old_telemetry_goes_and_replies_stay() {
        let mut o = outbox(3, 100);
        for i in 0..10 {
            o.push(Publish::telemetry(format!("status{i}"), "{}"));
            if i % 3 == 0 {
                o.push(Publish::reply(format!("ack{i}"), "{}"));
            }
        }
        assert_eq!(topics(&o.telemetry), ["status7", "status8", "status9"]);
        assert_eq!(topics(&o.replies), ["ack0", "ack3", "ack6", "ack9"]);
        assert_eq!((o.dropped.telemetry, o.dropped.replies), (7, 0));
    }

    #[test]
    fn replies_are_bounded_too_and_counted_when_dropped() {
        let mut o = outbox(1, 2);
        for i in 0..5 {
            o.push(Publish::reply(format!("ack{i}"), "{}"));
        }
        assert_eq!(topics(&o.replies), ["ack3", "ack4"]);
        assert_eq!(o.dropped.replies, 3);
    }

    #[test]
    fn a_message_larger_than_a_packet_is_never_queued() {
        let mut o = outbox(10, 10);
        let limit = o.packet_max;
        let fits = Publish::reply(
            "t",
            vec![b'x'; limit - Publish::reply("t", "").packet_len()],
        );
        assert_eq!(fits.packet_len(), limit);
        o.push(fits);
        o.push(Publish::reply("t", vec![b'x'; limit]));
        o.push(Publish::telemetry("t", vec![b'x'; limit]));
        assert_eq!(o.replies.len(), 1);
        assert!(o.telemetry.is_empty());
        assert_eq!(o.dropped.oversized, 2);
    }

    #[tokio::test]
    async fn replies_not_acknowledged_when_the_link_breaks_are_queued_again_in_order() {
        let (client, _eventloop) = AsyncClient::new(MqttOptions::new("t", "127.0.0.1", 1), 10);
        let mut o = outbox(10, 10);
        for topic in ["ack1", "ack2", "ack3"] {
            o.push(Publish::reply(topic, "{}"));
        }
        o.push(Publish::telemetry("status", "{}"));
        o.flush(&client);
        // ack1 and ack2 are written (packet ids 1 and 2), the status too (id 0); only ack1
        // is acknowledged before the connection breaks; ack3 never left the request queue.
        o.written(1);
        o.written(0);
        o.written(2);
        o.acknowledged(1);
        o.requeue_unacknowledged();
        assert_eq!(topics(&o.replies), ["ack2", "ack3"]);
        assert!(o.handed.is_empty() && o.unacked.is_empty());
    }

    #[tokio::test]
    async fn flushing_sends_telemetry_first_and_keeps_what_the_client_cannot_take() {
        // A client whose event loop never runs takes exactly its queue's capacity.
        let (client, _eventloop) = AsyncClient::new(MqttOptions::new("t", "127.0.0.1", 1), 3);
        let mut o = outbox(10, 10);
        o.push(Publish::telemetry("status1", "{}"));
        o.push(Publish::reply("ack1", "{}"));
        o.push(Publish::telemetry("status2", "{}"));
        o.push(Publish::reply("ack2", "{}"));
        o.push(Publish::reply("ack3", "{}"));
        o.flush(&client);
        assert!(o.telemetry.is_empty(), "status went ahead of the replies");
        assert_eq!(topics(&o.replies), ["ack2", "ack3"]);
    }
}
