//! What a course over ground says of the heading, and how surely.
//!
//! A course is the direction the antenna moves, from the receiver's velocity: from its
//! Doppler on most receivers (a few cm/s), from the difference of its positions on plain
//! ones (decimetres a second, so tens of degrees at walking pace). It differs from the
//! body's heading:
//! - by its velocity noise over the speed, so a course is worth little when slow;
//! - in a turn, by the turn rate times how late it is: the receiver's latency the
//!   configuration may not know, and its smoothing of the velocity (a lag of 0.1–0.5 s
//!   beyond the measured latency is common); the lever arm the configuration may not know
//!   and sideslip add more while turning. So its σ grows with the fastest turn rate of the
//!   last [`LAG_S`].
//!
//! The receiver's velocity noise is measured against the gyro: while driving straight, the
//! rotation between a course and the odom frame's yaw at its time changes only by the
//! gyro's drift from one course to the next, so the scatter of those changes is the
//! course's own (a robust spread: the median absolute change). Until enough courses show
//! it, a course counts no surer than [`UNPROVEN_SPEED_SIGMA_MPS`] allows.

use std::collections::VecDeque;

use super::planar::wrap;
use crate::time::Timestamp;

/// How late and smoothed a course may be beyond the configured latency, s.
pub const LAG_S: f64 = 0.5;
/// Driving straight, for teaching the gyro's bias: the odom frame turning slower than this
/// over the last [`STRAIGHT_FOR_S`] (a gyro whose bias drifted reads its error as a turn,
/// up to [`super::gyro_drift::MAX_DRIFT_RPS`]), rad/s.
pub const STRAIGHT_RPS: f64 = 0.05;
/// A course teaches the gyro's bias (RTK-fixed epochs only) after this long straight, s:
/// ten times the lag a receiver may have, so a smoothed course has settled.
pub const STRAIGHT_FOR_S: f64 = 10.0 * LAG_S;
/// ... and only when at most this uncertain (2°), rad.
pub const TEACHING_SIGMA: f64 = 0.035;
/// The noise is measured on courses turning slower than this, rad/s.
const NOISE_STRAIGHT_RPS: f64 = 0.05;
/// Consecutive courses further apart than this say nothing of each other's noise, s.
const MAX_GAP_S: f64 = 2.0;
/// The noise is measured over this lag: a receiver that smooths its velocity, or makes it
/// from its positions, errs alike from one course to the next, s.
const NOISE_LAG_S: f64 = 2.5;
/// Changes a measured noise needs ...
const MIN_CHANGES: usize = 8;
/// ... and the latest ones kept.
const MAX_CHANGES: usize = 64;
/// A course's velocity noise until its scatter is measured, 1σ m/s (a receiver whose
/// courses come from its positions).
pub const UNPROVEN_SPEED_SIGMA_MPS: f64 = 0.3;

/// How late a receiver's courses are beyond the configured latency, measured against the
/// gyro: in a turn the rotation between a course and the odom yaw at its time moves by the
/// turn rate times the lag (the odom frame has turned on since the velocity the course
/// shows), so a least-squares line of that rotation over the time and the turn rate has the
/// lag as its slope against the turn rate. A receiver's smoothing of its velocity lags it
/// as much as its time constant, and counts the same.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CourseLag {
    /// The latest courses: time (s since the first), rotation (unwrapped), turn rate.
    samples: VecDeque<(f64, f64, f64)>,
    first: Option<Timestamp>,
}

/// Courses the lag is fitted to: the last this long ...
const LAG_WINDOW_S: f64 = 60.0;
/// ... at most this many ...
const MAX_LAG_SAMPLES: usize = 600;
/// ... and at least this many, turning this much apart (the turn rates' spread, rad/s).
const MIN_LAG_SAMPLES: usize = 30;
const MIN_TURN_SPREAD_RPS: f64 = 0.03;
/// The lag's measured 1σ counts as at least this, s.
const MIN_LAG_SIGMA_S: f64 = 0.05;

impl CourseLag {
    /// A course at `t` as a heading (rad), the odom yaw then and the turn rate then.
    pub fn observe(&mut self, t: Timestamp, heading: f64, odom_yaw: f64, rate: f64) {
        if !(heading.is_finite() && odom_yaw.is_finite() && rate.is_finite()) {
            return;
        }
        let first = *self.first.get_or_insert(t);
        let s = t.saturating_since(first).as_secs_f64();
        let raw = wrap(heading - odom_yaw);
        let rotation = match self.samples.back() {
            Some(&(s0, r0, _)) if s >= s0 => r0 + wrap(raw - r0),
            Some(_) => return,
            None => raw,
        };
        self.samples.push_back((s, rotation, rate));
        while self.samples.len() > MAX_LAG_SAMPLES
            || self
                .samples
                .front()
                .is_some_and(|(s0, _, _)| s - s0 > LAG_WINDOW_S)
        {
            self.samples.pop_front();
        }
    }

    /// The lag (s) and its 1σ, once turns have shown it.
    pub fn lag(&self) -> Option<(f64, f64)> {
        let n = self.samples.len();
        if n < MIN_LAG_SAMPLES {
            return None;
        }
        let mean = |f: &dyn Fn(&(f64, f64, f64)) -> f64| {
            self.samples.iter().map(f).sum::<f64>() / n as f64
        };
        let (ts, rs, ws) = (mean(&|x| x.0), mean(&|x| x.1), mean(&|x| x.2));
        // Centred, the line r = a + b·t + c·ω is two unknowns b, c.
        let (mut stt, mut stw, mut sww, mut str_, mut swr) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(t, r, w) in &self.samples {
            let (t, r, w) = (t - ts, r - rs, w - ws);
            stt += t * t;
            stw += t * w;
            sww += w * w;
            str_ += t * r;
            swr += w * r;
        }
        if sww / (n as f64) < MIN_TURN_SPREAD_RPS.powi(2) {
            return None;
        }
        let det = stt * sww - stw * stw;
        if det <= 0.0 || !det.is_finite() {
            return None;
        }
        let b = (sww * str_ - stw * swr) / det;
        let c = (stt * swr - stw * str_) / det;
        let residual = self
            .samples
            .iter()
            .map(|&(t, r, w)| (r - rs - b * (t - ts) - c * (w - ws)).powi(2))
            .sum::<f64>()
            / (n as f64 - 3.0);
        let sigma = (residual * stt / det).sqrt();
        // The course shows the odom frame's rotation less the turn since the velocity's time.
        Some((-c, sigma.max(MIN_LAG_SIGMA_S)))
    }

    /// What a course's heading needs added at turn rate `rate`, and the 1σ of its timing,
    /// s: the lag's, or [`LAG_S`] until measured. A smoothing receiver is late by its time
    /// constant only in a steady turn; as a turn starts or ends it errs by up to the whole
    /// lag's turn, so half the lag counts as its timing's uncertainty.
    pub fn correction(&self, rate: f64) -> Correction {
        match self.lag() {
            Some((lag, sigma)) => Correction {
                add: rate * lag,
                timing_s: sigma.max(lag.abs() / 2.0),
                measured: true,
            },
            None => Correction {
                add: 0.0,
                timing_s: LAG_S,
                measured: false,
            },
        }
    }
}

/// What a course needs for its lag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correction {
    /// Add this to the course's heading, rad.
    pub add: f64,
    /// The 1σ of its timing, s.
    pub timing_s: f64,
    /// Whether turns have shown the lag (else `timing_s` is the lag a receiver may have).
    pub measured: bool,
}

impl Correction {
    /// The course's 1σ (rad) with `noise` (rad) turning at up to `turn` (rad/s); `None`
    /// when a lag the turns showed could err more than twice the noise: then a course errs
    /// systematically through the turn, which no σ describes. A lag not yet measured is
    /// counted as noise, a receiver's being unknown.
    pub fn sigma(&self, noise: f64, turn: f64) -> Option<f64> {
        let timing = turn.abs() * self.timing_s;
        (!self.measured || timing <= 2.0 * noise).then(|| noise.hypot(timing))
    }
}

/// The scatter of a receiver's courses, measured against the gyro.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CourseNoise {
    /// The latest straight courses: time, rotation against the odom yaw (unwrapped).
    recent: VecDeque<(Timestamp, f64)>,
    /// The latest second differences of the rotation over [`NOISE_LAG_S`], as velocity
    /// noise: times the speed, over √6, m/s.
    changes: VecDeque<f64>,
}

impl CourseNoise {
    /// A course at `t`: its direction as a heading (rad), the odom yaw at its time, the
    /// speed (m/s) and the fastest turn rate of the last [`LAG_S`] (rad/s).
    pub fn observe(&mut self, t: Timestamp, heading: f64, odom_yaw: f64, speed: f64, turn: f64) {
        if !(heading.is_finite() && odom_yaw.is_finite() && speed.is_finite()) {
            return;
        }
        if turn.abs() > NOISE_STRAIGHT_RPS {
            self.recent.clear();
            return;
        }
        let raw = wrap(heading - odom_yaw);
        let rotation = match self.recent.back() {
            Some(&(t0, r0)) if t > t0 && t.saturating_since(t0).as_secs_f64() <= MAX_GAP_S => {
                r0 + wrap(raw - r0)
            }
            Some(_) => {
                self.recent.clear();
                raw
            }
            None => raw,
        };
        // The second difference over the lag takes out a steady drift of the gyro; what is
        // left is the courses' own error, correlated or not, up to the lag.
        let s = |back: f64| {
            let then = t.as_micros() as f64 - back * 1e6;
            self.recent
                .iter()
                .min_by(|a, b| {
                    (a.0.as_micros() as f64 - then)
                        .abs()
                        .total_cmp(&(b.0.as_micros() as f64 - then).abs())
                })
                .filter(|(at, _)| (at.as_micros() as f64 - then).abs() <= 0.25 * back * 1e6)
                .map(|(_, r)| *r)
        };
        if let (Some(r1), Some(r2)) = (s(NOISE_LAG_S), s(2.0 * NOISE_LAG_S)) {
            self.changes
                .push_back((rotation - 2.0 * r1 + r2).abs() * speed.abs() / 6f64.sqrt());
            while self.changes.len() > MAX_CHANGES {
                self.changes.pop_front();
            }
        }
        self.recent.push_back((t, rotation));
        while self
            .recent
            .front()
            .is_some_and(|(at, _)| t.saturating_since(*at).as_secs_f64() > 2.5 * NOISE_LAG_S)
        {
            self.recent.pop_front();
        }
    }

    /// The receiver's velocity noise as its courses show it, 1σ m/s; `None` until measured.
    pub fn speed_sigma(&self) -> Option<f64> {
        if self.changes.len() < MIN_CHANGES {
            return None;
        }
        let mut sorted: Vec<f64> = self.changes.iter().copied().collect();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        // The median absolute value of a normal variable is 0.674 of its σ.
        Some(median / 0.674)
    }

    /// A course's noise, 1σ rad, at `speed` (m/s), the receiver's stated velocity noise
    /// being `stated` m/s.
    pub fn sigma(&self, stated: f64, speed: f64) -> f64 {
        let velocity = stated.max(self.speed_sigma().unwrap_or(UNPROVEN_SPEED_SIGMA_MPS));
        velocity.atan2(speed.abs())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(s: f64) -> Timestamp {
        Timestamp::from_micros((1e9 + s * 1e6) as u64)
    }

    #[test]
    fn the_scatter_against_the_gyro_is_the_receivers_velocity_noise() {
        // Doppler courses at 5 m/s with 0.05 m/s noise: 0.01 rad, on an odom frame that
        // drifts slowly against them.
        let mut doppler = CourseNoise::default();
        let mut from_positions = CourseNoise::default();
        let mut seed = 7u64;
        let mut noise = || {
            // A sum of uniforms: near normal, unit variance.
            (0..12)
                .map(|_| {
                    seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
                    (seed >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        for k in 0..100 {
            let s = k as f64 * 0.2;
            let drift = 0.001 * s;
            doppler.observe(at(s), 0.3 + 0.01 * noise(), 0.3 - drift, 5.0, 0.0);
            from_positions.observe(at(s), 0.3 + 0.5 * noise(), 0.3 - drift, 1.0, 0.0);
        }
        let d = doppler.speed_sigma().expect("measured");
        assert!((0.035..0.07).contains(&d), "{d}");
        let p = from_positions.speed_sigma().expect("measured");
        assert!((0.35..0.7).contains(&p), "{p}");
        // Slow, the noise over the speed grows.
        assert!(doppler.sigma(0.02, 5.0) < 0.02);
        assert!(from_positions.sigma(0.02, 1.0) > 0.3);
    }

    #[test]
    fn the_lag_is_the_rotations_slope_against_the_turn_rate() {
        let mut lag = CourseLag::default();
        let mut yaw = 0.0;
        // Laps: 20 s straight, 9 s turning at 0.35 rad/s; courses 0.4 s late, at 5 Hz, on a
        // gyro drifting by 0.001 rad/s.
        for k in 0..600 {
            let s = k as f64 * 0.2;
            let w = if (s % 29.0) < 20.0 { 0.0 } else { 0.35 };
            yaw += w * 0.2;
            let truth = yaw;
            let odom_yaw = truth - 0.001 * s;
            let course = truth - w * 0.4;
            lag.observe(at(s), course, odom_yaw, w);
        }
        let (l, sigma) = lag.lag().expect("turns show it");
        assert!((l - 0.4).abs() < 0.02 && sigma < 0.1, "{l} ± {sigma}");
        let c = lag.correction(0.35);
        assert!(
            (c.add - 0.14).abs() < 0.01 && (c.timing_s - 0.2).abs() < 0.02,
            "{c:?}"
        );
        // A 0.4 s lag in a 0.35 rad/s turn errs too much for a 1° course; straight, fine.
        assert_eq!(c.sigma(0.017, 0.35), None);
        assert!(c.sigma(0.017, 0.0).is_some());
        // Driving straight only, nothing shows it.
        let mut straight = CourseLag::default();
        for k in 0..200 {
            straight.observe(at(k as f64 * 0.2), 0.3, 0.0, 0.0);
        }
        assert_eq!(straight.lag(), None);
        let c = straight.correction(0.2);
        assert!(!c.measured && c.add == 0.0 && c.timing_s == LAG_S);
        // Not measured, the lag a receiver may have counts as noise.
        assert!((c.sigma(0.01, 0.2).unwrap() - 0.01f64.hypot(0.1)).abs() < 1e-12);
    }

    #[test]
    fn turns_and_gaps_say_nothing_of_the_noise() {
        let mut c = CourseNoise::default();
        for k in 0..50 {
            let s = k as f64 * 3.0;
            c.observe(at(s), k as f64, 0.0, 2.0, 0.0);
        }
        for k in 0..50 {
            let s = 200.0 + k as f64 * 0.2;
            c.observe(at(s), k as f64, 0.0, 2.0, 0.3);
        }
        assert_eq!(c.speed_sigma(), None);
        // Unmeasured, a course counts as a plain receiver's.
        let unproven = c.sigma(0.02, 3.0);
        assert!((unproven - 0.1f64.atan()).abs() < 1e-12, "{unproven}");
    }
}
