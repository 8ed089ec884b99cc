//! The simulated receiver's position error, with the processes real receivers show
//! (fitted on the Husky's SBAS log in `../shared/data/ekf/husky-test1`; docs/fusion.md's
//! section on the simulator's GNSS errors gives the fit):
//!
//! - a slow first-order Gauss-Markov wander, kept at unit variance and scaled by the current
//!   quality's σ and correlated fraction, so a change of fix quality changes the error at
//!   once, as on a receiver;
//! - the receiver's own smoothing of that wander, which makes it smooth over a few fixes;
//! - white noise on top;
//! - steps of the DGPS and single-point solution (a change of satellites or corrections),
//!   which then wander off with the slow part;
//! - RTK-float episodes while RTK fixed is possible;
//! - rare wild fixes hundreds of metres off, one fix each.
//!
//! The events draw from their own generator, so a plant without them draws the same numbers
//! as before they existed.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::devices::gnss::FixQuality;

/// The index of `q` in per-quality arrays: RTK fixed, float, DGPS, anything else (single).
pub(crate) fn quality_index(q: FixQuality) -> usize {
    match q {
        FixQuality::RtkFixed => 0,
        FixQuality::RtkFloat => 1,
        FixQuality::Dgps => 2,
        _ => 3,
    }
}

/// A value per fix quality (RTK fixed, float, DGPS, single), or one for all.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum PerQuality {
    /// The same for every quality.
    All(f64),
    /// RTK fixed, float, DGPS, single.
    Each([f64; 4]),
}

impl PerQuality {
    /// The value at `q`.
    pub fn at(&self, q: FixQuality) -> f64 {
        match self {
            Self::All(v) => *v,
            Self::Each(v) => v[quality_index(q)],
        }
    }

    /// Every value.
    pub fn values(&self) -> [f64; 4] {
        match self {
            Self::All(v) => [*v; 4],
            Self::Each(v) => *v,
        }
    }
}

/// `[gnss.faults]`: the receiver's error events. Every rate defaults to zero (none).
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct GnssFaults {
    /// The receiver's smoothing of its slow error, time constant s (0: none).
    pub smoothing_s: f64,
    /// Steps of a DGPS or single-point solution, per hour.
    pub steps_per_hour: f64,
    /// Their size, m (each between 0.5 and 1.5 times this, in any direction).
    pub step_m: f64,
    /// RTK-float episodes while RTK fixed is possible, per hour.
    pub float_per_hour: f64,
    /// Their mean length, s (exponentially distributed).
    pub float_s: f64,
    /// Wild fixes, per hour: one fix far off, with its usual quality and σ.
    pub wild_per_hour: f64,
    /// How far off, m: uniform between the two.
    pub wild_m: [f64; 2],
    /// How late the receiver's velocity (speed and course) is beyond its latency, s: a
    /// plain receiver's Doppler filter or position differences lag the motion by 0.1–0.5 s.
    pub velocity_lag_s: f64,
    /// Its smoothing of the velocity, time constant s (0: none).
    pub velocity_smoothing_s: f64,
}

/// One epoch's error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpochError {
    /// The quality the receiver reports (RTK fixed may have dropped to float).
    pub quality: FixQuality,
    /// East, north, m.
    pub offset: (f64, f64),
    /// Whether this is a wild fix.
    pub wild: bool,
}

/// The error state between epochs.
#[derive(Debug, Clone)]
pub struct GnssErrorProcess {
    /// Epoch interval, s.
    dt: f64,
    correlated_fraction: PerQuality,
    correlation_time_s: f64,
    /// The slow part of corrected fixes (DGPS, RTK) decorrelates over this distance too, m.
    correlation_distance_m: Option<f64>,
    faults: GnssFaults,
    /// The slow part, unit variance per axis.
    slow: (f64, f64),
    /// The slow part after the receiver's smoothing.
    smoothed: (f64, f64),
    /// Time left in an RTK-float episode, s.
    float_left_s: f64,
    events: ChaCha8Rng,
}

impl GnssErrorProcess {
    /// A process for epochs every `dt` seconds; `seed` drives the events.
    pub fn new(
        dt: f64,
        correlated_fraction: PerQuality,
        (correlation_time_s, correlation_distance_m): (f64, Option<f64>),
        faults: GnssFaults,
        seed: u64,
    ) -> Self {
        Self {
            dt,
            correlated_fraction,
            correlation_time_s,
            correlation_distance_m,
            faults,
            slow: (0.0, 0.0),
            smoothed: (0.0, 0.0),
            float_left_s: 0.0,
            // Its own stream: a different seed from the plant's noise.
            events: ChaCha8Rng::seed_from_u64(seed ^ 0x9E37_79B9_7F4A_7C15),
        }
    }

    /// The next epoch's error at `quality`, whose σ per axis `sigma_of` gives, the antenna
    /// having moved `moved_m` since the last. `noise` draws a normal number of a σ from the
    /// plant's generator (the slow and white parts).
    pub fn epoch(
        &mut self,
        quality: FixQuality,
        moved_m: f64,
        sigma_of: impl Fn(FixQuality) -> f64,
        mut noise: impl FnMut(f64) -> f64,
    ) -> EpochError {
        let quality = self.quality(quality);
        let sigma = sigma_of(quality);
        let by_distance = match self.correlation_distance_m {
            Some(d) if quality.is_corrected() && d > 0.0 => moved_m.max(0.0) / d,
            _ => 0.0,
        };
        let phi = (-self.dt / self.correlation_time_s - by_distance).exp();
        let drive = (1.0 - phi * phi).sqrt();
        self.slow = (
            phi * self.slow.0 + noise(drive),
            phi * self.slow.1 + noise(drive),
        );
        let f = self.faults;
        if matches!(quality, FixQuality::Dgps | FixQuality::Single)
            && sigma > 0.0
            && self.happens(f.steps_per_hour)
        {
            let size = f.step_m * self.events.random_range(0.5..=1.5) / sigma;
            let (e, n) = self.direction();
            self.slow = (self.slow.0 + size * e, self.slow.1 + size * n);
        }
        let a = if f.smoothing_s > 0.0 {
            (-self.dt / f.smoothing_s).exp()
        } else {
            0.0
        };
        self.smoothed = (
            a * self.smoothed.0 + (1.0 - a) * self.slow.0,
            a * self.smoothed.1 + (1.0 - a) * self.slow.1,
        );
        let fraction = self.correlated_fraction.at(quality);
        let sc = sigma * fraction;
        let white = sigma * (1.0 - fraction.powi(2)).max(0.0).sqrt();
        let mut offset = (
            sc * self.smoothed.0 + noise(white),
            sc * self.smoothed.1 + noise(white),
        );
        let wild = self.happens(f.wild_per_hour);
        if wild {
            let [low, high] = f.wild_m;
            let distance = if high > low {
                self.events.random_range(low..=high)
            } else {
                low
            };
            let (e, n) = self.direction();
            offset = (offset.0 + distance * e, offset.1 + distance * n);
        }
        EpochError {
            quality,
            offset,
            wild,
        }
    }

    /// RTK fixed drops to float for an episode now and then.
    fn quality(&mut self, quality: FixQuality) -> FixQuality {
        if quality != FixQuality::RtkFixed {
            self.float_left_s = 0.0;
            return quality;
        }
        if self.float_left_s <= 0.0 && self.happens(self.faults.float_per_hour) {
            // Exponential length: −ln(U) times the mean.
            let u: f64 = self.events.random_range(f64::EPSILON..1.0);
            self.float_left_s = -u.ln() * self.faults.float_s;
        }
        if self.float_left_s > 0.0 {
            self.float_left_s -= self.dt;
            FixQuality::RtkFloat
        } else {
            quality
        }
    }

    /// Whether an event of `per_hour` happens in this epoch.
    fn happens(&mut self, per_hour: f64) -> bool {
        per_hour > 0.0
            && self
                .events
                .random_bool((per_hour * self.dt / 3600.0).min(1.0))
    }

    fn direction(&mut self) -> (f64, f64) {
        let angle: f64 = self.events.random_range(0.0..std::f64::consts::TAU);
        (angle.cos(), angle.sin())
    }
}

/// A normal number of σ `sigma` from `rng` (0 for σ ≤ 0).
pub fn normal(rng: &mut ChaCha8Rng, sigma: f64) -> f64 {
    if sigma <= 0.0 {
        return 0.0;
    }
    Normal::new(0.0, sigma).map_or(0.0, |n| n.sample(rng))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sigma_of(q: FixQuality) -> f64 {
        match q {
            FixQuality::RtkFixed => 0.01,
            FixQuality::RtkFloat => 0.25,
            FixQuality::Dgps => 1.9,
            _ => 2.5,
        }
    }

    fn run(faults: GnssFaults, quality: FixQuality, epochs: usize) -> Vec<EpochError> {
        let mut p = GnssErrorProcess::new(0.4, PerQuality::All(0.99), (20.0, None), faults, 7);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        (0..epochs)
            .map(|_| p.epoch(quality, 0.0, sigma_of, |s| normal(&mut rng, s)))
            .collect()
    }

    #[test]
    fn without_faults_the_error_has_the_quality_sigma() {
        let e = run(GnssFaults::default(), FixQuality::Dgps, 200_000);
        let var = e.iter().map(|e| e.offset.0.powi(2)).sum::<f64>() / e.len() as f64;
        assert!((var.sqrt() - 1.9).abs() < 0.15, "σ {}", var.sqrt());
        assert!(e.iter().all(|e| !e.wild && e.quality == FixQuality::Dgps));
    }

    #[test]
    fn float_episodes_take_their_share_of_rtk_fixed() {
        let faults = GnssFaults {
            float_per_hour: 6.0,
            float_s: 20.0,
            ..GnssFaults::default()
        };
        // 100 hours at 2.5 Hz: 600 episodes of 20 s on average, 3.3 % of the time.
        let e = run(faults, FixQuality::RtkFixed, 900_000);
        let float = e
            .iter()
            .filter(|e| e.quality == FixQuality::RtkFloat)
            .count();
        let share = float as f64 / e.len() as f64;
        assert!((0.025..0.045).contains(&share), "float share {share}");
        // Below RTK fixed, no episodes.
        let e = run(faults, FixQuality::Dgps, 10_000);
        assert!(e.iter().all(|e| e.quality == FixQuality::Dgps));
    }

    #[test]
    fn wild_fixes_are_single_and_far() {
        let faults = GnssFaults {
            wild_per_hour: 10.0,
            wild_m: [100.0, 1000.0],
            ..GnssFaults::default()
        };
        let e = run(faults, FixQuality::RtkFixed, 90_000);
        let wild: Vec<_> = e.iter().enumerate().filter(|(_, e)| e.wild).collect();
        // 10 hours: about 100.
        assert!((60..140).contains(&wild.len()), "{} wild fixes", wild.len());
        for (i, w) in &wild {
            let d = w.offset.0.hypot(w.offset.1);
            assert!((99.0..1001.0).contains(&d), "{d} m");
            // The next fix is back where it belongs.
            if let Some(next) = e.get(i + 1).filter(|n| !n.wild) {
                assert!(next.offset.0.hypot(next.offset.1) < 0.1);
            }
        }
    }

    #[test]
    fn steps_move_dgps_but_never_rtk() {
        let faults = GnssFaults {
            steps_per_hour: 360.0,
            step_m: 3.0,
            smoothing_s: 2.0,
            ..GnssFaults::default()
        };
        let largest_change = |e: &[EpochError]| {
            e.windows(6)
                .map(|w| (w[5].offset.0 - w[0].offset.0).hypot(w[5].offset.1 - w[0].offset.1))
                .fold(0.0, f64::max)
        };
        let dgps = run(faults, FixQuality::Dgps, 9000);
        let quiet = run(GnssFaults::default(), FixQuality::Dgps, 9000);
        assert!(largest_change(&dgps) > largest_change(&quiet) + 1.0);
        let fixed = run(faults, FixQuality::RtkFixed, 9000);
        assert!(largest_change(&fixed) < 0.05);
    }
}
