//! NMEA 0183 sentences as a receiver writes them, for the simulated GNSS receiver.

use chrono::NaiveDateTime;

use crate::devices::gnss::FixQuality;
use crate::devices::gnss::encode::{angle, hms, quality_digit, sentence};

/// One epoch of a receiver's output.
#[derive(Debug, Clone, Copy)]
pub struct Epoch {
    /// UTC time of the epoch.
    pub utc: NaiveDateTime,
    /// Fix quality.
    pub quality: FixQuality,
    /// Latitude, longitude (degrees), ellipsoidal height (m).
    pub position: (f64, f64, f64),
    /// Speed over ground, m/s.
    pub speed_mps: f64,
    /// Course over ground, degrees true.
    pub course_deg: f64,
    /// 1σ position error the receiver reports (GST), m.
    pub sigma_m: f64,
    /// Dual-antenna heading, degrees true.
    pub heading_deg: Option<f64>,
    /// The age of the corrections, s (GGA's differential age); `None`: a steady 1 s.
    pub correction_age_s: Option<f64>,
}

/// GGA, RMC, VTG, GST and (with a heading) HDT for `e`, as one chunk.
pub fn epoch(e: &Epoch) -> String {
    let mut out = String::with_capacity(400);
    let geoid = -6.1;
    let (lat, lon, h) = e.position;
    let mode = match e.quality {
        FixQuality::RtkFixed => 'R',
        FixQuality::RtkFloat => 'F',
        FixQuality::Dgps => 'D',
        FixQuality::Invalid => 'N',
        _ => 'A',
    };
    let age = if matches!(
        e.quality,
        FixQuality::RtkFixed | FixQuality::RtkFloat | FixQuality::Dgps
    ) {
        match e.correction_age_s {
            Some(age) => format!("{:.1},0001", age.min(999.9)),
            None => "1.0,0001".to_owned(),
        }
    } else {
        ",".to_owned()
    };
    sentence(
        &mut out,
        &format!(
            "GNGGA,{},{},{},{},24,0.60,{:.4},M,{geoid:.3},M,{age}",
            hms(e.utc),
            angle(lat, true),
            angle(lon, false),
            quality_digit(e.quality),
            h - geoid
        ),
    );
    let knots = e.speed_mps / (1852.0 / 3600.0);
    let status = if e.quality.is_valid() { 'A' } else { 'V' };
    sentence(
        &mut out,
        &format!(
            "GNRMC,{},{status},{},{},{knots:.3},{:.2},{},,,{mode},V",
            hms(e.utc),
            angle(lat, true),
            angle(lon, false),
            e.course_deg,
            e.utc.format("%d%m%y")
        ),
    );
    sentence(
        &mut out,
        &format!(
            "GNVTG,{:.2},T,,M,{knots:.3},N,{:.3},K,{mode}",
            e.course_deg,
            e.speed_mps * 3.6
        ),
    );
    let s = e.sigma_m;
    sentence(
        &mut out,
        &format!(
            "GNGST,{},{s:.3},{s:.3},{s:.3},0.0,{s:.3},{s:.3},{:.3}",
            hms(e.utc),
            2.0 * s
        ),
    );
    if let Some(h) = e.heading_deg {
        sentence(&mut out, &format!("GNHDT,{h:.2},T"));
    }
    out
}
