//! Merges decoded sentences into one current GNSS fix.
//!
//! A receiver spreads an epoch over several sentences (GGA, RMC, VTG, GST, HDT, ...), in an
//! order that varies by vendor, and some carry no time. Position and quality come from GGA or
//! GNS when the epoch has one, else from RMC; speed, course, heading and accuracy each keep
//! their own receive time so the core can judge their freshness separately.

use chrono::{NaiveDateTime, NaiveTime};

use super::decode::{
    FixQuality, GnssSentence, GroundVelocity, GstAccuracy, PositionReport, TrueHeading,
};
use super::ubx::{NavPvt, NavSol, UbxMessage};
use super::utc::UtcTracker;
use crate::geodesy::Geodetic;
use crate::time::Timestamp;

/// A value with the host time at which it was received.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timed<T> {
    /// The value.
    pub value: T,
    /// Host receive time.
    pub rx: Timestamp,
}

/// A WGS84 position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoPosition {
    /// Latitude, degrees north.
    pub latitude_deg: f64,
    /// Longitude, degrees east.
    pub longitude_deg: f64,
    /// Altitude above mean sea level, metres.
    pub altitude_msl_m: Option<f64>,
    /// Geoid separation (ellipsoid minus MSL), metres.
    pub geoid_separation_m: Option<f64>,
    /// Height above the ellipsoid, metres, where the receiver states it apart (UBX NAV-SOL
    /// gives no MSL height).
    pub ellipsoid_height_m: Option<f64>,
}

impl GeoPosition {
    /// Height above the ellipsoid, m: as stated, else MSL height plus geoid separation
    /// (either taken as 0 when absent).
    pub fn height_above_ellipsoid_m(&self) -> f64 {
        self.ellipsoid_height_m.unwrap_or_else(|| {
            self.altitude_msl_m.unwrap_or(0.0) + self.geoid_separation_m.unwrap_or(0.0)
        })
    }
}

/// The receiver's current solution, as far as the sentences so far describe it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GnssFix {
    /// UTC time of day of the latest position report (valid or not).
    pub utc_time: Option<NaiveTime>,
    /// Full UTC date-time of the latest position report, once a date is known.
    pub utc: Option<NaiveDateTime>,
    /// Quality of the latest position report.
    pub quality: FixQuality,
    /// The latest valid position; kept when the fix is lost, so `quality` says whether it
    /// is current.
    pub position: Option<Timed<GeoPosition>>,
    /// Satellites used in the latest report.
    pub satellites: Option<u16>,
    /// HDOP of the latest report.
    pub hdop: Option<f64>,
    /// Age of differential corrections, seconds.
    pub diff_age_s: Option<f64>,
    /// Differential reference station id.
    pub diff_station: Option<u16>,
    /// Latest speed and course over ground.
    pub velocity: Option<Timed<GroundVelocity>>,
    /// Latest valid dual-antenna true heading, degrees (0 = north, clockwise).
    pub heading_deg: Option<Timed<f64>>,
    /// That heading's 1σ, degrees, where its sentence stated one.
    pub heading_sigma_deg: Option<f64>,
    /// Latest GST accuracy figures.
    pub accuracy: Option<Timed<GstAccuracy>>,
}

/// Builds [`GnssFix`] from a sentence stream.
#[derive(Debug, Clone, Default)]
pub struct FixAssembler {
    fix: GnssFix,
    utc: UtcTracker,
    /// Time of day of the epoch being assembled.
    epoch: Option<NaiveTime>,
    /// Whether this epoch already had a GGA or GNS, which outrank RMC for quality.
    epoch_has_position_report: bool,
    /// GPS time of week of the last NAV-PVT: the UBX epoch the other NAV messages refine.
    ubx_epoch: Option<u32>,
    /// ... when that NAV-PVT gave a valid position.
    ubx_located: bool,
    /// The receiver's GPS−UTC leap seconds (NAV-TIMEGPS), once valid.
    leap_s: Option<i8>,
}

impl FixAssembler {
    /// An empty assembler.
    pub fn new() -> Self {
        Self::default()
    }

    /// The fix as assembled so far.
    pub fn fix(&self) -> &GnssFix {
        &self.fix
    }

    /// Merges one decoded sentence received at host time `rx`.
    pub fn apply(&mut self, rx: Timestamp, sentence: &GnssSentence) {
        match sentence {
            // A constellation's own GNS after the epoch's combined one (Trimble: `$GNGNS`
            // with the position, then `$GPGNS`, `$GLGNS` with their satellites and no
            // position): a part of the epoch, not a report that voids it.
            GnssSentence::Gns(report)
                if report.latitude.is_none()
                    && report.longitude.is_none()
                    && self.epoch_has_position_report
                    && (report.time.is_none() || report.time == self.epoch) => {}
            GnssSentence::Gga(report) | GnssSentence::Gns(report) => {
                self.enter_epoch(report.time);
                self.epoch_has_position_report = true;
                self.apply_report(rx, report);
            }
            GnssSentence::Rmc(rmc) => {
                self.enter_epoch(rmc.time);
                if let (Some(time), Some(date)) = (rmc.time, rmc.date) {
                    self.utc.observe(time, Some(date));
                }
                if !self.epoch_has_position_report {
                    self.apply_report(
                        rx,
                        &PositionReport {
                            time: rmc.time,
                            quality: rmc.quality,
                            latitude: rmc.latitude,
                            longitude: rmc.longitude,
                            ..PositionReport::default()
                        },
                    );
                } else {
                    self.refresh_utc();
                }
                if let Some(v) = rmc.velocity {
                    self.fix.velocity = Some(Timed { value: v, rx });
                }
            }
            GnssSentence::Vtg(v) => self.fix.velocity = Some(Timed { value: *v, rx }),
            GnssSentence::Gst(accuracy) => {
                self.fix.accuracy = Some(Timed {
                    value: *accuracy,
                    rx,
                });
            }
            GnssSentence::Hdt(heading)
            | GnssSentence::Ths(heading)
            | GnssSentence::Heading(heading) => self.apply_heading(rx, *heading),
            GnssSentence::SecondaryAntenna => {}
            GnssSentence::Ksxt(k) => {
                self.enter_epoch(k.position.time);
                if let (Some(time), Some(date)) = (k.position.time, k.date) {
                    self.utc.observe(time, Some(date));
                }
                self.epoch_has_position_report = true;
                self.apply_report(rx, &k.position);
                self.fix.heading_deg = k.heading.heading_deg.map(|value| Timed { value, rx });
                self.fix.heading_sigma_deg = None;
                if let Some(v) = k.velocity {
                    self.fix.velocity = Some(Timed { value: v, rx });
                }
            }
            GnssSentence::Zda(zda) => {
                if let (Some(time), Some(date)) = (zda.time, zda.date) {
                    self.utc.observe(time, Some(date));
                    self.refresh_utc();
                }
            }
        }
    }

    /// Merges one decoded UBX message received at host time `rx`. NAV-PVT makes the epoch;
    /// NAV-HPPOSLLH, NAV-COV and NAV-DOP of the same epoch (by GPS time of week) refine it;
    /// NAV-RELPOSNED's moving-base heading is a dual-antenna heading. Returns whether the fix
    /// changed.
    pub fn apply_ubx(&mut self, rx: Timestamp, message: &UbxMessage) -> bool {
        match message {
            UbxMessage::NavPvt(pvt) => self.apply_pvt(rx, pvt),
            // A receiver that sends both: NAV-SOL comes first in the epoch, and NAV-PVT,
            // with its own UTC and MSL height, then describes the same solution.
            UbxMessage::NavSol(sol) => self.apply_sol(rx, sol),
            UbxMessage::NavTimeGps(time) => {
                self.leap_s = time.leap_s.or(self.leap_s);
                return false;
            }
            UbxMessage::NavHpPosLlh(hp) => {
                let refines = self.ubx_located && self.ubx_epoch == Some(hp.itow_ms);
                let Some(position) = self.fix.position.as_mut().filter(|_| refines) else {
                    return false;
                };
                if hp.invalid_llh {
                    return false;
                }
                // The epoch's position at full precision. It keeps the NAV-PVT's receive
                // time: it is the same measurement, which the localiser has taken once.
                position.value = GeoPosition {
                    latitude_deg: hp.latitude_deg,
                    longitude_deg: hp.longitude_deg,
                    altitude_msl_m: Some(hp.height_msl_m),
                    geoid_separation_m: Some(hp.height_m - hp.height_msl_m),
                    ellipsoid_height_m: Some(hp.height_m),
                };
            }
            UbxMessage::NavCov(cov) => {
                let Some((north, east)) = cov
                    .horizontal_sigma_m()
                    .filter(|_| self.ubx_epoch == Some(cov.itow_ms))
                else {
                    return false;
                };
                self.fix.accuracy = Some(Timed {
                    value: GstAccuracy {
                        time: self.fix.utc_time,
                        latitude_sd_m: Some(north),
                        longitude_sd_m: Some(east),
                        altitude_sd_m: cov.vertical_sigma_m(),
                        ..GstAccuracy::default()
                    },
                    rx,
                });
            }
            UbxMessage::NavDop(dop) if self.ubx_epoch == Some(dop.itow_ms) => {
                self.fix.hdop = Some(dop.hdop);
            }
            // Version 0 is a vector from a fixed base: no heading, and no reason to clear
            // one from elsewhere.
            UbxMessage::NavRelPosNed(relative) if relative.version >= 1 => {
                self.apply_heading(rx, relative.heading());
            }
            _ => return false,
        }
        true
    }

    fn apply_pvt(&mut self, rx: Timestamp, pvt: &NavPvt) {
        self.ubx_epoch = Some(pvt.itow_ms);
        if let Some(utc) = pvt.utc {
            self.enter_epoch(Some(utc.time()));
            self.utc.observe(utc.time(), Some(utc.date()));
        }
        self.epoch_has_position_report = true;
        let quality = pvt.quality();
        // No fix, or time only: the position fields are the last solution or zeros.
        let located = !pvt.invalid_llh && matches!(pvt.fix_type, 1..=4);
        self.ubx_located = located && quality.is_valid();
        self.apply_report(
            rx,
            &PositionReport {
                time: pvt.utc.map(|t| t.time()),
                quality,
                latitude: located.then_some(pvt.latitude_deg),
                longitude: located.then_some(pvt.longitude_deg),
                altitude_msl: Some(pvt.height_msl_m),
                geoid_separation: Some(pvt.height_m - pvt.height_msl_m),
                satellites: Some(u16::from(pvt.satellites)),
                hdop: None,
                diff_age_s: pvt.correction_age_s.filter(|_| quality.is_corrected()),
                diff_station: None,
            },
        );
        if !quality.is_valid() {
            return;
        }
        self.fix.velocity = Some(Timed {
            value: GroundVelocity {
                speed_mps: pvt.ground_speed_mps,
                course_deg: Some(pvt.motion_heading_deg.rem_euclid(360.0)),
            },
            rx,
        });
        // hAcc is the horizontal error's RMS; split evenly between north and east until
        // NAV-COV (later in the epoch) says how.
        let per_axis = pvt.h_acc_m / std::f64::consts::SQRT_2;
        self.fix.accuracy = Some(Timed {
            value: GstAccuracy {
                time: self.fix.utc_time,
                latitude_sd_m: Some(per_axis),
                longitude_sd_m: Some(per_axis),
                altitude_sd_m: Some(pvt.v_acc_m),
                ..GstAccuracy::default()
            },
            rx,
        });
    }

    fn apply_sol(&mut self, rx: Timestamp, sol: &NavSol) {
        self.ubx_epoch = Some(sol.itow_ms);
        let utc = sol.utc(self.leap_s);
        if let Some(utc) = utc {
            self.enter_epoch(Some(utc.time()));
            self.utc.observe(utc.time(), Some(utc.date()));
        }
        self.epoch_has_position_report = true;
        let quality = sol.quality();
        let [x, y, z] = sol.ecef_m;
        let here = Geodetic::from_ecef(&nalgebra::Vector3::new(x, y, z));
        let located = matches!(sol.fix_type, 1..=4) && (x, y, z) != (0.0, 0.0, 0.0);
        self.ubx_located = located && quality.is_valid();
        self.apply_report(
            rx,
            &PositionReport {
                time: utc.map(|t| t.time()),
                quality,
                latitude: located.then_some(here.lat_deg),
                longitude: located.then_some(here.lon_deg),
                satellites: Some(u16::from(sol.satellites)),
                ..PositionReport::default()
            },
        );
        if let Some(p) = self.fix.position.as_mut().filter(|p| p.rx == rx && located) {
            p.value.ellipsoid_height_m = Some(here.h_m);
        }
        if !quality.is_valid() {
            return;
        }
        // pAcc is three-dimensional: a third of its square on each axis.
        let per_axis = sol.p_acc_m / 3f64.sqrt();
        self.fix.accuracy = Some(Timed {
            value: GstAccuracy {
                time: self.fix.utc_time,
                latitude_sd_m: Some(per_axis),
                longitude_sd_m: Some(per_axis),
                altitude_sd_m: Some(per_axis),
                ..GstAccuracy::default()
            },
            rx,
        });
    }

    fn apply_heading(&mut self, rx: Timestamp, heading: TrueHeading) {
        let TrueHeading {
            heading_deg,
            sigma_deg,
        } = heading;
        self.fix.heading_deg = heading_deg.map(|value| Timed { value, rx });
        self.fix.heading_sigma_deg = sigma_deg.filter(|_| heading_deg.is_some());
    }

    /// Starts a new epoch when a timed sentence carries a new time of day.
    fn enter_epoch(&mut self, time: Option<NaiveTime>) {
        if time.is_some() && time != self.epoch {
            self.epoch = time;
            self.epoch_has_position_report = false;
        }
    }

    fn apply_report(&mut self, rx: Timestamp, report: &PositionReport) {
        let position = match (report.latitude, report.longitude) {
            (Some(latitude_deg), Some(longitude_deg)) => Some(GeoPosition {
                latitude_deg,
                longitude_deg,
                altitude_msl_m: report.altitude_msl,
                geoid_separation_m: report.geoid_separation,
                ellipsoid_height_m: None,
            }),
            _ => None,
        };
        // A quality that claims a fix without a position is no fix.
        self.fix.quality = match position {
            Some(_) => report.quality,
            None => FixQuality::Invalid,
        };
        if let Some(value) = position.filter(|_| report.quality.is_valid()) {
            self.fix.position = Some(Timed { value, rx });
        }
        self.fix.satellites = report.satellites;
        self.fix.hdop = report.hdop;
        self.fix.diff_age_s = report.diff_age_s;
        self.fix.diff_station = report.diff_station;
        if let Some(time) = report.time {
            self.fix.utc_time = Some(time);
            self.fix.utc = self.utc.observe(time, None);
        }
    }

    /// Re-resolves the fix's date-time after a date arrived for its epoch.
    fn refresh_utc(&mut self) {
        if let Some(time) = self.fix.utc_time {
            self.fix.utc = self.utc.resolve(time);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::gnss::decode::decode;
    use crate::devices::gnss::sentence::Sentence;

    fn feed(asm: &mut FixAssembler, rx_s: u64, body: &str) {
        let decoded = decode(&Sentence::parse(body)).unwrap().unwrap();
        asm.apply(Timestamp::from_micros(rx_s * 1_000_000), &decoded);
    }

    #[test]
    fn gga_quality_outranks_rmc_in_the_same_epoch() {
        let mut asm = FixAssembler::new();
        feed(
            &mut asm,
            1,
            "GPGGA,150119.000,5104.0859,N,11405.7387,W,5,8,0.94,1102.4,M,-17.5,M,1.0,0041",
        );
        feed(
            &mut asm,
            1,
            "GPRMC,150119.000,A,5104.0859,N,11405.7387,W,0.09,194.17,090322,,,D",
        );
        let fix = asm.fix();
        assert_eq!(fix.quality, FixQuality::RtkFloat);
        assert_eq!(fix.diff_age_s, Some(1.0));
        assert_eq!(fix.diff_station, Some(41));
        assert_eq!(fix.utc.unwrap().to_string(), "2022-03-09 15:01:19");
        let v = fix.velocity.unwrap().value;
        assert!((v.speed_mps - 0.09 * 1852.0 / 3600.0).abs() < 1e-12);
        assert_eq!(v.course_deg, Some(194.17));
    }

    #[test]
    fn rmc_sets_quality_without_gga() {
        let mut asm = FixAssembler::new();
        feed(
            &mut asm,
            1,
            "GNRMC,003832.000,A,4404.1271062,N,12118.8438377,W,000.0,171.0,290322,,,F,V",
        );
        assert_eq!(asm.fix().quality, FixQuality::RtkFloat);
        feed(
            &mut asm,
            2,
            "GNRMC,003833.000,V,4404.1271062,N,12118.8438377,W,,,290322,,,N,V",
        );
        assert_eq!(asm.fix().quality, FixQuality::Invalid);
        // The last valid position is kept, stamped when it was valid.
        let pos = asm.fix().position.unwrap();
        assert_eq!(pos.rx, Timestamp::from_micros(1_000_000));
    }

    #[test]
    fn lost_fix_keeps_last_valid_position() {
        let mut asm = FixAssembler::new();
        feed(
            &mut asm,
            1,
            "GNGGA,000705.00,4404.12938,N,12118.84590,W,1,20,0.9,1108.8,M,,M,,",
        );
        feed(
            &mut asm,
            2,
            "GNGGA,000706.00,4404.99999,N,12118.84590,W,0,00,99.99,1108.8,M,,M,,",
        );
        let fix = asm.fix();
        assert_eq!(fix.quality, FixQuality::Invalid);
        let pos = fix.position.unwrap();
        assert!((pos.value.latitude_deg - (44.0 + 4.12938 / 60.0)).abs() < 1e-12);
    }

    #[test]
    fn zda_dates_an_earlier_gga() {
        let mut asm = FixAssembler::new();
        feed(
            &mut asm,
            1,
            "GNGGA,231408.00,4503.94632,N,00739.54368,E,5,12,0.82,257.4,M,47.2,M,0.0,0041",
        );
        assert_eq!(asm.fix().utc, None);
        feed(&mut asm, 1, "GNZDA,231408.00,11,04,2025,00,00");
        assert_eq!(asm.fix().utc.unwrap().to_string(), "2025-04-11 23:14:08");
    }

    #[test]
    fn a_constellations_own_gns_is_part_of_the_epoch_not_its_end() {
        let mut asm = FixAssembler::new();
        feed(
            &mut asm,
            1,
            "GNGNS,014035.00,4332.69262,S,17235.48549,E,RR,13,0.9,25.63,11.24,,,U",
        );
        feed(&mut asm, 1, "GPGNS,014035.00,,,,,,8,,,,1.0,23");
        feed(&mut asm, 1, "GLGNS,014035.00,,,,,,5,,,,1.0,23");
        let fix = asm.fix();
        assert_eq!(fix.quality, FixQuality::RtkFixed);
        assert_eq!(fix.satellites, Some(13));
        // Alone in its epoch, a GNS without a position is no fix.
        feed(&mut asm, 2, "GPGNS,014036.00,,,,,,8,,,,1.0,23");
        assert_eq!(asm.fix().quality, FixQuality::Invalid);
    }

    #[test]
    fn a_stated_sigma_goes_with_its_heading() {
        let mut asm = FixAssembler::new();
        feed(
            &mut asm,
            1,
            "PSSN,HRP,142657.80,061222,152.236,,-0.708,0.084,,0.181,21,2,2.400,E",
        );
        assert_eq!(asm.fix().heading_sigma_deg, Some(0.084));
        feed(&mut asm, 2, "GNHDT,12.5,T");
        assert_eq!(asm.fix().heading_sigma_deg, None);
    }

    #[test]
    fn invalid_ths_clears_heading() {
        let mut asm = FixAssembler::new();
        feed(&mut asm, 1, "GNTHS,244.28,A");
        assert_eq!(asm.fix().heading_deg.unwrap().value, 244.28);
        feed(&mut asm, 2, "GNTHS,,V");
        assert_eq!(asm.fix().heading_deg, None);
        feed(&mut asm, 3, "GNHDT,12.5,T");
        assert_eq!(asm.fix().heading_deg.unwrap().value, 12.5);
    }
}
