//! The localisation feed: what the receiver, the IMU and the wheels said, given to the odom
//! frame's dead reckoning and the map frame's localiser (REP-105), and what the status and
//! the moves read back (the pose view, the fix's freshness, the frame tree).

use std::time::Duration;

use super::chassis::{ChassisFeedback, CommandRejected};
use super::core_config::CoreConfig;
use super::status::{FrameTree, GnssStatus, Localization, Pose2D, PoseCovariance, PoseReport};
use crate::config::chassis::WheelRadius;
use crate::config::motion::MinGnss;
use crate::control::PoseView;
use crate::devices::gnss::{FixQuality, GnssFix};
use crate::devices::imu::ImuSample;
use crate::fusion::epoch_clock::EpochClock;
use crate::fusion::localizer::{Localizer, LocateState, Measurement, yaw_of_heading_deg};
use crate::fusion::map_filter::Trust;
use crate::fusion::odometry::{OdomPose, Odometry, WheelReading};
use crate::geodesy::Geodetic;
use crate::time::Timestamp;

/// How far an epoch of `quality` is trusted: RTK fixed is believed over the wheels (and only
/// it may teach the dead reckoning); a lesser fix's step is its own error.
fn trust_of(quality: FixQuality) -> Trust {
    if quality == FixQuality::RtkFixed {
        Trust::OverWheels
    } else {
        Trust::UnderWheels
    }
}

/// A receiver's typical speed accuracy (1σ, m/s) at a fix quality, when the configuration
/// gives none: NMEA carries none. Speed comes from Doppler, which RTK does not sharpen;
/// differential and single fixes carry more multipath and fewer satellites.
fn typical_speed_sigma(quality: FixQuality) -> f64 {
    match quality {
        FixQuality::RtkFixed | FixQuality::RtkFloat => 0.04,
        FixQuality::Dgps | FixQuality::Pps => 0.06,
        _ => 0.1,
    }
}

/// What the feed takes from the core's settings.
#[derive(Debug, Clone, Copy)]
struct Settings {
    gnss_fix_timeout: Duration,
    cog_min_speed_mps: f64,
    heading_offset_deg: f64,
    imu_timeout: Option<Duration>,
    max_position_radius_m: f64,
}

/// The vehicle's sense of where it is.
#[derive(Debug, Clone)]
pub struct Localisation {
    settings: Settings,
    gnss_fix: Option<GnssFix>,
    gnss_link_down: bool,
    /// The heading last published, held while no fresh source exists.
    held_heading_deg: f64,
    /// The last plausible IMU sample.
    imu: Option<ImuSample>,
    imu_link_down: bool,
    localizer: Localizer,
    /// The `odom` frame: wheels and gyro, with or without GNSS; `None` without drives.
    odometry: Option<Odometry>,
    /// Receive times of the GNSS data already given to the localiser: heading, velocity,
    /// position.
    fed_gnss: (Option<Timestamp>, Option<Timestamp>, Option<Timestamp>),
    /// The GNSS epochs' arrivals against their UTC stamps.
    epoch_clock: EpochClock,
}

impl Localisation {
    /// Nothing known yet; the odom frame exists when the vehicle has drives.
    pub fn new(config: &CoreConfig) -> Self {
        Self {
            settings: Settings {
                gnss_fix_timeout: config.gnss_fix_timeout,
                cog_min_speed_mps: config.cog_min_speed_mps,
                heading_offset_deg: config.heading_offset_deg,
                imu_timeout: config.imu_timeout,
                max_position_radius_m: config.max_position_radius_m,
            },
            gnss_fix: None,
            gnss_link_down: false,
            held_heading_deg: 0.0,
            imu: None,
            imu_link_down: false,
            localizer: Localizer::new(config.localizer),
            odometry: config
                .chassis
                .map(|c| Odometry::new(c.track_m, config.localizer.gyro_bias_walk)),
            fed_gnss: (None, None, None),
            epoch_clock: EpochClock::default(),
        }
    }

    /// A new fix from the receiver at `t`: what is new in it goes to the localiser, and a
    /// drift of the odom heading proven against GNSS corrects the gyro's bias. Returns the
    /// localiser's events.
    pub fn gnss(&mut self, t: Timestamp, fix: &GnssFix) -> Vec<String> {
        self.gnss_fix = Some(*fix);
        self.feed(fix);
        if let Some(drift) = self.localizer.take_bias_correction()
            && let Some(odometry) = self.odometry.as_mut()
        {
            odometry.correct_bias(t, drift.rate, drift.sigma);
        }
        self.localizer.take_events()
    }

    /// The receiver's link went up or down (down: the fix is not ok from now on).
    pub fn gnss_link(&mut self, up: bool) {
        self.gnss_link_down = !up;
    }

    /// The IMU's link went up or down.
    pub fn imu_link(&mut self, up: bool) {
        self.imu_link_down = !up;
    }

    /// An IMU sample: a plausible one turns the odom frame by its gyro.
    pub fn imu(&mut self, sample: &ImuSample) {
        if sample.is_plausible() {
            self.imu = Some(*sample);
            if let Some(o) = &mut self.odometry {
                o.gyro(sample.rx, sample.gyro.z);
            }
        }
    }

    /// The drives' feedback at `t`, with the wheels' radii: a new reading moves the odom
    /// frame, and the map pose by its increment.
    pub fn wheels(&mut self, t: Timestamp, feedback: &ChassisFeedback, radius: WheelRadius) {
        let (Some(l), Some(r)) = (feedback.left.velocity_rad_s, feedback.right.velocity_rad_s)
        else {
            return;
        };
        let (vl, vr) = (l * radius.left, r * radius.right);
        // A reading counts once, at the time it arrived: the drives report less often than
        // the control loop polls them.
        let measured = feedback
            .left
            .received
            .max(feedback.right.received)
            .map_or(t, |r| r.min(t));
        let Some(o) = self
            .odometry
            .as_mut()
            .filter(|o| o.updated_at().is_none_or(|u| measured > u))
        else {
            return;
        };
        let travel = feedback
            .left
            .angle_rad
            .zip(feedback.right.angle_rad)
            .map(|(a, b)| (a * radius.left, b * radius.right));
        o.wheels(
            measured,
            WheelReading {
                speeds: (vl, vr),
                travel,
            },
        );
        // The map pose stands on the odom frame: it moves by its increments (REP-105).
        if let Some(pose) = o.pose() {
            self.localizer
                .set_gyro_bias_sigma(o.gyro_bias_sigma(measured));
            self.localizer.add(measured, Measurement::Odom(pose));
        }
    }

    /// Re-zeroes the map frame where the vehicle stands (`init_rtk_data`).
    pub fn zero_here(&mut self, t: Timestamp) -> Result<(), CommandRejected> {
        if self.localizer.zero_here(t) {
            Ok(())
        } else {
            Err(CommandRejected::NoPosition)
        }
    }

    /// Sets the map pose by hand (INIT_POSITION), within the configured radius of the datum.
    pub fn set_pose(
        &mut self,
        t: Timestamp,
        x: f64,
        y: f64,
        yaw: f64,
    ) -> Result<(), CommandRejected> {
        plausible_pose(x, y, yaw, self.settings.max_position_radius_m)?;
        self.localizer.set_pose(t, x, y, yaw);
        Ok(())
    }

    /// Moves the map frame's datum (SET_LNG_LAT) to a plausible place.
    pub fn set_datum(&mut self, datum: Geodetic) -> Result<(), CommandRejected> {
        plausible_place(&datum)?;
        self.localizer.set_datum(datum);
        Ok(())
    }

    /// The map frame's localiser.
    pub fn localizer(&self) -> &Localizer {
        &self.localizer
    }

    /// The receiver's latest fix.
    pub fn gnss_fix(&self) -> Option<&GnssFix> {
        self.gnss_fix.as_ref()
    }

    /// The `odom` frame's pose (wheels and gyro), once the drives have reported.
    pub fn odom_pose(&self) -> Option<OdomPose> {
        self.odometry.as_ref().and_then(Odometry::pose)
    }

    /// Whether an IMU is configured, its link is up and a plausible sample is fresh at `t`.
    pub fn imu_ok(&self, t: Timestamp) -> bool {
        self.settings.imu_timeout.is_some_and(|timeout| {
            !self.imu_link_down
                && self
                    .imu
                    .is_some_and(|s| t.saturating_since(s.rx) <= timeout)
        })
    }

    /// What a move sees: the `odom` pose, and the map pose while located.
    pub fn pose_view(&self, t: Timestamp) -> Option<PoseView> {
        let odometry = self.odometry.as_ref()?;
        let (odom, odom_at) = (odometry.pose()?, odometry.updated_at()?);
        let yaw_rate_at = odometry.yaw_rate_at().unwrap_or(odom_at);
        let located = self
            .localizer
            .published(t)
            .filter(|p| p.locate == LocateState::Good);
        let map = located.map(|p| p.map_pose);
        let wheel_scale = located.map(|p| p.wheel_scale);
        Some(PoseView {
            odom,
            odom_at,
            yaw_rate_at,
            map_xy: map.map(|(x, y, _)| (x, y)),
            map_yaw: map.map(|(_, _, yaw)| yaw),
            wheel_scale,
            gnss: MinGnss::of(self.fresh_fix_quality(t)),
        })
    }

    /// The quality of the GNSS fix at `t`: `Invalid` once stale or with the link down.
    pub fn fresh_fix_quality(&self, t: Timestamp) -> FixQuality {
        let Some(fix) = &self.gnss_fix else {
            return FixQuality::Invalid;
        };
        let fresh = fix
            .position
            .is_some_and(|p| t.saturating_since(p.rx) <= self.settings.gnss_fix_timeout);
        if !self.gnss_link_down && fix.quality.is_valid() && fresh {
            fix.quality
        } else {
            FixQuality::Invalid
        }
    }

    /// The `odom` pose and the map pose at `t`, without the rest of a status.
    pub fn pose_report(&self, t: Timestamp) -> PoseReport {
        let published = self.localizer.published(t);
        let odom = self.odom_pose();
        PoseReport {
            odom,
            frames: published.and_then(|p| {
                let (x, y, yaw) = p.map_to_odom;
                let (ox, oy, oyaw) = p.odom_pose?;
                Some(FrameTree {
                    map_to_odom: Pose2D { x, y, yaw },
                    odom_to_base: Pose2D {
                        x: ox,
                        y: oy,
                        yaw: oyaw,
                    },
                })
            }),
            map: published.map(|p| {
                let (x, y, yaw) = p.map_pose;
                let [xx, xy, yy, yaw_var] = p.map_covariance;
                (
                    Pose2D { x, y, yaw },
                    PoseCovariance {
                        xx,
                        xy,
                        yy,
                        yaw: yaw_var,
                    },
                )
            }),
            localization: match published.map_or(LocateState::Uninitialized, |p| p.locate) {
                LocateState::Uninitialized => Localization::Uninitialized,
                LocateState::Good => Localization::Good,
                LocateState::Lost => Localization::Lost,
            },
        }
    }

    /// Gives the localiser what is new in the fix: heading, course, position.
    fn feed(&mut self, fix: &GnssFix) {
        let latency = self.localizer.config().gnss_latency;
        if let Some(p) = fix.position
            && self.fed_gnss.2 != Some(p.rx)
        {
            self.epoch_clock.observe(p.rx, fix.utc);
        }
        // The epoch's time: its arrival without the link's jitter, less the latency.
        let clock = self.epoch_clock;
        let at = |rx: Timestamp| {
            let rx = clock.steady(rx, fix.utc);
            Timestamp::from_nanos(rx.as_nanos().saturating_sub(latency.as_nanos() as u64))
        };
        if let Some(h) = fix.heading_deg
            && self.fed_gnss.0 != Some(h.rx)
        {
            self.fed_gnss.0 = Some(h.rx);
            // The configured σ is the least the heading is trusted to; a receiver that
            // states a larger one (a float baseline) is taken at its word.
            let sigma = fix
                .heading_sigma_deg
                .map(f64::to_radians)
                .unwrap_or(0.0)
                .max(self.localizer.config().heading_sigma_rad);
            self.localizer.add(
                at(h.rx),
                Measurement::Heading {
                    yaw: yaw_of_heading_deg(h.value - self.settings.heading_offset_deg),
                    sigma,
                    trust: trust_of(fix.quality),
                },
            );
        }
        if let Some(v) = fix.velocity
            && self.fed_gnss.1 != Some(v.rx)
        {
            self.fed_gnss.1 = Some(v.rx);
            let speed = v.value.speed_mps;
            // The course's 1σ follows from the receiver's speed accuracy at this fix
            // quality, or its scatter when larger; the localiser models the antenna's motion
            // (turning, reversing) and drops a course too uncertain to help.
            let speed_sigma = self
                .localizer
                .config()
                .gnss_velocity_sigma_mps
                .unwrap_or_else(|| typical_speed_sigma(fix.quality));
            if let Some(course) = v.value.course_deg
                && speed >= self.localizer.config().cog_min_speed_mps
            {
                self.localizer.add(
                    at(v.rx),
                    Measurement::Course {
                        yaw: yaw_of_heading_deg(course),
                        speed,
                        speed_sigma,
                        trust: trust_of(fix.quality),
                    },
                );
            }
        }
        let Some(p) = fix.position.filter(|_| fix.quality.is_valid()) else {
            return;
        };
        if self.fed_gnss.2 == Some(p.rx) {
            return;
        }
        self.fed_gnss.2 = Some(p.rx);
        let here = Geodetic {
            lat_deg: p.value.latitude_deg,
            lon_deg: p.value.longitude_deg,
            h_m: p.value.height_above_ellipsoid_m(),
        };
        // Without a configured datum the first valid fix of any quality is the origin.
        if self.localizer.offer_datum(here) {
            self.localizer.add_event(format!(
                "datum: the first fix ({}) at {:.8}, {:.8}, {:.2} m is the local frame's origin \
                 (no localization.datum configured)",
                fix.quality, here.lat_deg, here.lon_deg, here.h_m
            ));
        }
        let Some(frame) = self.localizer.frame() else {
            return;
        };
        let enu = frame.to_enu(&here);
        let by_quality = fix.quality.typical_sigma_m();
        // The receiver's own error estimate for this epoch, when it sends GST.
        let sigma = fix
            .accuracy
            .filter(|a| {
                a.rx.saturating_since(p.rx) < Duration::from_secs(1)
                    && p.rx.saturating_since(a.rx) < Duration::from_secs(1)
            })
            .and_then(|a| a.value.latitude_sd_m.zip(a.value.longitude_sd_m))
            .map_or((by_quality, by_quality), |(lat, lon)| {
                (lon.max(0.005), lat.max(0.005))
            });
        self.localizer.add(
            at(p.rx),
            Measurement::Position {
                en: (enu.x, enu.y),
                sigma,
                trust: trust_of(fix.quality),
                corrected: fix.quality.is_corrected(),
            },
        );
    }

    /// What the status says of the receiver at `t`; a fresh heading (dual antenna, else the
    /// course while moving) is held for when none is fresh.
    pub fn gnss_status(&mut self, t: Timestamp) -> GnssStatus {
        let Some(fix) = &self.gnss_fix else {
            return GnssStatus::default();
        };
        let timeout = self.settings.gnss_fix_timeout;
        let fresh = |rx: Timestamp| t.saturating_since(rx) <= timeout;
        let quality = self.fresh_fix_quality(t);
        let ok = quality.is_valid();

        let dual_antenna = fix
            .heading_deg
            .filter(|h| !self.gnss_link_down && fresh(h.rx))
            .map(|h| (h.value - self.settings.heading_offset_deg).rem_euclid(360.0));
        let course = fix
            .velocity
            .filter(|v| !self.gnss_link_down && fresh(v.rx))
            .filter(|v| v.value.speed_mps >= self.settings.cog_min_speed_mps)
            .and_then(|v| v.value.course_deg);
        if let Some(heading) = dual_antenna.or(course) {
            self.held_heading_deg = heading;
        }

        let (latitude_deg, longitude_deg) = fix
            .position
            .map(|p| (p.value.latitude_deg, p.value.longitude_deg))
            .unwrap_or((0.0, 0.0));
        GnssStatus {
            ok,
            quality,
            latitude_deg,
            longitude_deg,
            heading_deg: self.held_heading_deg,
        }
    }
}

/// A pose set by hand: finite, and within `radius_m` of the datum.
fn plausible_pose(x: f64, y: f64, yaw: f64, radius_m: f64) -> Result<(), CommandRejected> {
    if ![x, y, yaw].iter().all(|v| v.is_finite()) {
        return Err(CommandRejected::NotFinite);
    }
    let distance = x.hypot(y);
    if distance > radius_m {
        return Err(CommandRejected::BeyondLimit {
            what: "distance from the datum",
            value: distance,
            limit: radius_m,
            unit: "m",
            key: "localization.max_position_radius_m",
        });
    }
    Ok(())
}

/// A place on the Earth: latitude ±90°, longitude ±180°, a height a ground vehicle can have.
fn plausible_place(p: &Geodetic) -> Result<(), CommandRejected> {
    let height = crate::geodesy::PLAUSIBLE_HEIGHT_M;
    for (what, value, min, max, unit) in [
        ("latitude", p.lat_deg, -90.0, 90.0, "degrees"),
        ("longitude", p.lon_deg, -180.0, 180.0, "degrees"),
        ("height", p.h_m, *height.start(), *height.end(), "m"),
    ] {
        if !value.is_finite() {
            return Err(CommandRejected::NotFinite);
        }
        if !(min..=max).contains(&value) {
            return Err(CommandRejected::OutOfRange {
                what,
                value,
                min,
                max,
                unit,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::gnss::Timed;
    use crate::devices::gnss::decode::GroundVelocity;
    use crate::vehicle::feedback::WheelFeedback;
    use crate::vehicle::test_rig::{self, at, fixed_at};

    fn place() -> Localisation {
        Localisation::new(&CoreConfig::default())
    }

    fn with_drives() -> Localisation {
        Localisation::new(&CoreConfig {
            chassis: Some(test_rig::chassis()),
            ..CoreConfig::default()
        })
    }

    /// Both wheels turning at `rad_s`, read at `ms`.
    fn wheels_at(ms: u64, rad_s: f64) -> ChassisFeedback {
        let wheel = WheelFeedback {
            velocity_rad_s: Some(rad_s),
            received: Some(at(ms)),
            ..WheelFeedback::default()
        };
        ChassisFeedback {
            left: wheel,
            right: wheel,
            ..ChassisFeedback::default()
        }
    }

    #[test]
    fn fix_goes_stale_after_the_timeout() {
        let mut p = place();
        assert!(!p.gnss_status(at(0)).ok);
        p.gnss(at(1_000), &fixed_at(1_000));
        let s = p.gnss_status(at(3_000));
        assert!(s.ok);
        assert_eq!(s.quality, FixQuality::RtkFixed);
        let s = p.gnss_status(at(3_001));
        assert!(!s.ok);
        assert_eq!(s.quality, FixQuality::Invalid);
        assert_eq!(s.latitude_deg, 23.1);
    }

    #[test]
    fn link_down_is_immediately_not_ok() {
        let mut p = place();
        p.gnss(at(0), &fixed_at(0));
        p.gnss_link(false);
        assert!(!p.gnss_status(at(100)).ok);
        assert_eq!(p.fresh_fix_quality(at(100)), FixQuality::Invalid);
        p.gnss_link(true);
        p.gnss(at(200), &fixed_at(200));
        assert!(p.gnss_status(at(300)).ok);
    }

    #[test]
    fn heading_prefers_dual_antenna_then_course_while_moving() {
        let mut p = place();
        let mut fix = fixed_at(0);
        fix.velocity = Some(Timed {
            value: GroundVelocity {
                speed_mps: 1.0,
                course_deg: Some(90.0),
            },
            rx: at(0),
        });
        fix.heading_deg = Some(Timed {
            value: 45.0,
            rx: at(0),
        });
        p.gnss(at(0), &fix);
        assert_eq!(p.gnss_status(at(100)).heading_deg, 45.0);
        fix.heading_deg = None;
        p.gnss(at(200), &fix);
        assert_eq!(p.gnss_status(at(300)).heading_deg, 90.0);
        // Slow: the course is noise, the last heading is held.
        fix.velocity = Some(Timed {
            value: GroundVelocity {
                speed_mps: 0.1,
                course_deg: Some(270.0),
            },
            rx: at(400),
        });
        p.gnss(at(400), &fix);
        assert_eq!(p.gnss_status(at(500)).heading_deg, 90.0);
    }

    /// docs/configuration.md: the configured heading σ is the least a heading is trusted
    /// to; a receiver that states a larger one is weighed by that, a smaller one is not.
    #[test]
    fn a_stated_heading_sigma_weighs_the_heading_when_larger_than_the_configured() {
        let yaw_variance = |stated: Option<f64>| {
            let mut p = place();
            for i in 0..20 {
                let mut fix = fixed_at(i * 100);
                fix.heading_deg = Some(Timed {
                    value: 45.0,
                    rx: at(i * 100),
                });
                fix.heading_sigma_deg = stated;
                p.gnss(at(i * 100), &fix);
            }
            let (_, covariance) = p.pose_report(at(1_950)).map.expect("located");
            covariance.yaw
        };
        let configured = yaw_variance(None);
        assert!(yaw_variance(Some(20.0)) > 10.0 * configured);
        assert_eq!(yaw_variance(Some(0.01)), configured);
    }

    #[test]
    fn the_first_valid_fix_places_the_map_frame_and_says_so() {
        let mut p = place();
        assert!(p.localizer().frame().is_none());
        let events = p.gnss(at(0), &fixed_at(0));
        assert!(p.localizer().frame().is_some());
        assert!(
            events
                .iter()
                .any(|e| e.contains("is the local frame's origin")),
            "{events:?}"
        );
        // The same epoch again teaches nothing new and says nothing.
        assert!(p.gnss(at(50), &fixed_at(0)).is_empty());
    }

    #[test]
    fn a_wheel_reading_moves_the_odom_frame_once_at_the_time_it_arrived() {
        let mut p = with_drives();
        assert_eq!(p.odom_pose(), None, "no reading yet");
        let radius = WheelRadius {
            left: 0.1,
            right: 0.1,
        };
        p.wheels(at(0), &wheels_at(0, 10.0), radius);
        // 1 m/s for 0.5 s, though the control loop passes it on at 0.5 s and again later.
        p.wheels(at(500), &wheels_at(500, 10.0), radius);
        let moved = p.odom_pose().expect("the odom frame runs").x;
        p.wheels(at(600), &wheels_at(500, 10.0), radius);
        assert_eq!(p.odom_pose().unwrap().x, moved, "a reading counts once");
        assert!((moved - 0.5).abs() < 1e-6, "moved {moved} m");
        // A move sees the odom pose, and no map pose before GNSS places the vehicle.
        let view = p.pose_view(at(600)).expect("a pose view with odometry");
        assert_eq!(view.map_xy, None);
    }

    /// A vehicle at rest at `ms`: gravity and no turn.
    fn at_rest(ms: u64) -> ImuSample {
        ImuSample {
            rx: at(ms),
            accel: nalgebra::Vector3::new(0.0, 0.0, 9.81),
            gyro: nalgebra::Vector3::zeros(),
            orientation: None,
        }
    }

    #[test]
    fn an_implausible_imu_sample_is_not_taken_and_a_stale_one_is_not_ok() {
        let mut p = Localisation::new(&CoreConfig {
            imu_timeout: Some(Duration::from_millis(200)),
            ..CoreConfig::default()
        });
        p.imu(&at_rest(0));
        assert!(p.imu_ok(at(200)));
        assert!(!p.imu_ok(at(201)));
        let mut wild = at_rest(300);
        wild.gyro.z = f64::NAN;
        p.imu(&wild);
        assert!(!p.imu_ok(at(300)), "a NaN rate is no sample");
        p.imu(&at_rest(400));
        assert!(p.imu_ok(at(400)));
        p.imu_link(false);
        assert!(
            !p.imu_ok(at(400)),
            "a link down is not ok whatever the last sample"
        );
    }

    #[test]
    fn a_pose_or_datum_set_by_hand_must_be_plausible() {
        let mut p = place();
        assert_eq!(
            p.set_pose(at(0), f64::NAN, 0.0, 0.0),
            Err(CommandRejected::NotFinite)
        );
        assert!(matches!(
            p.set_pose(at(0), 1e9, 0.0, 0.0),
            Err(CommandRejected::BeyondLimit { .. })
        ));
        assert_eq!(p.set_pose(at(0), 3.0, 4.0, 0.5), Ok(()));
        assert!(matches!(
            p.set_datum(Geodetic {
                lat_deg: 91.0,
                lon_deg: 0.0,
                h_m: 0.0
            }),
            Err(CommandRejected::OutOfRange { .. })
        ));
        assert_eq!(
            p.zero_here(at(0)),
            Err(CommandRejected::NoPosition),
            "without a datum there is no place to zero at"
        );
        p.gnss(at(100), &fixed_at(100));
        assert_eq!(p.zero_here(at(100)), Ok(()));
    }
}
