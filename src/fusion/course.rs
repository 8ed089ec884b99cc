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
/// twice the lag, so a smoothed course has settled.
pub const STRAIGHT_FOR_S: f64 = 2.0 * LAG_S;
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

    /// A course's 1σ (rad) at `speed` (m/s) while turning at up to `turn` (rad/s), the
    /// receiver's stated velocity noise being `stated` m/s.
    pub fn sigma(&self, stated: f64, speed: f64, turn: f64) -> f64 {
        let velocity = stated.max(self.speed_sigma().unwrap_or(UNPROVEN_SPEED_SIGMA_MPS));
        let noise = velocity.atan2(speed.abs());
        noise.hypot(turn.abs() * LAG_S)
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
        // Turning, the σ grows with the turn rate; slow, with the noise over the speed.
        assert!(doppler.sigma(0.02, 5.0, 0.5) > 0.2);
        assert!(doppler.sigma(0.02, 5.0, 0.0) < 0.02);
        assert!(from_positions.sigma(0.02, 1.0, 0.0) > 0.3);
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
        let unproven = c.sigma(0.02, 3.0, 0.0);
        assert!((unproven - 0.1f64.atan()).abs() < 1e-12, "{unproven}");
    }
}
