//! The operations of the rosbridge v2 protocol, as JSON text: what a client may send, and
//! what the server sends back. Parsing never panics; a message that is not an operation, or
//! one this server does not take, becomes a [`Refusal`] that answers with a `status`.

use serde_json::{Map, Value, json};

/// The longest text message a client may send, bytes (a `publish` of a long path fits).
pub const MAX_MESSAGE: usize = 256 * 1024;
/// The most messages a subscription may ask to have queued for it.
pub const MAX_QUEUE_LENGTH: usize = 100;

/// An operation from a client.
#[derive(Debug, Clone, PartialEq)]
pub enum ClientOp {
    /// Announces the client will publish `topic` of `msg_type`.
    Advertise {
        id: Option<String>,
        topic: String,
        msg_type: String,
    },
    /// Takes back an announcement.
    Unadvertise { id: Option<String>, topic: String },
    /// One message on `topic`.
    Publish {
        id: Option<String>,
        topic: String,
        msg: Value,
    },
    /// Asks for `topic`, at most one message per `throttle_ms` (0: every one), with up to
    /// `queue_length` waiting for the client (0: only the newest).
    Subscribe {
        id: Option<String>,
        topic: String,
        msg_type: Option<String>,
        throttle_ms: u64,
        queue_length: usize,
    },
    /// Ends a subscription (the one of `id`, or every one of the client on `topic`).
    Unsubscribe { id: Option<String>, topic: String },
    /// Calls `service` with `args`.
    CallService {
        id: Option<String>,
        service: String,
        args: Value,
    },
    /// The level of `status` messages the client wants.
    SetLevel { id: Option<String>, level: Level },
    /// Presents the access token (the `mac` of rosbridge's `auth`).
    Auth { token: String },
}

/// A `status` message's level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// Every message.
    Info,
    /// Warnings and errors.
    Warning,
    /// Errors only.
    Error,
    /// None.
    None,
}

impl Level {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "info" => Self::Info,
            "warning" => Self::Warning,
            "error" => Self::Error,
            "none" => Self::None,
            _ => return None,
        })
    }

    /// The level's name in the protocol.
    pub fn name(self) -> &'static str {
        match self {
            Self::Info => "info",
            Self::Warning => "warning",
            Self::Error => "error",
            Self::None => "none",
        }
    }
}

/// Why a client's message was not taken: answered with a `status` of level error.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    /// The operation's `id`, when it had one.
    pub id: Option<String>,
    /// The operation, when it could be read.
    pub op: Option<String>,
    /// What is wrong, and what to do.
    pub reason: String,
}

impl Refusal {
    fn new(id: Option<String>, op: Option<&str>, reason: impl Into<String>) -> Self {
        Self {
            id,
            op: op.map(str::to_owned),
            reason: reason.into(),
        }
    }

    /// The `status` message that answers it.
    pub fn status(&self) -> String {
        let msg = match &self.op {
            Some(op) => format!("{op}: {}", self.reason),
            None => self.reason.clone(),
        };
        status(Level::Error, self.id.as_deref(), &msg)
    }
}

/// Reads one text message of a client.
pub fn parse(text: &str) -> Result<ClientOp, Refusal> {
    if text.len() > MAX_MESSAGE {
        return Err(Refusal::new(
            None,
            None,
            format!(
                "message of {} bytes refused: the limit is {MAX_MESSAGE}",
                text.len()
            ),
        ));
    }
    let value: Value = serde_json::from_str(text)
        .map_err(|e| Refusal::new(None, None, format!("not JSON: {e}")))?;
    let Value::Object(fields) = value else {
        return Err(Refusal::new(None, None, "not a JSON object"));
    };
    let id = match fields.get("id") {
        None | Some(Value::Null) => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(Value::Number(n)) => Some(n.to_string()),
        Some(_) => return Err(Refusal::new(None, None, "`id` must be a string")),
    };
    let Some(op) = fields.get("op").and_then(Value::as_str) else {
        return Err(Refusal::new(id, None, "no `op` string"));
    };
    let f = Fields {
        fields: &fields,
        id: &id,
        op,
    };
    Ok(match op {
        "advertise" => ClientOp::Advertise {
            topic: f.name("topic")?,
            msg_type: f.string("type")?,
            id,
        },
        "unadvertise" => ClientOp::Unadvertise {
            topic: f.name("topic")?,
            id,
        },
        "publish" => ClientOp::Publish {
            topic: f.name("topic")?,
            // A message, always: an absent one must never stand for a zero command.
            msg: match fields.get("msg") {
                Some(msg @ Value::Object(_)) => msg.clone(),
                Some(_) => return Err(f.refuse("`msg` must be an object (the message)".into())),
                None => return Err(f.refuse("no `msg` object (the message)".into())),
            },
            id,
        },
        "subscribe" => ClientOp::Subscribe {
            topic: f.name("topic")?,
            msg_type: f.optional_string("type")?,
            throttle_ms: f.optional_u64("throttle_rate")?.unwrap_or(0),
            queue_length: usize::try_from(f.optional_u64("queue_length")?.unwrap_or(1))
                .unwrap_or(usize::MAX)
                .min(MAX_QUEUE_LENGTH),
            id,
        },
        "unsubscribe" => ClientOp::Unsubscribe {
            topic: f.name("topic")?,
            id,
        },
        "call_service" => ClientOp::CallService {
            service: f.name("service")?,
            args: match fields.get("args") {
                None | Some(Value::Null) => Value::Object(Map::new()),
                // roslibjs sends an empty list for a request without fields.
                Some(Value::Array(a)) if a.is_empty() => Value::Object(Map::new()),
                Some(v) => v.clone(),
            },
            id,
        },
        "set_level" => {
            let level = f.string("level")?;
            ClientOp::SetLevel {
                level: Level::parse(&level).ok_or_else(|| {
                    Refusal::new(
                        id.clone(),
                        Some(op),
                        format!("level {level:?}: give info, warning, error or none"),
                    )
                })?,
                id,
            }
        }
        "auth" => ClientOp::Auth {
            token: f.string("mac")?,
        },
        other => {
            return Err(Refusal::new(
                id,
                Some(other),
                "not an operation this server takes (advertise, unadvertise, publish, \
                 subscribe, unsubscribe, call_service, set_level, auth)",
            ));
        }
    })
}

/// The fields of one operation, read with refusals that name the field.
struct Fields<'a> {
    fields: &'a Map<String, Value>,
    id: &'a Option<String>,
    op: &'a str,
}

impl Fields<'_> {
    fn refuse(&self, reason: String) -> Refusal {
        Refusal::new(self.id.clone(), Some(self.op), reason)
    }

    fn string(&self, key: &str) -> Result<String, Refusal> {
        self.optional_string(key)?
            .ok_or_else(|| self.refuse(format!("no `{key}` string")))
    }

    fn optional_string(&self, key: &str) -> Result<Option<String>, Refusal> {
        match self.fields.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.clone())),
            Some(_) => Err(self.refuse(format!("`{key}` must be a string"))),
        }
    }

    /// A topic or service name: absolute, as ROS names go.
    fn name(&self, key: &str) -> Result<String, Refusal> {
        let name = self.string(key)?;
        let valid = name.starts_with('/')
            && name.len() <= 256
            && name[1..]
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/');
        if !valid {
            return Err(self.refuse(format!(
                "`{key}` {name:?} is not an absolute ROS name (e.g. /pose)"
            )));
        }
        Ok(name)
    }

    fn optional_u64(&self, key: &str) -> Result<Option<u64>, Refusal> {
        match self.fields.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(Value::Number(n)) => n
                .as_u64()
                .or_else(|| n.as_f64().filter(|f| *f >= 0.0).map(|f| f.min(1e12) as u64))
                .map(Some)
                .ok_or_else(|| self.refuse(format!("`{key}` must not be negative"))),
            Some(_) => Err(self.refuse(format!("`{key}` must be a number"))),
        }
    }
}

/// A `publish` message of the server.
pub fn publish(topic: &str, msg: &Value) -> String {
    json!({"op": "publish", "topic": topic, "msg": msg}).to_string()
}

/// A `service_response` message of the server.
pub fn service_response(service: &str, id: Option<&str>, result: Result<Value, String>) -> String {
    let mut m = Map::new();
    m.insert("op".into(), "service_response".into());
    if let Some(id) = id {
        m.insert("id".into(), id.into());
    }
    m.insert("service".into(), service.into());
    match result {
        Ok(values) => {
            m.insert("values".into(), values);
            m.insert("result".into(), true.into());
        }
        // rosbridge sends the error text as the values of a failed call.
        Err(reason) => {
            m.insert("values".into(), reason.into());
            m.insert("result".into(), false.into());
        }
    }
    Value::Object(m).to_string()
}

/// A `status` message of the server.
pub fn status(level: Level, id: Option<&str>, msg: &str) -> String {
    let mut m = Map::new();
    m.insert("op".into(), "status".into());
    if let Some(id) = id {
        m.insert("id".into(), id.into());
    }
    m.insert("level".into(), level.name().into());
    m.insert("msg".into(), msg.into());
    Value::Object(m).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_operations_of_roslibjs_are_read() {
        assert_eq!(
            parse(
                r#"{"op":"subscribe","id":"subscribe:/pose:1","type":"geometry_msgs/PoseWithCovarianceStamped","topic":"/pose","compression":"none","throttle_rate":100,"queue_length":2}"#
            ),
            Ok(ClientOp::Subscribe {
                id: Some("subscribe:/pose:1".into()),
                topic: "/pose".into(),
                msg_type: Some("geometry_msgs/PoseWithCovarianceStamped".into()),
                throttle_ms: 100,
                queue_length: 2,
            })
        );
        assert_eq!(
            parse(r#"{"op":"publish","topic":"/cmd_vel","msg":{"linear":{"x":0.2,"y":0,"z":0},"angular":{"x":0,"y":0,"z":0}}}"#)
                .map(|op| matches!(op, ClientOp::Publish { ref topic, .. } if topic == "/cmd_vel")),
            Ok(true)
        );
        assert_eq!(
            parse(
                r#"{"op":"call_service","id":"call_service:/rosapi/topics:3","service":"/rosapi/topics","args":[]}"#
            ),
            Ok(ClientOp::CallService {
                id: Some("call_service:/rosapi/topics:3".into()),
                service: "/rosapi/topics".into(),
                args: json!({}),
            })
        );
        assert_eq!(
            parse(r#"{"op":"subscribe","topic":"/odom"}"#),
            Ok(ClientOp::Subscribe {
                id: None,
                topic: "/odom".into(),
                msg_type: None,
                throttle_ms: 0,
                queue_length: 1,
            })
        );
    }

    #[test]
    fn bad_messages_are_refused_with_the_field_and_the_id() {
        let refusal = |text: &str| parse(text).expect_err(text);
        assert!(refusal("nonsense").reason.starts_with("not JSON"));
        assert_eq!(refusal("[1]").reason, "not a JSON object");
        let r = refusal(r#"{"op":"subscribe","id":"a","topic":"pose"}"#);
        assert_eq!(r.id.as_deref(), Some("a"));
        assert!(
            r.status().contains("not an absolute ROS name"),
            "{}",
            r.status()
        );
        let r = refusal(r#"{"op":"subscribe","topic":"/pose","throttle_rate":-5}"#);
        assert!(r.reason.contains("must not be negative"));
        let r = refusal(r#"{"op":"fragment","id":"x"}"#);
        assert!(r.status().contains("\"level\":\"error\""));
        assert!(
            refusal(&format!(
                r#"{{"op":"publish","topic":"/a","msg":"{}"}}"#,
                "x".repeat(MAX_MESSAGE)
            ))
            .reason
            .contains("limit")
        );
        let r = refusal(r#"{"op":"set_level","level":"loud"}"#);
        assert!(r.reason.contains("give info"));
    }

    #[test]
    fn queue_lengths_are_bounded() {
        let Ok(ClientOp::Subscribe { queue_length, .. }) =
            parse(r#"{"op":"subscribe","topic":"/pose","queue_length":1000000000000}"#)
        else {
            panic!("a subscription");
        };
        assert_eq!(queue_length, MAX_QUEUE_LENGTH);
    }

    #[test]
    fn answers_have_the_protocols_shape() {
        let v: Value =
            serde_json::from_str(&service_response("/x", Some("7"), Err("no".into()))).unwrap();
        assert_eq!(
            v,
            json!({"op":"service_response","id":"7","service":"/x","values":"no","result":false})
        );
        let v: Value = serde_json::from_str(&status(Level::Warning, None, "m")).unwrap();
        assert_eq!(v, json!({"op":"status","level":"warning","msg":"m"}));
    }
}
