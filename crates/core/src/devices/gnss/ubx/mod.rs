//! u-blox UBX: the frames chassisd reads from a receiver and the configuration it writes.
//!
//! Layouts follow u-blox's interface descriptions (ZED-F9P protocol 27 and later, NEO-M8P
//! protocol 20). Every message is checked against its documented length before a field is
//! read; a message of a known id whose length or version does not fit is a decode error,
//! counted like an NMEA sentence that does not decode. Ids chassisd does not read are left
//! alone.

pub mod config;
pub mod frame;

use std::borrow::Cow;

use chrono::{NaiveDate, NaiveDateTime, TimeDelta};

pub use frame::UbxFrame;

use super::decode::{DecodeError, FixQuality, TrueHeading};

/// A UBX message chassisd reads.
#[derive(Debug, Clone, PartialEq)]
pub enum UbxMessage {
    /// NAV-PVT: the navigation solution.
    NavPvt(NavPvt),
    /// NAV-SOL: the navigation solution in ECEF with GPS time (u-blox 6 to 8).
    NavSol(NavSol),
    /// NAV-TIMEGPS: GPS time and the leap seconds.
    NavTimeGps(NavTimeGps),
    /// NAV-HPPOSLLH: the position at full precision.
    NavHpPosLlh(NavHpPosLlh),
    /// NAV-COV: the position's covariance.
    NavCov(NavCov),
    /// NAV-RELPOSNED: the vector from the base (or moving base) to this antenna.
    NavRelPosNed(NavRelPosNed),
    /// NAV-STATUS: the fix status.
    NavStatus(NavStatus),
    /// NAV-SAT: satellites tracked and used.
    NavSat(NavSat),
    /// NAV-DOP: dilutions of precision.
    NavDop(NavDop),
    /// NAV-EOE: the end of an epoch's navigation messages.
    NavEoe {
        /// GPS time of week of the epoch, ms.
        itow_ms: u32,
    },
    /// RXM-RTCM: an RTCM message the receiver took in, and whether it used it.
    RxmRtcm(RxmRtcm),
    /// MON-VER: the receiver's software and hardware.
    MonVer(MonVer),
    /// ACK-ACK or ACK-NAK: the answer to a configuration message.
    Ack(Ack),
    /// CFG-VALGET's answer: configuration items read back.
    CfgValGet(config::ValGetAnswer),
}

/// NAV-PVT's class and id.
pub const NAV_PVT: (u8, u8) = (0x01, 0x07);
/// NAV-SOL's class and id.
pub const NAV_SOL: (u8, u8) = (0x01, 0x06);

/// The name of a UBX message by class and id, where chassisd knows it.
pub fn message_name(class: u8, id: u8) -> Option<&'static str> {
    Some(match (class, id) {
        (0x01, 0x01) => "NAV-POSECEF",
        (0x01, 0x03) => "NAV-STATUS",
        (0x01, 0x04) => "NAV-DOP",
        (0x01, 0x06) => "NAV-SOL",
        (0x01, 0x07) => "NAV-PVT",
        (0x01, 0x11) => "NAV-VELECEF",
        (0x01, 0x13) => "NAV-HPPOSECEF",
        (0x01, 0x14) => "NAV-HPPOSLLH",
        (0x01, 0x20) => "NAV-TIMEGPS",
        (0x01, 0x21) => "NAV-TIMEUTC",
        (0x01, 0x35) => "NAV-SAT",
        (0x01, 0x36) => "NAV-COV",
        (0x01, 0x3c) => "NAV-RELPOSNED",
        (0x01, 0x43) => "NAV-SIG",
        (0x01, 0x61) => "NAV-EOE",
        (0x02, 0x32) => "RXM-RTCM",
        (0x05, 0x00) => "ACK-NAK",
        (0x05, 0x01) => "ACK-ACK",
        (0x06, 0x8a) => "CFG-VALSET",
        (0x06, 0x8b) => "CFG-VALGET",
        (0x0a, 0x04) => "MON-VER",
        (0x0a, 0x38) => "MON-RF",
        _ => return None,
    })
}

/// The name a frame is counted under: its message name, else `UBX cc-ii`.
pub fn kind_of(frame: &UbxFrame<'_>) -> Cow<'static, str> {
    match message_name(frame.class, frame.id) {
        Some(name) => Cow::Borrowed(name),
        None => Cow::Owned(format!("UBX {:02X}-{:02X}", frame.class, frame.id)),
    }
}

/// Decodes `frame` if it is a message chassisd reads; other messages are `Ok(None)`.
pub fn decode(frame: &UbxFrame<'_>) -> Result<Option<UbxMessage>, DecodeError> {
    let p = Fields::new(frame);
    Ok(Some(match (frame.class, frame.id) {
        (0x01, 0x07) => UbxMessage::NavPvt(NavPvt::decode(p)?),
        (0x01, 0x06) => UbxMessage::NavSol(NavSol::decode(p)?),
        (0x01, 0x20) => UbxMessage::NavTimeGps(NavTimeGps::decode(p)?),
        (0x01, 0x14) => UbxMessage::NavHpPosLlh(NavHpPosLlh::decode(p)?),
        (0x01, 0x36) => UbxMessage::NavCov(NavCov::decode(p)?),
        (0x01, 0x3c) => UbxMessage::NavRelPosNed(NavRelPosNed::decode(p)?),
        (0x01, 0x03) => UbxMessage::NavStatus(NavStatus::decode(p)?),
        (0x01, 0x35) => UbxMessage::NavSat(NavSat::decode(p)?),
        (0x01, 0x04) => UbxMessage::NavDop(NavDop::decode(p)?),
        (0x01, 0x61) => UbxMessage::NavEoe {
            itow_ms: p.need(4)?.u32(0),
        },
        (0x02, 0x32) => UbxMessage::RxmRtcm(RxmRtcm::decode(p)?),
        (0x0a, 0x04) => UbxMessage::MonVer(MonVer::decode(p)?),
        (0x05, id @ (0x00 | 0x01)) => {
            let p = p.need(2)?;
            UbxMessage::Ack(Ack {
                class: p.u8(0),
                id: p.u8(1),
                accepted: id == 0x01,
            })
        }
        (0x06, 0x8b) => UbxMessage::CfgValGet(config::ValGetAnswer::decode(frame.payload)?),
        _ => return Ok(None),
    }))
}

/// A payload read by offset, little-endian, once its length is checked.
#[derive(Debug, Clone, Copy)]
struct Fields<'a> {
    name: &'static str,
    bytes: &'a [u8],
}

impl<'a> Fields<'a> {
    fn new(frame: &UbxFrame<'a>) -> Self {
        Self {
            name: message_name(frame.class, frame.id).unwrap_or("UBX"),
            bytes: frame.payload,
        }
    }

    /// The payload, when it holds at least `len` bytes.
    fn need(self, len: usize) -> Result<Self, DecodeError> {
        if self.bytes.len() >= len {
            Ok(self)
        } else {
            Err(self.error(format!("{} bytes where {len} are needed", self.bytes.len())))
        }
    }

    fn error(&self, reason: String) -> DecodeError {
        DecodeError {
            kind: self.name.to_owned(),
            reason,
        }
    }

    fn array<const N: usize>(&self, at: usize) -> [u8; N] {
        // Lengths are checked by `need` before any field is read; a short read would be a
        // layout bug here, and reads as zeros rather than a panic on a receiver's bytes.
        self.bytes
            .get(at..at + N)
            .and_then(|s| s.try_into().ok())
            .unwrap_or([0; N])
    }

    fn u8(&self, at: usize) -> u8 {
        self.array::<1>(at)[0]
    }

    fn i8(&self, at: usize) -> i8 {
        i8::from_le_bytes(self.array(at))
    }

    fn u16(&self, at: usize) -> u16 {
        u16::from_le_bytes(self.array(at))
    }

    fn u32(&self, at: usize) -> u32 {
        u32::from_le_bytes(self.array(at))
    }

    fn i32(&self, at: usize) -> i32 {
        i32::from_le_bytes(self.array(at))
    }

    fn f32(&self, at: usize) -> f64 {
        f64::from(f32::from_le_bytes(self.array(at)))
    }
}

/// The carrier-phase solution (RTK) a message reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CarrierSolution {
    /// No carrier-phase solution.
    #[default]
    None,
    /// Carrier phase with float ambiguities.
    Float,
    /// Carrier phase with fixed (integer) ambiguities.
    Fixed,
}

impl CarrierSolution {
    fn from_bits(bits: u32) -> Self {
        match bits & 0b11 {
            1 => Self::Float,
            2 => Self::Fixed,
            _ => Self::None,
        }
    }
}

/// The fix quality of a u-blox fix type and its flags, as NMEA's GGA would state it.
fn quality_of(fix_type: u8, fix_ok: bool, diff: bool, carrier: CarrierSolution) -> FixQuality {
    if !fix_ok {
        return FixQuality::Invalid;
    }
    match fix_type {
        // 2D, 3D, GNSS combined with dead reckoning.
        2..=4 => match carrier {
            CarrierSolution::Fixed => FixQuality::RtkFixed,
            CarrierSolution::Float => FixQuality::RtkFloat,
            CarrierSolution::None if diff => FixQuality::Dgps,
            CarrierSolution::None => FixQuality::Single,
        },
        1 => FixQuality::DeadReckoning,
        // No fix, time only.
        _ => FixQuality::Invalid,
    }
}

/// The upper bounds of NAV-PVT's correction-age classes, s (class 0: not available).
const CORRECTION_AGE_BOUNDS_S: [f64; 12] = [
    1.0, 2.0, 5.0, 10.0, 15.0, 20.0, 30.0, 45.0, 60.0, 90.0, 120.0, 240.0,
];

/// NAV-PVT (`01 07`, 92 bytes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavPvt {
    /// GPS time of week of the epoch, ms: the key that ties an epoch's messages together.
    pub itow_ms: u32,
    /// UTC of the epoch, to the millisecond, when the receiver marks date and time valid.
    pub utc: Option<NaiveDateTime>,
    /// 0 no fix, 1 dead reckoning only, 2 2D, 3 3D, 4 GNSS and dead reckoning, 5 time only.
    pub fix_type: u8,
    /// The fix is within the receiver's limits (`gnssFixOK`).
    pub fix_ok: bool,
    /// Differential corrections were applied.
    pub differential: bool,
    /// The carrier-phase solution.
    pub carrier: CarrierSolution,
    /// Satellites used.
    pub satellites: u8,
    /// Latitude, degrees.
    pub latitude_deg: f64,
    /// Longitude, degrees.
    pub longitude_deg: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// Height above mean sea level, m.
    pub height_msl_m: f64,
    /// Horizontal accuracy estimate, m.
    pub h_acc_m: f64,
    /// Vertical accuracy estimate, m.
    pub v_acc_m: f64,
    /// Ground speed, m/s.
    pub ground_speed_mps: f64,
    /// Heading of motion, degrees.
    pub motion_heading_deg: f64,
    /// Position DOP.
    pub pdop: f64,
    /// The receiver marks latitude, longitude and heights invalid (`invalidLlh`, protocol
    /// 27.11 and later; reserved, so zero, before).
    pub invalid_llh: bool,
    /// Age of the corrections, the upper bound of the receiver's class, s.
    pub correction_age_s: Option<f64>,
}

impl NavPvt {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(92)?;
        let valid = p.u8(11);
        let flags = p.u8(21);
        let flags3 = p.u16(78);
        let utc = if valid & 0b11 == 0b11 {
            let utc = utc_of(
                p.u16(4),
                p.u8(6),
                p.u8(7),
                p.u8(8),
                p.u8(9),
                p.u8(10),
                p.i32(16),
            );
            Some(utc.ok_or_else(|| p.error("date or time out of range".into()))?)
        } else {
            None
        };
        let age_class = usize::from((flags3 >> 1) & 0x0f);
        Ok(Self {
            itow_ms: p.u32(0),
            utc,
            fix_type: p.u8(20),
            fix_ok: flags & 0x01 != 0,
            differential: flags & 0x02 != 0,
            carrier: CarrierSolution::from_bits(u32::from(flags >> 6)),
            satellites: p.u8(23),
            longitude_deg: f64::from(p.i32(24)) * 1e-7,
            latitude_deg: f64::from(p.i32(28)) * 1e-7,
            height_m: f64::from(p.i32(32)) * 1e-3,
            height_msl_m: f64::from(p.i32(36)) * 1e-3,
            h_acc_m: f64::from(p.u32(40)) * 1e-3,
            v_acc_m: f64::from(p.u32(44)) * 1e-3,
            ground_speed_mps: f64::from(p.i32(60)) * 1e-3,
            motion_heading_deg: f64::from(p.i32(64)) * 1e-5,
            pdop: f64::from(p.u16(76)) * 0.01,
            invalid_llh: flags3 & 0x01 != 0,
            correction_age_s: age_class
                .checked_sub(1)
                .and_then(|i| CORRECTION_AGE_BOUNDS_S.get(i))
                .copied(),
        })
    }

    /// The fix quality, as GGA would state it.
    pub fn quality(&self) -> FixQuality {
        quality_of(self.fix_type, self.fix_ok, self.differential, self.carrier)
    }

    /// Whether the position fields hold a position.
    pub fn has_position(&self) -> bool {
        self.quality().is_valid() && !self.invalid_llh
    }
}

/// UTC from NAV-PVT's fields, rounded to the millisecond: `nano` (−1e9..1e9) corrects the
/// whole second to the instant of the epoch, which falls on a millisecond.
fn utc_of(
    year: u16,
    month: u8,
    day: u8,
    hour: u8,
    minute: u8,
    second: u8,
    nano: i32,
) -> Option<NaiveDateTime> {
    if !(-1_000_000_000..=1_000_000_000).contains(&nano) || second > 60 {
        return None;
    }
    let date = NaiveDate::from_ymd_opt(i32::from(year), u32::from(month), u32::from(day))?;
    // A leap second (60) is counted as the next minute's 0.
    let whole = date.and_hms_opt(u32::from(hour), u32::from(minute), 0)?
        + TimeDelta::seconds(i64::from(second));
    let ms = (i64::from(nano) + if nano < 0 { -500_000 } else { 500_000 }) / 1_000_000;
    Some(whole + TimeDelta::milliseconds(ms))
}

/// NAV-SOL (`01 06`, 52 bytes): the solution as u-blox 6 to 8 (and their timing receivers)
/// send it, in ECEF with GPS time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavSol {
    /// GPS time of week, ms.
    pub itow_ms: u32,
    /// GPS week and time of week (s, with `fTOW`), when the receiver marks both set.
    pub gps_time: Option<(u16, f64)>,
    /// Fix type, as NAV-PVT's.
    pub fix_type: u8,
    /// The fix is within the receiver's limits (`gpsFixOk`).
    pub fix_ok: bool,
    /// Differential corrections applied.
    pub differential: bool,
    /// ECEF position, m.
    pub ecef_m: [f64; 3],
    /// 3D position accuracy, m.
    pub p_acc_m: f64,
    /// ECEF velocity, m/s.
    pub ecef_velocity_mps: [f64; 3],
    /// Position DOP.
    pub pdop: f64,
    /// Satellites used.
    pub satellites: u8,
}

impl NavSol {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(52)?;
        let flags = p.u8(11);
        let itow_ms = p.u32(0);
        // Week number and time of week both set.
        let gps_time = (flags & 0x0c == 0x0c).then(|| {
            (
                p.u16(8),
                f64::from(itow_ms) * 1e-3 + f64::from(p.i32(4)) * 1e-9,
            )
        });
        let cm = |at: usize| f64::from(p.i32(at)) * 1e-2;
        Ok(Self {
            itow_ms,
            gps_time,
            fix_type: p.u8(10),
            fix_ok: flags & 0x01 != 0,
            differential: flags & 0x02 != 0,
            ecef_m: [cm(12), cm(16), cm(20)],
            p_acc_m: f64::from(p.u32(24)) * 1e-2,
            ecef_velocity_mps: [cm(28), cm(32), cm(36)],
            pdop: f64::from(p.u16(44)) * 0.01,
            satellites: p.u8(47),
        })
    }

    /// The fix quality, as GGA would state it (NAV-SOL has no carrier solution).
    pub fn quality(&self) -> FixQuality {
        quality_of(
            self.fix_type,
            self.fix_ok,
            self.differential,
            CarrierSolution::None,
        )
    }

    /// UTC of the epoch, to the millisecond, with `leap_s` GPS−UTC leap seconds (the
    /// receiver's from NAV-TIMEGPS, else [`leap_seconds_at`]).
    pub fn utc(&self, leap_s: Option<i8>) -> Option<NaiveDateTime> {
        let (week, tow) = self.gps_time?;
        let gps = gps_epoch()
            + TimeDelta::weeks(i64::from(week))
            + TimeDelta::milliseconds((tow * 1e3).round() as i64);
        let leap = leap_s.map_or_else(|| leap_seconds_at(gps), i64::from);
        Some(gps - TimeDelta::seconds(leap))
    }
}

/// NAV-TIMEGPS (`01 20`, 16 bytes): GPS time and GPS−UTC leap seconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NavTimeGps {
    /// GPS time of week, ms.
    pub itow_ms: u32,
    /// GPS−UTC leap seconds, when the receiver marks them valid (from the almanac, not its
    /// firmware's default).
    pub leap_s: Option<i8>,
}

impl NavTimeGps {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(16)?;
        Ok(Self {
            itow_ms: p.u32(0),
            leap_s: (p.u8(11) & 0x04 != 0).then(|| p.i8(10)),
        })
    }
}

/// The GPS time scale's start, 1980-01-06 00:00:00.
fn gps_epoch() -> NaiveDateTime {
    NaiveDate::from_ymd_opt(1980, 1, 6)
        .and_then(|d| d.and_hms_opt(0, 0, 0))
        .unwrap_or_default()
}

/// GPS−UTC at GPS time `gps`, from the leap seconds IERS has announced (the last at the end
/// of 2016; none since, to the Bulletin C of 2026). A receiver's NAV-TIMEGPS, when valid,
/// takes precedence.
pub fn leap_seconds_at(gps: NaiveDateTime) -> i64 {
    // UTC dates from which GPS−UTC is 1, 2, ...; a GPS time passes each date that many
    // seconds after UTC does.
    const STEPS: [(i32, u32); 18] = [
        (1981, 7),
        (1982, 7),
        (1983, 7),
        (1985, 7),
        (1988, 1),
        (1990, 1),
        (1991, 1),
        (1992, 7),
        (1993, 7),
        (1994, 7),
        (1996, 1),
        (1997, 7),
        (1999, 1),
        (2006, 1),
        (2009, 1),
        (2012, 7),
        (2015, 7),
        (2017, 1),
    ];
    STEPS
        .iter()
        .enumerate()
        .take_while(|(i, (year, month))| {
            NaiveDate::from_ymd_opt(*year, *month, 1)
                .and_then(|d| d.and_hms_opt(0, 0, 0))
                .is_some_and(|step| gps - TimeDelta::seconds(*i as i64 + 1) >= step)
        })
        .count() as i64
}

/// NAV-HPPOSLLH (`01 14`, 36 bytes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavHpPosLlh {
    /// GPS time of week, ms.
    pub itow_ms: u32,
    /// Latitude, degrees, to 1e-9.
    pub latitude_deg: f64,
    /// Longitude, degrees, to 1e-9.
    pub longitude_deg: f64,
    /// Height above the ellipsoid, m, to 0.1 mm.
    pub height_m: f64,
    /// Height above mean sea level, m.
    pub height_msl_m: f64,
    /// Horizontal accuracy estimate, m.
    pub h_acc_m: f64,
    /// Vertical accuracy estimate, m.
    pub v_acc_m: f64,
    /// The receiver marks the position invalid (`invalidLlh`, newer firmware).
    pub invalid_llh: bool,
}

impl NavHpPosLlh {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(36)?;
        if p.u8(0) != 0 {
            return Err(p.error(format!("version {} is not 0", p.u8(0))));
        }
        // The standard part in 1e-7 degrees and the extra in 1e-9, joined as integers.
        let degrees =
            |at: usize, hp: usize| (i64::from(p.i32(at)) * 100 + i64::from(p.i8(hp))) as f64 * 1e-9;
        let metres =
            |at: usize, hp: usize| (i64::from(p.i32(at)) * 10 + i64::from(p.i8(hp))) as f64 * 1e-4;
        Ok(Self {
            itow_ms: p.u32(4),
            longitude_deg: degrees(8, 24),
            latitude_deg: degrees(12, 25),
            height_m: metres(16, 26),
            height_msl_m: metres(20, 27),
            h_acc_m: f64::from(p.u32(28)) * 1e-4,
            v_acc_m: f64::from(p.u32(32)) * 1e-4,
            invalid_llh: p.u8(3) & 0x01 != 0,
        })
    }
}

/// NAV-COV (`01 36`, 64 bytes): the position covariance in north, east, down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavCov {
    /// GPS time of week, ms.
    pub itow_ms: u32,
    /// The position covariance is valid.
    pub position_valid: bool,
    /// Position covariance NN, NE, ND, EE, ED, DD, m².
    pub position_ned_m2: [f64; 6],
}

impl NavCov {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(64)?;
        Ok(Self {
            itow_ms: p.u32(0),
            position_valid: p.u8(5) != 0,
            position_ned_m2: std::array::from_fn(|i| p.f32(16 + 4 * i)),
        })
    }

    /// North and east 1σ and their correlation's orientation, when the covariance is valid
    /// and positive: (north σ m, east σ m).
    pub fn horizontal_sigma_m(&self) -> Option<(f64, f64)> {
        let [nn, _, _, ee, _, _] = self.position_ned_m2;
        (self.position_valid && nn.is_finite() && ee.is_finite() && nn > 0.0 && ee > 0.0)
            .then(|| (nn.sqrt(), ee.sqrt()))
    }

    /// Down 1σ, m, when valid.
    pub fn vertical_sigma_m(&self) -> Option<f64> {
        let dd = self.position_ned_m2[5];
        (self.position_valid && dd.is_finite() && dd > 0.0).then(|| dd.sqrt())
    }
}

/// NAV-RELPOSNED (`01 3C`): version 0 (40 bytes, M8P) or 1 (64 bytes, F9).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavRelPosNed {
    /// Message version.
    pub version: u8,
    /// GPS time of week, ms.
    pub itow_ms: u32,
    /// The base's reference station id.
    pub ref_station: u16,
    /// North, east, down from the base to this antenna, m.
    pub relative_ned_m: [f64; 3],
    /// Their accuracies, m.
    pub accuracy_ned_m: [f64; 3],
    /// Length of the vector, m (version 1).
    pub length_m: Option<f64>,
    /// Heading of the vector, degrees (version 1; see [`Self::heading`]).
    pub heading_deg: Option<f64>,
    /// That heading's accuracy, degrees (version 1).
    pub heading_accuracy_deg: Option<f64>,
    /// The flags word: fix ok (bit 0), differential (1), vector valid (2), carrier
    /// solution (3-4), moving base (5), base position or observations missing (6, 7),
    /// heading valid (8, version 1).
    pub flags: u32,
}

impl NavRelPosNed {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let version = p.need(1)?.u8(0);
        let cm_hp =
            |at: usize, hp: usize| (i64::from(p.i32(at)) * 100 + i64::from(p.i8(hp))) as f64 * 1e-4;
        let tenth_mm = |at: usize| f64::from(p.u32(at)) * 1e-4;
        match version {
            0 => {
                let p = p.need(40)?;
                Ok(Self {
                    version,
                    itow_ms: p.u32(4),
                    ref_station: p.u16(2),
                    relative_ned_m: [cm_hp(8, 20), cm_hp(12, 21), cm_hp(16, 22)],
                    accuracy_ned_m: [tenth_mm(24), tenth_mm(28), tenth_mm(32)],
                    length_m: None,
                    heading_deg: None,
                    heading_accuracy_deg: None,
                    // Bits 8 and up do not exist in version 0.
                    flags: p.u32(36) & 0xff,
                })
            }
            1 => {
                let p = p.need(64)?;
                Ok(Self {
                    version,
                    itow_ms: p.u32(4),
                    ref_station: p.u16(2),
                    relative_ned_m: [cm_hp(8, 32), cm_hp(12, 33), cm_hp(16, 34)],
                    accuracy_ned_m: [tenth_mm(36), tenth_mm(40), tenth_mm(44)],
                    length_m: Some(cm_hp(20, 35)),
                    heading_deg: Some(f64::from(p.i32(24)) * 1e-5),
                    heading_accuracy_deg: Some(f64::from(p.u32(52)) * 1e-5),
                    flags: p.u32(60),
                })
            }
            other => Err(p.error(format!("version {other} is not 0 or 1"))),
        }
    }

    /// The carrier-phase solution of the vector.
    pub fn carrier(&self) -> CarrierSolution {
        CarrierSolution::from_bits(self.flags >> 3)
    }

    /// The vector's base moves with the vehicle (moving-base mode).
    pub fn moving_base(&self) -> bool {
        self.flags & 0x20 != 0
    }

    /// The heading of a moving-base vector, as a dual-antenna heading: only in moving-base
    /// mode (a vector from a fixed base says nothing of the vehicle's heading), when the
    /// receiver marks the fix, the vector and its heading valid and the ambiguities fixed (a
    /// float vector between two antennas a metre apart can point anywhere). Version 0 has no
    /// heading.
    pub fn heading(&self) -> TrueHeading {
        const NEEDED: u32 = 0x01 | 0x04 | 0x20 | 0x100;
        let valid = self.flags & NEEDED == NEEDED && self.carrier() == CarrierSolution::Fixed;
        TrueHeading {
            heading_deg: self
                .heading_deg
                .filter(|_| valid)
                .map(|h| h.rem_euclid(360.0)),
            sigma_deg: self.heading_accuracy_deg.filter(|s| valid && *s > 0.0),
        }
    }
}

/// NAV-STATUS (`01 03`, 16 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NavStatus {
    /// GPS time of week, ms.
    pub itow_ms: u32,
    /// Fix type, as NAV-PVT's.
    pub fix_type: u8,
    /// The fix is within limits.
    pub fix_ok: bool,
    /// Differential corrections applied.
    pub differential: bool,
    /// Carrier-phase solution.
    pub carrier: CarrierSolution,
    /// Time to first fix, ms.
    pub ttff_ms: u32,
}

impl NavStatus {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(16)?;
        let flags = p.u8(5);
        Ok(Self {
            itow_ms: p.u32(0),
            fix_type: p.u8(4),
            fix_ok: flags & 0x01 != 0,
            differential: flags & 0x02 != 0,
            carrier: CarrierSolution::from_bits(u32::from(p.u8(7) >> 6)),
            ttff_ms: p.u32(8),
        })
    }

    /// The fix quality, as GGA would state it.
    pub fn quality(&self) -> FixQuality {
        quality_of(self.fix_type, self.fix_ok, self.differential, self.carrier)
    }
}

/// NAV-SAT (`01 35`): satellites tracked and used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NavSat {
    /// GPS time of week, ms.
    pub itow_ms: u32,
    /// Satellites in the message.
    pub tracked: u16,
    /// Those used in the navigation solution.
    pub used: u16,
}

impl NavSat {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(8)?;
        let count = usize::from(p.u8(5));
        let p = p.need(8 + 12 * count)?;
        let used = (0..count)
            .filter(|i| p.u32(8 + 12 * i + 8) & 0x08 != 0)
            .count();
        Ok(Self {
            itow_ms: p.u32(0),
            tracked: count as u16,
            used: used as u16,
        })
    }
}

/// NAV-DOP (`01 04`, 18 bytes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavDop {
    /// GPS time of week, ms.
    pub itow_ms: u32,
    /// Horizontal DOP.
    pub hdop: f64,
}

impl NavDop {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(18)?;
        Ok(Self {
            itow_ms: p.u32(0),
            hdop: f64::from(p.u16(12)) * 0.01,
        })
    }
}

/// Whether the receiver used an RTCM message (RXM-RTCM).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RtcmUse {
    /// The receiver does not say.
    Unknown,
    /// Received but not used.
    NotUsed,
    /// Used.
    Used,
}

/// RXM-RTCM (`02 32`, 8 bytes): one RTCM message that reached the receiver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RxmRtcm {
    /// The message failed its CRC at the receiver.
    pub crc_failed: bool,
    /// Whether it was used.
    pub used: RtcmUse,
    /// Reference station id.
    pub ref_station: u16,
    /// RTCM message type (1005, 1077, 1230, ...).
    pub message_type: u16,
}

impl RxmRtcm {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(8)?;
        let flags = p.u8(1);
        Ok(Self {
            crc_failed: flags & 0x01 != 0,
            used: match (flags >> 1) & 0b11 {
                1 => RtcmUse::NotUsed,
                2 => RtcmUse::Used,
                _ => RtcmUse::Unknown,
            },
            ref_station: p.u16(4),
            message_type: p.u16(6),
        })
    }
}

/// MON-VER (`0A 04`): software, hardware and the extension strings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MonVer {
    /// Software version (`EXT CORE 1.00 (0fa0ae)`).
    pub software: String,
    /// Hardware version (`00190000`).
    pub hardware: String,
    /// Extensions (`FWVER=HPG 1.32`, `PROTVER=27.31`, `MOD=ZED-F9P`, ...).
    pub extensions: Vec<String>,
}

impl MonVer {
    fn decode(p: Fields<'_>) -> Result<Self, DecodeError> {
        let p = p.need(40)?;
        if (p.bytes.len() - 40) % 30 != 0 {
            return Err(p.error(format!(
                "{} bytes is not 40 plus 30 per extension",
                p.bytes.len()
            )));
        }
        let text = |s: &[u8]| {
            let end = s.iter().position(|&b| b == 0).unwrap_or(s.len());
            String::from_utf8_lossy(&s[..end]).trim().to_owned()
        };
        Ok(Self {
            software: text(&p.bytes[..30]),
            hardware: text(&p.bytes[30..40]),
            extensions: p.bytes[40..].chunks(30).map(text).collect(),
        })
    }

    /// The value of an extension `KEY=value`.
    fn extension(&self, key: &str) -> Option<&str> {
        self.extensions
            .iter()
            .find_map(|e| e.strip_prefix(key)?.strip_prefix('='))
    }

    /// Firmware (`HPG 1.32`).
    pub fn firmware(&self) -> Option<&str> {
        self.extension("FWVER")
    }

    /// Protocol version (`27.31`). Protocol 17 and older write `PROTVER 17.00`.
    pub fn protocol(&self) -> Option<&str> {
        self.extension("PROTVER").or_else(|| {
            self.extensions
                .iter()
                .find_map(|e| e.strip_prefix("PROTVER "))
        })
    }

    /// Module (`ZED-F9P`).
    pub fn module(&self) -> Option<&str> {
        self.extension("MOD")
    }

    /// One line for a person: module, firmware, protocol, software, hardware.
    pub fn summary(&self) -> String {
        format!(
            "u-blox {}, firmware {}, protocol {} (software {}, hardware {})",
            self.module().unwrap_or("(module not stated)"),
            self.firmware().unwrap_or("(not stated)"),
            self.protocol().unwrap_or("(not stated)"),
            self.software,
            self.hardware
        )
    }
}

/// ACK-ACK or ACK-NAK.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ack {
    /// Class of the message answered.
    pub class: u8,
    /// Id of the message answered.
    pub id: u8,
    /// ACK-ACK (true) or ACK-NAK.
    pub accepted: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(class: u8, id: u8, payload: &[u8]) -> UbxFrame<'_> {
        UbxFrame { class, id, payload }
    }

    /// NAV-PVT from gpsd's ZED-F9P RTK log (HPG 1.32): RTK float at 2022-10-11 11:04:24.
    const F9P_PVT: &str = "1045ad0ce6070a0b0b041837170000005dcb00000343ea156e2c11092f54171c57430d00b59c0c00430100002102000003000000f9ffffffeaffffff08000000740c2e016501000080a81201cd000e005c414f210000000000000000";

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    #[test]
    fn nav_pvt_of_a_real_f9p() {
        let payload = hex(F9P_PVT);
        let Some(UbxMessage::NavPvt(pvt)) = decode(&frame(1, 7, &payload)).unwrap() else {
            panic!("not a NAV-PVT")
        };
        assert_eq!(pvt.utc.unwrap().to_string(), "2022-10-11 11:04:24");
        assert_eq!(pvt.quality(), FixQuality::RtkFloat);
        assert!((pvt.latitude_deg - 47.1290927).abs() < 1e-12);
        assert!((pvt.longitude_deg - 15.2120430).abs() < 1e-12);
        assert_eq!(pvt.satellites, 21);
        assert!(pvt.has_position());
        assert_eq!(pvt.correction_age_s, Some(30.0));
    }

    #[test]
    fn short_and_unknown_versions_are_errors_unknown_ids_are_not() {
        let payload = hex(F9P_PVT);
        let err = decode(&frame(1, 7, &payload[..91])).unwrap_err();
        assert_eq!(
            err.to_string(),
            "malformed NAV-PVT: 91 bytes where 92 are needed"
        );
        let err = decode(&frame(1, 0x3c, &[2; 64])).unwrap_err();
        assert!(err.to_string().contains("version 2"), "{err}");
        assert_eq!(decode(&frame(1, 0x26, &[0; 24])).unwrap(), None);
        // NAV-SAT claiming more satellites than it carries.
        let mut sat = vec![0u8; 8 + 12];
        sat[5] = 2;
        assert!(decode(&frame(1, 0x35, &sat)).is_err());
    }

    #[test]
    fn gps_time_becomes_utc_across_leap_seconds() {
        let at = |s: &str| NaiveDateTime::parse_from_str(s, "%Y-%m-%d %H:%M:%S").unwrap();
        assert_eq!(leap_seconds_at(at("1980-01-06 00:00:00")), 0);
        assert_eq!(leap_seconds_at(at("2016-12-31 23:59:59")), 17);
        // UTC 2017-01-01 00:00:00 is GPS 00:00:18.
        assert_eq!(leap_seconds_at(at("2017-01-01 00:00:17")), 17);
        assert_eq!(leap_seconds_at(at("2017-01-01 00:00:18")), 18);
        assert_eq!(leap_seconds_at(at("2026-11-28 12:00:00")), 18);
        let sol = NavSol {
            itow_ms: 0,
            gps_time: Some((2190, 365_174.0)),
            fix_type: 3,
            fix_ok: true,
            differential: false,
            ecef_m: [0.0; 3],
            p_acc_m: 1.0,
            ecef_velocity_mps: [0.0; 3],
            pdop: 1.0,
            satellites: 9,
        };
        // GPS week 2190, 365,174 s: 2021-12-30 05:26:14 GPS, 05:25:56 UTC.
        assert_eq!(sol.utc(None).unwrap().to_string(), "2021-12-30 05:25:56");
        assert_eq!(
            sol.utc(Some(17)).unwrap().to_string(),
            "2021-12-30 05:25:57"
        );
    }

    #[test]
    fn utc_rounds_nano_to_the_epochs_millisecond() {
        let t = utc_of(2021, 6, 10, 18, 18, 56, -249_999_950).unwrap();
        assert_eq!(t.to_string(), "2021-06-10 18:18:55.750");
        let t = utc_of(2016, 12, 31, 23, 59, 60, 400).unwrap();
        assert_eq!(t.to_string(), "2017-01-01 00:00:00");
        assert!(utc_of(2021, 2, 30, 0, 0, 0, 0).is_none());
        assert!(utc_of(2021, 2, 3, 0, 0, 0, 1_000_000_001).is_none());
    }

    fn relposned_v1(flags: u32, heading_e5: i32, acc_e5: u32) -> Vec<u8> {
        let mut p = vec![0u8; 64];
        p[0] = 1;
        p[8..12].copy_from_slice(&(-50i32).to_le_bytes());
        p[32] = (-7i8) as u8;
        p[24..28].copy_from_slice(&heading_e5.to_le_bytes());
        p[52..56].copy_from_slice(&acc_e5.to_le_bytes());
        p[60..64].copy_from_slice(&flags.to_le_bytes());
        p
    }

    #[test]
    fn relposned_heading_needs_fixed_ambiguities_and_every_valid_flag() {
        // fix ok, vector valid, fixed (2 << 3), moving base, heading valid.
        let good = 0x01 | 0x04 | (2 << 3) | 0x20 | 0x100;
        let p = relposned_v1(good, -9_000_000, 25_000);
        let Some(UbxMessage::NavRelPosNed(r)) = decode(&frame(1, 0x3c, &p)).unwrap() else {
            panic!()
        };
        assert!((r.relative_ned_m[0] - (-0.5007)).abs() < 1e-12);
        assert!(r.moving_base());
        let h = r.heading();
        assert_eq!(h.heading_deg, Some(270.0));
        assert_eq!(h.sigma_deg, Some(0.25));
        for bad in [
            good & !0x100,
            good & !0x04,
            good & !0x01,
            good & !0x20,
            good & !(3 << 3) | (1 << 3),
        ] {
            let p = relposned_v1(bad, 1_000_000, 25_000);
            let Some(UbxMessage::NavRelPosNed(r)) = decode(&frame(1, 0x3c, &p)).unwrap() else {
                panic!()
            };
            assert_eq!(r.heading().heading_deg, None, "flags {bad:#x}");
        }
    }

    #[test]
    fn relposned_v0_of_a_real_m8p_has_no_heading() {
        // gpsd's NEO-M8P log: version 0, fix ok only.
        let p =
            hex("00000000dcce87180000000000000000000000000000000000000000000000000000000001000000");
        let Some(UbxMessage::NavRelPosNed(r)) = decode(&frame(1, 0x3c, &p)).unwrap() else {
            panic!()
        };
        assert_eq!((r.version, r.itow_ms, r.flags), (0, 411_553_500, 1));
        assert_eq!(r.heading().heading_deg, None);
    }

    #[test]
    fn mon_ver_names_the_firmware_and_protocol() {
        let mut p = vec![0u8; 40 + 30 * 3];
        for (at, s) in [
            (0, "EXT CORE 1.00 (0fa0ae)"),
            (30, "00190000"),
            (40, "ROM BASE 0x118B2060"),
            (70, "FWVER=HPG 1.32"),
            (100, "PROTVER=27.31"),
        ] {
            p[at..at + s.len()].copy_from_slice(s.as_bytes());
        }
        let Some(UbxMessage::MonVer(v)) = decode(&frame(0x0a, 4, &p)).unwrap() else {
            panic!()
        };
        assert_eq!(v.firmware(), Some("HPG 1.32"));
        assert_eq!(v.protocol(), Some("27.31"));
        assert_eq!(v.module(), None);
        assert!(decode(&frame(0x0a, 4, &p[..41])).is_err());
    }

    #[test]
    fn rxm_rtcm_of_a_real_m8p() {
        let p = [0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0xce, 0x04];
        let Some(UbxMessage::RxmRtcm(r)) = decode(&frame(2, 0x32, &p)).unwrap() else {
            panic!()
        };
        assert_eq!(
            (r.message_type, r.used, r.crc_failed),
            (1230, RtcmUse::Unknown, false)
        );
    }
}
