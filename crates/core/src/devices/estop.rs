//! Hardware e-stop inputs on CAN. A safety relay or an I/O module broadcasts a status frame
//! periodically; one bit of it is the e-stop circuit. The profile (TOML in `devices/`) names
//! the frame, the bit, the level that means pressed, and how long silence may last before it
//! counts as pressed: a cut cable or a dead module must stop the vehicle like the button.

use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::devices::can::Frame;
use crate::devices::profile::ProfileError;
use crate::time::Timestamp;

/// What an e-stop input reports at a control tick.
#[derive(Debug, Clone, PartialEq)]
pub struct EStopInput {
    /// Its name from the configuration.
    pub name: String,
    /// The last decoded level: `Some(true)` pressed. `None` until first heard.
    pub pressed: Option<bool>,
    /// When it was last heard.
    pub heard: Option<Timestamp>,
    /// Silence longer than this counts as pressed.
    pub timeout: Duration,
}

/// The level of the bit while the e-stop is pressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ActiveLevel {
    /// Pressed reads 1.
    High,
    /// Pressed reads 0 (a normally-closed circuit: a broken wire reads pressed).
    Low,
}

/// An e-stop profile.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct EStopProfile {
    /// Human-readable name.
    pub name: String,
    /// The status frame's identifier.
    pub id: u32,
    /// Whether the identifier is 29-bit.
    #[serde(default)]
    pub extended: bool,
    /// The byte of the data field holding the bit, 0 first.
    pub byte: u8,
    /// The bit within that byte, 0 the least significant.
    pub bit: u8,
    /// The level that means pressed.
    pub active: ActiveLevel,
    /// Silence longer than this counts as pressed, ms.
    pub timeout_ms: u64,
}

impl EStopProfile {
    /// Parses and checks a profile's text; `file` names it in errors.
    pub fn from_toml(text: &str, file: &Path) -> Result<Self, ProfileError> {
        let profile: Self = toml::from_str(text).map_err(|e| ProfileError::parse(file, &e))?;
        profile.validate(file, "")?;
        Ok(profile)
    }

    /// Checks ranges; `prefix` is put before keys in errors.
    pub fn validate(&self, file: &Path, prefix: &str) -> Result<(), ProfileError> {
        let invalid = |key: &str, problem: String, fix: &str| {
            ProfileError::invalid(file, &format!("{prefix}{key}"), problem, fix)
        };
        let max_id = if self.extended { 0x1FFF_FFFF } else { 0x7FF };
        if self.id > max_id {
            return Err(invalid(
                "id",
                format!("{:#x} does not fit the identifier", self.id),
                if self.extended {
                    "use a 29-bit identifier"
                } else {
                    "use an 11-bit identifier, or set extended = true"
                },
            ));
        }
        if self.byte > 7 {
            return Err(invalid(
                "byte",
                self.byte.to_string(),
                "use 0 to 7 (a classic CAN frame has 8 bytes)",
            ));
        }
        if self.bit > 7 {
            return Err(invalid("bit", self.bit.to_string(), "use 0 to 7"));
        }
        if !(10..=10_000).contains(&self.timeout_ms) {
            return Err(invalid(
                "timeout_ms",
                format!("{} ms", self.timeout_ms),
                "use 10 to 10000 ms, at least two of the module's periods",
            ));
        }
        Ok(())
    }

    /// Whether `frame` is this input's status frame.
    pub fn matches(&self, frame: &Frame) -> bool {
        frame.id() == self.id && frame.is_extended() == self.extended
    }

    /// Decodes this input's status frame: `Ok(pressed)`, or an error when the frame is too
    /// short to hold the bit.
    pub fn decode(&self, frame: &Frame) -> Result<bool, String> {
        let byte = frame.data().get(usize::from(self.byte)).ok_or_else(|| {
            format!(
                "{} data bytes, the e-stop bit is in byte {}",
                frame.data().len(),
                self.byte
            )
        })?;
        let high = byte >> self.bit & 1 == 1;
        Ok(high == (self.active == ActiveLevel::High))
    }
}

/// One configured e-stop input and what was last heard from it.
#[derive(Debug, Clone)]
pub struct EStopSignal {
    name: String,
    profile: EStopProfile,
    pressed: Option<bool>,
    heard: Option<Timestamp>,
    malformed: u64,
}

impl EStopSignal {
    /// A signal not heard yet (which counts as pressed).
    pub fn new(name: String, profile: EStopProfile) -> Self {
        Self {
            name,
            profile,
            pressed: None,
            heard: None,
            malformed: 0,
        }
    }

    /// Takes a received frame; other frames are ignored. A frame too short for the bit does
    /// not count as heard; the error says why.
    pub fn on_frame(&mut self, t: Timestamp, frame: &Frame) -> Result<(), String> {
        if !self.profile.matches(frame) {
            return Ok(());
        }
        match self.profile.decode(frame) {
            Ok(pressed) => {
                if self.pressed != Some(pressed) {
                    tracing::info!(
                        estop = %self.name,
                        "e-stop {}",
                        if pressed { "pressed" } else { "released" }
                    );
                }
                self.pressed = Some(pressed);
                self.heard = Some(t);
                Ok(())
            }
            Err(e) => {
                self.malformed += 1;
                // A flood of them logs at 1, 2, 4, 8, ... rather than every frame.
                if self.malformed.is_power_of_two() {
                    tracing::warn!(estop = %self.name, count = self.malformed, "malformed e-stop frame: {e}");
                }
                Err(e)
            }
        }
    }

    /// The input for the safety supervisor.
    pub fn input(&self) -> EStopInput {
        EStopInput {
            name: self.name.clone(),
            pressed: self.pressed,
            heard: self.heard,
            timeout: Duration::from_millis(self.profile.timeout_ms),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile(active: ActiveLevel) -> EStopProfile {
        EStopProfile {
            name: "test".into(),
            id: 0x191,
            extended: false,
            byte: 1,
            bit: 3,
            active,
            timeout_ms: 200,
        }
    }

    #[test]
    fn decodes_the_bit_at_either_level() {
        let high = profile(ActiveLevel::High);
        let low = profile(ActiveLevel::Low);
        let set = Frame::std(0x191, [0x00, 0x08]);
        let clear = Frame::std(0x191, [0xFF, 0xF7]);
        assert_eq!(high.decode(&set), Ok(true));
        assert_eq!(high.decode(&clear), Ok(false));
        assert_eq!(low.decode(&set), Ok(false));
        assert_eq!(low.decode(&clear), Ok(true));
    }

    #[test]
    fn matches_id_and_format() {
        let p = profile(ActiveLevel::Low);
        assert!(p.matches(&Frame::std(0x191, [0, 0])));
        assert!(!p.matches(&Frame::std(0x192, [0, 0])));
        assert!(!p.matches(&Frame::ext(0x191, [0, 0])));
    }

    #[test]
    fn short_frame_is_counted_and_not_heard() {
        let mut s = EStopSignal::new("front".into(), profile(ActiveLevel::Low));
        assert!(
            s.on_frame(Timestamp::from_nanos(1), &Frame::std(0x191, [0xFF]))
                .is_err()
        );
        assert_eq!(s.input().heard, None);
        assert_eq!(s.input().pressed, None);
        s.on_frame(Timestamp::from_nanos(2), &Frame::std(0x191, [0x00, 0x08]))
            .unwrap();
        assert_eq!(s.input().pressed, Some(false));
        assert_eq!(s.input().heard, Some(Timestamp::from_nanos(2)));
    }

    #[test]
    fn refuses_out_of_range_profiles() {
        let file = Path::new("estop.toml");
        let mut p = profile(ActiveLevel::Low);
        p.id = 0x800;
        assert!(p.validate(file, "").is_err());
        p.extended = true;
        assert!(p.validate(file, "").is_ok());
        p.byte = 8;
        assert!(p.validate(file, "").is_err());
        p.byte = 0;
        p.bit = 8;
        assert!(p.validate(file, "").is_err());
        p.bit = 0;
        p.timeout_ms = 5;
        assert!(p.validate(file, "").is_err());
    }
}
