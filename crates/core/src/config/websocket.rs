//! `[websocket]`: the rosbridge v2 server of device-mqtt-api.md's WebSocket topics.

use std::net::SocketAddr;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{ConfigError, check_range};

/// `[websocket]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WebsocketConfig {
    /// Address and port to listen on (rosbridge's usual port is 9090). The default is this
    /// computer only; `0.0.0.0:9090` opens it to the network, where a `token` belongs.
    #[serde(default = "default_bind")]
    pub bind: String,
    /// When set, a client must present it (rosbridge's `auth` operation with the token as
    /// `mac`, or `?token=` in the URL) before anything else.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub token: Option<String>,
    /// Messages waiting for one client before its oldest are dropped (and counted).
    #[serde(default = "default_client_queue")]
    pub client_queue: usize,
    /// Authenticated clients served at once; more are turned away. With a token, clients
    /// still to present it have as many places again, apart, for 20 s each.
    #[serde(default = "default_max_clients")]
    pub max_clients: usize,
    /// Messages a client may publish per second (beyond it they are refused with a status).
    #[serde(default = "default_command_rate_hz")]
    pub command_rate_hz: f64,
    /// Web pages (origins, as `http://host:port`) that may open a WebSocket besides
    /// chassisd's own page. Clients that send no `Origin` (roslibpy, Foxglove's native
    /// client) are always let through to the token check.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub allowed_origins: Vec<String>,
    /// `/odom`'s rate, Hz (1 to the control loop's 100).
    #[serde(default = "default_odom_rate_hz")]
    pub odom_rate_hz: f64,
}

fn default_bind() -> String {
    "127.0.0.1:9090".into()
}

fn default_client_queue() -> usize {
    256
}

fn default_max_clients() -> usize {
    16
}

fn default_command_rate_hz() -> f64 {
    50.0
}

fn default_odom_rate_hz() -> f64 {
    50.0
}

impl Default for WebsocketConfig {
    fn default() -> Self {
        Self {
            bind: default_bind(),
            token: None,
            client_queue: default_client_queue(),
            max_clients: default_max_clients(),
            command_rate_hz: default_command_rate_hz(),
            allowed_origins: Vec::new(),
            odom_rate_hz: default_odom_rate_hz(),
        }
    }
}

impl WebsocketConfig {
    /// The defaults, listening on `bind` (`--websocket ADDR`).
    pub fn with_bind(bind: &str) -> Self {
        Self {
            bind: bind.to_owned(),
            ..Self::default()
        }
    }

    /// The address to listen on.
    pub fn address(&self) -> Option<SocketAddr> {
        self.bind.parse().ok()
    }

    /// Checks the values; `file` names the configuration in the error.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        if self.address().is_none() {
            return Err(ConfigError::invalid(
                file,
                "websocket.bind",
                format!("{:?} is not an address and port", self.bind),
                "write it as \"127.0.0.1:9090\" (this computer) or \"0.0.0.0:9090\" (every \
                 interface)",
            ));
        }
        if self.token.is_none()
            && let Some(address) = self.address()
            && !address.ip().is_loopback()
        {
            return Err(ConfigError::invalid(
                file,
                "websocket.token",
                format!(
                    "is not set, and the server would listen on {address} beyond this \
                     computer: anyone on the network could drive the vehicle"
                ),
                if file == Path::new("--websocket") {
                    // The simulator's flag: it has no configuration to hold a token.
                    "use --websocket 127.0.0.1:PORT to keep it to this computer, or \
                     `chassisd run` with websocket.token set in its configuration"
                } else {
                    "set websocket.token to a long random string (e.g. from `openssl rand -hex \
                     16`), or bind = \"127.0.0.1:9090\" to keep it to this computer"
                },
            ));
        }
        for origin in &self.allowed_origins {
            if !is_origin(origin) {
                return Err(ConfigError::invalid(
                    file,
                    "websocket.allowed_origins",
                    format!("{origin:?} is not an origin"),
                    "write each as a browser sends it: scheme, host and port, no path, e.g. \
                     \"http://robot.local:9090\"",
                ));
            }
        }
        if let Some(token) = &self.token
            && (token.len() < 8 || token.chars().any(char::is_whitespace))
        {
            return Err(ConfigError::invalid(
                file,
                "websocket.token",
                "is shorter than 8 characters or holds white space",
                "use a long random string, e.g. from `openssl rand -hex 16`",
            ));
        }
        check_range(
            file,
            "websocket.client_queue",
            self.client_queue as f64,
            4.0..=100_000.0,
            "messages",
        )?;
        check_range(
            file,
            "websocket.max_clients",
            self.max_clients as f64,
            1.0..=1000.0,
            "clients",
        )?;
        check_range(
            file,
            "websocket.command_rate_hz",
            self.command_rate_hz,
            1.0..=10_000.0,
            "messages/s",
        )?;
        check_range(
            file,
            "websocket.odom_rate_hz",
            self.odom_rate_hz,
            1.0..=100.0,
            "Hz",
        )
    }
}

/// Whether `s` is an origin as browsers send it: `http` or `https`, a host, a port at most,
/// nothing after.
fn is_origin(s: &str) -> bool {
    let Some(rest) = s
        .strip_prefix("http://")
        .or_else(|| s.strip_prefix("https://"))
    else {
        return false;
    };
    !rest.is_empty()
        && !rest.contains(['/', '?', '#', '@'])
        && !rest.chars().any(|c| c.is_whitespace() || c.is_control())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_server_open_to_the_network_needs_a_token() {
        let file = Path::new("v.toml");
        let open = WebsocketConfig::with_bind("0.0.0.0:9090");
        let e = open.validate(file).unwrap_err().to_string();
        assert!(
            e.contains("websocket.token") && e.contains("127.0.0.1:9090"),
            "{e}"
        );
        let guarded = WebsocketConfig {
            token: Some("0123456789abcdef".into()),
            ..open
        };
        assert!(guarded.validate(file).is_ok());
        assert!(
            WebsocketConfig::with_bind("[::1]:9090")
                .validate(file)
                .is_ok()
        );
    }

    #[test]
    fn allowed_origins_are_origins() {
        let file = Path::new("v.toml");
        let with = |o: &str| WebsocketConfig {
            allowed_origins: vec![o.into()],
            ..WebsocketConfig::default()
        };
        assert!(with("http://robot.local:9090").validate(file).is_ok());
        assert!(with("https://ops.example.com").validate(file).is_ok());
        for bad in [
            "robot.local",
            "http://",
            "http://a/b",
            "ftp://a",
            "http://a b",
        ] {
            assert!(with(bad).validate(file).is_err(), "{bad}");
        }
    }

    #[test]
    fn addresses_and_tokens_are_checked_with_the_fix() {
        let file = Path::new("v.toml");
        assert!(WebsocketConfig::default().validate(file).is_ok());
        let e = WebsocketConfig::with_bind("localhost")
            .validate(file)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("websocket.bind") && e.contains("0.0.0.0:9090"),
            "{e}"
        );
        let e = WebsocketConfig {
            token: Some("short".into()),
            ..WebsocketConfig::default()
        }
        .validate(file)
        .unwrap_err()
        .to_string();
        assert!(e.contains("openssl rand"), "{e}");
        for rate in [0.5, 101.0, f64::NAN] {
            let e = WebsocketConfig {
                odom_rate_hz: rate,
                ..WebsocketConfig::default()
            }
            .validate(file)
            .unwrap_err()
            .to_string();
            assert!(e.contains("websocket.odom_rate_hz"), "{rate}: {e}");
        }
    }
}
