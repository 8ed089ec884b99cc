//! The localiser: the map frame of REP-105 over the `odom` frame. The core gives it the odom
//! frame's poses (wheels and gyro, [`super::odometry`]) and the GNSS measurements; the map
//! filter ([`super::map_filter`]) estimates the map→odom correction from them. Here: the
//! local ENU frame of the datum, the frame INIT_POSITION sets, what is published (pose,
//! covariance, `nav.locate`, the correction), and the wheels' scale against RTK, used by the
//! moves once it is proven and never by the dead reckoning.

use std::f64::consts::FRAC_PI_2;
use std::time::Duration;

use nalgebra::Vector3;

use super::course::{self, CourseLag, CourseNoise};
use super::gnss_only::GnssOnly;
use super::gyro_drift::{Drift, GyroDrift};
use super::map_filter::{Fix, FixOutcome, MapFilter, MapFilterConfig, Trust};
use super::odometry::OdomPose;
pub use super::planar::heading_deg_of_yaw;
use super::planar::wrap;
use super::wheel_scale::WheelScale;
use crate::geodesy::{Enu, Geodetic};
use crate::time::Timestamp;

/// A vehicle slower than [`crate::fusion::odometry::STILL_MPS`] and turning slower than this
/// stands still, rad/s.
pub const STILL_RPS: f64 = 0.005;
/// How far ahead of the last odom pose a published pose is extrapolated, at most.
const MAX_EXTRAPOLATION: Duration = Duration::from_millis(500);

/// Settings of the localiser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalizerConfig {
    /// GNSS antenna in the vehicle frame (x forward, y left), m.
    pub antenna: (f64, f64),
    /// The datum, when fixed by configuration; else the first valid fix.
    pub datum: Option<Geodetic>,
    /// How long a position fix takes to arrive after its epoch.
    pub gnss_latency: Duration,
    /// `LOCATE_TRUE` while the 1σ position uncertainty is within this, m.
    pub locate_bound_m: f64,
    /// `LOCATE_TRUE` also needs the 1σ heading within this, rad.
    pub converged_yaw_rad: f64,
    /// Dual-antenna heading noise, 1σ rad.
    pub heading_sigma_rad: f64,
    /// Course over ground is used only above this speed, m/s.
    pub cog_min_speed_mps: f64,
    /// Fixes that jumped away together are taken after this long (the vehicle really is
    /// elsewhere); headings rejected this long replace the heading.
    pub relocate_after: Duration,
    /// Wheel speed noise: 1σ m/s plus a fraction of the speed (slip), for the ROS odometry's
    /// covariance.
    pub odometry_sigma: (f64, f64),
    /// Yaw rate from the wheels, 1σ rad/s, for the same.
    pub odometry_yaw_rate_sigma: f64,
    /// Gyro noise, 1σ rad/s.
    pub gyro_sigma: f64,
    /// The slowly wandering part of a fix's error, as a fraction of its 1σ (all but RTK
    /// fixed).
    pub gnss_correlated_fraction: f64,
    /// The same for RTK-fixed fixes.
    pub rtk_correlated_fraction: f64,
    /// Its correlation time (standing).
    pub gnss_correlation: Duration,
    /// Its correlation distance (moving), m.
    pub gnss_correlation_m: f64,
    /// The odom heading's random walk while moving, rad/√s (the gyro's angle random walk).
    pub heading_walk: f64,
    /// The gyro bias's random walk, rad/s per √s (it leaves what a standstill taught).
    pub gyro_bias_walk: f64,
    /// The odom frame's position error per metre driven: variance along and across the
    /// heading, m²/m (the wheels' slip and scale), and its heading error per radian turned,
    /// rad²/rad.
    pub odom_error: (f64, f64, f64),
    /// The receiver's velocity accuracy, 1σ per axis, m/s; `None`: typical by fix quality.
    pub gnss_velocity_sigma_mps: Option<f64>,
    /// The wheels' random slip, a variance per metre driven, m²/m ([`WheelScale`]).
    pub wheel_slip: f64,
    /// How fast the wheels' scale may change, 1σ per √m driven (the map filter's).
    pub wheel_scale_walk: f64,
}

impl Default for LocalizerConfig {
    fn default() -> Self {
        let map = MapFilterConfig::default();
        Self {
            antenna: (0.0, 0.0),
            datum: None,
            gnss_latency: Duration::ZERO,
            locate_bound_m: 0.5,
            converged_yaw_rad: 5f64.to_radians(),
            heading_sigma_rad: 0.5f64.to_radians(),
            cog_min_speed_mps: 0.3,
            relocate_after: map.relocate_after,
            odometry_sigma: (0.01, 0.02),
            odometry_yaw_rate_sigma: 0.05,
            gyro_sigma: 0.003,
            gnss_correlated_fraction: map.gnss_correlated_fraction,
            rtk_correlated_fraction: map.rtk_correlated_fraction,
            gnss_correlation: Duration::from_secs_f64(map.gnss_correlation_s),
            gnss_correlation_m: map.gnss_correlation_m,
            heading_walk: map.yaw_per_s.sqrt(),
            gyro_bias_walk: map.bias_walk,
            odom_error: (map.along_per_m, map.across_per_m, map.yaw_per_rad),
            gnss_velocity_sigma_mps: None,
            wheel_slip: 1e-4,
            wheel_scale_walk: map.scale_walk,
        }
    }
}

impl LocalizerConfig {
    fn map_filter(&self) -> MapFilterConfig {
        MapFilterConfig {
            antenna: self.antenna,
            gnss_correlated_fraction: self.gnss_correlated_fraction,
            rtk_correlated_fraction: self.rtk_correlated_fraction,
            gnss_correlation_s: self.gnss_correlation.as_secs_f64(),
            gnss_correlation_m: self.gnss_correlation_m,
            relocate_after: self.relocate_after,
            yaw_per_s: self.heading_walk * self.heading_walk,
            bias_walk: self.gyro_bias_walk,
            scale_walk: self.wheel_scale_walk,
            along_per_m: self.odom_error.0,
            across_per_m: self.odom_error.1,
            yaw_per_rad: self.odom_error.2,
        }
    }
}

/// One measurement, in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Measurement {
    /// The `odom` frame's pose (wheels and gyro).
    Odom(OdomPose),
    /// GNSS antenna position: east, north (m), their 1σ and how far the fix is trusted.
    Position {
        /// East, north, m.
        en: (f64, f64),
        /// 1σ east, north, m.
        sigma: (f64, f64),
        /// RTK (over the wheels) or not.
        trust: Trust,
        /// Whether differential corrections shaped it ([`Fix::corrected`]).
        corrected: bool,
    },
    /// Dual-antenna heading as ENU yaw, rad.
    Heading {
        /// Yaw, rad.
        yaw: f64,
        /// 1σ, rad.
        sigma: f64,
        /// The quality of the epoch it came with: only a heading of an RTK-fixed epoch may
        /// teach the odom frame's gyro bias.
        trust: Trust,
    },
    /// Course over ground: the direction the antenna moves, as an ENU angle (rad).
    Course {
        /// Direction of the antenna's velocity, rad.
        yaw: f64,
        /// The receiver's speed over ground, m/s.
        speed: f64,
        /// The receiver's stated velocity noise, 1σ per axis, m/s.
        speed_sigma: f64,
        /// The quality of the epoch it came with: only a course of an RTK-fixed epoch,
        /// driving straight and fast enough, may teach the odom frame's gyro bias.
        trust: Trust,
    },
}

/// Where localisation stands (`nav.locate`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LocateState {
    /// Not converged yet.
    #[default]
    Uninitialized,
    /// Within the bound.
    Good,
    /// Lost: uncertainty beyond the bound.
    Lost,
}

/// The localiser's answer at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Published {
    /// x, y (m), yaw (rad) in the map frame.
    pub map_pose: (f64, f64, f64),
    /// var x, cov xy, var y (m²), var yaw (rad²) in the map frame.
    pub map_covariance: [f64; 4],
    /// Whether the pose is good enough to publish as located.
    pub locate: LocateState,
    /// Odometry distance per true distance, once proven against RTK; else 1.
    pub wheel_scale: f64,
    /// The map→odom correction in the map frame: the odom frame's origin (x, y, m) and
    /// rotation (rad), so that map pose = correction ∘ odom pose.
    pub map_to_odom: (f64, f64, f64),
    /// The odom pose carried to the same time as the map pose (x, y, yaw); `None` without
    /// odometry.
    pub odom_pose: Option<(f64, f64, f64)>,
}

/// Counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LocalizerStats {
    /// Fixes, headings and courses applied.
    pub applied: u64,
    /// Fixes dropped for disagreeing with their neighbours, and headings or courses rejected.
    pub rejected: u64,
    /// Agreeing fixes that widened the filter (slipping wheels, a relocation).
    pub resets: u64,
}

/// The localiser.
#[derive(Debug, Clone)]
pub struct Localizer {
    config: LocalizerConfig,
    frame: Option<Enu>,
    filter: MapFilter,
    /// The latest odom pose and its time.
    odom: Option<(Timestamp, OdomPose)>,
    /// Latest heading seen before the filter started, to start with.
    last_heading: Option<(Timestamp, f64, f64)>,
    /// Headings rejected without a break: first time and count.
    heading_rejections: Option<RejectedHeadings>,
    scale: WheelScale,
    /// The odom heading's drift against RTK-grade headings: what may correct the bias.
    drift: GyroDrift,
    /// The same against every heading and course: what widens the map heading.
    drift_seen: GyroDrift,
    /// When the gyro's bias was last learnt (a standstill) or corrected.
    bias_since: Option<Timestamp>,
    /// How well the odom frame knows the bias it turns by, 1σ rad/s, as it last said.
    gyro_bias_sigma: Option<f64>,
    /// A proven drift, until the core corrects the gyro's bias by it.
    bias_correction: Option<Drift>,
    /// The last RTK fix a direction between two starts from.
    rtk_from: Option<RtkAnchor>,
    /// The frame poses are published in.
    map: MapFrame,
    /// The pose while no odom pose ever came (a vehicle without wheels).
    gnss_only: GnssOnly,
    /// The courses' scatter against the gyro.
    course_noise: CourseNoise,
    /// The courses' lag against the gyro.
    course_lag: CourseLag,
    /// What happened that an operator should read in the log, until taken.
    events: Vec<String>,
}

/// An RTK fix a direction is measured from.
#[derive(Debug, Clone, Copy)]
struct RtkAnchor {
    t: Timestamp,
    /// East/north, m.
    en: (f64, f64),
    sigma: f64,
    /// The antenna's odom position then, m.
    antenna: (f64, f64),
}

/// Headings the gate rejected without a break, as rotations of the odom frame.
#[derive(Debug, Clone, PartialEq)]
struct RejectedHeadings {
    since: Timestamp,
    /// Rotation (rad) and 1σ of each, the latest [`MAX_REJECTIONS_KEPT`].
    rotations: Vec<(f64, f64)>,
}

/// Rejected headings kept.
const MAX_REJECTIONS_KEPT: usize = 16;

impl RejectedHeadings {
    fn push(&mut self, rotation: f64, sigma: f64) {
        if self.rotations.len() >= MAX_REJECTIONS_KEPT {
            self.rotations.remove(0);
        }
        self.rotations.push((rotation, sigma));
    }

    /// The circular mean of the rotations and the 1σ of one of them, averaged.
    fn mean(&self) -> (f64, f64) {
        let (s, c) = self
            .rotations
            .iter()
            .fold((0.0, 0.0), |(s, c), (r, _)| (s + r.sin(), c + r.cos()));
        let sigma =
            self.rotations.iter().map(|(_, s)| s).sum::<f64>() / self.rotations.len().max(1) as f64;
        (s.atan2(c), sigma)
    }

    /// Whether a rotation with 1σ `sigma` agrees with the run's within 3σ of both.
    fn agrees(&self, rotation: f64, sigma: f64) -> bool {
        let (mean, run_sigma) = self.mean();
        wrap(rotation - mean).abs() <= 3.0 * sigma.hypot(run_sigma)
    }
}

/// What a heading may teach the dead reckoning besides the map pose's heading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Teaches {
    /// The odom heading's drift (the gyro's bias error): a dual-antenna heading of an
    /// RTK-fixed epoch.
    Drift,
    /// Nothing: a course, or a heading of a lesser epoch.
    Nothing,
}

impl Teaches {
    fn of(trust: Trust) -> Self {
        match trust {
            Trust::OverWheels => Self::Drift,
            Trust::UnderWheels => Self::Nothing,
        }
    }
}

/// A course over ground is never trusted beyond this, rad (1°) ...
const MIN_COURSE_SIGMA: f64 = 0.017_453_292_519_943_295;
/// ... and not used when less certain than this (15°).
const MAX_COURSE_SIGMA: f64 = 0.261_799_387_799_494_4;

/// How uncertain a heading's time is (the receiver's output timing and the latency's jitter;
/// the gyro's samples' transport), s.
const HEADING_TIME_SIGMA_S: f64 = 0.02;

/// The direction between two RTK fixes teaches the gyro's drift once its 1σ is within this,
/// rad (1 cm fixes 1.4 m apart).
const RTK_DIRECTION_SIGMA_RAD: f64 = 0.01;

/// A drift not yet proven widens the heading by the rate it has at this many of its σ below
/// its estimate, and bounds the drift's uncertainty by the rate this many σ above it.
const DRIFT_CONFIDENCE: f64 = 2.0;

/// Headings rejected this many times (over `relocate_after`) replace the heading.
const MIN_REJECTIONS_TO_RELOCATE: usize = 3;

impl Localizer {
    /// A localiser with nothing known.
    pub fn new(config: LocalizerConfig) -> Self {
        Self {
            frame: config.datum.map(Enu::new),
            filter: MapFilter::new(config.map_filter()),
            config,
            odom: None,
            last_heading: None,
            heading_rejections: None,
            scale: WheelScale::new(config.wheel_slip),
            drift: GyroDrift::default(),
            drift_seen: GyroDrift::default(),
            bias_since: None,
            gyro_bias_sigma: None,
            bias_correction: None,
            rtk_from: None,
            map: MapFrame::default(),
            gnss_only: GnssOnly::default(),
            course_noise: CourseNoise::default(),
            course_lag: CourseLag::default(),
            events: Vec::new(),
        }
    }

    /// Settings.
    pub fn config(&self) -> &LocalizerConfig {
        &self.config
    }

    /// The local frame, once it has a datum.
    pub fn frame(&self) -> Option<&Enu> {
        self.frame.as_ref()
    }

    /// Where the map frame lies on the globe, once there is a datum.
    pub fn map_placement(&self) -> Option<MapPlacement> {
        Some(MapPlacement {
            frame: self.frame?,
            map: self.map,
        })
    }

    /// Sets the datum unless one is set (the first valid position).
    pub fn offer_datum(&mut self, datum: Geodetic) -> bool {
        if self.frame.is_some() {
            return false;
        }
        self.frame = Some(Enu::new(datum));
        true
    }

    /// Adds an event for the log.
    pub fn add_event(&mut self, event: String) {
        self.events.push(event);
    }

    /// Takes the events since the last call (the filter's start, the datum's choice).
    pub fn take_events(&mut self) -> Vec<String> {
        let mut events = std::mem::take(&mut self.events);
        events.extend(self.filter.take_events());
        events
    }

    /// Counters.
    pub fn stats(&self) -> LocalizerStats {
        let s = self.filter.stats();
        LocalizerStats {
            applied: s.taken + s.headings,
            rejected: s.dropped + s.headings_rejected,
            resets: s.widened,
        }
    }

    /// The map filter.
    pub fn filter(&self) -> &MapFilter {
        &self.filter
    }

    /// Pose of the vehicle reference point in the ENU frame at the latest odom pose (at
    /// the latest fix without odometry).
    pub fn pose(&self) -> Option<(f64, f64, f64)> {
        if self.odom.is_none() {
            return self.gnss_only.pose(self.config.antenna);
        }
        self.filter.pose()
    }

    /// [`Localizer::published`] without odometry.
    fn published_without_odometry(&self, t: Timestamp) -> Option<Published> {
        let ((x, y, yaw), sigma, yaw_sigma) = self.gnss_only.pose_at(t, self.config.antenna)?;
        let locate =
            if sigma <= self.config.locate_bound_m && yaw_sigma <= self.config.converged_yaw_rad {
                LocateState::Good
            } else {
                LocateState::Lost
            };
        Some(Published {
            map_pose: self.map.pose_of(x, y, yaw),
            map_covariance: [sigma * sigma, 0.0, sigma * sigma, yaw_sigma * yaw_sigma],
            locate,
            wheel_scale: 1.0,
            map_to_odom: self.map.pose_of(0.0, 0.0, 0.0),
            odom_pose: None,
        })
    }

    /// What the vehicle publishes about its place at `t`: the map pose (INIT_POSITION's
    /// frame; the ENU frame of the datum until then) carried from the latest odom pose by
    /// its speed and yaw rate, its covariance, `nav.locate`, the wheels' scale and the
    /// map→odom correction; `None` before the filter starts.
    pub fn published(&self, t: Timestamp) -> Option<Published> {
        if self.odom.is_none() {
            return self.published_without_odometry(t);
        }
        let (x, y, yaw) = self.filter.pose()?;
        // Both the map pose and the odom pose are carried to `t` by the last speeds, so the
        // correction composed with the one is the other.
        let (dt, v, w, odom) = match self.odom {
            Some((to, o)) => (
                t.saturating_since(to).min(MAX_EXTRAPOLATION).as_secs_f64(),
                o.v,
                o.w,
                (o.x, o.y, o.yaw),
            ),
            None => (0.0, 0.0, 0.0, (0.0, 0.0, 0.0)),
        };
        let carried = |(x, y, yaw): (f64, f64, f64)| {
            let mid = yaw + w * dt / 2.0;
            (
                x + v * dt * mid.cos(),
                y + v * dt * mid.sin(),
                wrap(yaw + w * dt),
            )
        };
        let (ex, ey, eyaw) = carried((x, y, yaw));
        let locate = if self.filter.position_sigma() <= self.config.locate_bound_m
            && self.filter.yaw_sigma() <= self.config.converged_yaw_rad
        {
            LocateState::Good
        } else {
            LocateState::Lost
        };
        let (s, c) = self.map.rotation.sin_cos();
        let [a, b, d, var_yaw] = self.filter.covariance();
        // Rᵀ P R with R the rotation by `rotation`.
        let xx = c * c * a + 2.0 * c * s * b + s * s * d;
        let yy = s * s * a - 2.0 * c * s * b + c * c * d;
        let xy = -c * s * a + (c * c - s * s) * b + c * s * d;
        let correction = self.filter.map_to_odom().unwrap_or((0.0, 0.0, 0.0));
        Some(Published {
            map_pose: self.map.pose_of(ex, ey, eyaw),
            map_covariance: [xx, xy, yy, var_yaw],
            locate,
            wheel_scale: self.scale.proven().unwrap_or(1.0),
            map_to_odom: self.map.pose_of(correction.0, correction.1, correction.2),
            odom_pose: Some(carried(odom)),
        })
    }

    /// The `nav.locate` state at `t`: uninitialised without a map pose, good while both the
    /// position and the heading are within their bounds, else lost.
    pub fn locate(&self, t: Timestamp) -> LocateState {
        self.published(t)
            .map_or(LocateState::Uninitialized, |p| p.locate)
    }

    /// Adds a measurement that describes time `t`.
    pub fn add(&mut self, t: Timestamp, m: Measurement) {
        match m {
            Measurement::Odom(pose) => {
                if self.odom.is_some_and(|(to, _)| t < to) {
                    return;
                }
                self.odom = Some((t, pose));
                self.filter.odom(t, pose);
                if pose.v.abs() < super::odometry::STILL_MPS && pose.w.abs() < STILL_RPS {
                    // A standstill teaches the odom frame its bias afresh.
                    self.restart_drift(t);
                }
            }
            Measurement::Position {
                en,
                sigma,
                trust,
                corrected,
            } => {
                self.gnss_only.fix(t, en, sigma);
                let started = self.filter.is_started();
                let outcome = self.filter.fix(Fix {
                    t,
                    en,
                    sigma,
                    trust,
                    corrected,
                });
                if outcome == FixOutcome::Taken
                    && let Some(o) = self.filter.odom_pose_at(t)
                {
                    let antenna = self.antenna_in_odom(&o);
                    self.scale.fix(t, en, sigma, antenna);
                    if trust == Trust::OverWheels {
                        self.rtk_direction(t, en, sigma.0.max(sigma.1), antenna);
                    } else {
                        self.rtk_from = None;
                    }
                }
                if !started
                    && self.filter.is_started()
                    && let Some((ht, yaw, hs)) = self.last_heading
                    && t.saturating_since(ht) <= Duration::from_secs(2)
                {
                    self.filter.heading(yaw, hs);
                }
            }
            Measurement::Heading { yaw, sigma, trust } => {
                self.gnss_only.heading(yaw, sigma);
                self.heading(t, yaw, sigma, Teaches::of(trust));
            }
            Measurement::Course {
                yaw,
                speed,
                speed_sigma,
                trust,
            } => self.course(t, yaw, speed, speed_sigma, trust),
        }
    }

    /// A course over ground at `t`: the heading it shows, as surely as its noise against
    /// the gyro and the turn rate allow ([`super::course`]).
    fn course(&mut self, t: Timestamp, yaw: f64, speed: f64, speed_sigma: f64, trust: Trust) {
        let Some((_, latest)) = self.odom else {
            // Without wheels, forward or back is unknown: the course is taken as the
            // heading.
            let sigma = speed_sigma.atan2(speed.abs()).max(MIN_COURSE_SIGMA);
            if sigma <= MAX_COURSE_SIGMA {
                self.gnss_only.heading(yaw, sigma);
            }
            return;
        };
        let then = self.filter.odom_pose_at(t).unwrap_or(latest);
        let before = |s: f64| {
            Timestamp::from_nanos(
                t.as_nanos()
                    .saturating_sub(Duration::from_secs_f64(s).as_nanos() as u64),
            )
        };
        let turn = self
            .filter
            .max_turn_rate(before(course::LAG_S), t)
            .max(then.w.abs());
        // Free of what makes a course differ from the heading: no turn for long enough that
        // the receiver's lag and smoothing, the lever arm and sideslip are all zero.
        let straight = self
            .filter
            .max_turn_rate(before(course::STRAIGHT_FOR_S), t)
            .max(then.w.abs())
            <= course::STRAIGHT_RPS;
        let Some(heading) = self.filter.heading_of_course(yaw, then.v, then.w) else {
            return;
        };
        self.course_noise.observe(t, heading, then.yaw, speed, turn);
        self.course_lag.observe(t, heading, then.yaw, then.w);
        // Late by the lag the turns showed: the heading has turned on since.
        let lag = self.course_lag.correction(then.w);
        let heading = wrap(heading + lag.add);
        let noise = self
            .course_noise
            .sigma(speed_sigma, speed)
            .max(MIN_COURSE_SIGMA);
        let Some(sigma) = lag.sigma(noise, turn) else {
            return;
        };
        if sigma <= MAX_COURSE_SIGMA {
            // A course is the antenna's direction of motion, late and smoothed by the
            // receiver: in a turn it is not the body's heading, so only an RTK-fixed
            // epoch's course, straight and fast, teaches the gyro's bias.
            let teaches = if straight && sigma <= course::TEACHING_SIGMA {
                Teaches::of(trust)
            } else {
                Teaches::Nothing
            };
            self.heading(t, heading, sigma, teaches);
        }
    }

    fn antenna_in_odom(&self, o: &OdomPose) -> (f64, f64) {
        let (ax, ay) = self.config.antenna;
        let (s, c) = o.yaw.sin_cos();
        (o.x + c * ax - s * ay, o.y + s * ax + c * ay)
    }

    /// A heading measured at `t`: carried to the latest odom pose by the odom frame's turn
    /// since (a fix arrives after its epoch), then applied when it passes the gate; a run of
    /// rejections as long as a relocation means the heading is wrong (a bad start, a slip on
    /// the spot), and the measured one replaces it.
    fn heading(&mut self, t: Timestamp, yaw: f64, sigma: f64, teaches: Teaches) {
        let (turned, rate) = match (self.odom, self.filter.odom_pose_at(t)) {
            (Some((_, now)), Some(then)) => (wrap(now.yaw - then.yaw), then.w),
            _ => (0.0, 0.0),
        };
        // While turning, the heading's time is as uncertain as the receiver's output timing.
        let sigma = sigma.hypot(rate * HEADING_TIME_SIGMA_S);
        let measured = yaw;
        let yaw = wrap(yaw + turned);
        if !self.filter.is_started() {
            self.last_heading = Some((t, yaw, sigma));
            return;
        }
        if self.filter.heading(yaw, sigma) {
            self.heading_rejections = None;
            if let Some(then) = self.filter.odom_pose_at(t) {
                self.observe_drift(t, measured, sigma, then.yaw, teaches);
            }
            return;
        }
        // The rejected heading as a rotation of the odom frame: rejections that agree with
        // each other for a relocation's time show the heading wrong; scattered ones (a noisy
        // course) show nothing.
        let now_yaw = self.odom.map_or(0.0, |(_, o)| o.yaw);
        let rotation = wrap(yaw - now_yaw);
        let mut run = self
            .heading_rejections
            .take()
            .filter(|run| run.agrees(rotation, sigma))
            .unwrap_or(RejectedHeadings {
                since: t,
                rotations: Vec::new(),
            });
        run.push(rotation, sigma);
        if run.rotations.len() >= MIN_REJECTIONS_TO_RELOCATE
            && t.saturating_since(run.since) >= self.config.relocate_after
        {
            let (mean, mean_sigma) = run.mean();
            self.filter.reset_heading(wrap(now_yaw + mean), mean_sigma);
            return;
        }
        self.heading_rejections = Some(run);
    }

    /// The direction between two RTK fixes far apart against their σ, against the odom
    /// frame's between the same times: a measured rotation of the odom frame.
    fn rtk_direction(&mut self, t: Timestamp, en: (f64, f64), sigma: f64, antenna: (f64, f64)) {
        let here = RtkAnchor {
            t,
            en,
            sigma,
            antenna,
        };
        let Some(from) = self.rtk_from else {
            self.rtk_from = Some(here);
            return;
        };
        if t.saturating_since(from.t) > super::gyro_drift::MIN_SPAN {
            // Too long: the odom frame turned meanwhile.
            self.rtk_from = Some(here);
            return;
        }
        let (gx, gy) = (en.0 - from.en.0, en.1 - from.en.1);
        let (ox, oy) = (antenna.0 - from.antenna.0, antenna.1 - from.antenna.1);
        let (g, o) = (gx.hypot(gy), ox.hypot(oy));
        let direction_sigma = sigma.hypot(from.sigma) / g.max(1e-9);
        if direction_sigma > RTK_DIRECTION_SIGMA_RAD || o <= 0.0 {
            return;
        }
        self.rtk_from = Some(here);
        self.observe_drift(
            t,
            gy.atan2(gx),
            direction_sigma,
            oy.atan2(ox),
            Teaches::Drift,
        );
    }

    /// A heading (rad, 1σ) measured at `t`, the odom yaw then: what the odom heading's
    /// drift is seen to be widens the map heading's uncertainty, whatever measured it; only
    /// an RTK-grade heading may prove it and correct the gyro's bias.
    fn observe_drift(
        &mut self,
        t: Timestamp,
        heading: f64,
        sigma: f64,
        odom_yaw: f64,
        teaches: Teaches,
    ) {
        self.drift_seen.observe(t, heading, sigma, odom_yaw);
        if teaches == Teaches::Drift {
            self.drift.observe(t, heading, sigma, odom_yaw);
        }
        if let Some(drift) = self.drift.proven() {
            self.drift.restart();
            self.drift_seen.restart();
            self.events.push(format!(
                "gyro bias corrected by {:+.5} rad/s: the odom heading drifted so against GNSS \
                 (1σ {:.5} rad/s over {} headings in {:.0} s)",
                drift.rate,
                drift.sigma,
                drift.samples,
                drift.span.as_secs_f64()
            ));
            // The bias moved by that rate since it was last learnt: it walks at least that
            // fast (a warming gyro's bias ramps), and the drift's uncertainty grows so.
            let since = self
                .bias_since
                .map_or(drift.span, |s| t.saturating_since(s).max(drift.span));
            let moved = (drift.rate.abs() - DRIFT_CONFIDENCE * drift.sigma).max(0.0);
            self.filter
                .set_bias_walk(moved * moved / since.as_secs_f64().max(1.0));
            self.filter.reset_drift(drift.sigma);
            self.bias_since = Some(t);
            self.bias_correction = Some(drift);
        }
        // Only a fit over enough headings and time says anything of the drift (a few courses
        // while accelerating make any slope).
        let seen = &self.drift_seen;
        let fit = seen.fit().filter(|_| {
            seen.len() >= super::gyro_drift::MIN_SAMPLES
                && seen.span() >= super::gyro_drift::MIN_SPAN
        });
        let span = seen.span().as_secs_f64();
        let walk = fit.map_or(0.0, |(slope, sigma, chi2)| {
            // A line that explains the headings bounds the drift rate itself: the consider
            // state's mean stays zero, so its variance is at most the rate's mean square.
            if chi2 <= super::gyro_drift::MAX_REDUCED_CHI2 {
                self.filter.bound_drift(slope * slope + sigma * sigma);
            }
            // Until it is proven, the drift widens the heading as it goes (a random walk of
            // r²·T per second matches the drift's r·t at horizon T, the time it has run
            // uncorrected), at the rate it has at least with 97.7 % confidence, and no faster
            // than a bias can drift.
            let rate = (slope.abs() - DRIFT_CONFIDENCE * sigma)
                .clamp(0.0, super::gyro_drift::MAX_DRIFT_RPS);
            rate * rate * span
        });
        self.filter.set_heading_drift(walk);
    }

    /// The odom frame knows the gyro bias it turns by to 1σ `sigma` rad/s (`None`: it has
    /// learnt none): a standstill restarts the odom heading's drift with that uncertainty.
    pub fn set_gyro_bias_sigma(&mut self, sigma: Option<f64>) {
        self.gyro_bias_sigma = sigma.filter(|s| s.is_finite() && *s >= 0.0);
    }

    /// The odom heading's drift starts afresh: a standstill taught the gyro its bias at `t`.
    fn restart_drift(&mut self, t: Timestamp) {
        self.drift.restart();
        self.drift_seen.restart();
        self.bias_since = Some(t);
        self.filter.set_heading_drift(0.0);
        self.filter.set_bias_walk(0.0);
        // A bias known to σ leaves a drift of σ; one never learnt keeps what the filter had.
        if let Some(sigma) = self.gyro_bias_sigma {
            self.filter.reset_drift(sigma);
        }
    }

    /// A proven drift of the odom heading, once: the gyro's bias is to be corrected by its
    /// rate.
    pub fn take_bias_correction(&mut self) -> Option<Drift> {
        self.bias_correction.take()
    }

    /// Re-zeroes the local frame at the position at `t` (`init_rtk_data`): the datum moves
    /// there and the map frame becomes its ENU frame. Returns false when there is no
    /// position yet.
    pub fn zero_here(&mut self, _t: Timestamp) -> bool {
        let (Some(frame), Some((x, y, _))) = (self.frame, self.pose()) else {
            return false;
        };
        let here = frame.to_geodetic(&Vector3::new(x, y, 0.0));
        self.set_datum(here);
        true
    }

    /// Moves the local frame to `datum`, keeping the vehicle where it is on the ground. The
    /// map frame becomes that ENU frame again.
    pub fn set_datum(&mut self, datum: Geodetic) {
        self.map = MapFrame::default();
        let old = self.frame.replace(Enu::new(datum));
        let (Some(old), Some(new), Some((x, y, _))) = (old, self.frame, self.pose()) else {
            return;
        };
        let g = old.to_geodetic(&Vector3::new(x, y, 0.0));
        let enu = new.to_enu(&g);
        self.filter.shift(enu.x - x, enu.y - y);
        self.gnss_only.shift(enu.x - x, enu.y - y);
        self.scale.forget_fixes();
    }

    /// Sets the pose (INIT_POSITION): x, y (m), yaw (rad). Once GNSS places the vehicle, the
    /// filter keeps following GNSS in its ENU frame and the map frame is moved and turned
    /// so that the vehicle reads this pose there. Before that, the filter starts from it.
    pub fn set_pose(&mut self, t: Timestamp, x: f64, y: f64, yaw: f64) {
        if self.frame.is_some()
            && let Some(p) = self.published(t)
        {
            let (ex, ey, eyaw) = self.pose().unwrap_or(p.map_pose);
            self.map = MapFrame::placing(ex, ey, eyaw, x, y, yaw);
            return;
        }
        self.map = MapFrame::default();
        self.filter
            .set_pose((x, y, wrap(yaw)), (0.05, 1f64.to_radians()));
    }
}

/// Where the map frame lies on the globe: the datum's ENU frame, and the map frame in it
/// (INIT_POSITION moves and turns it). Equal placements put every position at the same
/// map point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapPlacement {
    frame: Enu,
    map: MapFrame,
}

impl MapPlacement {
    /// The datum's ENU frame, unmoved: what the map frame is before INIT_POSITION.
    pub fn at_datum(datum: Geodetic) -> Self {
        Self {
            frame: Enu::new(datum),
            map: MapFrame::default(),
        }
    }

    /// The WGS84 position (latitude, longitude, degrees) of map coordinates (x, y), m: the
    /// inverse of [`MapPlacement::place`].
    pub fn geodetic(&self, x: f64, y: f64) -> (f64, f64) {
        let (ex, ey) = self.map.enu_of(x, y);
        let g = self.frame.to_geodetic(&Vector3::new(ex, ey, 0.0));
        (g.lat_deg, g.lon_deg)
    }

    /// The map frame's x axis's angle from east, rad (0 until INIT_POSITION turns it): what
    /// turns a covariance in map coordinates into east and north.
    pub fn rotation(&self) -> f64 {
        self.map.rotation
    }

    /// The datum's height above the ellipsoid, m: the height of the map's plane.
    pub fn height_m(&self) -> f64 {
        self.frame.datum().h_m
    }

    /// A WGS84 position's map coordinates (x, y), m.
    pub fn place(&self, lat_deg: f64, lon_deg: f64) -> (f64, f64) {
        let enu = self.frame.to_enu(&Geodetic {
            lat_deg,
            lon_deg,
            h_m: self.frame.datum().h_m,
        });
        let (x, y, _) = self.map.pose_of(enu.x, enu.y, 0.0);
        (x, y)
    }
}

/// The map frame in the filter's ENU frame: its origin and its x axis's angle from east.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct MapFrame {
    origin: (f64, f64),
    rotation: f64,
}

impl MapFrame {
    /// The frame in which the ENU pose (ex, ey, eyaw) reads (x, y, yaw).
    fn placing(ex: f64, ey: f64, eyaw: f64, x: f64, y: f64, yaw: f64) -> Self {
        let rotation = wrap(eyaw - yaw);
        let (s, c) = rotation.sin_cos();
        Self {
            origin: (ex - (c * x - s * y), ey - (s * x + c * y)),
            rotation,
        }
    }

    /// The ENU position of map coordinates (x, y).
    fn enu_of(&self, x: f64, y: f64) -> (f64, f64) {
        let (s, c) = self.rotation.sin_cos();
        (self.origin.0 + c * x - s * y, self.origin.1 + s * x + c * y)
    }

    /// An ENU pose in this frame.
    fn pose_of(&self, x: f64, y: f64, yaw: f64) -> (f64, f64, f64) {
        let (dx, dy) = (x - self.origin.0, y - self.origin.1);
        let (s, c) = self.rotation.sin_cos();
        (c * dx + s * dy, -s * dx + c * dy, wrap(yaw - self.rotation))
    }
}

/// ENU yaw (rad, counter-clockwise from east) of a true heading (degrees, clockwise from
/// north).
pub fn yaw_of_heading_deg(heading_deg: f64) -> f64 {
    wrap(FRAC_PI_2 - heading_deg.to_radians())
}
