//! The simulator's GNSS errors against a real receiver's: the Husky's SBAS fixes
//! (`../shared/data/ekf/husky-test1`) measured against the robot's own dead reckoning, and a
//! plant's error process at the same rate and quality, compared by their variograms (how far
//! the error moves in a given time) and their rate of steps.
//!
//! The data's error is each fix minus the wheels-and-gyro track (the gyro's bias taken from
//! the standstill), the track fitted to all the fixes by one rotation, scale and shift. Over
//! short lags that difference is the receiver's error; over minutes the track's own drift
//! adds to it, so the long lags bound the receiver's wander from above.

use serde::Serialize;

use super::husky::HuskyData;
use crate::devices::gnss::FixQuality;
use crate::sim::gnss_error::{GnssErrorProcess, normal};
use crate::sim::plant::PlantConfig;

/// The lags the variogram is compared at, in fixes of the data's 2.5 Hz (0.4 s to 40 s).
pub const LAGS: [usize; 7] = [1, 2, 5, 10, 25, 50, 100];
/// A step: the error moves this far within [`STEP_FIXES`] fixes, m.
const STEP_M: f64 = 2.0;
/// ... this many fixes (2 s at 2.5 Hz).
const STEP_FIXES: usize = 5;
/// Hours of the plant's process to measure.
const PLANT_HOURS: f64 = 20.0;

/// The two side by side.
#[derive(Debug, Clone, Serialize)]
pub struct ErrorFit {
    /// The lags, s.
    pub lags_s: Vec<f64>,
    /// The data's error: RMS change over each lag, per axis, m.
    pub data_m: Vec<f64>,
    /// The plant's (its DGPS quality), m.
    pub plant_m: Vec<f64>,
    /// Steps per hour in the data.
    pub data_steps_per_hour: f64,
    /// And in the plant.
    pub plant_steps_per_hour: f64,
}

/// The fit of `plant`'s DGPS error process to `data`.
pub fn fit(data: &HuskyData, plant: &PlantConfig, seed: u64) -> ErrorFit {
    let measured = data_errors(data);
    let dt = measured.windows(2).map(|w| w[1].0 - w[0].0).sum::<f64>()
        / measured.len().saturating_sub(1).max(1) as f64;
    let simulated = plant_errors(plant, dt, seed);
    let hours = |e: &[(f64, f64, f64)]| e.len() as f64 * dt / 3600.0;
    ErrorFit {
        lags_s: LAGS.iter().map(|&l| l as f64 * dt).collect(),
        data_m: variogram(&measured),
        plant_m: variogram(&simulated),
        data_steps_per_hour: steps(&measured) as f64 / hours(&measured),
        plant_steps_per_hour: steps(&simulated) as f64 / hours(&simulated),
    }
}

/// Each fix's error against the fitted dead reckoning: time, east, north.
pub fn data_errors(data: &HuskyData) -> Vec<(f64, f64, f64)> {
    let track = data.dead_reckoning();
    let fixes = data.fixes();
    // The track at each fix's time (linear between its samples).
    let mut pairs = Vec::with_capacity(fixes.len());
    let mut k = 0;
    for &(t, e, n) in &fixes {
        while k + 1 < track.len() && track[k + 1].0 < t {
            k += 1;
        }
        let (Some(a), Some(b)) = (track.get(k), track.get(k + 1)) else {
            continue;
        };
        let f = if b.0 > a.0 {
            ((t - a.0) / (b.0 - a.0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let p = (a.1 + f * (b.1 - a.1), a.2 + f * (b.2 - a.2));
        pairs.push((t, p, (e, n)));
    }
    // Least squares similarity: fix = s·R·track + c, as complex numbers w = a·z + c.
    let n = pairs.len().max(1) as f64;
    let mean = |points: &mut dyn Iterator<Item = (f64, f64)>| {
        let (x, y) = points.fold((0.0, 0.0), |s, v| (s.0 + v.0, s.1 + v.1));
        (x / n, y / n)
    };
    let zm = mean(&mut pairs.iter().map(|p| p.1));
    let wm = mean(&mut pairs.iter().map(|p| p.2));
    let (mut num_re, mut num_im, mut den) = (0.0, 0.0, 0.0);
    for (_, z, w) in &pairs {
        let (zx, zy) = (z.0 - zm.0, z.1 - zm.1);
        let (wx, wy) = (w.0 - wm.0, w.1 - wm.1);
        // Σ conj(z)·w and Σ |z|².
        num_re += zx * wx + zy * wy;
        num_im += zx * wy - zy * wx;
        den += zx * zx + zy * zy;
    }
    let (a_re, a_im) = if den > 0.0 {
        (num_re / den, num_im / den)
    } else {
        (1.0, 0.0)
    };
    pairs
        .iter()
        .map(|(t, z, w)| {
            let (zx, zy) = (z.0 - zm.0, z.1 - zm.1);
            let fitted = (a_re * zx - a_im * zy + wm.0, a_im * zx + a_re * zy + wm.1);
            (*t, w.0 - fitted.0, w.1 - fitted.1)
        })
        .collect()
}

/// `plant`'s DGPS error at one epoch per `dt` for [`PLANT_HOURS`], wild fixes left out (the
/// data has none).
fn plant_errors(plant: &PlantConfig, dt: f64, seed: u64) -> Vec<(f64, f64, f64)> {
    let g = plant.gnss;
    let faults = crate::sim::gnss_error::GnssFaults {
        wild_per_hour: 0.0,
        ..g.faults
    };
    let mut process = GnssErrorProcess::new(
        dt,
        g.correlated_fraction,
        (g.correlation_time_s, g.correlation_distance_m),
        faults,
        seed,
    );
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(seed);
    let epochs = (PLANT_HOURS * 3600.0 / dt) as usize;
    (0..epochs)
        .map(|i| {
            let e = process.epoch(
                FixQuality::Dgps,
                // The Husky's pace: about 1 m/s.
                dt,
                |q| plant.sigma(q),
                |s| normal(&mut rng, s),
            );
            (i as f64 * dt, e.offset.0, e.offset.1)
        })
        .collect()
}

/// The RMS change of the error over each of [`LAGS`], per axis, m.
pub fn variogram(errors: &[(f64, f64, f64)]) -> Vec<f64> {
    LAGS.iter()
        .map(|&lag| {
            let (sum, n) = errors
                .iter()
                .zip(errors.iter().skip(lag))
                .fold((0.0, 0usize), |(s, n), (a, b)| {
                    (s + (b.1 - a.1).powi(2) + (b.2 - a.2).powi(2), n + 1)
                });
            (sum / (2.0 * n.max(1) as f64)).sqrt()
        })
        .collect()
}

/// Steps: the error moving more than [`STEP_M`] within [`STEP_FIXES`] fixes, one count per
/// run of such moments.
fn steps(errors: &[(f64, f64, f64)]) -> usize {
    let mut count = 0;
    let mut in_step = false;
    for (a, b) in errors.iter().zip(errors.iter().skip(STEP_FIXES)) {
        let big = (b.1 - a.1).hypot(b.2 - a.2) > STEP_M;
        if big && !in_step {
            count += 1;
        }
        in_step = big;
    }
    count
}

impl std::fmt::Display for ErrorFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "| GNSS error: RMS change over a lag, per axis | {} | steps (> {STEP_M} m in {:.0} s) per hour |",
            self.lags_s
                .iter()
                .map(|l| format!("{l:.1} s"))
                .collect::<Vec<_>>()
                .join(" | "),
            self.lags_s.first().map_or(0.0, |l| l * STEP_FIXES as f64),
        )?;
        writeln!(f, "|---{}|---|", "|---".repeat(self.lags_s.len()))?;
        for (name, values, steps) in [
            ("Husky, SBAS fixes", &self.data_m, self.data_steps_per_hour),
            ("plant, DGPS", &self.plant_m, self.plant_steps_per_hour),
        ] {
            writeln!(
                f,
                "| {name} | {} | {steps:.0} |",
                values
                    .iter()
                    .map(|v| format!("{v:.2} m"))
                    .collect::<Vec<_>>()
                    .join(" | ")
            )?;
        }
        Ok(())
    }
}
