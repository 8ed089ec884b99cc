//! NTRIP: RTK corrections from a caster on the internet (a base station's RTCM 3 stream),
//! sans-IO. The connection itself lives in `runtime::links::ntrip`.
//!
//! - [`url`]: the caster's address, with a password that never prints;
//! - [`request`]: the GET a client sends (NTRIP 1.0 or 2.0, Basic authentication);
//! - [`response`]: the caster's head, read tolerantly;
//! - [`chunked`]: NTRIP 2.0's chunked bodies;
//! - [`sourcetable`]: the mountpoints a caster has, and which want GGA;
//! - [`backoff`]: when to connect again;
//! - [`tls`]: the certificates an `ntrips://` caster is checked against.
//!
//! The frames themselves are found and checked by [`crate::devices::gnss::rtcm`].

pub mod backoff;
pub mod chunked;
pub mod request;
pub mod response;
pub mod sourcetable;
pub mod tls;
pub mod url;

use std::time::Duration;

/// What the client connects to and how (from `[ntrip]`, or `chassisd ntrip`'s arguments).
#[derive(Debug, Clone)]
pub struct NtripSpec {
    /// The caster and mountpoint.
    pub url: url::NtripUrl,
    /// NTRIP 2.0 or 1.0 (a 1.0 answer to a 2.0 request is taken as it comes).
    pub version: request::Version,
    /// GGA every this long (`None`: never, unless the caster's table says the mountpoint
    /// needs it).
    pub gga_interval: Option<Duration>,
    /// A connection without a valid frame for this long is dropped; also the connect and
    /// head timeout.
    pub timeout: Duration,
    /// TLS, for `ntrips://`.
    pub tls: Option<std::sync::Arc<rustls::ClientConfig>>,
    /// How the user names the caster's authority (`ntrip.ca_file`, `--ca-file`), for the
    /// advice when a TLS handshake fails.
    pub ca_setting: &'static str,
}
