//! The localiser: the EKF fed by wheel odometry, the gyro, GNSS position, dual-antenna
//! heading and course over ground, in the local ENU frame of a datum.
//!
//! - Measurements are applied in the order of the time they describe, not of their arrival:
//!   the last second of measurements is kept with the filter state after each, and a late one
//!   (a GNSS fix arrives after the IMU samples of its epoch) rewinds to before its time and
//!   re-applies what followed.
//! - GNSS position, heading and course are gated on the innovation's Mahalanobis distance; a
//!   run of rejected positions means the vehicle really is elsewhere (it was carried, or the
//!   filter drifted), and resets the position to GNSS.
//! - The GNSS antenna's lever arm is rotated by the heading.

use std::collections::VecDeque;
use std::f64::consts::FRAC_PI_2;
use std::time::Duration;

use nalgebra::{SMatrix, SVector, Vector3};

use super::ekf::{
    BIAS, BIAS_RATE, Cov, Ekf, GNSS_E, GNSS_N, N, ProcessNoise, SCALE, State, V, W, X, Y, YAW, wrap,
};
use super::geodesy::{Enu, Geodetic};
use crate::time::Timestamp;

/// χ² gate, 1 degree of freedom, 99.9 %.
const GATE_1: f64 = 10.83;
/// χ² gate, 2 degrees of freedom, 99.9 %.
const GATE_2: f64 = 13.82;
/// A gyro whose last rate is younger than this many of its measured periods is the source of
/// yaw rate, not the wheels ...
const GYRO_LIVE_PERIODS: f64 = 5.0;
/// ... and never younger than this.
const GYRO_LIVE_MIN: Duration = Duration::from_millis(50);
use crate::fusion::odometry::STILL_MPS;
/// A vehicle slower than [`STILL_MPS`] and turning slower than this stands still, rad/s.
pub const STILL_RPS: f64 = 0.005;
/// The yaw rate of standing wheels, 1σ rad/s.
const STILL_YAW_RATE_SIGMA: f64 = 0.002;
/// A fix whose σ is below this fraction of the last one's marks a better fix quality ...
const QUALITY_STEP: f64 = 0.5;
/// The gyro bias's rate of change before anything has shown it, 1σ rad/s² (a warming
/// MEMS gyro's drift).
const INITIAL_BIAS_RATE_SIGMA: f64 = 3e-5;
/// The wheels' scale error before GNSS has shown it, 1σ (tyre wear and load).
const INITIAL_SCALE_SIGMA: f64 = 0.02;
/// Fixes inform the heading (through the antenna's lever arm and the motion between them)
/// only once its 1σ is within this, rad.
const HEADING_FROM_POSITIONS_RAD: f64 = 0.5;
/// The heading's 1σ before anything has shown it, rad.
const UNKNOWN_YAW_SIGMA: f64 = std::f64::consts::PI;
/// A relocation needs at least this many rejected positions, whatever their rate.
pub const MIN_REJECTIONS_TO_RELOCATE: u32 = 3;

/// Settings of the localiser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalizerConfig {
    /// GNSS antenna in the vehicle frame (x forward, y left), m.
    pub antenna: (f64, f64),
    /// The datum, when fixed by configuration; else the first RTK-fixed position.
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
    /// Positions rejected without a break for this long (and at least
    /// [`MIN_REJECTIONS_TO_RELOCATE`] of them) reset the position to GNSS. A glitch shorter
    /// than this is ridden out; a vehicle that really moved is found again after it.
    pub relocate_after: Duration,
    /// How far back a late measurement may reach.
    pub window: Duration,
    /// Process noise.
    pub noise: ProcessNoise,
    /// Wheel speed noise: 1σ m/s plus a fraction of the speed (slip).
    pub odometry_sigma: (f64, f64),
    /// Yaw rate from the wheels, 1σ rad/s (slips when turning).
    pub odometry_yaw_rate_sigma: f64,
    /// Gyro noise, 1σ rad/s.
    pub gyro_sigma: f64,
    /// The slowly wandering part of a fix's error, as a fraction of its 1σ; its
    /// correlation time is `noise.gnss_correlation_s`.
    pub gnss_correlated_fraction: f64,
    /// The receiver's velocity accuracy, 1σ per axis, m/s; `None`: typical by fix quality.
    pub gnss_velocity_sigma_mps: Option<f64>,
}

impl Default for LocalizerConfig {
    fn default() -> Self {
        Self {
            antenna: (0.0, 0.0),
            datum: None,
            gnss_latency: Duration::ZERO,
            locate_bound_m: 0.5,
            converged_yaw_rad: 5f64.to_radians(),
            heading_sigma_rad: 0.5f64.to_radians(),
            cog_min_speed_mps: 0.3,
            relocate_after: Duration::from_secs(3),
            window: Duration::from_secs(1),
            noise: ProcessNoise {
                accel: 1.0,
                angular_accel: 0.5,
                bias_walk: 2e-5,
                bias_rate_walk: 3e-6,
                position: 0.002,
                position_per_speed: 0.006,
                scale_walk: 1e-4,
                gnss_correlation_s: 30.0,
                gnss_error: (0.0, 0.0),
            },
            gnss_correlated_fraction: 0.5,
            gnss_velocity_sigma_mps: None,
            odometry_sigma: (0.01, 0.02),
            odometry_yaw_rate_sigma: 0.05,
            gyro_sigma: 0.003,
        }
    }
}

/// One measurement, in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Measurement {
    /// Wheel odometry: forward speed (m/s) and yaw rate (rad/s).
    Odometry {
        /// Forward speed, m/s.
        v: f64,
        /// Yaw rate, rad/s.
        w: f64,
    },
    /// Gyro yaw rate, rad/s (bias included).
    Gyro {
        /// Yaw rate, rad/s.
        wz: f64,
    },
    /// GNSS antenna position: east, north (m) and their 1σ.
    Position {
        /// East, north, m.
        en: (f64, f64),
        /// 1σ east, north, m.
        sigma: (f64, f64),
    },
    /// Dual-antenna heading as ENU yaw, rad.
    Heading {
        /// Yaw, rad.
        yaw: f64,
        /// 1σ, rad.
        sigma: f64,
    },
    /// Course over ground: the direction the antenna moves, as an ENU angle (rad).
    Course {
        /// Direction of the antenna's velocity, rad.
        yaw: f64,
        /// 1σ, rad.
        sigma: f64,
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

/// The localiser's answer at one time, from a single prediction of its filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Published {
    /// x, y (m), yaw (rad) in the map frame.
    pub map_pose: (f64, f64, f64),
    /// var x, cov xy, var y (m²), var yaw (rad²) in the map frame.
    pub map_covariance: [f64; 4],
    /// Whether the pose is good enough to publish as located.
    pub locate: LocateState,
    /// Odometry distance per true distance.
    pub wheel_scale: f64,
}

/// Counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LocalizerStats {
    /// Measurements applied.
    pub applied: u64,
    /// Positions, headings or courses rejected by the gate.
    pub rejected: u64,
    /// Position resets after a run of rejections.
    pub resets: u64,
    /// Measurements applied after later ones (rewound).
    pub late: u64,
    /// Measurements older than the window, dropped.
    pub too_late: u64,
}

#[derive(Debug, Clone, PartialEq)]
struct Filter {
    ekf: Ekf,
    time: Timestamp,
    /// The current run of rejected positions: its first time and its length.
    rejections: Option<(Timestamp, u32)>,
    /// The same for headings and courses.
    heading_rejections: Option<(Timestamp, u32)>,
    /// The last gyro rate applied.
    last_gyro: Option<Timestamp>,
    /// The larger 1σ of the last position fix.
    last_position_sigma: Option<f64>,
    /// The steady 1σ of the GNSS error at the current fix quality, east and north, m.
    gnss_error: (f64, f64),
    /// The wheels stood still at the last odometry: the pose holds.
    still: bool,
    /// Smoothed interval between gyro samples, s.
    gyro_period: Option<f64>,
}

/// The localiser.
#[derive(Debug, Clone)]
pub struct Localizer {
    config: LocalizerConfig,
    frame: Option<Enu>,
    /// The filter before the oldest buffered measurement.
    base: Option<Filter>,
    /// Measurements in time order, with the filter after each.
    buffer: VecDeque<(Timestamp, Measurement, Filter)>,
    /// Latest heading and course seen, to initialise with.
    last_heading: Option<(Timestamp, f64)>,
    /// The last position's time, and the interval before it: the receiver's period.
    last_position: (Option<Timestamp>, Option<Duration>),
    last_speed: f64,
    /// The frame poses are published in.
    map: MapFrame,
    stats: LocalizerStats,
    /// What happened that an operator should read in the log, until taken.
    events: Vec<String>,
}

impl Localizer {
    /// A localiser with nothing known.
    pub fn new(config: LocalizerConfig) -> Self {
        Self {
            frame: config.datum.map(Enu::new),
            config,
            base: None,
            buffer: VecDeque::new(),
            last_heading: None,
            last_position: (None, None),
            last_speed: 0.0,
            map: MapFrame::default(),
            stats: LocalizerStats::default(),
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

    /// Sets the datum unless one is set (the first RTK-fixed position).
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
        std::mem::take(&mut self.events)
    }

    /// Counters.
    pub fn stats(&self) -> LocalizerStats {
        self.stats
    }

    fn current(&self) -> Option<&Filter> {
        self.buffer.back().map(|(_, _, f)| f).or(self.base.as_ref())
    }

    /// The filter's state, if initialised.
    pub fn ekf(&self) -> Option<&Ekf> {
        self.current().map(|f| &f.ekf)
    }

    /// Pose of the vehicle reference point: x, y (m, ENU), yaw (rad).
    pub fn pose(&self) -> Option<(f64, f64, f64)> {
        self.ekf().map(|e| (e.x[X], e.x[Y], e.x[YAW]))
    }

    /// What the vehicle publishes about its place at `t`, from one prediction of the
    /// filter to `t`: the pose and its covariance in the map frame (INIT_POSITION's frame;
    /// the ENU frame of the datum until then), `nav.locate` and the wheels' scale; `None`
    /// before the filter starts.
    pub fn published(&self, t: Timestamp) -> Option<Published> {
        let e = self.predicted(t)?;
        let locate = if e.position_sigma() <= self.config.locate_bound_m
            && e.yaw_sigma() <= self.config.converged_yaw_rad
        {
            LocateState::Good
        } else {
            LocateState::Lost
        };
        let (s, c) = self.map.rotation.sin_cos();
        let (a, b, d) = (e.p[(X, X)], e.p[(X, Y)], e.p[(Y, Y)]);
        // Rᵀ P R with R the rotation by `rotation`.
        let xx = c * c * a + 2.0 * c * s * b + s * s * d;
        let yy = s * s * a - 2.0 * c * s * b + c * c * d;
        let xy = -c * s * a + (c * c - s * s) * b + c * s * d;
        Some(Published {
            map_pose: self.map.pose_of(e.x[X], e.x[Y], e.x[YAW]),
            map_covariance: [xx, xy, yy, e.p[(YAW, YAW)]],
            locate,
            wheel_scale: 1.0 + e.x[SCALE],
        })
    }

    /// The filter predicted to `t` (no measurement since then), without changing it.
    pub fn predicted(&self, t: Timestamp) -> Option<Ekf> {
        let f = self.current()?;
        let mut ekf = f.ekf.clone();
        if t > f.time {
            let dt = t.saturating_since(f.time).as_secs_f64();
            if f.still {
                ekf.predict_still(dt, &self.noise(f));
            } else {
                ekf.predict(dt, &self.noise(f));
            }
        }
        Some(ekf)
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
            Measurement::Heading { yaw, .. } | Measurement::Course { yaw, .. } => {
                self.last_heading = Some((t, yaw));
            }
            Measurement::Odometry { v, .. } => self.last_speed = v,
            Measurement::Position { .. } => {
                if let Some(before) = self.last_position.0.filter(|&b| t > b) {
                    self.last_position.1 = Some(t.saturating_since(before));
                }
                self.last_position.0 = Some(t);
            }
            _ => {}
        }
        let Some(current) = self.current().cloned() else {
            self.try_initialise(t, &m);
            return;
        };
        if t >= current.time {
            let mut f = current;
            self.apply(&mut f, t, &m);
            self.buffer.push_back((t, m, f));
            self.trim();
            return;
        }
        // Late: rewind to before `t`, then re-apply everything after it.
        let base_time = self.base.as_ref().map_or(t, |b| b.time);
        if t < base_time {
            self.stats.too_late += 1;
            return;
        }
        self.stats.late += 1;
        let at = self.buffer.partition_point(|(bt, _, _)| *bt <= t);
        let mut f = if at == 0 {
            self.base.clone()
        } else {
            self.buffer.get(at - 1).map(|(_, _, f)| f.clone())
        }
        .unwrap_or(current);
        let later: Vec<(Timestamp, Measurement)> = self
            .buffer
            .drain(at..)
            .map(|(bt, bm, _)| (bt, bm))
            .collect();
        self.apply(&mut f, t, &m);
        self.buffer.push_back((t, m, f.clone()));
        for (bt, bm) in later {
            self.apply(&mut f, bt, &bm);
            self.buffer.push_back((bt, bm, f.clone()));
        }
        self.trim();
    }

    /// Drops buffered measurements older than the window; the filter before the oldest
    /// kept one becomes the base.
    fn trim(&mut self) {
        let Some(newest) = self.buffer.back().map(|(t, _, _)| *t) else {
            return;
        };
        while self.buffer.len() > 1
            && self
                .buffer
                .front()
                .is_some_and(|(t, _, _)| newest.saturating_since(*t) > self.config.window)
        {
            if let Some((_, _, f)) = self.buffer.pop_front() {
                self.base = Some(f);
            }
        }
    }

    fn try_initialise(&mut self, t: Timestamp, m: &Measurement) {
        let Measurement::Position { en, sigma } = *m else {
            return;
        };
        // A recent heading (dual antenna, or course while moving): from the last second, or
        // from the last one and a half of the receiver's periods when that is longer (a
        // 1 Hz receiver's last heading can be a whole period old). Without one the filter
        // starts anyway, its heading unknown until course or a second antenna gives it.
        let max_age = self
            .last_position
            .1
            .map_or(Duration::from_secs(1), |period| {
                period.mul_f64(1.5).max(Duration::from_secs(1))
            });
        let heading = self
            .last_heading
            .filter(|(ht, _)| t.saturating_since(*ht) < max_age || *ht > t)
            .map(|(_, yaw)| yaw);
        let yaw = heading.unwrap_or(0.0);
        let (ax, ay) = self.config.antenna;
        let (s, c) = yaw.sin_cos();
        let mut x = State::zeros();
        x[X] = en.0 - (c * ax - s * ay);
        x[Y] = en.1 - (s * ax + c * ay);
        x[YAW] = yaw;
        x[V] = self.last_speed;
        let mut p = Cov::zeros();
        // With the heading unknown, so is where the antenna sits around the vehicle.
        let lever = if heading.is_some() {
            0.0
        } else {
            ax * ax + ay * ay
        };
        p[(X, X)] = sigma.0.powi(2) + 0.01 + lever;
        p[(Y, Y)] = sigma.1.powi(2) + 0.01 + lever;
        p[(YAW, YAW)] = match heading {
            Some(_) => 5f64.to_radians().powi(2),
            None => UNKNOWN_YAW_SIGMA.powi(2),
        };
        p[(V, V)] = 0.25;
        p[(W, W)] = 0.25;
        p[(BIAS, BIAS)] = 0.02f64.powi(2);
        p[(BIAS_RATE, BIAS_RATE)] = INITIAL_BIAS_RATE_SIGMA.powi(2);
        p[(SCALE, SCALE)] = INITIAL_SCALE_SIGMA.powi(2);
        // The first fix's slow error is in the position it gave.
        let slow = self.config.gnss_correlated_fraction;
        for (i, g, sd) in [(X, GNSS_E, sigma.0), (Y, GNSS_N, sigma.1)] {
            p[(g, g)] = (slow * sd).powi(2);
            p[(i, g)] = -(slow * sd).powi(2);
            p[(g, i)] = -(slow * sd).powi(2);
        }
        self.events.push(match heading {
            Some(yaw) => format!(
                "localisation started: position from a fix with 1σ {:.2} m, heading {:.1}° from GNSS",
                sigma.0.max(sigma.1),
                heading_deg_of_yaw(yaw)
            ),
            None => format!(
                "localisation started: position from a fix with 1σ {:.2} m; heading unknown \
                 (LOCATE_FALSE) until course over ground while moving or a dual-antenna heading gives it",
                sigma.0.max(sigma.1)
            ),
        });
        self.base = Some(Filter {
            ekf: Ekf::new(x, p),
            time: t,
            rejections: None,
            heading_rejections: None,
            last_gyro: None,
            last_position_sigma: Some(sigma.0.max(sigma.1)),
            gnss_error: (slow * sigma.0, slow * sigma.1),
            still: false,
            gyro_period: None,
        });
        self.buffer.clear();
    }

    /// Predicts `f` to `t` and applies `m`.
    fn apply(&mut self, f: &mut Filter, t: Timestamp, m: &Measurement) {
        if t > f.time {
            let dt = t.saturating_since(f.time).as_secs_f64();
            if f.still {
                f.ekf.predict_still(dt, &self.noise(f));
            } else {
                f.ekf.predict(dt, &self.noise(f));
            }
            f.time = t;
        }
        // A still vehicle's pose moves only by GNSS: wheel and gyro updates leave it.
        let pose: &[usize] = &[X, Y, YAW];
        let e = &mut f.ekf;
        let row = |i: usize| {
            let mut h = SMatrix::<f64, 1, N>::zeros();
            h[(0, i)] = 1.0;
            h
        };
        let one = |v: f64| SVector::<f64, 1>::new(v);
        let var = |s: f64| SMatrix::<f64, 1, 1>::new(s * s);
        match *m {
            Measurement::Odometry { v, w } => {
                let (base, rel) = self.config.odometry_sigma;
                let still = v.abs() < STILL_MPS && w.abs() < STILL_RPS;
                let kept: &[usize] = if still { pose } else { &[] };
                // The wheels read v·(1 + scale).
                let scale = 1.0 + e.x[SCALE];
                let mut h = row(V);
                h[(0, V)] = scale;
                h[(0, SCALE)] = e.x[V];
                e.update_except(
                    one(v - e.x[V] * scale),
                    &h,
                    &var(base + rel * v.abs()),
                    &[],
                    f64::INFINITY,
                    kept,
                );
                // The wheels' yaw rate carries the slip and track errors, which the gyro bias
                // would soak up; with a live gyro it is used only when the wheels stand still,
                // where it is exact (and makes the bias observable).
                let live_for = f
                    .gyro_period
                    .map_or(GYRO_LIVE_MIN, |p| {
                        Duration::from_secs_f64(p * GYRO_LIVE_PERIODS)
                    })
                    .max(GYRO_LIVE_MIN);
                let gyro_live = f
                    .last_gyro
                    .is_some_and(|g| t.saturating_since(g) <= live_for);
                f.still = still;
                let yaw_rate_sigma = match (gyro_live, still) {
                    (false, _) => Some(self.config.odometry_yaw_rate_sigma),
                    (true, true) => Some(STILL_YAW_RATE_SIGMA),
                    (true, false) => None,
                };
                if let Some(sigma) = yaw_rate_sigma {
                    f.ekf.update_except(
                        one(w - f.ekf.x[W]),
                        &row(W),
                        &var(sigma),
                        &[],
                        f64::INFINITY,
                        kept,
                    );
                }
                self.stats.applied += 1;
            }
            Measurement::Gyro { wz } => {
                let mut step = 0.0;
                if let Some(last) = f.last_gyro.filter(|&l| t > l) {
                    let dt = t.saturating_since(last).as_secs_f64();
                    // A gap (a lost link) turns the yaw over a few periods at most.
                    step = f.gyro_period.map_or(dt, |p| dt.min(p * GYRO_LIVE_PERIODS));
                    f.gyro_period = Some(match f.gyro_period {
                        // Gaps (a lost link) count as a few periods at most.
                        Some(p) => p + (dt.min(p * GYRO_LIVE_PERIODS) - p) * 0.05,
                        None => dt,
                    });
                }
                f.last_gyro = Some(t);
                let mut h = row(W);
                h[(0, BIAS)] = 1.0;
                let kept: &[usize] = if f.still { pose } else { &[] };
                let rate_before = e.x[W];
                e.update_except(
                    one(wz - e.x[W] - e.x[BIAS]),
                    &h,
                    &var(self.config.gyro_sigma),
                    &[],
                    f64::INFINITY,
                    kept,
                );
                if !f.still {
                    // The prediction turned the yaw at the old rate since the last sample; the
                    // trapezoid rule turns it at the mean of the old and the new, so a turn
                    // that speeds up leaves no lag. A refinement of the mean's integration:
                    // the covariance already holds the rate's uncertainty.
                    e.x[YAW] = wrap(e.x[YAW] + (e.x[W] - rate_before) * step / 2.0);
                }
                self.stats.applied += 1;
            }
            Measurement::Heading { yaw, sigma } => {
                let r = e.update(
                    &one(yaw),
                    &one(e.x[YAW]),
                    &row(YAW),
                    &var(sigma),
                    &[0],
                    GATE_1,
                );
                self.count(r.applied);
                self.heading_run(f, t, r.applied, yaw, sigma);
            }
            Measurement::Course { yaw, sigma } => {
                // The antenna moves at (v - ω·ay, ω·ax) in the vehicle frame: off the heading
                // while turning, and behind it when reversing.
                let (ax, ay) = self.config.antenna;
                let (along, across) = (e.x[V] - e.x[W] * ay, e.x[W] * ax);
                let speed_sq = along * along + across * across;
                if speed_sq < 0.01 {
                    return;
                }
                let mut h = row(YAW);
                h[(0, V)] = -across / speed_sq;
                h[(0, W)] = (along * ax + across * ay) / speed_sq;
                let offset = across.atan2(along);
                let predicted = e.x[YAW] + offset;
                let r = e.update(&one(yaw), &one(predicted), &h, &var(sigma), &[0], GATE_1);
                self.count(r.applied);
                self.heading_run(f, t, r.applied, wrap(yaw - offset), sigma);
            }
            Measurement::Position { en, sigma } => {
                // The fix's error is a slowly wandering part (a state of the filter, which
                // averaging cannot remove) plus white noise. A new fix quality brings an
                // error unrelated to the last one's.
                let sigma_now = sigma.0.max(sigma.1);
                let slow = self.config.gnss_correlated_fraction;
                let slow_sigma = (sigma.0 * slow, sigma.1 * slow);
                let new_quality = f.last_position_sigma.is_none_or(|before| {
                    sigma_now < before * QUALITY_STEP || sigma_now * QUALITY_STEP > before
                });
                if new_quality {
                    e.reset_gnss_error(slow_sigma);
                }
                f.gnss_error = slow_sigma;
                f.last_position_sigma = Some(sigma_now);
                let white = (1.0 - slow * slow).max(0.0).sqrt();
                let (ax, ay) = self.config.antenna;
                let (s, c) = e.x[YAW].sin_cos();
                let hx = SVector::<f64, 2>::new(
                    e.x[X] + c * ax - s * ay + e.x[GNSS_E],
                    e.x[Y] + s * ax + c * ay + e.x[GNSS_N],
                );
                let mut h = SMatrix::<f64, 2, N>::zeros();
                h[(0, X)] = 1.0;
                h[(1, Y)] = 1.0;
                h[(0, YAW)] = -s * ax - c * ay;
                h[(1, YAW)] = c * ax - s * ay;
                h[(0, GNSS_E)] = 1.0;
                h[(1, GNSS_N)] = 1.0;
                let r = SMatrix::<f64, 2, 2>::new(
                    (sigma.0 * white).powi(2),
                    0.0,
                    0.0,
                    (sigma.1 * white).powi(2),
                );
                let z = SVector::<f64, 2>::new(en.0, en.1);
                // While the heading is unknown, fixes set neither it nor what it would
                // teach (bias, its rate, the wheels' scale): linearised about a wrong heading
                // they would make up a confident, wrong one that the course gate then keeps
                // out. Once it is known they inform every state: a jump fails the gate, and
                // the fixes' slow wander is a state of its own, not bias.
                let kept: &[usize] = if e.yaw_sigma() > HEADING_FROM_POSITIONS_RAD {
                    &[YAW, BIAS, BIAS_RATE, SCALE]
                } else {
                    &[]
                };
                let result = e.update_except(z - hx, &h, &r, &[], GATE_2, kept);
                self.count(result.applied);
                if result.applied {
                    f.rejections = None;
                } else {
                    let (since, count) = f.rejections.map_or((t, 1), |(s, n)| (s, n + 1));
                    f.rejections = Some((since, count));
                    if count >= MIN_REJECTIONS_TO_RELOCATE
                        && t.saturating_since(since) >= self.config.relocate_after
                    {
                        // The vehicle is elsewhere: take GNSS's word for the position.
                        let e = &mut f.ekf;
                        e.x[X] = en.0 - (c * ax - s * ay);
                        e.x[Y] = en.1 - (s * ax + c * ay);
                        for i in 0..N {
                            e.p[(X, i)] = 0.0;
                            e.p[(i, X)] = 0.0;
                            e.p[(Y, i)] = 0.0;
                            e.p[(i, Y)] = 0.0;
                        }
                        e.p[(X, X)] = sigma.0.powi(2);
                        e.p[(Y, Y)] = sigma.1.powi(2);
                        e.reset_gnss_error(slow_sigma);
                        f.rejections = None;
                        self.stats.resets += 1;
                    }
                }
            }
        }
    }

    /// The process noise of `f`, its GNSS error at the current fix quality.
    fn noise(&self, f: &Filter) -> ProcessNoise {
        ProcessNoise {
            gnss_error: f.gnss_error,
            ..self.config.noise
        }
    }

    /// Tracks runs of rejected headings (dual antenna or course): a run as long as a
    /// position relocation's means the heading is wrong (a bad start, a slip on the spot),
    /// and the measured `yaw` (with its `sigma`) replaces it.
    fn heading_run(&mut self, f: &mut Filter, t: Timestamp, applied: bool, yaw: f64, sigma: f64) {
        if applied {
            f.heading_rejections = None;
            return;
        }
        let (since, count) = f.heading_rejections.map_or((t, 1), |(s, n)| (s, n + 1));
        f.heading_rejections = Some((since, count));
        if count >= MIN_REJECTIONS_TO_RELOCATE
            && t.saturating_since(since) >= self.config.relocate_after
        {
            let e = &mut f.ekf;
            e.x[YAW] = yaw;
            for i in 0..N {
                e.p[(YAW, i)] = 0.0;
                e.p[(i, YAW)] = 0.0;
            }
            e.p[(YAW, YAW)] = sigma * sigma;
            f.heading_rejections = None;
            self.stats.resets += 1;
        }
    }

    fn count(&mut self, applied: bool) {
        if applied {
            self.stats.applied += 1;
        } else {
            self.stats.rejected += 1;
        }
    }

    /// Re-zeroes the local frame at the position at `t` (`init_rtk_data`): the datum moves
    /// there and the map frame becomes its ENU frame. Returns false when there is no
    /// position yet.
    pub fn zero_here(&mut self, t: Timestamp) -> bool {
        let (Some(frame), Some(e)) = (self.frame, self.predicted(t)) else {
            return false;
        };
        let here = frame.to_geodetic(&Vector3::new(e.x[X], e.x[Y], 0.0));
        self.set_datum(here);
        true
    }

    /// Moves the local frame to `datum`, keeping the vehicle where it is on the ground. The
    /// map frame becomes that ENU frame again.
    pub fn set_datum(&mut self, datum: Geodetic) {
        self.map = MapFrame::default();
        let old = self.frame.replace(Enu::new(datum));
        let (Some(old), Some(new)) = (old, self.frame) else {
            return;
        };
        let shift = |f: &mut Filter| {
            let g = old.to_geodetic(&Vector3::new(f.ekf.x[X], f.ekf.x[Y], 0.0));
            let enu = new.to_enu(&g);
            f.ekf.x[X] = enu.x;
            f.ekf.x[Y] = enu.y;
        };
        if let Some(b) = &mut self.base {
            shift(b);
        }
        for (_, _, f) in &mut self.buffer {
            shift(f);
        }
    }

    /// Sets the pose (INIT_POSITION): x, y (m), yaw (rad). Once GNSS places the vehicle, the
    /// filter keeps following GNSS in its ENU frame and the map frame is moved and turned
    /// so that the vehicle reads this pose there. Before that, the filter starts from it.
    pub fn set_pose(&mut self, t: Timestamp, x: f64, y: f64, yaw: f64) {
        if self.frame.is_some()
            && let Some(e) = self.predicted(t)
        {
            self.map = MapFrame::placing(e.x[X], e.x[Y], e.x[YAW], x, y, yaw);
            return;
        }
        self.map = MapFrame::default();
        let mut state = self.ekf().map_or_else(State::zeros, |e| e.x);
        state[X] = x;
        state[Y] = y;
        state[YAW] = wrap(yaw);
        let mut p = self.ekf().map_or_else(
            || {
                let mut p = Cov::zeros();
                p[(V, V)] = 0.25;
                p[(W, W)] = 0.25;
                p[(BIAS, BIAS)] = 0.02f64.powi(2);
                p[(BIAS_RATE, BIAS_RATE)] = INITIAL_BIAS_RATE_SIGMA.powi(2);
                p[(SCALE, SCALE)] = INITIAL_SCALE_SIGMA.powi(2);
                p
            },
            |e| e.p,
        );
        for i in 0..N {
            for j in [X, Y, YAW] {
                p[(i, j)] = 0.0;
                p[(j, i)] = 0.0;
            }
        }
        p[(X, X)] = 0.05f64.powi(2);
        p[(Y, Y)] = 0.05f64.powi(2);
        p[(YAW, YAW)] = 1f64.to_radians().powi(2);
        let time = self.current().map_or(t, |f| f.time.max(t));
        self.base = Some(Filter {
            ekf: Ekf::new(state, p),
            time,
            rejections: None,
            heading_rejections: None,
            last_gyro: None,
            last_position_sigma: None,
            gnss_error: (0.0, 0.0),
            still: false,
            gyro_period: None,
        });
        self.buffer.clear();
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

/// True heading (degrees, 0–360, clockwise from north) of an ENU yaw.
pub fn heading_deg_of_yaw(yaw: f64) -> f64 {
    (90.0 - yaw.to_degrees()).rem_euclid(360.0)
}
