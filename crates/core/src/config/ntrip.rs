//! `[ntrip]`: RTK corrections from an NTRIP caster (`ntrips://` over TLS), written to the
//! GNSS receiver's port (or to `port`). The password is a secret: it never reaches a log, a status or a recording
//! (recordings keep the URL with `***`, and no `password_file`).

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::{ConfigError, STANDARD_BAUDS, check_range};
use crate::ntrip::NtripSpec;
use crate::ntrip::request::Version;
use crate::ntrip::url::{NtripUrl, Password};

/// The key of the caster's authority file, as errors name it.
const CA_SETTING: &str = "ntrip.ca_file";

/// `[ntrip]`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct NtripConfig {
    /// `ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT` (RTKLIB's form; `ntrips://` for TLS).
    pub url: String,
    /// A file whose first line is the password, instead of one in the URL (relative to the
    /// configuration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub password_file: Option<PathBuf>,
    /// NTRIP version asked for: 2 (default) or 1. A caster that answers `ICY` is taken as
    /// 1.0 either way.
    #[serde(default = "default_version")]
    pub version: u8,
    /// The rover's position goes to the caster as GGA every this many seconds (at least 1;
    /// 0 sends none, unless the caster's table says the mountpoint needs it).
    #[serde(default = "default_gga_interval_s")]
    pub gga_interval_s: f64,
    /// The position sent as GGA before the receiver's first fix.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fallback_position: Option<FallbackPosition>,
    /// A connection with no valid RTCM frame for this long is dropped, s; corrections this
    /// old are stale everywhere they are reported.
    #[serde(default = "default_timeout_s")]
    pub timeout_s: f64,
    /// Write the corrections to this serial port instead of the receiver's `[gnss] port`
    /// (a receiver's second UART).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub port: Option<String>,
    /// `port`'s baud rate.
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// Frames waiting for the port before the oldest are dropped (and counted).
    #[serde(default = "default_queue_frames")]
    pub queue_frames: usize,
    /// With `ntrips://`: the caster's certificate authority (PEM, relative to the
    /// configuration), trusted besides this computer's own roots.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ca_file: Option<PathBuf>,
}

/// `[ntrip] fallback_position`: latitude and longitude in degrees, height in metres (above
/// mean sea level, as GGA carries it).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FallbackPosition {
    /// Degrees north.
    pub lat: f64,
    /// Degrees east.
    pub lon: f64,
    /// Metres.
    #[serde(default)]
    pub height: f64,
}

fn default_version() -> u8 {
    2
}

fn default_gga_interval_s() -> f64 {
    10.0
}

fn default_timeout_s() -> f64 {
    10.0
}

fn default_baud() -> u32 {
    115_200
}

fn default_queue_frames() -> usize {
    256
}

impl NtripConfig {
    /// The defaults with this caster (`--ntrip URL`).
    pub fn with_url(url: &str) -> Self {
        Self {
            url: url.to_owned(),
            password_file: None,
            version: default_version(),
            gga_interval_s: default_gga_interval_s(),
            fallback_position: None,
            timeout_s: default_timeout_s(),
            port: None,
            baud: default_baud(),
            queue_frames: default_queue_frames(),
            ca_file: None,
        }
    }

    /// Makes `password_file` and `ca_file` relative to the configuration's folder `base`.
    pub fn resolve(&mut self, base: &Path) {
        for file in [&mut self.password_file, &mut self.ca_file]
            .into_iter()
            .flatten()
        {
            if file.is_relative() {
                *file = base.join(&*file);
            }
        }
    }

    /// How long corrections stay fresh.
    pub fn timeout(&self) -> Duration {
        Duration::from_secs_f64(self.timeout_s)
    }

    /// The URL as parsed (the password file not read yet).
    pub fn parsed_url(&self) -> Result<NtripUrl, String> {
        NtripUrl::parse(&self.url).map_err(|e| e.to_string())
    }

    /// The URL safe to print: the password as `***`.
    pub fn display_url(&self) -> String {
        self.parsed_url()
            .map_or_else(|_| "(invalid URL)".to_owned(), |u| u.to_string())
    }

    /// This section as a recording keeps it: the password out of the URL, no password file and
    /// no certificate file.
    pub fn redacted(&self) -> Self {
        Self {
            url: self.display_url(),
            password_file: None,
            // A replay connects to nothing: no file outside the recording is named.
            ca_file: None,
            ..self.clone()
        }
    }

    /// What the client needs, the password file read now.
    pub fn spec(&self) -> Result<NtripSpec, String> {
        let mut url = self.parsed_url()?;
        if let Some(file) = &self.password_file {
            let text = std::fs::read_to_string(file).map_err(|e| {
                format!(
                    "ntrip.password_file {}: cannot read: {e} (the file must exist, be readable \
                     by this user, and hold the caster's password on its first line)",
                    file.display()
                )
            })?;
            url.password = Password::new(text.lines().next().unwrap_or("").trim_end());
        }
        let tls = if url.tls {
            Some(crate::ntrip::tls::client_config(
                self.ca_file.as_deref(),
                CA_SETTING,
            )?)
        } else {
            None
        };
        Ok(NtripSpec {
            tls,
            url,
            version: if self.version == 1 {
                Version::V1
            } else {
                Version::V2
            },
            gga_interval: (self.gga_interval_s > 0.0)
                .then(|| Duration::from_secs_f64(self.gga_interval_s)),
            timeout: self.timeout(),
            ca_setting: CA_SETTING,
        })
    }

    /// Checks the URL and the ranges.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        let invalid =
            |key: &str, problem: String, fix: &str| ConfigError::invalid(file, key, problem, fix);
        let url = self.parsed_url().map_err(|e| {
            invalid(
                "ntrip.url",
                e,
                "e.g. url = \"ntrip://user:password@caster.example.org:2101/MOUNT\"",
            )
        })?;
        if self.ca_file.is_some() && !url.tls {
            return Err(invalid(
                "ntrip.ca_file",
                "is set, and the URL is ntrip:// (no TLS)".into(),
                "write the URL as ntrips://, or remove ca_file",
            ));
        }
        if self.password_file.is_some() && !url.password.expose().is_empty() {
            return Err(invalid(
                "ntrip.password_file",
                "is set, and the URL holds a password too".into(),
                "keep the password in one place: remove it from the URL",
            ));
        }
        if !matches!(self.version, 1 | 2) {
            return Err(invalid(
                "ntrip.version",
                format!("{} is not an NTRIP version", self.version),
                "set 2 (NTRIP 2.0, the default) or 1",
            ));
        }
        if self.gga_interval_s != 0.0 {
            check_range(
                file,
                "ntrip.gga_interval_s",
                self.gga_interval_s,
                1.0..=3600.0,
                "seconds (0 sends none)",
            )?;
        }
        check_range(
            file,
            "ntrip.timeout_s",
            self.timeout_s,
            1.0..=300.0,
            "seconds",
        )?;
        if let Some(p) = &self.fallback_position {
            check_range(
                file,
                "ntrip.fallback_position.lat",
                p.lat,
                -90.0..=90.0,
                "degrees",
            )?;
            check_range(
                file,
                "ntrip.fallback_position.lon",
                p.lon,
                -180.0..=180.0,
                "degrees",
            )?;
            check_range(
                file,
                "ntrip.fallback_position.height",
                p.height,
                -1000.0..=10000.0,
                "metres",
            )?;
        }
        if let Some(port) = &self.port
            && port.trim().is_empty()
        {
            return Err(invalid(
                "ntrip.port",
                "is empty".into(),
                "name the receiver's correction port, e.g. \"/dev/ttyUSB1\", or remove the key to use [gnss] port",
            ));
        }
        if !STANDARD_BAUDS.contains(&self.baud) {
            return Err(invalid(
                "ntrip.baud",
                format!("{} is not a standard rate", self.baud),
                "use one of 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600",
            ));
        }
        if !(1..=65_536).contains(&self.queue_frames) {
            return Err(invalid(
                "ntrip.queue_frames",
                format!("{} is outside 1..=65536", self.queue_frames),
                "set a queue of some hundred frames (the default is 256)",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(text: &str) -> Result<NtripConfig, String> {
        let c: NtripConfig = toml::from_str(text).map_err(|e| e.to_string())?;
        c.validate(Path::new("t.toml")).map_err(|e| e.to_string())?;
        Ok(c)
    }

    #[test]
    fn the_issue_example_loads_with_its_defaults() {
        let c = check("url = \"ntrip://u:p@caster.example.org:2101/MOUNT\"").unwrap();
        assert_eq!((c.version, c.gga_interval_s, c.timeout_s), (2, 10.0, 10.0));
        let spec = c.spec().unwrap();
        assert_eq!(spec.url.password.expose(), "p");
        assert_eq!(spec.gga_interval, Some(Duration::from_secs(10)));
        assert_eq!(spec.version, Version::V2);
    }

    #[test]
    fn bad_values_are_refused_with_their_key() {
        for (text, key) in [
            ("url = \"http://x/M\"", "ntrip.url"),
            (
                "url = \"ntrip://x/M\"\nca_file = \"ca.pem\"",
                "ntrip.ca_file",
            ),
            ("url = \"ntrip://x/M\"\nversion = 3", "ntrip.version"),
            (
                "url = \"ntrip://x/M\"\ngga_interval_s = 0.5",
                "ntrip.gga_interval_s",
            ),
            ("url = \"ntrip://x/M\"\ntimeout_s = 0", "ntrip.timeout_s"),
            (
                "url = \"ntrip://x/M\"\nfallback_position = { lat = 91, lon = 0 }",
                "ntrip.fallback_position.lat",
            ),
            (
                "url = \"ntrip://u:p@x/M\"\npassword_file = \"pw\"",
                "ntrip.password_file",
            ),
            ("url = \"ntrip://x/M\"\nbaud = 1234", "ntrip.baud"),
            (
                "url = \"ntrip://x/M\"\nqueue_frames = 0",
                "ntrip.queue_frames",
            ),
        ] {
            let e = check(text).unwrap_err();
            assert!(e.contains(&format!("`{key}`")), "{text}: {e}");
        }
        let c = check("url = \"ntrip://x/M\"\ngga_interval_s = 0").unwrap();
        assert_eq!(c.spec().unwrap().gga_interval, None);
    }

    #[test]
    fn the_recorded_form_holds_no_password() {
        let mut c = NtripConfig::with_url("ntrip://rover:s3cret@10.0.0.1:2101/M");
        let r = c.redacted();
        assert!(!r.url.contains("s3cret"), "{}", r.url);
        assert!(r.url.contains("rover") && r.url.contains("10.0.0.1:2101/M"));
        c.url = "ntrip://rover@10.0.0.1/M".into();
        c.password_file = Some("/etc/chassisd/ntrip.pw".into());
        assert_eq!(c.redacted().password_file, None);
    }

    #[test]
    fn the_password_file_gives_the_password() {
        let dir = std::env::temp_dir().join(format!("chassisd-ntrip-pw-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("pw"), "from-file\nignored\n").unwrap();
        let mut c = NtripConfig::with_url("ntrip://rover@10.0.0.1/M");
        c.password_file = Some("pw".into());
        c.resolve(&dir);
        assert_eq!(c.spec().unwrap().url.password.expose(), "from-file");
        c.password_file = Some(dir.join("missing"));
        assert!(c.spec().unwrap_err().contains("cannot read"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
