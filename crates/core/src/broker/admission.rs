//! Who the embedded broker lets in: credentials, a client identifier the broker can route,
//! and a client limit with one place kept for chassisd's own client.

use super::wire::{Connect, Refusal, Version};

/// The user name and password every client must present.
#[derive(Clone, PartialEq, Eq)]
pub struct Credentials {
    /// The user name.
    pub username: String,
    /// The password.
    pub password: String,
}

impl std::fmt::Debug for Credentials {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // The password never reaches a log.
        f.debug_struct("Credentials")
            .field("username", &self.username)
            .finish_non_exhaustive()
    }
}

/// The longest client identifier let through, bytes: far beyond any real client's, short
/// enough that a flood of them costs little.
pub const MAX_CLIENT_ID: usize = 256;

/// The gate's rules.
#[derive(Debug, Clone)]
pub struct Policy {
    /// Required of every client when set; without it, anyone who reaches the port is let in
    /// (allowed on loopback only: the configuration refuses it elsewhere).
    pub credentials: Option<Credentials>,
    /// Clients connected at once, chassisd's own not counted.
    pub max_clients: usize,
    /// chassisd's own client identifier: it always finds a place, so a full broker never
    /// silences the vehicle's own status and command link. It carries a part no other
    /// client can guess (`mqtt.client_id_suffix`).
    pub own_client_id: Option<String>,
    /// Identifiers no other client may present: chassisd's own without its unguessable
    /// part, and `mqtt.reserved_client_ids`. MQTT hands an identifier to its newest
    /// connection, so a client presenting chassisd's would close chassisd's session.
    pub reserved_client_ids: Vec<String>,
}

/// Places taken.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Places {
    /// Other clients connected.
    pub clients: usize,
    /// Connections holding chassisd's own client identifier.
    pub own: usize,
}

/// Which place an admitted client holds (given back with [`Places::leave`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// One of `max_clients`.
    Client,
    /// The place kept for chassisd's own client.
    Own,
}

impl Places {
    /// Gives back a place.
    pub fn leave(&mut self, place: Place) {
        match place {
            Place::Client => self.clients = self.clients.saturating_sub(1),
            Place::Own => self.own = self.own.saturating_sub(1),
        }
    }
}

/// How many connections may hold chassisd's own identifier at once: the daemon's link, and
/// its reconnection while the broker still holds the old one.
const OWN_PLACES: usize = 2;

/// Decides on a CONNECT, taking a place when it is admitted.
pub fn admit(policy: &Policy, places: &mut Places, connect: &Connect) -> Result<Place, Refusal> {
    if !matches!(connect.version, Version::V4 | Version::V5) {
        return Err(Refusal::UnacceptableVersion);
    }
    if let Some(required) = &policy.credentials {
        let (Some(user), Some(password)) = (&connect.username, &connect.password) else {
            return Err(Refusal::NotAuthorized);
        };
        // Both compared, always, so the time taken says nothing about which was wrong.
        let user_ok = crate::secret::matches(required.username.as_bytes(), user.as_bytes());
        let password_ok = crate::secret::matches(required.password.as_bytes(), password);
        if !(user_ok & password_ok) {
            return Err(Refusal::BadCredentials);
        }
    }
    if !routable_client_id(&connect.client_id) {
        return Err(Refusal::IdentifierRejected);
    }
    let own = policy
        .own_client_id
        .as_deref()
        .is_some_and(|id| id == connect.client_id);
    if !own && policy.reserved_client_ids.contains(&connect.client_id) {
        return Err(Refusal::ReservedIdentifier);
    }
    if own && places.own < OWN_PLACES {
        places.own += 1;
        return Ok(Place::Own);
    }
    if places.clients >= policy.max_clients {
        return Err(Refusal::ServerUnavailable);
    }
    places.clients += 1;
    Ok(Place::Client)
}

/// Whether the broker can route a client under `id`: rumqttd refuses identifiers with a
/// topic separator or wildcard, and its refusal is not one a client can be told about, so
/// the gate refuses them first. Control characters make log lines lie; very long ones are
/// a flood's tool.
pub fn routable_client_id(id: &str) -> bool {
    id.len() <= MAX_CLIENT_ID
        && !id.contains(['+', '#', '/', '$'])
        && !id.chars().any(char::is_control)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn connect(id: &str, credentials: Option<(&str, &str)>) -> Connect {
        Connect {
            version: Version::V4,
            client_id: id.into(),
            keep_alive_s: 30,
            username: credentials.map(|c| c.0.into()),
            password: credentials.map(|c| c.1.as_bytes().to_vec()),
            will_topic: None,
            max_packet_to_client: None,
            retained_will: None,
        }
    }

    fn policy(max: usize, credentials: bool) -> Policy {
        Policy {
            credentials: credentials.then(|| Credentials {
                username: "op".into(),
                password: "s3cret".into(),
            }),
            max_clients: max,
            own_client_id: Some("chassisd-sim".into()),
            reserved_client_ids: vec!["chassisd".into(), "app-main".into()],
        }
    }

    #[test]
    fn credentials_are_required_when_configured() {
        let p = policy(8, true);
        let mut places = Places::default();
        assert_eq!(
            admit(&p, &mut places, &connect("a", None)),
            Err(Refusal::NotAuthorized)
        );
        assert_eq!(
            admit(&p, &mut places, &connect("a", Some(("op", "wrong")))),
            Err(Refusal::BadCredentials)
        );
        assert_eq!(
            admit(&p, &mut places, &connect("a", Some(("evil", "s3cret")))),
            Err(Refusal::BadCredentials)
        );
        assert_eq!(places, Places::default());
        assert_eq!(
            admit(&p, &mut places, &connect("a", Some(("op", "s3cret")))),
            Ok(Place::Client)
        );
        // chassisd's own identifier needs them too.
        assert_eq!(
            admit(&p, &mut places, &connect("chassisd-sim", None)),
            Err(Refusal::NotAuthorized)
        );
    }

    #[test]
    fn the_limit_refuses_others_but_keeps_a_place_for_chassisd() {
        let p = policy(2, false);
        let mut places = Places::default();
        assert_eq!(
            admit(&p, &mut places, &connect("a", None)),
            Ok(Place::Client)
        );
        assert_eq!(
            admit(&p, &mut places, &connect("b", None)),
            Ok(Place::Client)
        );
        assert_eq!(
            admit(&p, &mut places, &connect("c", None)),
            Err(Refusal::ServerUnavailable)
        );
        assert_eq!(
            admit(&p, &mut places, &connect("chassisd-sim", None)),
            Ok(Place::Own)
        );
        assert_eq!(
            admit(&p, &mut places, &connect("chassisd-sim", None)),
            Ok(Place::Own)
        );
        // A third connection under the daemon's name competes like any other.
        assert_eq!(
            admit(&p, &mut places, &connect("chassisd-sim", None)),
            Err(Refusal::ServerUnavailable)
        );
        places.leave(Place::Client);
        assert_eq!(
            admit(&p, &mut places, &connect("c", None)),
            Ok(Place::Client)
        );
    }

    #[test]
    fn reserved_identifiers_are_refused_to_everyone_else() {
        let p = policy(8, false);
        let mut places = Places::default();
        for id in ["chassisd", "app-main"] {
            assert_eq!(
                admit(&p, &mut places, &connect(id, None)),
                Err(Refusal::ReservedIdentifier),
                "{id}"
            );
        }
        assert_eq!(places, Places::default());
        // The exact own identifier (with its unguessable part) is chassisd's place.
        assert_eq!(
            admit(&p, &mut places, &connect("chassisd-sim", None)),
            Ok(Place::Own)
        );
    }

    #[test]
    fn identifiers_the_broker_cannot_route_are_refused() {
        let p = policy(8, false);
        let mut places = Places::default();
        for id in [
            "a/b",
            "a+b",
            "#",
            "$SYS",
            "a\nb",
            &"x".repeat(MAX_CLIENT_ID + 1),
        ] {
            assert_eq!(
                admit(&p, &mut places, &connect(id, None)),
                Err(Refusal::IdentifierRejected),
                "{id:?}"
            );
        }
        // An empty identifier gets one assigned by the broker.
        assert_eq!(
            admit(&p, &mut places, &connect("", None)),
            Ok(Place::Client)
        );
    }

    #[test]
    fn old_versions_are_refused_as_such() {
        let p = policy(8, false);
        let mut c = connect("a", None);
        c.version = Version::V3;
        assert_eq!(
            admit(&p, &mut Places::default(), &c),
            Err(Refusal::UnacceptableVersion)
        );
    }

    #[test]
    fn the_password_never_reaches_debug_output() {
        let c = Credentials {
            username: "op".into(),
            password: "hunter2".into(),
        };
        assert!(!format!("{c:?}").contains("hunter2"));
    }
}
