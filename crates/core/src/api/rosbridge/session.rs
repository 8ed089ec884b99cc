//! One client's rosbridge session, sans-IO: its authentication, its status level and its
//! subscriptions (each with its throttle and queue length), and what each operation it sends
//! asks of the server. The server's task moves the bytes and keeps the queues; what an
//! operation means is decided here, with the time passed in, so a new operation is a change
//! to this folder alone.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use super::adapter;
use super::ops::{self, ClientOp, Level};
use super::topics::{self, Flow};

/// Subscriptions one client may hold on one topic.
pub const MAX_SUBSCRIPTIONS: usize = 16;
/// Wrong tokens a client may send; the last one closes its connection.
pub const MAX_AUTH_FAILURES: u32 = 5;
/// After a wrong token, no other is checked for this long, doubled each time (1, 2, 4, 8 s).
pub const AUTH_DELAY: Duration = Duration::from_secs(1);

/// One subscription of a client.
#[derive(Debug, Clone)]
struct Subscription {
    id: Option<String>,
    throttle: Duration,
    queue_length: usize,
    last_sent: Option<Instant>,
}

/// What the server does for an operation.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// A `status` message of this level, sent when the client wants the level.
    Status(Level, String),
    /// A service response.
    Answer(String),
    /// The connection closes (after what is queued).
    Close,
    /// The client subscribed to this latched topic ([`topics::Topic::is_latched`]): its last message goes to it at
    /// once.
    SubscribedToLatched(&'static str),
    /// A message for the engine on `name` (a topic clients publish, its check passed), as
    /// the client named it in `topic`, with the operation's `id`.
    Publish {
        /// The topic table's name.
        name: &'static str,
        /// The topic as the client gave it.
        topic: String,
        /// The message.
        msg: Value,
        /// The operation's id.
        id: Option<String>,
    },
}

/// One connected client.
#[derive(Debug, Clone)]
pub struct Session {
    /// Presented the token (or none is needed).
    pub authenticated: bool,
    /// The lowest level of status messages it wants.
    pub level: Level,
    /// Wrong tokens it sent.
    auth_failures: u32,
    /// No token is checked for it before this (after a wrong one).
    locked_until: Option<Instant>,
    /// Its subscriptions, by topic.
    subscriptions: BTreeMap<&'static str, Vec<Subscription>>,
}

impl Session {
    /// A new session, authenticated already when no token is needed or the handshake
    /// carried it.
    pub fn new(authenticated: bool) -> Self {
        Self {
            authenticated,
            level: Level::Info,
            auth_failures: 0,
            locked_until: None,
            subscriptions: BTreeMap::new(),
        }
    }

    /// Whether the client wants a status message of `level`.
    pub fn wants_level(&self, level: Level) -> bool {
        level >= self.level
    }

    /// Adds a subscription to `topic`; refused beyond [`MAX_SUBSCRIPTIONS`] on one topic
    /// (a client subscribing in a loop must not grow the server without end).
    pub fn subscribe(
        &mut self,
        topic: &'static str,
        id: Option<String>,
        throttle: Duration,
        queue_length: usize,
    ) -> Result<(), String> {
        let subs = self.subscriptions.entry(topic).or_default();
        // The same id again replaces its subscription (a client re-subscribing).
        subs.retain(|s| id.is_none() || s.id != id);
        if subs.len() >= MAX_SUBSCRIPTIONS {
            return Err(format!(
                "{topic} has {MAX_SUBSCRIPTIONS} subscriptions of this client already; \
                 unsubscribe first"
            ));
        }
        subs.push(Subscription {
            id,
            throttle,
            queue_length,
            last_sent: None,
        });
        Ok(())
    }

    /// Ends the subscription `id` on `topic`, or every one on `topic` without an id.
    pub fn unsubscribe(&mut self, topic: &str, id: Option<&str>) {
        if let Some(subs) = self.subscriptions.get_mut(topic) {
            match id {
                Some(id) => subs.retain(|s| s.id.as_deref() != Some(id)),
                None => subs.clear(),
            }
            if subs.is_empty() {
                self.subscriptions.remove(topic);
            }
        }
    }

    /// Whether any subscription on `topic` would take a message at `now`.
    pub fn wants(&self, topic: &str, now: Instant) -> bool {
        self.subscriptions
            .get(topic)
            .is_some_and(|subs| subs.iter().any(|s| due(s, now)))
    }

    /// Takes a message on `topic` at `now` if a subscription is due (once, however many
    /// subscribe): the queue length it may wait in, or `None` when none is due.
    pub fn take(&mut self, topic: &str, now: Instant) -> Option<usize> {
        let subs = self.subscriptions.get_mut(topic)?;
        let mut keep = None;
        for s in subs.iter_mut().filter(|s| due(s, now)) {
            s.last_sent = Some(now);
            keep = Some(keep.unwrap_or(0).max(s.queue_length));
        }
        keep
    }

    /// Wrong tokens it sent so far (the server sums them up in its log).
    pub fn auth_failures(&self) -> u32 {
        self.auth_failures
    }

    /// What the operation `text` asks at `now`; `token` is the configured one.
    pub fn on_op(&mut self, text: &str, now: Instant, token: Option<&str>) -> Vec<Action> {
        let op = match ops::parse(text) {
            Ok(op) => op,
            Err(refusal) => return vec![Action::Status(Level::Error, refusal.status())],
        };
        if !self.authenticated {
            return self.authenticate(op, now, token);
        }
        let refuse = |op_id: Option<&str>, reason: &str| {
            vec![Action::Status(
                Level::Error,
                ops::status(Level::Error, op_id, reason),
            )]
        };
        match op {
            ClientOp::Auth { .. } | ClientOp::Unadvertise { .. } => Vec::new(),
            ClientOp::SetLevel { level, .. } => {
                self.level = level;
                Vec::new()
            }
            ClientOp::Subscribe {
                id: sub_id,
                topic,
                msg_type,
                throttle_ms,
                queue_length,
            } => match topics::find(&topic) {
                Some(t) if matches!(t.flow, Flow::Published(_)) => {
                    match msg_type.filter(|given| !topics::type_matches(t, given)) {
                        Some(given) => refuse(
                            sub_id.as_deref(),
                            &format!("subscribe: {topic} is {}, not {given}", t.msg_type),
                        ),
                        None => {
                            let op_id = sub_id.clone();
                            match self.subscribe(
                                t.name,
                                sub_id,
                                Duration::from_millis(throttle_ms),
                                queue_length,
                            ) {
                                Err(reason) => {
                                    refuse(op_id.as_deref(), &format!("subscribe: {reason}"))
                                }
                                Ok(()) if t.is_latched() => {
                                    vec![Action::SubscribedToLatched(t.name)]
                                }
                                Ok(()) => Vec::new(),
                            }
                        }
                    }
                }
                Some(t) => refuse(
                    sub_id.as_deref(),
                    &format!(
                        "subscribe: {topic} ({}) is published by clients, not by chassisd",
                        t.msg_type
                    ),
                ),
                None => refuse(sub_id.as_deref(), &unknown_topic("subscribe", &topic)),
            },
            ClientOp::Unsubscribe { id: sub_id, topic } => {
                self.unsubscribe(&topic, sub_id.as_deref());
                Vec::new()
            }
            ClientOp::Advertise {
                id: op_id,
                topic,
                msg_type,
            } => match topics::find(&topic) {
                Some(t)
                    if matches!(t.flow, Flow::Subscribed) && topics::type_matches(t, &msg_type) =>
                {
                    Vec::new()
                }
                Some(t) if matches!(t.flow, Flow::Subscribed) => refuse(
                    op_id.as_deref(),
                    &format!("advertise: {topic} is {}, not {msg_type}", t.msg_type),
                ),
                Some(t) => refuse(
                    op_id.as_deref(),
                    &format!("advertise: {topic} ({}) is chassisd's own", t.msg_type),
                ),
                None => refuse(op_id.as_deref(), &unknown_topic("advertise", &topic)),
            },
            ClientOp::CallService {
                id: op_id,
                service,
                args,
            } => vec![Action::Answer(ops::service_response(
                &service,
                op_id.as_deref(),
                call_service(&service, &args),
            ))],
            ClientOp::Publish {
                id: op_id,
                topic,
                msg,
            } => {
                let refuse = |reason: &str| refuse(op_id.as_deref(), &format!("publish: {reason}"));
                match topics::find(&topic) {
                    Some(t) if matches!(t.flow, Flow::Subscribed) => {
                        match adapter::check(t.name, &topic, &msg) {
                            Ok(()) => vec![Action::Publish {
                                name: t.name,
                                topic,
                                msg,
                                id: op_id,
                            }],
                            Err(reason) => refuse(&reason),
                        }
                    }
                    Some(t) => refuse(&format!("{topic} ({}) is chassisd's own", t.msg_type)),
                    None => refuse(&unknown_topic("publish", &topic)),
                }
            }
        }
    }

    /// An operation from a client that has not authenticated: only `auth` is taken, and a
    /// wrong token costs it time, then its connection.
    fn authenticate(&mut self, op: ClientOp, now: Instant, token: Option<&str>) -> Vec<Action> {
        let status =
            |level: Level, text: &str| Action::Status(level, ops::status(level, None, text));
        if let Some(until) = self.locked_until.filter(|&u| now < u) {
            let wait = until.duration_since(now).as_secs_f64();
            let text = format!("authentication: wait {wait:.1} s before trying again");
            return vec![status(Level::Error, &text)];
        }
        match op {
            ClientOp::Auth { token: given } if token_matches(token, &given) => {
                self.authenticated = true;
                vec![status(Level::Info, "authenticated")]
            }
            ClientOp::Auth { .. } => {
                self.auth_failures += 1;
                let n = self.auth_failures;
                if n >= MAX_AUTH_FAILURES {
                    let text = format!("authentication failed {n} times: the connection closes");
                    return vec![Action::Close, status(Level::Error, &text)];
                }
                let delay = AUTH_DELAY * 2u32.pow(n - 1);
                self.locked_until = Some(now + delay);
                let text = format!(
                    "authentication failed ({n} of {MAX_AUTH_FAILURES}); the next try is \
                     taken after {} s",
                    delay.as_secs()
                );
                vec![status(Level::Error, &text)]
            }
            _ => vec![status(
                Level::Error,
                "authenticate first: send {\"op\": \"auth\", \"mac\": TOKEN} or connect \
                 with ?token=TOKEN (websocket.token)",
            )],
        }
    }
}

fn due(s: &Subscription, now: Instant) -> bool {
    s.last_sent
        .is_none_or(|last| now.saturating_duration_since(last) >= s.throttle)
}

/// Whether `given` is the configured token, compared in a time that does not depend on
/// where they differ.
pub fn token_matches(configured: Option<&str>, given: &str) -> bool {
    configured.is_some_and(|c| crate::secret::matches(c.as_bytes(), given.as_bytes()))
}

/// Why `topic` is not one of the server's, for `op`.
fn unknown_topic(op: &str, topic: &str) -> String {
    match topics::refusal(topic) {
        Some(reason) => format!("{op}: {reason}"),
        None => format!(
            "{op}: no topic {topic}; chassisd's topics are {}",
            topics::TOPICS
                .iter()
                .map(|t| t.name)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The services a client may call: rosapi's topic list and topic type.
fn call_service(service: &str, args: &Value) -> Result<Value, String> {
    match service {
        "/rosapi/topics" => Ok(json!({
            "topics": topics::TOPICS.iter().map(|t| t.name).collect::<Vec<_>>(),
            "types": topics::TOPICS.iter().map(|t| t.msg_type).collect::<Vec<_>>(),
        })),
        "/rosapi/topic_type" => {
            let topic = args.get("topic").and_then(Value::as_str).unwrap_or("");
            Ok(json!({"type": topics::find(topic).map_or("", |t| t.msg_type)}))
        }
        other => Err(format!(
            "no service {other}; chassisd answers /rosapi/topics and /rosapi/topic_type"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn op(session: &mut Session, text: &str, now: Instant) -> Vec<Action> {
        session.on_op(text, now, Some("s3cret-token"))
    }

    fn is_error(actions: &[Action], needle: &str) -> bool {
        actions
            .iter()
            .any(|a| matches!(a, Action::Status(Level::Error, t) if t.contains(needle)))
    }

    #[test]
    fn a_throttled_subscription_takes_one_message_per_period() {
        let mut s = Session::new(true);
        s.subscribe("/pose", None, Duration::from_millis(500), 10)
            .unwrap();
        let t0 = Instant::now();
        let taken: Vec<bool> = (0..10)
            .map(|i| {
                s.take("/pose", t0 + Duration::from_millis(100 * i))
                    .is_some()
            })
            .collect();
        assert_eq!(
            taken,
            [
                true, false, false, false, false, true, false, false, false, false
            ]
        );
    }

    #[test]
    fn subscriptions_on_a_topic_are_bounded() {
        let mut s = Session::new(true);
        for _ in 0..MAX_SUBSCRIPTIONS {
            s.subscribe("/pose", None, Duration::ZERO, 1).unwrap();
        }
        assert!(s.subscribe("/pose", None, Duration::ZERO, 1).is_err());
        // Re-subscribing under an id it holds replaces that one.
        let mut s = Session::new(true);
        for i in 0..MAX_SUBSCRIPTIONS {
            s.subscribe("/pose", Some(i.to_string()), Duration::ZERO, 1)
                .unwrap();
        }
        assert!(
            s.subscribe("/pose", Some("3".into()), Duration::ZERO, 1)
                .is_ok()
        );
    }

    #[test]
    fn unsubscribing_by_id_keeps_the_others_and_the_longest_queue_wins() {
        let mut s = Session::new(true);
        s.subscribe("/pose", Some("a".into()), Duration::ZERO, 1)
            .unwrap();
        s.subscribe("/pose", Some("b".into()), Duration::ZERO, 5)
            .unwrap();
        assert_eq!(s.take("/pose", Instant::now()), Some(5));
        s.unsubscribe("/pose", Some("a"));
        assert!(s.wants("/pose", Instant::now()));
        s.unsubscribe("/pose", Some("b"));
        assert!(!s.wants("/pose", Instant::now()));
    }

    #[test]
    fn only_the_configured_token_matches() {
        assert!(token_matches(Some("s3cret-token"), "s3cret-token"));
        assert!(!token_matches(Some("s3cret-token"), "s3cret-tokeN"));
        assert!(!token_matches(Some("s3cret-token"), "s3cret"));
        assert!(!token_matches(
            Some("s3cret-token"),
            "s3cret-token-and-more"
        ));
        assert!(!token_matches(Some("s3cret-token"), ""));
        assert!(!token_matches(None, "anything"));
    }

    #[test]
    fn nothing_but_auth_is_taken_before_it_and_wrong_tokens_cost_time_then_the_connection() {
        let mut s = Session::new(false);
        let t0 = Instant::now();
        let sub = r#"{"op":"subscribe","topic":"/pose"}"#;
        assert!(is_error(&op(&mut s, sub, t0), "authenticate first"));
        let wrong = r#"{"op":"auth","mac":"nope"}"#;
        assert!(is_error(&op(&mut s, wrong, t0), "(1 of 5)"));
        // Locked for a second: even the right token waits.
        let right = r#"{"op":"auth","mac":"s3cret-token"}"#;
        assert!(is_error(&op(&mut s, right, t0), "wait"));
        let mut t = t0 + Duration::from_secs(1);
        for n in 2..MAX_AUTH_FAILURES {
            assert!(is_error(&op(&mut s, wrong, t), &format!("({n} of 5)")));
            t += AUTH_DELAY * 2u32.pow(n - 1);
        }
        let last = op(&mut s, wrong, t);
        assert_eq!(last.first(), Some(&Action::Close));
        assert!(!s.authenticated);
        let mut fresh = Session::new(false);
        let ok = op(&mut fresh, right, t0);
        assert!(fresh.authenticated);
        assert!(matches!(&ok[..], [Action::Status(Level::Info, t)] if t.contains("authenticated")));
    }

    #[test]
    fn publishes_are_checked_against_the_topic_table() {
        let mut s = Session::new(true);
        let now = Instant::now();
        let twist = r#"{"op":"publish","id":"p1","topic":"/cmd_vel","msg":{"linear":{"x":0.3},"angular":{"z":0.0}}}"#;
        assert!(matches!(
            &op(&mut s, twist, now)[..],
            [Action::Publish { name: "/cmd_vel", id: Some(id), .. }] if id == "p1"
        ));
        let own = r#"{"op":"publish","topic":"/pose","msg":{}}"#;
        assert!(is_error(&op(&mut s, own, now), "chassisd's own"));
        let unknown = r#"{"op":"publish","topic":"/nowhere","msg":{}}"#;
        assert!(is_error(&op(&mut s, unknown, now), "no topic /nowhere"));
        let half = r#"{"op":"publish","topic":"/cmd_vel","msg":{"linear":{"x":0.3}}}"#;
        assert!(is_error(&op(&mut s, half, now), "angular.z"));
    }

    #[test]
    fn subscribing_to_the_plan_asks_for_the_path_under_way_and_services_answer() {
        let mut s = Session::new(true);
        let now = Instant::now();
        let plan = r#"{"op":"subscribe","topic":"/plan"}"#;
        assert_eq!(
            op(&mut s, plan, now),
            [Action::SubscribedToLatched("/plan")]
        );
        let zones = r#"{"op":"subscribe","topic":"/zones"}"#;
        assert_eq!(
            op(&mut s, zones, now),
            [Action::SubscribedToLatched("/zones")]
        );
        assert!(s.wants("/plan", now));
        let wrong_type = r#"{"op":"subscribe","topic":"/pose","type":"std_msgs/String"}"#;
        assert!(is_error(
            &op(&mut s, wrong_type, now),
            "not std_msgs/String"
        ));
        let topics = r#"{"op":"call_service","id":"c1","service":"/rosapi/topics"}"#;
        assert!(matches!(
            &op(&mut s, topics, now)[..],
            [Action::Answer(text)] if text.contains("/wheel_speeds") || text.contains("/pose")
        ));
    }
}
