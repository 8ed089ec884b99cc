//! A checksummed NMEA sentence body split into its address and fields.

/// One sentence body as delivered by the framer (between `$` and `*`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sentence<'a> {
    /// The address field, e.g. `GNGGA` or `PSTI`.
    pub address: &'a str,
    /// Talker id: two characters (`GP`, `GN`, ...), or `P` for proprietary sentences.
    pub talker: &'a str,
    /// Sentence type: the three-letter formatter (`GGA`) for standard sentences, else the
    /// whole address (`PSTI`, `GYOACC`).
    pub kind: &'a str,
    /// Everything after the first comma (may be empty).
    pub data: &'a str,
}

impl<'a> Sentence<'a> {
    /// Splits a sentence body. Bodies from the framer are printable ASCII, so byte offsets are
    /// character boundaries.
    pub fn parse(body: &'a str) -> Self {
        let (address, data) = body.split_once(',').unwrap_or((body, ""));
        let standard = address.len() == 5
            && !address.starts_with('P')
            && address.bytes().all(|b| b.is_ascii_alphanumeric());
        let (talker, kind) = if standard {
            (&address[..2], &address[2..])
        } else if address.starts_with('P') {
            ("P", address)
        } else {
            (address.get(..2).unwrap_or(address), address)
        };
        Self {
            address,
            talker,
            kind,
            data,
        }
    }

    /// The data fields, split on commas. A sentence with no data has one empty field.
    pub fn fields(&self) -> Fields<'a> {
        Fields {
            kind: self.kind,
            inner: self.data.split(','),
            index: 0,
        }
    }
}

/// Iterator over a sentence's fields that remembers positions for error messages.
#[derive(Debug, Clone)]
pub struct Fields<'a> {
    kind: &'a str,
    inner: std::str::Split<'a, char>,
    index: usize,
}

/// A field that could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{kind}: field {field} ({what}): {reason}")]
pub struct FieldError {
    /// Sentence type.
    pub kind: String,
    /// One-based field number after the address, as the NMEA tables count them.
    pub field: usize,
    /// What the field holds.
    pub what: &'static str,
    /// Why it was rejected.
    pub reason: String,
}

impl<'a> Fields<'a> {
    /// The next raw field, or an empty string when the sentence is shorter (NMEA allows
    /// trailing fields to be omitted).
    pub fn next_raw(&mut self) -> &'a str {
        self.index += 1;
        self.inner.next().unwrap_or("")
    }

    /// An error about the field returned last.
    pub fn error(&self, what: &'static str, reason: impl Into<String>) -> FieldError {
        FieldError {
            kind: self.kind.to_owned(),
            field: self.index,
            what,
            reason: reason.into(),
        }
    }

    /// The next field as a finite number; empty is `None`.
    pub fn next_f64(&mut self, what: &'static str) -> Result<Option<f64>, FieldError> {
        let raw = self.next_raw();
        if raw.is_empty() {
            return Ok(None);
        }
        match raw.parse::<f64>() {
            Ok(v) if v.is_finite() && !raw.contains(['e', 'E', 'i', 'n', 'N']) => Ok(Some(v)),
            _ => Err(self.error(what, format!("{raw:?} is not a decimal number"))),
        }
    }

    /// The next field as an unsigned integer; empty is `None`.
    pub fn next_u16(&mut self, what: &'static str) -> Result<Option<u16>, FieldError> {
        let raw = self.next_raw();
        if raw.is_empty() {
            return Ok(None);
        }
        raw.parse::<u16>()
            .map(Some)
            .map_err(|_| self.error(what, format!("{raw:?} is not an integer")))
    }

    /// The next two fields as a latitude (`ddmm.mmm`, `N|S`) or longitude (`dddmm.mmm`,
    /// `E|W`) in degrees; both empty is `None`.
    pub fn next_angle(&mut self, what: &'static str) -> Result<Option<f64>, FieldError> {
        let (deg_digits, positive, negative, limit) = match what {
            "latitude" => (2, 'N', 'S', 90.0),
            _ => (3, 'E', 'W', 180.0),
        };
        let value = self.next_raw();
        let value_field = self.index;
        let hemisphere = self.next_raw();
        if value.is_empty() && hemisphere.is_empty() {
            return Ok(None);
        }
        let parsed = parse_degrees_minutes(value, deg_digits);
        let sign = match hemisphere {
            h if h.len() == 1 && h.starts_with(positive) => 1.0,
            h if h.len() == 1 && h.starts_with(negative) => -1.0,
            other => {
                return Err(self.error(what, format!("hemisphere {other:?}")));
            }
        };
        match parsed {
            Some(deg) if deg <= limit => Ok(Some(sign * deg)),
            _ => Err(FieldError {
                kind: self.kind.to_owned(),
                field: value_field,
                what,
                reason: format!("{value:?} is not a valid angle"),
            }),
        }
    }

    /// The next field as a UTC time of day (`hhmmss[.sss]`); empty is `None`.
    pub fn next_time(&mut self) -> Result<Option<chrono::NaiveTime>, FieldError> {
        let raw = self.next_raw();
        if raw.is_empty() {
            return Ok(None);
        }
        parse_hhmmss(raw)
            .map(Some)
            .ok_or_else(|| self.error("UTC time", format!("{raw:?} is not hhmmss.ss")))
    }
}

/// Parses `ddmm.mmmm` (or `dddmm.mmmm`) into degrees. Minutes must be below 60.
fn parse_degrees_minutes(raw: &str, deg_digits: usize) -> Option<f64> {
    if raw.len() < deg_digits + 2 || !raw.bytes().all(|b| b.is_ascii_digit() || b == b'.') {
        return None;
    }
    let degrees: f64 = raw.get(..deg_digits)?.parse().ok()?;
    let minutes: f64 = raw.get(deg_digits..)?.parse().ok()?;
    (minutes < 60.0).then(|| degrees + minutes / 60.0)
}

/// Parses `hhmmss` with optional fractional seconds.
pub fn parse_hhmmss(raw: &str) -> Option<chrono::NaiveTime> {
    let bytes = raw.as_bytes();
    if bytes.len() < 6 || !bytes[..6].iter().all(u8::is_ascii_digit) {
        return None;
    }
    let hour: u32 = raw.get(0..2)?.parse().ok()?;
    let minute: u32 = raw.get(2..4)?.parse().ok()?;
    let second: u32 = raw.get(4..6)?.parse().ok()?;
    let nanos = match raw.get(6..)? {
        "" => 0,
        frac => {
            let digits = frac.strip_prefix('.')?;
            if digits.is_empty() || digits.len() > 9 || !digits.bytes().all(|b| b.is_ascii_digit())
            {
                return None;
            }
            let value: u32 = digits.parse().ok()?;
            value * 10u32.pow(9 - digits.len() as u32)
        }
    };
    chrono::NaiveTime::from_hms_nano_opt(hour, minute, second, nanos)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_standard_and_proprietary_addresses() {
        let s = Sentence::parse("GNGGA,1,2");
        assert_eq!((s.talker, s.kind, s.data), ("GN", "GGA", "1,2"));
        let p = Sentence::parse("PSTI,030,003832.000");
        assert_eq!((p.talker, p.kind), ("P", "PSTI"));
        let odd = Sentence::parse("GYOACC,1");
        assert_eq!((odd.talker, odd.kind), ("GY", "GYOACC"));
        let bare = Sentence::parse("GPGGA");
        assert_eq!((bare.kind, bare.data), ("GGA", ""));
    }

    #[test]
    fn decodes_angles_with_many_decimals() {
        let s = Sentence::parse("X,4404.1271062,N,12118.8438377,W");
        let mut f = s.fields();
        let lat = f.next_angle("latitude").unwrap().unwrap();
        let lon = f.next_angle("longitude").unwrap().unwrap();
        assert!((lat - (44.0 + 4.1271062 / 60.0)).abs() < 1e-12);
        assert!((lon + (121.0 + 18.8438377 / 60.0)).abs() < 1e-12);
    }

    #[test]
    fn rejects_bad_angles_with_field_numbers() {
        let s = Sentence::parse("X,4465.0,N,12118.0,Q");
        let mut f = s.fields();
        let err = f.next_angle("latitude").unwrap_err();
        assert_eq!(err.field, 1);
        let err = f.next_angle("longitude").unwrap_err();
        assert_eq!(err.field, 4);
        assert!(err.to_string().contains("hemisphere"));
    }

    #[test]
    fn parses_times() {
        let t = parse_hhmmss("231408.25").unwrap();
        assert_eq!(t.to_string(), "23:14:08.250");
        assert!(parse_hhmmss("246000").is_none());
        assert!(parse_hhmmss("1234").is_none());
        assert!(parse_hhmmss("123456.").is_none());
        assert!(parse_hhmmss("123456.1234567890").is_none());
    }

    #[test]
    fn numbers_must_be_plain_decimals() {
        let s = Sentence::parse("X,1.5,inf,1e3,,NaN");
        let mut f = s.fields();
        assert_eq!(f.next_f64("a").unwrap(), Some(1.5));
        assert!(f.next_f64("b").is_err());
        assert!(f.next_f64("c").is_err());
        assert_eq!(f.next_f64("d").unwrap(), None);
        assert!(f.next_f64("e").is_err());
        assert_eq!(f.next_f64("beyond the end").unwrap(), None);
    }
}
