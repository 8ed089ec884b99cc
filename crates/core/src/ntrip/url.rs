//! The caster's address in RTKLIB's form: `ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT`
//! (`ntrips://` for TLS). User and password may be percent-encoded; the password never
//! appears in `Debug` or `Display`.

use std::fmt;

/// The port when the URL names none (the NTRIP convention; 443 over TLS).
pub const DEFAULT_PORT: u16 = 2101;
/// The port of `ntrips://` without one.
pub const DEFAULT_TLS_PORT: u16 = 443;

/// A password that never prints.
#[derive(Clone, Default, PartialEq, Eq)]
pub struct Password(String);

impl Password {
    /// Wraps a password.
    pub fn new(p: impl Into<String>) -> Self {
        Self(p.into())
    }

    /// The password itself, for the Authorization header only.
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for Password {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("\"***\"")
    }
}

/// A parsed caster address.
#[derive(Clone, PartialEq, Eq)]
pub struct NtripUrl {
    /// TLS (`ntrips://`).
    pub tls: bool,
    /// User name ("" for none).
    pub user: String,
    /// Password (empty for none).
    pub password: Password,
    /// Host name or address (an IPv6 address without its brackets).
    pub host: String,
    /// TCP port.
    pub port: u16,
    /// Mountpoint, without the slash.
    pub mountpoint: String,
}

/// What is wrong with a URL, and how to write it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{problem} (write ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT, or ntrips:// for TLS)")]
pub struct UrlError {
    /// The problem.
    pub problem: String,
}

fn err(problem: impl Into<String>) -> UrlError {
    UrlError {
        problem: problem.into(),
    }
}

/// Decodes `%XX` escapes.
fn percent_decode(s: &str, what: &str) -> Result<String, UrlError> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = bytes
                .get(i + 1..i + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| err(format!("the {what} has a % not followed by two hex digits")))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| err(format!("the {what} is not UTF-8 once decoded")))
}

impl NtripUrl {
    /// Parses `text`.
    pub fn parse(text: &str) -> Result<Self, UrlError> {
        let text = text.trim();
        let (tls, rest) = if let Some(r) = text.strip_prefix("ntrip://") {
            (false, r)
        } else if let Some(r) = text.strip_prefix("ntrips://") {
            (true, r)
        } else {
            return Err(err("the URL must start with ntrip:// or ntrips://"));
        };
        let (authority, mountpoint) = rest
            .split_once('/')
            .ok_or_else(|| err("no mountpoint after the host"))?;
        let mountpoint = percent_decode(mountpoint, "mountpoint")?;
        if mountpoint.is_empty() {
            return Err(err("the mountpoint is empty"));
        }
        if !mountpoint
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_.~".contains(c))
        {
            return Err(err(format!(
                "the mountpoint {mountpoint:?} has characters a caster does not use (letters, \
                 digits, - _ . ~)"
            )));
        }
        // The last @ separates the credentials: a password may hold an unescaped @.
        let (credentials, host_port) = match authority.rsplit_once('@') {
            Some((c, h)) => (Some(c), h),
            None => (None, authority),
        };
        let (user, password) = match credentials {
            None => (String::new(), String::new()),
            Some(c) => match c.split_once(':') {
                Some((u, p)) => (percent_decode(u, "user")?, percent_decode(p, "password")?),
                None => (percent_decode(c, "user")?, String::new()),
            },
        };
        if user.contains(':') {
            return Err(err(
                "the user name holds a colon, which Basic authentication cannot carry",
            ));
        }
        let (host, port) = split_host_port(host_port)?;
        let port = port.unwrap_or(if tls { DEFAULT_TLS_PORT } else { DEFAULT_PORT });
        Ok(Self {
            tls,
            user,
            password: Password::new(password),
            host,
            port,
            mountpoint,
        })
    }

    /// `host:port` for a connect (IPv6 in brackets).
    pub fn address(&self) -> String {
        if self.host.contains(':') {
            format!("[{}]:{}", self.host, self.port)
        } else {
            format!("{}:{}", self.host, self.port)
        }
    }
}

fn split_host_port(s: &str) -> Result<(String, Option<u16>), UrlError> {
    let (host, port) = if let Some(rest) = s.strip_prefix('[') {
        let (h, after) = rest
            .split_once(']')
            .ok_or_else(|| err("an IPv6 address without its closing ]"))?;
        let port = match after {
            "" => None,
            p => Some(
                p.strip_prefix(':')
                    .ok_or_else(|| err("junk after the IPv6 address"))?,
            ),
        };
        (h.to_owned(), port)
    } else {
        match s.rsplit_once(':') {
            Some((h, p)) => (h.to_owned(), Some(p)),
            None => (s.to_owned(), None),
        }
    };
    if host.is_empty() {
        return Err(err("no host"));
    }
    if !host
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "-.:".contains(c))
    {
        return Err(err(format!("the host {host:?} is not a name or address")));
    }
    let port = match port {
        None => None,
        Some(p) => Some(
            p.parse::<u16>()
                .ok()
                .filter(|p| *p > 0)
                .ok_or_else(|| err(format!("the port {p:?} is not 1 to 65535")))?,
        ),
    };
    Ok((host, port))
}

impl fmt::Display for NtripUrl {
    /// The URL with the password as `***`: safe for logs and status.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let scheme = if self.tls { "ntrips" } else { "ntrip" };
        write!(f, "{scheme}://")?;
        if !self.user.is_empty() {
            f.write_str(&self.user)?;
            if !self.password.expose().is_empty() {
                f.write_str(":***")?;
            }
            f.write_str("@")?;
        }
        write!(f, "{}/{}", self.address(), self.mountpoint)
    }
}

impl fmt::Debug for NtripUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "NtripUrl({self})")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rtklib_form_parses() {
        let u = NtripUrl::parse("ntrip://me:s3cr%40t@caster.example.org:2102/MOUNT_1").unwrap();
        assert!(!u.tls);
        assert_eq!(u.user, "me");
        assert_eq!(u.password.expose(), "s3cr@t");
        assert_eq!(u.host, "caster.example.org");
        assert_eq!(u.port, 2102);
        assert_eq!(u.mountpoint, "MOUNT_1");
        let u = NtripUrl::parse("ntrips://rtk2go.com/NEAR").unwrap();
        assert!(u.tls && u.port == 443 && u.user.is_empty());
        let u = NtripUrl::parse("ntrip://u:p@[::1]/M").unwrap();
        assert_eq!(
            (u.host.as_str(), u.port, u.address().as_str()),
            ("::1", 2101, "[::1]:2101")
        );
        // An unescaped @ in the password: the last one ends the credentials.
        let u = NtripUrl::parse("ntrip://u:p@ss@h:1/M").unwrap();
        assert_eq!(u.password.expose(), "p@ss");
    }

    #[test]
    fn the_password_never_prints() {
        let u = NtripUrl::parse("ntrip://me:hunter2@h:2101/M").unwrap();
        for shown in [
            format!("{u}"),
            format!("{u:?}"),
            format!("{:?}", u.password),
        ] {
            assert!(!shown.contains("hunter2"), "{shown}");
        }
        assert_eq!(u.to_string(), "ntrip://me:***@h:2101/M");
    }

    #[test]
    fn bad_urls_say_what_is_wrong() {
        for (url, says) in [
            ("http://h/M", "must start with"),
            ("ntrip://h:2101", "no mountpoint"),
            ("ntrip://h:2101/", "mountpoint is empty"),
            ("ntrip://h:99999/M", "port"),
            ("ntrip://h:0/M", "port"),
            ("ntrip://u:p@/M", "no host"),
            ("ntrip://h/M\r\nX: y", "mountpoint"),
            ("ntrip://h/a b", "mountpoint"),
            ("ntrip://u:%zz@h/M", "password"),
            ("ntrip://bad host/M", "host"),
        ] {
            let e = NtripUrl::parse(url).unwrap_err().to_string();
            assert!(e.contains(says), "{url}: {e}");
            assert!(
                e.contains("ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT"),
                "{e}"
            );
        }
    }
}
