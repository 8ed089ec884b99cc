//! Typed decoding of the NMEA sentences chassisd uses.
//!
//! RMC, VTG, GST, HDT, ZDA and the core of GGA go through the `nmea` crate's field parsers.
//! The crate's gaps are filled here rather than losing data (docs/protocols/nmea.md):
//! - its sentence-level entry point rejects sentences over 102 bytes, so sentences come from
//!   our framer and are handed to the per-type parsers directly, whatever their length;
//! - its GGA drops the differential age and station, parsed here from fields 13 and 14;
//! - it rejects GNS mode fields longer than two characters (one per constellation), so GNS is
//!   decoded here;
//! - it has no THS (true heading and status), decoded here;
//! - it has none of the vendors' dual-antenna headings (Trimble `PTNL,AVR`, Septentrio
//!   `PSSN,HRP`, `PASHR`, Unicore `HPR` and `TRA`), decoded here, each valid only with the
//!   quality it states;
//! - Unicore's `H` forms (`GNGGAH`, `GNRMCH`, ...) are its second (heading) antenna's
//!   sentences: checked as their plain forms, never taken as the vehicle's position, which
//!   they would move by the length of the baseline;
//! - it keeps several values as `f32`; they are widened through their shortest decimal form,
//!   so `244.28` stays `244.28` rather than `244.27999877929688`.

use chrono::{Datelike, NaiveDate, NaiveTime};
use nmea::SentenceType;
use nmea::sentences::rmc::RmcStatusOfFix;
use nmea::sentences::{FaaMode, FixType};

use super::sentence::{FieldError, Sentence};

/// Metres per second in one knot.
const MPS_PER_KNOT: f64 = 1852.0 / 3600.0;
/// Metres per second in one km/h.
const MPS_PER_KMH: f64 = 1.0 / 3.6;

/// GNSS fix quality, as GGA reports it (and as RMC/GNS mode letters map onto it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FixQuality {
    /// No fix (GGA 0, RMC `V`, mode `N`).
    #[default]
    Invalid,
    /// Autonomous single-point fix (GGA 1, mode `A`).
    Single,
    /// Differential: SBAS or DGPS (GGA 2, modes `D` and `P`).
    Dgps,
    /// Precise Positioning Service (GGA 3).
    Pps,
    /// RTK with fixed integer ambiguities (GGA 4, mode `R`).
    RtkFixed,
    /// RTK float (GGA 5, mode `F`).
    RtkFloat,
    /// Dead reckoning (GGA 6, mode `E`).
    DeadReckoning,
    /// Position entered by hand (GGA 7, mode `M`).
    Manual,
    /// Simulator output (GGA 8, mode `S`).
    Simulation,
}

impl FixQuality {
    /// A horizontal 1σ typical of this quality, m, for a receiver that states none (no
    /// GST): what the localiser weighs a fix by, and `/fix` approximates its covariance with.
    pub fn typical_sigma_m(self) -> f64 {
        match self {
            Self::RtkFixed => 0.02,
            Self::RtkFloat => 0.3,
            Self::Dgps => 0.8,
            _ => 2.5,
        }
    }

    /// Whether the receiver computed this position from satellites.
    pub fn is_valid(self) -> bool {
        matches!(
            self,
            Self::Single | Self::Dgps | Self::Pps | Self::RtkFixed | Self::RtkFloat
        )
    }

    /// Whether corrections shaped this position (DGPS/SBAS, RTK): its slow error is then the
    /// corrections' residuals and multipath, which change as the antenna moves; a single
    /// fix's (the atmosphere, the orbits) only with time.
    pub fn is_corrected(self) -> bool {
        matches!(self, Self::Dgps | Self::RtkFloat | Self::RtkFixed)
    }

    /// The `rtk.status` code of rtk-mqtt-protocol.md: 0 none, 1 single, 2 DGPS, 4 RTK fixed,
    /// 5 RTK float. PPS counts as single (it is not differential); dead reckoning, manual and
    /// simulated positions are not GNSS fixes and count as none.
    pub fn rtk_status(self) -> u8 {
        match self {
            Self::Single | Self::Pps => 1,
            Self::Dgps => 2,
            Self::RtkFixed => 4,
            Self::RtkFloat => 5,
            Self::Invalid | Self::DeadReckoning | Self::Manual | Self::Simulation => 0,
        }
    }

    /// Preference order when several constellations report different modes (GNS).
    fn rank(self) -> u8 {
        match self {
            Self::RtkFixed => 8,
            Self::RtkFloat => 7,
            Self::Dgps => 6,
            Self::Pps => 5,
            Self::Single => 4,
            Self::DeadReckoning => 3,
            Self::Manual => 2,
            Self::Simulation => 1,
            Self::Invalid => 0,
        }
    }

    /// The quality a NMEA mode indicator letter stands for.
    pub fn from_mode_letter(c: char) -> Option<Self> {
        Some(match c {
            'A' | 'C' | 'U' => Self::Single, // C and U: Quectel's caution/unsafe variants of A
            'D' | 'P' => Self::Dgps,
            'R' => Self::RtkFixed,
            'F' => Self::RtkFloat,
            'E' => Self::DeadReckoning,
            'M' => Self::Manual,
            'S' => Self::Simulation,
            'N' | 'V' => Self::Invalid,
            _ => return None,
        })
    }
}

/// In plain words, for people (logs, refusals, the live page).
impl std::fmt::Display for FixQuality {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Invalid => "no fix",
            Self::Single => "single (no corrections)",
            Self::Dgps => "DGPS",
            Self::Pps => "PPS",
            Self::RtkFixed => "RTK fixed",
            Self::RtkFloat => "RTK float",
            Self::DeadReckoning => "dead reckoning",
            Self::Manual => "entered by hand",
            Self::Simulation => "simulated",
        })
    }
}

impl From<FixType> for FixQuality {
    fn from(fix: FixType) -> Self {
        match fix {
            FixType::Invalid => Self::Invalid,
            FixType::Gps => Self::Single,
            FixType::DGps => Self::Dgps,
            FixType::Pps => Self::Pps,
            FixType::Rtk => Self::RtkFixed,
            FixType::FloatRtk => Self::RtkFloat,
            FixType::Estimated => Self::DeadReckoning,
            FixType::Manual => Self::Manual,
            FixType::Simulation => Self::Simulation,
        }
    }
}

fn quality_from_faa(mode: FaaMode) -> FixQuality {
    match mode {
        FaaMode::Autonomous | FaaMode::Caution | FaaMode::Unsafe => FixQuality::Single,
        FaaMode::Differential | FaaMode::Precise => FixQuality::Dgps,
        FaaMode::FixedRtk => FixQuality::RtkFixed,
        FaaMode::FloatRtk => FixQuality::RtkFloat,
        FaaMode::Estimated => FixQuality::DeadReckoning,
        FaaMode::Manual => FixQuality::Manual,
        FaaMode::Simulator => FixQuality::Simulation,
        FaaMode::DataNotValid => FixQuality::Invalid,
    }
}

/// A position fix from GGA or GNS.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PositionReport {
    /// UTC time of the fix.
    pub time: Option<NaiveTime>,
    /// Fix quality.
    pub quality: FixQuality,
    /// Latitude, degrees north (WGS84).
    pub latitude: Option<f64>,
    /// Longitude, degrees east (WGS84).
    pub longitude: Option<f64>,
    /// Altitude above mean sea level, metres.
    pub altitude_msl: Option<f64>,
    /// Geoid separation (ellipsoid minus MSL), metres.
    pub geoid_separation: Option<f64>,
    /// Satellites used.
    pub satellites: Option<u16>,
    /// Horizontal dilution of precision.
    pub hdop: Option<f64>,
    /// Age of the differential corrections, seconds.
    pub diff_age_s: Option<f64>,
    /// Differential reference station id.
    pub diff_station: Option<u16>,
}

/// Speed and course over ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundVelocity {
    /// Speed over ground, m/s.
    pub speed_mps: f64,
    /// Course over ground, degrees true (0 = north, clockwise); absent when not moving.
    pub course_deg: Option<f64>,
}

/// RMC: recommended minimum data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rmc {
    /// UTC time.
    pub time: Option<NaiveTime>,
    /// UTC date.
    pub date: Option<NaiveDate>,
    /// Quality from the status (`A`/`D`/`V`) and the mode indicator.
    pub quality: FixQuality,
    /// Latitude, degrees north.
    pub latitude: Option<f64>,
    /// Longitude, degrees east.
    pub longitude: Option<f64>,
    /// Speed and course, when present.
    pub velocity: Option<GroundVelocity>,
}

/// GST: pseudorange error statistics, all in metres (orientation in degrees from true north).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GstAccuracy {
    /// UTC time of the associated fix.
    pub time: Option<NaiveTime>,
    /// RMS of the pseudorange residuals, metres.
    pub rms_m: Option<f64>,
    /// Error ellipse semi-major axis, 1σ, metres.
    pub semi_major_m: Option<f64>,
    /// Error ellipse semi-minor axis, 1σ, metres.
    pub semi_minor_m: Option<f64>,
    /// Orientation of the semi-major axis, degrees from true north.
    pub orientation_deg: Option<f64>,
    /// Latitude error, 1σ, metres.
    pub latitude_sd_m: Option<f64>,
    /// Longitude error, 1σ, metres.
    pub longitude_sd_m: Option<f64>,
    /// Altitude error, 1σ, metres.
    pub altitude_sd_m: Option<f64>,
}

/// True heading from a dual-antenna receiver (HDT, THS, and the vendors' own sentences).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueHeading {
    /// Heading, degrees true (0 = north, clockwise); `None` when the receiver marks it invalid
    /// or states a quality too poor for it (a float or code solution where it states one).
    pub heading_deg: Option<f64>,
    /// Its 1σ, degrees, where the receiver states one (Septentrio, PASHR).
    pub sigma_deg: Option<f64>,
}

/// `$KSXT` (Unicore and compatible receivers): a whole solution in one sentence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ksxt {
    /// UTC date of the solution.
    pub date: Option<NaiveDate>,
    /// Position, its quality (0 none, 1 single, 2 RTK float, 3 RTK fixed), satellites and
    /// differential age; the height is not kept (its datum is not documented).
    pub position: PositionReport,
    /// Heading at its own quality (3, fixed, only).
    pub heading: TrueHeading,
    /// Speed and track over ground.
    pub velocity: Option<GroundVelocity>,
}

/// ZDA: UTC date and time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZdaDate {
    /// UTC time.
    pub time: Option<NaiveTime>,
    /// UTC date.
    pub date: Option<NaiveDate>,
}

/// A decoded sentence of a type chassisd uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GnssSentence {
    /// GGA position fix.
    Gga(PositionReport),
    /// GNS multi-constellation position fix.
    Gns(PositionReport),
    /// RMC minimum data.
    Rmc(Rmc),
    /// VTG course and speed.
    Vtg(GroundVelocity),
    /// GST accuracy.
    Gst(GstAccuracy),
    /// HDT true heading.
    Hdt(TrueHeading),
    /// THS true heading and status.
    Ths(TrueHeading),
    /// A vendor's dual-antenna heading: Trimble `PTNL,AVR`, Septentrio `PSSN,HRP`, `PASHR`,
    /// Unicore `HPR` and `TRA`.
    Heading(TrueHeading),
    /// A sentence of a dual-antenna receiver's second antenna (Unicore's `GGAH`, `RMCH`,
    /// ...): checked, and never the vehicle's position.
    SecondaryAntenna,
    /// `$KSXT`: position, heading and velocity of one epoch.
    Ksxt(Ksxt),
    /// ZDA date.
    Zda(ZdaDate),
}

/// A sentence of a known type whose fields could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("malformed {kind}: {reason}")]
pub struct DecodeError {
    /// Sentence type.
    pub kind: String,
    /// What was wrong.
    pub reason: String,
}

impl From<FieldError> for DecodeError {
    fn from(e: FieldError) -> Self {
        Self {
            reason: format!("field {} ({}): {}", e.field, e.what, e.reason),
            kind: e.kind,
        }
    }
}

/// Decodes `sentence` if its type is one chassisd uses; other types are `Ok(None)`.
pub fn decode(sentence: &Sentence<'_>) -> Result<Option<GnssSentence>, DecodeError> {
    if sentence.talker == "P" {
        return decode_proprietary(sentence);
    }
    match sentence.kind {
        "#UNIHEADINGA" | "#HEADINGA" => {
            return Ok(Some(GnssSentence::Heading(decode_uniheading(sentence)?)));
        }
        "KSXT" => return Ok(Some(GnssSentence::Ksxt(decode_ksxt(sentence)?))),
        _ => {}
    }
    match variant_of(sentence) {
        Some((kind, 'H')) => {
            let plain = decode_standard(&Sentence { kind, ..*sentence })?;
            Ok(plain.map(|_| GnssSentence::SecondaryAntenna))
        }
        Some((kind, _)) => decode_standard(&Sentence { kind, ..*sentence }),
        None => decode_standard(sentence),
    }
}

/// Unicore's six-letter addresses: a talker, a standard formatter and `H` (the second
/// antenna's sentence: `GNGGAH`) or `2` (`GNHPR2`, `GNTRA2`, `GNTHS2`, whose layout is the
/// plain one's); the formatter and the suffix.
fn variant_of<'a>(sentence: &Sentence<'a>) -> Option<(&'a str, char)> {
    let address = sentence.address;
    if address.len() != 6 || !address.bytes().all(|b| b.is_ascii_alphanumeric()) {
        return None;
    }
    let (formatter, suffix) = (&address[2..5], address[5..].chars().next()?);
    match suffix {
        'H' => Some((formatter, 'H')),
        '2' if matches!(formatter, "HPR" | "TRA" | "THS") => Some((formatter, '2')),
        _ => None,
    }
}

/// A standard sentence's decoding, by its formatter.
fn decode_standard(sentence: &Sentence<'_>) -> Result<Option<GnssSentence>, DecodeError> {
    let decoded = match sentence.kind {
        "GGA" => GnssSentence::Gga(decode_gga(sentence)?),
        "GNS" => GnssSentence::Gns(decode_gns(sentence)?),
        "RMC" => GnssSentence::Rmc(decode_rmc(sentence)?),
        "VTG" => match decode_vtg(sentence)? {
            Some(velocity) => GnssSentence::Vtg(velocity),
            // `$GPVTG,,T,,M,,N,,K,N`: legal, and nothing to use.
            None => return Ok(None),
        },
        "GST" => GnssSentence::Gst(decode_gst(sentence)?),
        "HDT" => GnssSentence::Hdt(decode_hdt(sentence)?),
        "THS" => GnssSentence::Ths(decode_ths(sentence)?),
        "ZDA" => GnssSentence::Zda(decode_zda(sentence)?),
        "HPR" | "TRA" => GnssSentence::Heading(decode_hpr(sentence)?),
        _ => return Ok(None),
    };
    Ok(Some(decoded))
}

/// The proprietary sentences chassisd uses: the vendors' dual-antenna headings.
fn decode_proprietary(sentence: &Sentence<'_>) -> Result<Option<GnssSentence>, DecodeError> {
    let (sub, rest) = sentence.data.split_once(',').unwrap_or((sentence.data, ""));
    let heading = match (sentence.kind, sub) {
        ("PTNL", "AVR") => decode_avr(&Sentence {
            kind: "PTNL,AVR",
            data: rest,
            ..*sentence
        })?,
        ("PSSN", "HRP") => decode_hrp(&Sentence {
            kind: "PSSN,HRP",
            data: rest,
            ..*sentence
        })?,
        // The attitude form (`$PASHR,time,heading,T,...`), not Ashtech's `$PASHR,POS,...`.
        ("PASHR", _) if sentence.data.split(',').nth(2) == Some("T") => decode_pashr(sentence)?,
        _ => return Ok(None),
    };
    Ok(Some(GnssSentence::Heading(heading)))
}

/// The sentence in the form the `nmea` crate's per-type parsers take. They do not look at
/// the checksum (the framer verified it) or the length.
fn crate_sentence<'a>(sentence: &Sentence<'a>, message_id: SentenceType) -> nmea::NmeaSentence<'a> {
    nmea::NmeaSentence {
        talker_id: sentence.talker,
        message_id,
        data: sentence.data,
        checksum: 0,
    }
}

fn crate_error(kind: &str, e: nmea::Error<'_>) -> DecodeError {
    DecodeError {
        kind: kind.to_owned(),
        reason: e.to_string(),
    }
}

/// Widens an `f32` from the `nmea` crate through its shortest round-trip decimal, which is
/// the decimal the receiver sent whenever it had at most six significant digits (and
/// mostly when it had seven).
fn widen(v: f32) -> Option<f64> {
    if !v.is_finite() {
        return None;
    }
    zmij::Buffer::new().format_finite(v).parse().ok()
}

fn decode_gga(sentence: &Sentence<'_>) -> Result<PositionReport, DecodeError> {
    let gga = nmea::sentences::parse_gga(crate_sentence(sentence, SentenceType::GGA))
        .map_err(|e| crate_error("GGA", e))?;
    // Fields 13 and 14 (age of corrections, station id) that the crate drops.
    let mut fields = sentence.fields();
    for _ in 0..12 {
        fields.next_raw();
    }
    let diff_age_s = fields.next_f64("differential age")?;
    let diff_station = fields.next_u16("differential station")?;
    Ok(PositionReport {
        time: gga.fix_time,
        quality: gga.fix_type.map(FixQuality::from).unwrap_or_default(),
        latitude: gga.latitude,
        longitude: gga.longitude,
        altitude_msl: gga.altitude.and_then(widen),
        geoid_separation: gga.geoid_separation.and_then(widen),
        satellites: gga.fix_satellites.and_then(|n| u16::try_from(n).ok()),
        hdop: gga.hdop.and_then(widen),
        diff_age_s,
        diff_station,
    })
}

/// `$--GNS,hhmmss.ss,llll.ll,a,yyyyy.yy,a,c--c,xx,x.x,x.x,x.x,x.x,x.x,a`: the mode field has
/// one letter per constellation (GPS, GLONASS, Galileo, BeiDou, ...); the best one counts.
fn decode_gns(sentence: &Sentence<'_>) -> Result<PositionReport, DecodeError> {
    let mut f = sentence.fields();
    let time = f.next_time()?;
    let latitude = f.next_angle("latitude")?;
    let longitude = f.next_angle("longitude")?;
    let modes = f.next_raw();
    let mut quality = FixQuality::Invalid;
    for c in modes.chars() {
        let q = FixQuality::from_mode_letter(c)
            .ok_or_else(|| f.error("mode indicator", format!("unknown mode letter {c:?}")))?;
        if q.rank() > quality.rank() {
            quality = q;
        }
    }
    let satellites = f.next_u16("satellites")?;
    let hdop = f.next_f64("HDOP")?;
    let altitude_msl = f.next_f64("altitude")?;
    let geoid_separation = f.next_f64("geoid separation")?;
    let diff_age_s = f.next_f64("differential age")?;
    let diff_station = f.next_u16("differential station")?;
    Ok(PositionReport {
        time,
        quality,
        latitude,
        longitude,
        altitude_msl,
        geoid_separation,
        satellites,
        hdop,
        diff_age_s,
        diff_station,
    })
}

fn decode_rmc(sentence: &Sentence<'_>) -> Result<Rmc, DecodeError> {
    let rmc = nmea::sentences::parse_rmc(crate_sentence(sentence, SentenceType::RMC))
        .map_err(|e| crate_error("RMC", e))?;
    let quality = match (rmc.status_of_fix, rmc.faa_mode) {
        (RmcStatusOfFix::Invalid, _) => FixQuality::Invalid,
        (_, Some(mode)) => quality_from_faa(mode),
        (RmcStatusOfFix::Differential, None) => FixQuality::Dgps,
        (RmcStatusOfFix::Autonomous, None) => FixQuality::Single,
    };
    let velocity = rmc
        .speed_over_ground
        .and_then(widen)
        .map(|knots| GroundVelocity {
            speed_mps: knots * MPS_PER_KNOT,
            course_deg: rmc.true_course.and_then(widen),
        });
    Ok(Rmc {
        time: rmc.fix_time,
        date: rmc.fix_date.map(gps_era_date),
        quality,
        latitude: rmc.lat,
        longitude: rmc.lon,
        velocity,
    })
}

/// RMC's two-digit years 80 to 82 are the GPS epoch's first years (a receiver's default
/// date after a cold start or a week-number rollover), not 2080 to 2082 as the nmea crate's
/// 1983 pivot reads them.
fn gps_era_date(date: NaiveDate) -> NaiveDate {
    match date.year() {
        2080..=2082 => date.with_year(date.year() - 100).unwrap_or(date),
        _ => date,
    }
}

/// VTG's speed and course; `None` for a VTG with no speed (a receiver without a fix sends
/// its fields empty).
fn decode_vtg(sentence: &Sentence<'_>) -> Result<Option<GroundVelocity>, DecodeError> {
    let vtg = nmea::sentences::parse_vtg(crate_sentence(sentence, SentenceType::VTG))
        .map_err(|e| crate_error("VTG", e))?;
    Ok(vtg
        .speed_over_ground
        .and_then(widen)
        .map(|knots| GroundVelocity {
            speed_mps: knots * MPS_PER_KNOT,
            course_deg: vtg.true_course.and_then(widen),
        }))
}

fn decode_gst(sentence: &Sentence<'_>) -> Result<GstAccuracy, DecodeError> {
    let gst = nmea::sentences::parse_gst(crate_sentence(sentence, SentenceType::GST))
        .map_err(|e| crate_error("GST", e))?;
    Ok(GstAccuracy {
        time: gst.time,
        rms_m: gst.rms_sd.and_then(widen),
        semi_major_m: gst.ellipse_semi_major_sd.and_then(widen),
        semi_minor_m: gst.ellipse_semi_minor_sd.and_then(widen),
        orientation_deg: gst.err_ellipse_orientation.and_then(widen),
        latitude_sd_m: gst.lat_sd.and_then(widen),
        longitude_sd_m: gst.long_sd.and_then(widen),
        altitude_sd_m: gst.alt_sd.and_then(widen),
    })
}

fn decode_hdt(sentence: &Sentence<'_>) -> Result<TrueHeading, DecodeError> {
    let hdt = nmea::sentences::parse_hdt(crate_sentence(sentence, SentenceType::HDT))
        .map_err(|e| crate_error("HDT", e))?;
    let heading_deg = hdt.heading.and_then(widen);
    check_heading("HDT", heading_deg)?;
    Ok(TrueHeading {
        heading_deg,
        sigma_deg: None,
    })
}

/// `$--THS,x.x,a`: heading and mode (A autonomous, E estimated, M manual, S simulator,
/// V not valid). Only autonomous headings are used, and Unicore's `T`: its `GNTHS2` sends
/// it with the heading its `GNHPR2` reports at fixed quality (its manual names no `T`).
fn decode_ths(sentence: &Sentence<'_>) -> Result<TrueHeading, DecodeError> {
    let mut f = sentence.fields();
    let heading = f.next_f64("heading")?;
    let mode = f.next_raw();
    let valid = match mode {
        "A" | "T" => true,
        "E" | "M" | "S" | "V" | "" => false,
        other => {
            return Err(f
                .error("mode indicator", format!("unknown mode {other:?}"))
                .into());
        }
    };
    check_heading("THS", heading)?;
    Ok(TrueHeading {
        heading_deg: heading.filter(|_| valid),
        sigma_deg: None,
    })
}

/// Unicore `$--HPR` and `$--TRA` (and their `2` forms): time, heading, pitch, roll, quality
/// (4: fixed ambiguities), satellites, differential age, station. Only a fixed baseline's
/// heading is used: these state no σ, and a float one can be degrees off. The time is not
/// read: the heading keeps its arrival time, and `HPR2` sends `-00001.00` there.
fn decode_hpr(sentence: &Sentence<'_>) -> Result<TrueHeading, DecodeError> {
    let mut f = sentence.fields();
    f.next_raw();
    let heading = f.next_f64("heading")?;
    f.next_f64("pitch")?;
    f.next_f64("roll")?;
    let quality = f.next_u16("quality")?;
    check_heading(sentence.kind, heading)?;
    Ok(TrueHeading {
        heading_deg: heading.filter(|_| quality == Some(4)),
        sigma_deg: None,
    })
}

/// Trimble `$PTNL,AVR`: time, yaw, `Yaw`, tilt, `Tilt`, roll, `Roll` (empty in older
/// firmware), baseline length, quality (0 none, 1 autonomous, 2 RTK float, 3 RTK fixed,
/// 4 DGPS), PDOP, satellites. Only an RTK fixed baseline's yaw is used (no σ is stated).
fn decode_avr(sentence: &Sentence<'_>) -> Result<TrueHeading, DecodeError> {
    let mut f = sentence.fields();
    f.next_raw();
    let yaw = f.next_f64("yaw")?;
    f.next_raw();
    f.next_f64("tilt")?;
    f.next_raw();
    f.next_f64("roll")?;
    f.next_raw();
    f.next_f64("baseline length")?;
    let quality = f.next_u16("quality")?;
    let heading = signed_heading(sentence.kind, yaw)?;
    Ok(TrueHeading {
        heading_deg: heading.filter(|_| quality == Some(3)),
        sigma_deg: None,
    })
}

/// Septentrio `$PSSN,HRP`: time, date, heading, roll, pitch, their σ (heading, roll,
/// pitch), satellites, attitude mode (0: none), magnetic variation and its side. Any
/// attitude the receiver computed is used with the heading σ it states, which is what
/// tells a float solution from a fixed one.
fn decode_hrp(sentence: &Sentence<'_>) -> Result<TrueHeading, DecodeError> {
    let mut f = sentence.fields();
    f.next_raw();
    f.next_raw();
    let heading = f.next_f64("heading")?;
    f.next_f64("roll")?;
    f.next_f64("pitch")?;
    let sigma = f.next_f64("heading σ")?;
    f.next_f64("roll σ")?;
    f.next_f64("pitch σ")?;
    f.next_u16("satellites")?;
    let mode = f.next_u16("attitude mode")?;
    check_heading(sentence.kind, heading)?;
    Ok(TrueHeading {
        heading_deg: heading.filter(|_| mode.is_some_and(|m| m > 0)),
        sigma_deg: stated_sigma(sentence.kind, sigma)?,
    })
}

/// `$PASHR` in its attitude form (Applanix, NovAtel, Trimble): time, heading, `T`, roll,
/// pitch, heave, roll σ, pitch σ, heading σ, GNSS quality (0: none, in every vendor's
/// table), IMU status. The heading is used with the σ it states unless the quality is 0.
fn decode_pashr(sentence: &Sentence<'_>) -> Result<TrueHeading, DecodeError> {
    let mut f = sentence.fields();
    f.next_raw();
    let heading = f.next_f64("heading")?;
    f.next_raw();
    f.next_f64("roll")?;
    f.next_f64("pitch")?;
    f.next_f64("heave")?;
    f.next_f64("roll σ")?;
    f.next_f64("pitch σ")?;
    let sigma = f.next_f64("heading σ")?;
    let quality = f.next_u16("quality")?;
    check_heading("PASHR", heading)?;
    Ok(TrueHeading {
        heading_deg: heading.filter(|_| quality != Some(0)),
        sigma_deg: stated_sigma("PASHR", sigma)?,
    })
}

/// Unicore's `#UNIHEADINGA` (and the NovAtel-style `#HEADINGA`): a header, `;`, then the
/// solution status, the position type, baseline length, heading, pitch, a reserved field,
/// heading σ, pitch σ, the station and satellite counts. Only a computed solution with
/// integer ambiguities (`L1_INT`, `NARROW_INT`, `WIDE_INT`) is used, with its σ: a float
/// one states σ of hundreds of degrees.
fn decode_uniheading(sentence: &Sentence<'_>) -> Result<TrueHeading, DecodeError> {
    let kind = sentence.kind;
    let (_, solution) = sentence.data.split_once(';').ok_or_else(|| DecodeError {
        kind: kind.to_owned(),
        reason: "no `;` between header and body".into(),
    })?;
    let mut f = Sentence {
        data: solution,
        ..*sentence
    }
    .fields();
    let status = f.next_raw();
    let position_type = f.next_raw();
    f.next_f64("baseline length")?;
    let heading = f.next_f64("heading")?;
    f.next_f64("pitch")?;
    f.next_raw();
    let sigma = f.next_f64("heading σ")?;
    check_heading(kind, heading)?;
    let fixed = status == "SOL_COMPUTED" && position_type.ends_with("_INT");
    Ok(TrueHeading {
        heading_deg: heading.filter(|_| fixed),
        sigma_deg: stated_sigma(kind, sigma)?,
    })
}

/// `$KSXT`: time (`YYYYMMDDhhmmss.ss`, UTC), longitude and latitude (decimal degrees),
/// height, heading, pitch, track, speed (km/h), roll, position quality, heading quality
/// (each 0 none, 1 single, 2 RTK float, 3 RTK fixed), heading satellites, position
/// satellites, east, north and up from the base, east, north and up velocity (km/h),
/// differential age, base satellites.
fn decode_ksxt(sentence: &Sentence<'_>) -> Result<Ksxt, DecodeError> {
    let mut f = sentence.fields();
    let stamp = f.next_raw();
    let (date, time) = match stamp {
        "" => (None, None),
        s => ksxt_time(s)
            .ok_or_else(|| f.error("time", format!("{s:?} is not YYYYMMDDhhmmss.ss")))?,
    };
    let longitude = f.next_f64("longitude")?;
    let latitude = f.next_f64("latitude")?;
    f.next_f64("height")?;
    let heading = f.next_f64("heading")?;
    f.next_f64("pitch")?;
    let track = f.next_f64("track")?;
    let speed_kmh = f.next_f64("speed")?;
    f.next_f64("roll")?;
    let position_quality = ksxt_quality(&mut f, "position quality")?;
    let heading_quality = ksxt_quality(&mut f, "heading quality")?;
    f.next_u16("heading satellites")?;
    let satellites = f.next_u16("position satellites")?;
    for what in [
        "east",
        "north",
        "up",
        "east velocity",
        "north velocity",
        "up velocity",
    ] {
        f.next_f64(what)?;
    }
    let diff_age_s = f.next_f64("differential age")?;
    if latitude.is_some_and(|l| !(-90.0..=90.0).contains(&l))
        || longitude.is_some_and(|l| !(-180.0..=180.0).contains(&l))
    {
        return Err(DecodeError {
            kind: "KSXT".into(),
            reason: format!("position {latitude:?}, {longitude:?} outside the globe"),
        });
    }
    check_heading("KSXT", heading)?;
    Ok(Ksxt {
        date,
        position: PositionReport {
            time,
            quality: position_quality,
            latitude,
            longitude,
            satellites,
            diff_age_s,
            ..PositionReport::default()
        },
        heading: TrueHeading {
            heading_deg: heading.filter(|_| heading_quality == FixQuality::RtkFixed),
            sigma_deg: None,
        },
        velocity: speed_kmh.map(|kmh| GroundVelocity {
            speed_mps: kmh * MPS_PER_KMH,
            course_deg: track,
        }),
    })
}

/// KSXT's `YYYYMMDDhhmmss.ss`.
fn ksxt_time(s: &str) -> Option<(Option<NaiveDate>, Option<NaiveTime>)> {
    let (date, time) = (s.get(..8)?, s.get(8..)?);
    if !date.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let date = NaiveDate::from_ymd_opt(
        date[..4].parse().ok()?,
        date[4..6].parse().ok()?,
        date[6..].parse().ok()?,
    )?;
    Some((Some(date), Some(super::sentence::parse_hhmmss(time)?)))
}

/// KSXT's quality codes: 0 none, 1 single, 2 RTK float, 3 RTK fixed.
fn ksxt_quality(
    f: &mut super::sentence::Fields<'_>,
    what: &'static str,
) -> Result<FixQuality, DecodeError> {
    Ok(match f.next_u16(what)? {
        None | Some(0) => FixQuality::Invalid,
        Some(1) => FixQuality::Single,
        Some(2) => FixQuality::RtkFloat,
        Some(3) => FixQuality::RtkFixed,
        Some(other) => return Err(f.error(what, format!("unknown quality {other}")).into()),
    })
}

/// A yaw that may be sent signed (Trimble's `+149.4688`, or -180..180), as 0..360.
fn signed_heading(kind: &str, yaw: Option<f64>) -> Result<Option<f64>, DecodeError> {
    match yaw {
        Some(y) if !(-360.0..=360.0).contains(&y) => Err(DecodeError {
            kind: kind.to_owned(),
            reason: format!("yaw {y} outside -360..360"),
        }),
        y => Ok(y.map(|y| y.rem_euclid(360.0))),
    }
}

/// A stated σ: a size, so below 0 is an error; 0 (some receivers' "unknown") is none.
fn stated_sigma(kind: &str, sigma: Option<f64>) -> Result<Option<f64>, DecodeError> {
    match sigma {
        Some(s) if s < 0.0 => Err(DecodeError {
            kind: kind.to_owned(),
            reason: format!("σ {s} below 0"),
        }),
        s => Ok(s.filter(|&s| s > 0.0)),
    }
}

fn check_heading(kind: &str, heading: Option<f64>) -> Result<(), DecodeError> {
    match heading {
        Some(h) if !(0.0..=360.0).contains(&h) => Err(DecodeError {
            kind: kind.to_owned(),
            reason: format!("heading {h} outside 0..360"),
        }),
        _ => Ok(()),
    }
}

fn decode_zda(sentence: &Sentence<'_>) -> Result<ZdaDate, DecodeError> {
    let zda = nmea::sentences::parse_zda(crate_sentence(sentence, SentenceType::ZDA))
        .map_err(|e| crate_error("ZDA", e))?;
    let date = match (zda.year, zda.month, zda.day) {
        (Some(y), Some(m), Some(d)) => Some(
            NaiveDate::from_ymd_opt(i32::from(y), u32::from(m), u32::from(d)).ok_or_else(|| {
                DecodeError {
                    kind: "ZDA".into(),
                    reason: format!("invalid date {y:04}-{m:02}-{d:02}"),
                }
            })?,
        ),
        _ => None,
    };
    Ok(ZdaDate {
        time: zda.utc_time,
        date,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode_body(body: &str) -> Result<Option<GnssSentence>, DecodeError> {
        decode(&Sentence::parse(body))
    }

    proptest::proptest! {
        /// Any decimal of up to six significant digits (what f32 is sure to keep) comes
        /// back exactly as sent.
        #[test]
        fn widen_gives_back_the_sent_decimal(
            mantissa in 0u32..1_000_000,
            point in 0usize..9,
            negative in proptest::bool::ANY,
        ) {
            let digits = format!("{mantissa:0>width$}", width = point + 1);
            let (whole, frac) = digits.split_at(digits.len() - point);
            let sign = if negative { "-" } else { "" };
            let sent = if point == 0 { format!("{sign}{whole}") } else { format!("{sign}{whole}.{frac}") };
            let received: f32 = sent.parse().unwrap();
            proptest::prop_assert_eq!(widen(received), Some(sent.parse::<f64>().unwrap()), "{}", sent);
        }
    }

    #[test]
    fn widen_keeps_the_sent_decimal() {
        assert_eq!(widen(244.28), Some(244.28));
        assert_eq!(widen(0.049), Some(0.049));
        assert_eq!(widen(f32::NAN), None);
    }

    #[test]
    fn rank_prefers_rtk() {
        assert!(FixQuality::RtkFixed.rank() > FixQuality::RtkFloat.rank());
        assert!(FixQuality::RtkFloat.rank() > FixQuality::Dgps.rank());
        assert!(FixQuality::Single.rank() > FixQuality::Invalid.rank());
    }

    #[test]
    fn unknown_and_proprietary_types_are_not_errors() {
        assert_eq!(decode_body("GPGSV,1,1,00"), Ok(None));
        assert_eq!(decode_body("PSTI,030,1"), Ok(None));
    }

    fn heading_of(body: &str) -> TrueHeading {
        match decode_body(body) {
            Ok(Some(GnssSentence::Heading(h) | GnssSentence::Ths(h))) => h,
            other => panic!("{body}: {other:?}"),
        }
    }

    #[test]
    fn vendor_headings_are_used_at_the_quality_they_state() {
        // Trimble: RTK fixed (3) only; signed yaws are brought to 0..360.
        let avr = "PTNL,AVR,181059.6,+149.4688,Yaw,+0.0134,Tilt,,,60.191,3,2.5,6";
        assert_eq!(heading_of(avr).heading_deg, Some(149.4688));
        let float = "PTNL,AVR,145331.50,-35.9990,Yaw,-7.8209,Tilt,-0.4305,Roll,444.232,2,1.2,17";
        assert_eq!(heading_of(float).heading_deg, None);
        let fixed = float.replace(",2,1.2,", ",3,1.2,");
        assert_eq!(heading_of(&fixed).heading_deg, Some(324.001));
        // Septentrio: any attitude it computed, with its σ; mode 0 none.
        let hrp = heading_of("PSSN,HRP,142657.80,061222,152.236,,-0.708,0.084,,0.181,21,2,2.400,E");
        assert_eq!(
            (hrp.heading_deg, hrp.sigma_deg),
            (Some(152.236), Some(0.084))
        );
        let none = "PSSN,HRP,142657.80,061222,152.236,,-0.708,0.084,,0.181,21,0,2.400,E";
        assert_eq!(heading_of(none).heading_deg, None);
        // PASHR's attitude form with its σ; quality 0 none; Ashtech's forms are not headings.
        let pashr = heading_of("PASHR,183944.821,74.52,T,-1.63,1.51,0.14,0.020,0.020,0.012,2,1");
        assert_eq!(
            (pashr.heading_deg, pashr.sigma_deg),
            (Some(74.52), Some(0.012))
        );
        let lost = "PASHR,183944.821,74.52,T,-1.63,1.51,0.14,0.020,0.020,0.012,0,1";
        assert_eq!(heading_of(lost).heading_deg, None);
        assert_eq!(decode_body("PASHR,POS,0,10,151858.00,3723.4"), Ok(None));
        // Unicore: fixed (4) only, the `2` forms as the plain ones, HPR2's odd time unread.
        let hpr = "GNHPR,074615.00,320.9610,-66.1712,000.0000,4,47,0.00,0999";
        assert_eq!(heading_of(hpr).heading_deg, Some(320.961));
        let hpr2 = "GNHPR2,-00001.00,088.3640,-00.0873,000.0000,4,32,0.00,0401";
        assert_eq!(heading_of(hpr2).heading_deg, Some(88.364));
        let tra2 = "GNTRA2,090415.00,88.36,-0.09,0.00,5,30,0.00,0000";
        assert_eq!(heading_of(tra2).heading_deg, None);
        assert_eq!(heading_of("GNTHS2,88.3640,T").heading_deg, Some(88.364));
    }

    #[test]
    fn bad_vendor_headings_are_errors() {
        assert!(decode_body("PTNL,AVR,181059.6,+549.4,Yaw,+0.0134,Tilt,,,60.191,3,2.5,6").is_err());
        assert!(decode_body("PSSN,HRP,142657.80,061222,152.236,,-0.708,-1,,0.181,21,2").is_err());
        assert!(decode_body("GNHPR,074615.00,x,-66.1712,000.0000,4,47,0.00,0999").is_err());
        assert!(
            decode_body("PASHR,183944.821,74.52,T,-1.63,1.51,0.14,0.020,0.020,0.012,x").is_err()
        );
    }

    #[test]
    fn the_second_antennas_sentences_are_checked_but_never_a_position() {
        let ggah =
            "GNGGAH,073346.00,4004.73874301,N,11614.19077585,E,1,28,0.6,64.2831,M,8.4925,M,,";
        assert_eq!(decode_body(ggah), Ok(Some(GnssSentence::SecondaryAntenna)));
        assert!(decode_body("GNGGAH,073346.00,4004.7,N,11614.1,E,x,28").is_err());
        // Other six-letter addresses are not variants.
        assert_eq!(
            decode_body("GNGGA2,073346.00,4004.7,N,11614.1,E,1,28"),
            Ok(None)
        );
    }

    #[test]
    fn ksxt_gives_position_heading_and_velocity_each_at_its_quality() {
        let body = "KSXT,20211016083433.00,116.31296102,39.95817066,49.4911,223.57,-11.32,330.19,0.024,,1,3,28,27,,,,-0.012,0.021,0.020,,";
        let Ok(Some(GnssSentence::Ksxt(k))) = decode_body(body) else {
            panic!("{:?}", decode_body(body))
        };
        assert_eq!(k.date, NaiveDate::from_ymd_opt(2021, 10, 16));
        assert_eq!(k.position.time.unwrap().to_string(), "08:34:33");
        assert_eq!(k.position.quality, FixQuality::Single);
        assert_eq!(
            (k.position.latitude, k.position.longitude),
            (Some(39.95817066), Some(116.31296102))
        );
        assert_eq!(k.position.satellites, Some(27));
        assert_eq!(k.heading.heading_deg, Some(223.57));
        let v = k.velocity.unwrap();
        assert!((v.speed_mps - 0.024 / 3.6).abs() < 1e-12);
        assert_eq!(v.course_deg, Some(330.19));
        // A float heading is not used; an unknown quality or a position off the globe is an error.
        let float = body.replace(",1,3,28,", ",3,2,28,");
        let Ok(Some(GnssSentence::Ksxt(k))) = decode_body(&float) else {
            panic!()
        };
        assert_eq!(
            (k.position.quality, k.heading.heading_deg),
            (FixQuality::RtkFixed, None)
        );
        assert!(decode_body(&body.replace(",1,3,28,", ",7,3,28,")).is_err());
        assert!(decode_body(&body.replace("39.95817066", "99.5")).is_err());
        assert!(decode_body(&body.replace("20211016083433.00", "2021101608")).is_err());
    }

    #[test]
    fn uniheading_is_used_with_integer_ambiguities_and_its_sigma() {
        let fixed = "#UNIHEADINGA,79,GPS,FINE,2242,167498200,0,0,18,22;SOL_COMPUTED,L1_INT,2.7889,296.7233,-25.7710,0.0000,0.1127,0.1812,\"999\",49,37,37,0,3,00,1,51";
        let h = heading_of(fixed);
        assert_eq!((h.heading_deg, h.sigma_deg), (Some(296.7233), Some(0.1127)));
        let float = "#HEADINGA,COM1,13495,95.0,FINE,2415,73711.000,17020772,13,18;SOL_COMPUTED,L1_FLOAT,12.2446,260.1887,-35.0258,0.0000,292.7253,155.0128,\"999\",29,7,7,0,3,00,0,51";
        assert_eq!(heading_of(float).heading_deg, None);
        let none = "#UNIHEADINGA,97,GPS,FINE,2190,365174000,0,0,18,12;INSUFFICIENT_OBS,NONE,0.0000,0.0000,0.0000,0.0000,0.0000,0.0000,\"\",0,0,0,0,0,00,0,0";
        assert_eq!(heading_of(none).heading_deg, None);
        assert!(decode_body("#UNIHEADINGA,79,GPS,FINE").is_err());
    }

    #[test]
    fn an_empty_vtg_is_legal_and_gives_nothing() {
        assert_eq!(decode_body("GPVTG,,T,,M,,N,,K,N"), Ok(None));
    }

    #[test]
    fn malformed_known_type_is_an_error() {
        let err = decode_body("GPGGA,123519,4807.038,N,01131.000,E,x,08").unwrap_err();
        assert_eq!(err.kind, "GGA");
        assert!(decode_body("GNTHS,400.0,A").is_err());
        assert!(decode_body("GNTHS,100.0,Q").is_err());
    }
}
