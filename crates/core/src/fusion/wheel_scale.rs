//! The wheels' scale against RTK: odometry distance per true distance (tyre wear, load and
//! systematic slip make the wheels read long or short). The moves divide their distance by
//! it once it is proven; the dead reckoning never uses it, so a wrong scale can never make
//! an outage worse.
//!
//! The fixes taken one after another form a chain of segments, each at least
//! [`MIN_SEGMENT_M`] long; the scale is the antenna's odom distance along the chain over its
//! GNSS distance, older segments fading. Consecutive segments share a fix, so along a straight
//! run the fixes' errors cancel but at the chain's two ends: the GNSS distance's variance is
//! Σ σₖ²·|wₖ₋₁uₖ₋₁ − wₖuₖ|² over the fixes, with uₖ the direction of segment k and wₖ its
//! weight. The wheels' random slip adds its variance per metre (`localization.
//! wheel_slip_m2_per_m`) times each segment's odom distance, weighted likewise. The scale is
//! proven once the chain holds at least [`MIN_SEGMENTS`] segments and its 1σ is within
//! [`PROVEN_SIGMA`].

use crate::time::Timestamp;

/// Fixes with a larger 1σ do not inform the scale, m (RTK only: a DGPS fix's metre of error
/// over a few metres of driving says nothing of a 0.5 % scale).
const MAX_FIX_SIGMA_M: f64 = 0.1;
/// A segment is at least this long, m.
pub const MIN_SEGMENT_M: f64 = 1.0;
/// Segments a proven scale rests on, at least.
pub const MIN_SEGMENTS: u32 = 5;
/// A proven scale's 1σ, at most.
pub const PROVEN_SIGMA: f64 = 0.003;
/// Each segment's weight relative to the next (older segments fade: tyres wear, loads change).
const FORGET: f64 = 0.995;
/// A scale further than this from 1 is not a wheel's (a lever arm or a frame gone wrong).
const MAX_ERROR: f64 = 0.1;

/// The end of the chain: its fix and the antenna's odom position there, the fix's 1σ, and
/// the last segment's direction (none before the first segment).
#[derive(Debug, Clone, Copy, PartialEq)]
struct ChainEnd {
    en: (f64, f64),
    antenna: (f64, f64),
    sigma: f64,
    direction: Option<(f64, f64)>,
}

/// The scale's estimator.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelScale {
    /// The wheels' random slip, m²/m.
    slip_per_m: f64,
    end: Option<ChainEnd>,
    /// Weighted odom and GNSS distances, m.
    sum_odom: f64,
    sum_gnss: f64,
    /// The GNSS distance's variance from every fix but the chain's end, m².
    var_inner: f64,
    /// The odom distance's variance from the random slip, m².
    var_slip: f64,
    segments: u32,
}

impl WheelScale {
    /// An estimator for wheels whose random slip has variance `slip_per_m` per metre, m²/m.
    pub fn new(slip_per_m: f64) -> Self {
        Self {
            slip_per_m: if slip_per_m.is_finite() {
                slip_per_m.max(0.0)
            } else {
                0.0
            },
            end: None,
            sum_odom: 0.0,
            sum_gnss: 0.0,
            var_inner: 0.0,
            var_slip: 0.0,
            segments: 0,
        }
    }

    /// A fix taken by the map filter at `_t`: east, north (m), its 1σ, and the antenna's
    /// position in the odom frame then.
    pub fn fix(&mut self, _t: Timestamp, en: (f64, f64), sigma: (f64, f64), antenna: (f64, f64)) {
        let s = sigma.0.max(sigma.1);
        if s > MAX_FIX_SIGMA_M || !s.is_finite() {
            self.break_chain();
            return;
        }
        let Some(end) = self.end else {
            self.end = Some(ChainEnd {
                en,
                antenna,
                sigma: s,
                direction: None,
            });
            return;
        };
        let (dx, dy) = (en.0 - end.en.0, en.1 - end.en.1);
        let g = dx.hypot(dy);
        if g < MIN_SEGMENT_M {
            return;
        }
        let o = (antenna.0 - end.antenna.0).hypot(antenna.1 - end.antenna.1);
        let u = (dx / g, dy / g);
        // The shared fix: the segment before it (faded once more) against this one.
        let (px, py) = end
            .direction
            .map_or((0.0, 0.0), |(x, y)| (FORGET * x, FORGET * y));
        self.var_inner = FORGET * FORGET * self.var_inner
            + end.sigma * end.sigma * ((px - u.0).powi(2) + (py - u.1).powi(2));
        self.var_slip = FORGET * FORGET * self.var_slip + self.slip_per_m * o;
        self.sum_odom = FORGET * self.sum_odom + o;
        self.sum_gnss = FORGET * self.sum_gnss + g;
        self.segments = self.segments.saturating_add(1);
        self.end = Some(ChainEnd {
            en,
            antenna,
            sigma: s,
            direction: Some(u),
        });
    }

    /// The chain ends at its last fix; the next fix starts a new one.
    fn break_chain(&mut self) {
        if let Some(ChainEnd {
            sigma,
            direction: Some(_),
            ..
        }) = self.end
        {
            self.var_inner += sigma * sigma;
        }
        self.end = None;
    }

    /// Odometry distance per true distance, and its 1σ, once any segment was measured.
    pub fn estimate(&self) -> Option<(f64, f64)> {
        if self.segments == 0 || self.sum_gnss <= 0.0 {
            return None;
        }
        let pending = match self.end {
            Some(ChainEnd {
                sigma,
                direction: Some(_),
                ..
            }) => sigma * sigma,
            _ => 0.0,
        };
        let scale = self.sum_odom / self.sum_gnss;
        let gnss = scale * scale * (self.var_inner + pending);
        let sigma = (gnss + self.var_slip).sqrt() / self.sum_gnss;
        Some((scale, sigma))
    }

    /// The scale once proven.
    pub fn proven(&self) -> Option<f64> {
        let (scale, sigma) = self.estimate()?;
        (self.segments >= MIN_SEGMENTS && sigma <= PROVEN_SIGMA && (scale - 1.0).abs() <= MAX_ERROR)
            .then_some(scale)
    }

    /// The fixes so far were in another frame: the next segment starts afresh.
    pub fn forget_fixes(&mut self) {
        self.break_chain();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t() -> Timestamp {
        Timestamp::from_micros(0)
    }

    #[test]
    fn eight_metres_of_rtk_prove_a_half_percent_scale() {
        let mut w = WheelScale::new(0.0);
        // Wheels read 0.5 % long; 1 cm fixes every 0.1 m with ±1 cm of error.
        for k in 0..=80 {
            let truth = k as f64 * 0.1;
            let err = if k % 3 == 0 { 0.01 } else { -0.01 };
            w.fix(t(), (truth + err, 0.0), (0.01, 0.01), (truth * 1.005, 0.0));
        }
        let (scale, sigma) = w.estimate().expect("estimated");
        assert!(sigma < PROVEN_SIGMA, "{sigma}");
        assert!((scale - 1.005).abs() < 3.0 * sigma, "{scale} ± {sigma}");
        assert!(w.proven().is_some());
    }

    #[test]
    fn a_zigzag_does_not_cancel_the_fixes_errors() {
        // Segments turning back and forth: each shared fix's error counts twice.
        let (mut straight, mut zigzag) = (WheelScale::new(0.0), WheelScale::new(0.0));
        for k in 0..=10 {
            let x = k as f64;
            straight.fix(t(), (x, 0.0), (0.01, 0.01), (x, 0.0));
            let y = if k % 2 == 0 { 0.0 } else { 1.0 };
            zigzag.fix(t(), (x, y), (0.01, 0.01), (x, y));
        }
        let (_, s) = straight.estimate().expect("estimated");
        let (_, z) = zigzag.estimate().expect("estimated");
        assert!(z > 2.0 * s, "straight {s}, zigzag {z}");
    }

    #[test]
    fn dgps_fixes_prove_nothing() {
        let mut w = WheelScale::new(0.0);
        for k in 0..200 {
            let truth = k as f64 * 0.5;
            w.fix(t(), (truth, 0.0), (0.8, 0.8), (truth * 1.005, 0.0));
        }
        assert_eq!(w.proven(), None);
    }

    /// Drives `metres` straight on wheels reading 0.65 % long with random slip of
    /// `slip_per_m`, under 1.5 cm RTK fixes every 0.2 m; the estimator after it.
    fn slipping_drive(seed: u64, metres: f64, slip_per_m: f64) -> WheelScale {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let unit = Normal::new(0.0, 1.0).expect("unit normal");
        let mut w = WheelScale::new(slip_per_m);
        let (step, mut odom) = (0.2, 0.0);
        for k in 0..=(metres / step) as u32 {
            let truth = k as f64 * step;
            if k > 0 {
                odom += step * 1.0065 + (slip_per_m * step).sqrt() * unit.sample(&mut rng);
            }
            let fix = truth + 0.015 * unit.sample(&mut rng);
            w.fix(t(), (fix, 0.0), (0.015, 0.015), (odom, 0.0));
        }
        w
    }

    #[test]
    fn random_slip_takes_more_metres_to_prove_and_the_sigma_it_claims_holds() {
        // 8 m prove the scale to 0.3 % when the wheels do not slip, not when they do.
        assert!(slipping_drive(1, 8.0, 0.0).proven().is_some());
        assert!(slipping_drive(1, 8.0, 1e-4).proven().is_none());
        // Over 200 drives of 40 m, the scale is proven and within 2σ of the truth in at
        // least 90 % of them (95 % expected).
        let within = (0..200)
            .filter(|&seed| {
                let w = slipping_drive(seed, 40.0, 1e-4);
                let (scale, sigma) = w.estimate().expect("estimated");
                assert!(w.proven().is_some(), "seed {seed}: ±{sigma}");
                (scale - 1.0065).abs() <= 2.0 * sigma
            })
            .count();
        assert!(within >= 180, "{within} of 200 within 2σ");
    }
}
