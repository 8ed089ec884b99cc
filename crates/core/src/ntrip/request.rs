//! The request a client sends for a mountpoint (or for the sourcetable, with an empty one).

use base64::Engine as _;
use base64::engine::general_purpose::STANDARD;

use super::url::NtripUrl;

/// The protocol version asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
pub enum Version {
    /// NTRIP 1.0: `GET /MOUNT HTTP/1.0`, answered `ICY 200 OK`.
    #[serde(rename = "1")]
    V1,
    /// NTRIP 2.0: HTTP/1.1 with `Ntrip-Version: Ntrip/2.0`, usually chunked.
    #[serde(rename = "2")]
    V2,
}

/// What the client calls itself.
pub const USER_AGENT: &str = concat!("NTRIP chassisd/", env!("CARGO_PKG_VERSION"));

/// The request for `url`'s mountpoint (`sourcetable`: for the caster's table instead).
pub fn request(url: &NtripUrl, version: Version, sourcetable: bool) -> String {
    let path = if sourcetable {
        ""
    } else {
        url.mountpoint.as_str()
    };
    let mut r = match version {
        Version::V1 => format!("GET /{path} HTTP/1.0\r\n"),
        Version::V2 => format!(
            "GET /{path} HTTP/1.1\r\nHost: {}\r\nNtrip-Version: Ntrip/2.0\r\n",
            url.address()
        ),
    };
    r.push_str(&format!("User-Agent: {USER_AGENT}\r\n"));
    if !url.user.is_empty() {
        let credentials = format!("{}:{}", url.user, url.password.expose());
        r.push_str(&format!(
            "Authorization: Basic {}\r\n",
            STANDARD.encode(credentials)
        ));
    }
    r.push_str("Connection: close\r\n\r\n");
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_versions_with_basic_authentication() {
        let url = NtripUrl::parse("ntrip://user:pass@caster:2101/MOUNT").unwrap();
        let v1 = request(&url, Version::V1, false);
        assert!(v1.starts_with("GET /MOUNT HTTP/1.0\r\n"), "{v1}");
        // base64("user:pass")
        assert!(v1.contains("Authorization: Basic dXNlcjpwYXNz\r\n"), "{v1}");
        assert!(!v1.contains("Ntrip-Version"));
        assert!(v1.ends_with("\r\n\r\n"));
        let v2 = request(&url, Version::V2, false);
        assert!(
            v2.starts_with("GET /MOUNT HTTP/1.1\r\nHost: caster:2101\r\n"),
            "{v2}"
        );
        assert!(v2.contains("Ntrip-Version: Ntrip/2.0\r\n"));
        let table = request(&url, Version::V2, true);
        assert!(table.starts_with("GET / HTTP/1.1\r\n"));
        let anonymous = NtripUrl::parse("ntrip://caster/MOUNT").unwrap();
        assert!(!request(&anonymous, Version::V1, false).contains("Authorization"));
    }
}
