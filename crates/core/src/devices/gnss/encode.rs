//! NMEA 0183 sentences written by chassisd: the simulated receiver's output, and the GGA an
//! NTRIP client sends a caster (the rover's position, which a virtual reference station
//! needs before it sends anything).

use std::fmt::Write;

use chrono::{NaiveTime, Timelike};

use super::FixQuality;
use super::framer::checksum;

/// Appends `$body*HH\r\n` to `out`.
pub fn sentence(out: &mut String, body: &str) {
    let _ = write!(out, "${body}*{:02X}\r\n", checksum(body.as_bytes()));
}

/// `hhmmss.ss`.
pub fn hms(t: impl Timelike) -> String {
    format!(
        "{:02}{:02}{:02}.{:02}",
        t.hour(),
        t.minute(),
        t.second(),
        t.nanosecond() / 10_000_000
    )
}

/// `ddmm.mmmmmmmm,N` (latitude) or `dddmm.mmmmmmmm,E` (longitude).
pub fn angle(value: f64, lat: bool) -> String {
    let hemisphere = match (lat, value >= 0.0) {
        (true, true) => 'N',
        (true, false) => 'S',
        (false, true) => 'E',
        (false, false) => 'W',
    };
    let v = value.abs();
    let deg = v.trunc();
    let min = (v - deg) * 60.0;
    if lat {
        format!("{deg:02.0}{min:011.8},{hemisphere}")
    } else {
        format!("{deg:03.0}{min:011.8},{hemisphere}")
    }
}

/// The GGA quality digit.
pub fn quality_digit(q: FixQuality) -> u8 {
    match q {
        FixQuality::Invalid => 0,
        FixQuality::Single => 1,
        FixQuality::Dgps => 2,
        FixQuality::Pps => 3,
        FixQuality::RtkFixed => 4,
        FixQuality::RtkFloat => 5,
        FixQuality::DeadReckoning => 6,
        FixQuality::Manual => 7,
        FixQuality::Simulation => 8,
    }
}

/// The rover's position for a GGA.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GgaFix {
    /// UTC time of the fix (`None`: the time of sending).
    pub utc: Option<NaiveTime>,
    /// Fix quality (a configured fallback position is sent as a single-point fix).
    pub quality: FixQuality,
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Height above mean sea level, m.
    pub altitude_msl_m: f64,
    /// Geoid separation, m.
    pub geoid_separation_m: f64,
    /// Satellites used.
    pub satellites: u8,
    /// Horizontal dilution of precision.
    pub hdop: f64,
}

impl GgaFix {
    /// A configured position (before the receiver's first fix): a single-point fix,
    /// stamped when sent, with plausible satellites and HDOP (a virtual reference station
    /// ignores a GGA that claims none).
    pub fn fallback(lat_deg: f64, lon_deg: f64, altitude_msl_m: f64) -> Self {
        Self {
            utc: None,
            quality: FixQuality::Single,
            lat_deg,
            lon_deg,
            altitude_msl_m,
            geoid_separation_m: 0.0,
            satellites: 12,
            hdop: 1.0,
        }
    }

    /// The receiver's latest valid fix, stamped when sent (a caster checks that a GGA is
    /// current); `None` without a valid position.
    pub fn from_fix(fix: &super::GnssFix) -> Option<Self> {
        let position = fix.position?.value;
        if fix.quality == FixQuality::Invalid {
            return None;
        }
        Some(Self {
            utc: None,
            quality: fix.quality,
            lat_deg: position.latitude_deg,
            lon_deg: position.longitude_deg,
            altitude_msl_m: position.altitude_msl_m.unwrap_or(0.0),
            geoid_separation_m: position.geoid_separation_m.unwrap_or(0.0),
            satellites: fix.satellites.map_or(12, |n| n.min(99) as u8),
            hdop: fix.hdop.unwrap_or(1.0),
        })
    }

    /// The GGA sentence, `now` standing in for a missing time.
    pub fn gga_at(&self, now: NaiveTime) -> String {
        let mut out = String::with_capacity(96);
        let lat = self.lat_deg.clamp(-90.0, 90.0);
        let lon = (self.lon_deg + 180.0).rem_euclid(360.0) - 180.0;
        let quality = match self.quality {
            // A caster wants a usable position: an invalid fix goes as a single-point one.
            FixQuality::Invalid => 1,
            q => quality_digit(q),
        };
        sentence(
            &mut out,
            &format!(
                "GPGGA,{},{},{},{quality},{:02},{:.1},{:.3},M,{:.3},M,,",
                hms(self.utc.unwrap_or(now)),
                angle(lat, true),
                angle(lon, false),
                self.satellites.min(99),
                self.hdop.clamp(0.0, 99.9),
                self.altitude_msl_m.clamp(-9999.0, 99_999.0),
                self.geoid_separation_m.clamp(-999.0, 999.0),
            ),
        );
        out
    }

    /// The GGA sentence, stamped now when the fix has no time.
    pub fn gga(&self) -> String {
        self.gga_at(chrono::Utc::now().time())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::gnss::GnssReceiver;
    use crate::time::Timestamp;

    #[test]
    fn a_gga_reads_back_as_the_fix_it_came_from() {
        let fix = GgaFix {
            utc: NaiveTime::from_hms_milli_opt(12, 34, 56, 780),
            quality: FixQuality::RtkFixed,
            lat_deg: -33.856_785_12,
            lon_deg: 151.215_297_34,
            altitude_msl_m: 41.234,
            geoid_separation_m: 22.1,
            satellites: 17,
            hdop: 0.7,
        };
        let text = fix.gga();
        assert!(
            text.starts_with("$GPGGA,123456.78,3351.40710720,S,15112.91784040,E,4,17,0.7,"),
            "{text}"
        );
        let mut r = GnssReceiver::new();
        r.push(Timestamp::from_micros(1), text.as_bytes(), |_| {});
        let f = r.fix();
        let p = f.position.expect("a position").value;
        assert!((p.latitude_deg - fix.lat_deg).abs() < 1e-9);
        assert!((p.longitude_deg - fix.lon_deg).abs() < 1e-9);
        assert_eq!(f.quality, FixQuality::RtkFixed);
    }

    #[test]
    fn odd_numbers_still_make_a_valid_sentence() {
        let fix = GgaFix {
            utc: None,
            quality: FixQuality::Invalid,
            lat_deg: 95.0,
            lon_deg: 190.0,
            altitude_msl_m: 1e9,
            geoid_separation_m: -1e9,
            satellites: 200,
            hdop: f64::NAN,
        };
        let text = fix.gga_at(NaiveTime::MIN);
        let mut r = GnssReceiver::new();
        r.push(Timestamp::from_micros(1), text.as_bytes(), |_| {});
        assert_eq!(r.stats().framer.checksum_errors, 0, "{text}");
        assert!(text.contains(",1,99,"), "{text}");
    }
}
