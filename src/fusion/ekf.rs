//! A planar extended Kalman filter on fixed-size matrices. State: x, y (m, local ENU), yaw
//! (rad, counter-clockwise from east), v (m/s forward), ω (rad/s), the gyro's z bias (rad/s)
//! with its rate of change (rad/s², temperature drift), the slowly wandering part of the
//! GNSS position error, east and north (m, a first-order Gauss–Markov process: multipath and
//! atmosphere change over tens of seconds, so averaging fixes cannot remove it), and the
//! wheels' scale error (the wheels read v·(1 + s): tyre wear, load and systematic slip, which
//! GNSS shows while it is there and which would otherwise grow into the drift of an outage).
//! Updates use the Joseph form, so the covariance stays symmetric and positive
//! definite, and report the innovation's Mahalanobis distance for gating.

use nalgebra::{SMatrix, SVector};
use std::f64::consts::PI;

/// State dimension.
pub const N: usize = 10;
/// Index of x.
pub const X: usize = 0;
/// Index of y.
pub const Y: usize = 1;
/// Index of yaw.
pub const YAW: usize = 2;
/// Index of forward speed.
pub const V: usize = 3;
/// Index of yaw rate.
pub const W: usize = 4;
/// Index of gyro bias.
pub const BIAS: usize = 5;
/// Index of the GNSS error, east.
pub const GNSS_E: usize = 6;
/// Index of the GNSS error, north.
pub const GNSS_N: usize = 7;
/// Index of the gyro bias's rate of change (a temperature drift), rad/s².
pub const BIAS_RATE: usize = 8;
/// Index of the wheels' scale error: they read the forward speed times (1 + this).
pub const SCALE: usize = 9;

/// State vector.
pub type State = SVector<f64, N>;
/// Covariance.
pub type Cov = SMatrix<f64, N, N>;

/// Wraps an angle into (-π, π].
pub fn wrap(a: f64) -> f64 {
    let mut a = a % (2.0 * PI);
    if a > PI {
        a -= 2.0 * PI;
    } else if a <= -PI {
        a += 2.0 * PI;
    }
    a
}

/// The 1σ along the major axis of a 2-D covariance (var x, var y, cov xy): the square root
/// of its largest eigenvalue.
pub fn largest_sigma(xx: f64, yy: f64, xy: f64) -> f64 {
    let mean = (xx + yy) / 2.0;
    let spread = (((xx - yy) / 2.0).powi(2) + xy * xy).sqrt();
    (mean + spread).max(0.0).sqrt()
}

/// Process noise densities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessNoise {
    /// Forward acceleration, m/s² per √s.
    pub accel: f64,
    /// Angular acceleration, rad/s² per √s.
    pub angular_accel: f64,
    /// Gyro bias random walk, rad/s per √s.
    pub bias_walk: f64,
    /// Random walk of the bias's rate of change, rad/s² per √s.
    pub bias_rate_walk: f64,
    /// Position diffusion (sideways slip), m per √s.
    pub position: f64,
    /// Position diffusion along the heading per unit of speed (random wheel slip that
    /// persists over many odometry samples), m per √s per m/s.
    pub position_per_speed: f64,
    /// Random walk of the wheels' scale error, per √s.
    pub scale_walk: f64,
    /// The GNSS error's correlation time, s.
    pub gnss_correlation_s: f64,
    /// The GNSS error's steady 1σ, east and north, m (set from the current fix quality).
    pub gnss_error: (f64, f64),
}

/// The result of one update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Innovation {
    /// Squared Mahalanobis distance of the innovation (normalised innovation squared).
    pub nis: f64,
    /// Whether it was applied (within the gate).
    pub applied: bool,
}

/// The filter.
#[derive(Debug, Clone, PartialEq)]
pub struct Ekf {
    /// State estimate.
    pub x: State,
    /// Covariance.
    pub p: Cov,
}

/// Entries of the transition's Jacobian that differ from the identity, at most.
const TRANSITION_ENTRIES: usize = 8;

/// A state transition's Jacobian that differs from the identity in a few entries.
#[derive(Debug, Clone, Copy, Default)]
struct Transition {
    entries: [(usize, usize, f64); TRANSITION_ENTRIES],
    len: usize,
}

impl Transition {
    /// Sets entry (`row`, `col`); each entry is set at most once, and at most
    /// [`TRANSITION_ENTRIES`] of them (the model's own, not an input's).
    fn set(&mut self, row: usize, col: usize, value: f64) {
        self.entries[self.len] = (row, col, value);
        self.len += 1;
    }

    fn diagonal(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.entries[..self.len]
            .iter()
            .filter(|(i, j, _)| i == j)
            .map(|&(i, _, v)| (i, v))
    }

    fn off_diagonal(&self) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
        self.entries[..self.len]
            .iter()
            .filter(|(i, j, _)| i != j)
            .copied()
    }

    /// F P Fᵀ by row and column operations: each row of F P is its diagonal entry times
    /// that row of P plus the off-diagonal terms, read from P as it was; then the same on
    /// the columns of F P.
    fn congruence(&self, p: &Cov) -> Cov {
        let mut fp = *p;
        for (i, v) in self.diagonal() {
            fp.row_mut(i).scale_mut(v);
        }
        for (i, j, v) in self.off_diagonal() {
            for k in 0..N {
                fp[(i, k)] += v * p[(j, k)];
            }
        }
        let mut fpf = fp;
        for (i, v) in self.diagonal() {
            fpf.column_mut(i).scale_mut(v);
        }
        for (i, j, v) in self.off_diagonal() {
            for k in 0..N {
                fpf[(k, i)] += v * fp[(k, j)];
            }
        }
        fpf
    }
}

impl Ekf {
    /// A filter at `x` with covariance `p`.
    pub fn new(x: State, p: Cov) -> Self {
        Self { x, p }
    }

    /// Propagates by `dt` seconds: constant speed and yaw rate along the heading.
    pub fn predict(&mut self, dt: f64, q: &ProcessNoise) {
        self.propagate(dt, q, true);
    }

    /// Propagates by `dt` seconds while the wheels stand still: the pose stays (no motion and
    /// no slip), while the speed, yaw rate, bias and GNSS error evolve as ever.
    pub fn predict_still(&mut self, dt: f64, q: &ProcessNoise) {
        self.propagate(dt, q, false);
    }

    fn propagate(&mut self, dt: f64, q: &ProcessNoise, moving: bool) {
        if dt <= 0.0 {
            return;
        }
        let (yaw, v, w) = (self.x[YAW], self.x[V], self.x[W]);
        let (s, c) = yaw.sin_cos();
        // The transition's Jacobian is the identity but for these entries (row, column,
        // value); the covariance follows them alone rather than through a dense product.
        let mut f = Transition::default();
        let mut qm = Cov::zeros();
        if moving {
            self.x[X] += v * c * dt;
            self.x[Y] += v * s * dt;
            self.x[YAW] = wrap(yaw + w * dt);
            f.set(X, YAW, -v * s * dt);
            f.set(X, V, c * dt);
            f.set(Y, YAW, v * c * dt);
            f.set(Y, V, s * dt);
            f.set(YAW, W, dt);
            // Wheel slip errs along the wheels' direction; across it only the vehicle's
            // sideways slip (slopes, skids) moves it.
            let along = (q.position + q.position_per_speed * v.abs()).powi(2) * dt;
            let across = q.position.powi(2) * dt;
            qm[(X, X)] = along * c * c + across * s * s;
            qm[(Y, Y)] = along * s * s + across * c * c;
            qm[(X, Y)] = (along - across) * s * c;
            qm[(Y, X)] = qm[(X, Y)];
        }
        self.x[BIAS] += self.x[BIAS_RATE] * dt;
        f.set(BIAS, BIAS_RATE, dt);
        let phi = (-dt / q.gnss_correlation_s.max(1e-3)).exp();
        f.set(GNSS_E, GNSS_E, phi);
        f.set(GNSS_N, GNSS_N, phi);
        self.x[GNSS_E] *= phi;
        self.x[GNSS_N] *= phi;
        qm[(V, V)] = q.accel.powi(2) * dt;
        qm[(W, W)] = q.angular_accel.powi(2) * dt;
        qm[(BIAS, BIAS)] = q.bias_walk.powi(2) * dt;
        qm[(BIAS_RATE, BIAS_RATE)] = q.bias_rate_walk.powi(2) * dt;
        qm[(SCALE, SCALE)] = q.scale_walk.powi(2) * dt;
        qm[(GNSS_E, GNSS_E)] = q.gnss_error.0.powi(2) * (1.0 - phi * phi);
        qm[(GNSS_N, GNSS_N)] = q.gnss_error.1.powi(2) * (1.0 - phi * phi);
        self.p = f.congruence(&self.p) + qm;
        self.symmetrise();
    }

    /// Forgets the GNSS error (a new fix quality, whose error is unrelated to the last):
    /// zero with 1σ `sigma` (east, north), uncorrelated with the rest.
    pub fn reset_gnss_error(&mut self, sigma: (f64, f64)) {
        for g in [GNSS_E, GNSS_N] {
            self.x[g] = 0.0;
            for i in 0..N {
                self.p[(i, g)] = 0.0;
                self.p[(g, i)] = 0.0;
            }
        }
        self.p[(GNSS_E, GNSS_E)] = sigma.0.powi(2);
        self.p[(GNSS_N, GNSS_N)] = sigma.1.powi(2);
    }

    /// A measurement update: `z` measured, `hx` predicted from the state, `h` its Jacobian,
    /// `r` its covariance. Components listed in `angles` are wrapped. Applied only when the
    /// normalised innovation squared is within `gate` (pass `f64::INFINITY` to always apply).
    pub fn update<const M: usize>(
        &mut self,
        z: &SVector<f64, M>,
        hx: &SVector<f64, M>,
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
        angles: &[usize],
        gate: f64,
    ) -> Innovation {
        self.update_except(z - hx, h, r, angles, gate, &[])
    }

    /// [`Ekf::update`] of the innovation `y` (measured minus predicted) that leaves the
    /// states in `kept` unchanged (their gain rows zeroed, as a Schmidt filter does): the
    /// Joseph form keeps the covariance right for any gain.
    pub fn update_except<const M: usize>(
        &mut self,
        mut y: SVector<f64, M>,
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
        angles: &[usize],
        gate: f64,
        kept: &[usize],
    ) -> Innovation {
        for &i in angles {
            y[i] = wrap(y[i]);
        }
        let s = h * self.p * h.transpose() + r;
        let Some(s_inv) = s.try_inverse() else {
            return Innovation {
                nis: f64::INFINITY,
                applied: false,
            };
        };
        let nis = (y.transpose() * s_inv * y)[(0, 0)];
        if nis.is_nan() || nis > gate {
            return Innovation {
                nis,
                applied: false,
            };
        }
        let mut k = self.p * h.transpose() * s_inv;
        for &i in kept {
            k.row_mut(i).fill(0.0);
        }
        self.x += k * y;
        self.x[YAW] = wrap(self.x[YAW]);
        // Joseph form: (I - KH) P (I - KH)ᵀ + K R Kᵀ.
        let i_kh = Cov::identity() - k * h;
        self.p = i_kh * self.p * i_kh.transpose() + k * r * k.transpose();
        self.symmetrise();
        Innovation { nis, applied: true }
    }

    fn symmetrise(&mut self) {
        for i in 0..N {
            for j in i + 1..N {
                let mean = (self.p[(i, j)] + self.p[(j, i)]) * 0.5;
                self.p[(i, j)] = mean;
                self.p[(j, i)] = mean;
            }
        }
    }

    /// The 1σ position uncertainty: the square root of the largest eigenvalue of the
    /// position covariance, m.
    pub fn position_sigma(&self) -> f64 {
        largest_sigma(self.p[(X, X)], self.p[(Y, Y)], self.p[(X, Y)])
    }

    /// The 1σ yaw uncertainty, rad.
    pub fn yaw_sigma(&self) -> f64 {
        self.p[(YAW, YAW)].max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q() -> ProcessNoise {
        ProcessNoise {
            accel: 0.5,
            angular_accel: 0.5,
            bias_walk: 1e-4,
            bias_rate_walk: 1e-6,
            position: 0.01,
            position_per_speed: 0.0,
            scale_walk: 1e-4,
            gnss_correlation_s: 30.0,
            gnss_error: (0.0, 0.0),
        }
    }

    proptest::proptest! {
        #[test]
        fn sparse_congruence_is_the_dense_product(
            values in proptest::collection::vec(-10.0f64..10.0, N * N),
            entries in proptest::collection::vec((0..N, 0..N, -3.0f64..3.0), 0..8),
        ) {
            let a = Cov::from_iterator(values);
            let p = a * a.transpose();
            let mut f = Transition::default();
            let mut dense = Cov::identity();
            let mut seen = std::collections::BTreeSet::new();
            for (i, j, v) in entries {
                if seen.insert((i, j)) {
                    f.set(i, j, v);
                    dense[(i, j)] = v;
                }
            }
            let want = dense * p * dense.transpose();
            let got = f.congruence(&p);
            let scale = want.amax().max(1.0);
            proptest::prop_assert!((got - want).amax() <= 1e-12 * scale, "{got} vs {want}");
        }
    }

    #[test]
    fn wraps_angles() {
        assert!((wrap(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap(-3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap(0.5) - 0.5).abs() < 1e-15);
        assert!((wrap(2.0 * PI + 0.1) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn predicts_along_the_heading() {
        let mut x = State::zeros();
        x[YAW] = PI / 2.0;
        x[V] = 2.0;
        let mut f = Ekf::new(x, Cov::identity() * 0.01);
        for _ in 0..100 {
            f.predict(0.01, &q());
        }
        assert!(f.x[X].abs() < 1e-9 && (f.x[Y] - 2.0).abs() < 1e-9);
        assert!(f.p[(Y, Y)] > 0.01, "uncertainty grows");
    }

    #[test]
    fn updates_keep_the_covariance_symmetric_positive_definite() {
        let mut f = Ekf::new(State::zeros(), Cov::identity() * 10.0);
        let mut h = SMatrix::<f64, 2, N>::zeros();
        h[(0, X)] = 1.0;
        h[(1, Y)] = 1.0;
        let r = SMatrix::<f64, 2, 2>::identity() * 1e-6;
        for i in 0..1000 {
            f.predict(0.1, &q());
            let z = SVector::<f64, 2>::new(f64::from(i) * 1e-3, 1.0);
            let hx = SVector::<f64, 2>::new(f.x[X], f.x[Y]);
            f.update(&z, &hx, &h, &r, &[], f64::INFINITY);
            assert_eq!(f.p, f.p.transpose());
            assert!(f.p.cholesky().is_some(), "not positive definite at {i}");
        }
        assert!((f.x[Y] - 1.0).abs() < 1e-3);
    }

    #[test]
    fn gate_rejects_outliers() {
        let mut f = Ekf::new(State::zeros(), Cov::identity() * 0.01);
        let mut h = SMatrix::<f64, 1, N>::zeros();
        h[(0, X)] = 1.0;
        let r = SMatrix::<f64, 1, 1>::new(0.01);
        let far = f.update(
            &SVector::<f64, 1>::new(5.0),
            &SVector::<f64, 1>::new(0.0),
            &h,
            &r,
            &[],
            10.83,
        );
        assert!(!far.applied && far.nis > 1000.0);
        assert_eq!(f.x[X], 0.0);
        let near = f.update(
            &SVector::<f64, 1>::new(0.1),
            &SVector::<f64, 1>::new(0.0),
            &h,
            &r,
            &[],
            10.83,
        );
        assert!(near.applied);
    }
}
