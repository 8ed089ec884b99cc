//! The odom heading's drift against GNSS: the part of the gyro's bias the last standstill did
//! not see (it changed with temperature since, or the vehicle has not stopped). The odom
//! frame's yaw then turns at that rate against the true heading, so the rotation between the
//! two (a measured heading less the odom yaw at its time) moves on a line whose slope is the
//! bias's error. Once that slope is proven, the dead reckoning's bias is corrected by it.
//!
//! Proven means, over the last [`WINDOW`] of samples taken while moving:
//! - at least [`MIN_SAMPLES`] samples spanning at least [`MIN_SPAN`];
//! - the line explains them: their reduced χ² about it is at most [`MAX_REDUCED_CHI2`], so a
//!   step (a relocation, a receiver's jump) or a wobble is not mistaken for a drift;
//! - the slope is at least [`MIN_SIGNIFICANCE`] times its 1σ and within [`MAX_DRIFT_RPS`].
//!
//! Only measurements of the heading itself teach it: a dual-antenna heading, a course over
//! ground, and the direction between two RTK-fixed fixes far apart against their σ. Fixes of a
//! lesser quality never do: an SBAS step would otherwise read as a turn of the odom frame.

use std::collections::VecDeque;
use std::time::Duration;

use super::planar::wrap;
use crate::time::Timestamp;

/// Samples older than this are forgotten: the bias changes, and a line is fitted to now.
pub const WINDOW: Duration = Duration::from_secs(30);
/// The samples must span this long.
pub const MIN_SPAN: Duration = Duration::from_secs(10);
/// And be this many (RTK directions come every other fix at 1 Hz and walking pace).
pub const MIN_SAMPLES: usize = 10;
/// The samples' spread about the line, in units of their σ, at most.
pub const MAX_REDUCED_CHI2: f64 = 2.0;
/// The slope over its 1σ, at least.
pub const MIN_SIGNIFICANCE: f64 = 5.0;
/// A drift faster than this is no bias (a gyro fault, a frame gone wrong), rad/s.
pub const MAX_DRIFT_RPS: f64 = 0.05;
/// Samples kept, bounding memory at any rate.
const MAX_SAMPLES: usize = 1024;

/// One measured rotation of the odom frame against the true heading.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    t: Timestamp,
    /// Measured heading less the odom yaw, unwrapped against the first sample, rad.
    rotation: f64,
    var: f64,
}

/// A proven drift.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drift {
    /// The odom yaw's drift against the truth, rad/s: add it to the gyro's bias.
    pub rate: f64,
    /// Its 1σ, rad/s.
    pub sigma: f64,
    /// Samples it rests on.
    pub samples: usize,
    /// The span they cover.
    pub span: Duration,
}

/// The drift's estimator.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GyroDrift {
    samples: VecDeque<Sample>,
}

impl GyroDrift {
    /// A heading measured at `t` (ENU yaw, rad, 1σ `sigma`) and the odom yaw then.
    pub fn observe(&mut self, t: Timestamp, heading: f64, sigma: f64, odom_yaw: f64) {
        if !(heading.is_finite() && odom_yaw.is_finite() && sigma.is_finite() && sigma > 0.0) {
            return;
        }
        if self.samples.back().is_some_and(|s| t < s.t) {
            return;
        }
        let raw = wrap(heading - odom_yaw);
        let rotation = match self.samples.back() {
            Some(last) => last.rotation + wrap(raw - last.rotation),
            None => raw,
        };
        self.samples.push_back(Sample {
            t,
            rotation,
            var: sigma * sigma,
        });
        while self.samples.len() > MAX_SAMPLES
            || self
                .samples
                .front()
                .is_some_and(|s| t.saturating_since(s.t) > WINDOW)
        {
            self.samples.pop_front();
        }
    }

    /// The odom frame's bias changed (a standstill taught it): what was measured before
    /// describes another drift.
    pub fn restart(&mut self) {
        self.samples.clear();
    }

    /// The time the samples held span.
    pub fn span(&self) -> Duration {
        match (self.samples.front(), self.samples.back()) {
            (Some(a), Some(b)) => b.t.saturating_since(a.t),
            _ => Duration::ZERO,
        }
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether no sample is held.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The weighted line through the samples: slope (rad/s), its 1σ and the reduced χ².
    pub fn fit(&self) -> Option<(f64, f64, f64)> {
        let first = self.samples.front()?.t;
        let n = self.samples.len();
        if n < 3 {
            return None;
        }
        let at = |s: &Sample| s.t.saturating_since(first).as_secs_f64();
        let (mut sw, mut st, mut sr) = (0.0, 0.0, 0.0);
        for s in &self.samples {
            let w = 1.0 / s.var;
            sw += w;
            st += w * at(s);
            sr += w * s.rotation;
        }
        let (tm, rm) = (st / sw, sr / sw);
        let (mut stt, mut str_) = (0.0, 0.0);
        for s in &self.samples {
            let w = 1.0 / s.var;
            stt += w * (at(s) - tm).powi(2);
            str_ += w * (at(s) - tm) * (s.rotation - rm);
        }
        if stt <= 0.0 {
            return None;
        }
        let slope = str_ / stt;
        let chi2: f64 = self
            .samples
            .iter()
            .map(|s| (s.rotation - rm - slope * (at(s) - tm)).powi(2) / s.var)
            .sum();
        Some((slope, (1.0 / stt).sqrt(), chi2 / (n - 2) as f64))
    }

    /// The drift once proven (see the module's criterion).
    pub fn proven(&self) -> Option<Drift> {
        let (first, last) = (self.samples.front()?, self.samples.back()?);
        let span = last.t.saturating_since(first.t);
        if self.samples.len() < MIN_SAMPLES || span < MIN_SPAN {
            return None;
        }
        let (slope, sigma, reduced_chi2) = self.fit()?;
        let proven = reduced_chi2 <= MAX_REDUCED_CHI2
            && slope.abs() >= MIN_SIGNIFICANCE * sigma
            && slope.abs() <= MAX_DRIFT_RPS;
        // The rotation falls as the odom yaw runs ahead: the drift is minus the slope.
        proven.then_some(Drift {
            rate: -slope,
            sigma,
            samples: self.samples.len(),
            span,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(s: f64) -> Timestamp {
        Timestamp::from_nanos((s * 1e9) as u64)
    }

    /// Headings at 10 Hz with 0.3° noise against an odom yaw drifting at `drift` rad/s.
    fn drifting(drift: f64, seconds: f64, noise: impl Fn(usize) -> f64) -> GyroDrift {
        let mut d = GyroDrift::default();
        for i in 0..(seconds * 10.0) as usize {
            let t = i as f64 / 10.0;
            let truth = 0.3 * (t / 7.0).sin();
            d.observe(
                at(t),
                truth + noise(i),
                0.3f64.to_radians(),
                truth + drift * t,
            );
        }
        d
    }

    /// Deterministic noise of about 1σ = 0.3°.
    fn noise(i: usize) -> f64 {
        let u = ((i as f64 * 12.9898).sin() * 43_758.545).rem_euclid(1.0);
        (u - 0.5) * 2.0 * 0.3f64.to_radians() * 3f64.sqrt()
    }

    #[test]
    fn a_steady_drift_is_proven_with_its_rate() {
        let d = drifting(0.002, 20.0, noise);
        let drift = d.proven().expect("proven");
        assert!((drift.rate - 0.002).abs() < 3.0 * drift.sigma, "{drift:?}");
        assert!(drift.sigma < 2e-4);
    }

    #[test]
    fn no_drift_or_too_short_a_span_is_not_proven() {
        assert_eq!(drifting(0.0, 30.0, noise).proven(), None);
        assert_eq!(drifting(0.01, 5.0, noise).proven(), None);
    }

    #[test]
    fn a_step_is_not_a_drift() {
        // The rotation steps by 3° halfway (a receiver's jump), with no drift.
        let step = |i: usize| noise(i) + if i >= 150 { 3f64.to_radians() } else { 0.0 };
        let d = drifting(0.0, 30.0, step);
        let (slope, _, chi2) = d.fit().expect("fit");
        assert!(slope.abs() > 1e-3, "the step reads as a slope");
        assert!(chi2 > MAX_REDUCED_CHI2);
        assert_eq!(d.proven(), None);
    }

    #[test]
    fn the_window_forgets_old_samples_and_restart_clears_them() {
        let mut d = drifting(0.002, 100.0, noise);
        assert!(d.len() <= 301, "{}", d.len());
        d.restart();
        assert!(d.is_empty());
        assert_eq!(d.proven(), None);
    }

    #[test]
    fn non_finite_or_out_of_order_samples_are_ignored() {
        let mut d = GyroDrift::default();
        d.observe(at(1.0), 0.1, 0.01, 0.0);
        d.observe(at(0.5), 0.1, 0.01, 0.0);
        d.observe(at(2.0), f64::NAN, 0.01, 0.0);
        d.observe(at(2.0), 0.1, 0.0, 0.0);
        assert_eq!(d.len(), 1);
    }
}
