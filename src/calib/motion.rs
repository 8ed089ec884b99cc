//! The wheel radii, the track, the GNSS antenna's place and the dual-antenna heading offset,
//! fitted together from driving with RTK fixed.
//!
//! The yaw comes from the gyro, integrated over windows of 15 s or less (its bias drifts
//! too much for longer). Within a window the centre of the axle moves by what the wheels
//! say, each wheel's angle times its radius, along the gyro's yaw; the antenna sits at `a`
//! in the vehicle frame. A window's path is known up to where it starts and which way it
//! points, so each window gets a translation and a rotation of its own, and every window
//! shares the radii and the antenna:
//!
//! `p_i = c_k + R(φ_k) (r_l V_l(t_i) + r_r V_r(t_i) + R(ψ(t_i)) a)`
//!
//! with `V(t) = ∫ dθ/2 (cos ψ, sin ψ)`. For fixed rotations the model is linear in the
//! radii and the antenna; for fixed radii and antenna each window's rotation and
//! translation have a closed form. The two steps alternate until nothing changes. No path
//! needs to be straight: a miscalibrated vehicle's "straight" runs are arcs, and any
//! driving with enough turning and distance serves.
//!
//! The track follows from the yaw equation `r_r Δθ_r − r_l Δθ_l = T Δψ` over one-second
//! spans, dominated by the turns on the spot; the heading offset is the receiver's heading
//! less the fitted yaw, averaged over every heading inside a window.

use nalgebra::{DMatrix, DVector, Matrix2, Matrix2x4, UnitQuaternion, Vector2, Vector3, Vector4};

use super::data::{Dataset, FixPoint};
use super::{Refusal, refuse};
use crate::config::chassis::WheelRadius;
use crate::devices::gnss::FixQuality;

/// A window lasts at most this long, s (the gyro bias may walk 0.01°/s in minutes).
const WINDOW_S: f64 = 15.0;
/// A gap between fixes longer than this ends a window, s.
const MAX_FIX_GAP_S: f64 = 2.0;
/// A fix further than this from both its neighbours, beyond what the vehicle can drive in
/// between, disagrees with them (a wild fix a receiver still calls RTK fixed), m ...
const WILD_TOLERANCE_M: f64 = 0.5;
/// ... at this speed at most, m/s.
const WILD_MAX_SPEED: f64 = 5.0;
/// A window needs this many fixes ...
const MIN_WINDOW_FIXES: usize = 5;
/// ... and this much wheel travel, m, or this much turning, rad.
const MIN_WINDOW_TRAVEL_M: f64 = 0.3;
const MIN_WINDOW_TURN_RAD: f64 = 0.3;
/// The fit needs this much driving in RTK-fixed windows, s.
const MIN_DRIVING_S: f64 = 60.0;
/// Fits with a worse position residual (RMS per axis) are refused: slip or a bad fix, m.
const MAX_RESIDUAL_M: f64 = 0.05;
/// Gauss-Newton stops when no parameter moves more than this (m, rad).
const CONVERGED_M: f64 = 1e-10;
const MAX_ITERATIONS: usize = 50;
/// The track's yaw spans, s.
const TRACK_SPAN_S: f64 = 1.0;
/// The track's spans must turn this much in all, rad (a full turn each way is 12.6).
const MIN_TRACK_TURN_RAD: f64 = 6.0;
/// The fit is refused when the yaw equation's residual exceeds this fraction of the arcs.
const MAX_TRACK_RESIDUAL: f64 = 0.2;

/// What the fit gave.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionResult {
    /// Rolling radius of each wheel, m.
    pub radius: WheelRadius,
    /// Formal 1σ of each radius (white-noise assumption; correlated GNSS error makes the
    /// real one larger), m.
    pub radius_sigma: [f64; 2],
    /// Effective track, m.
    pub track_m: f64,
    /// Formal 1σ of the track, m.
    pub track_sigma_m: f64,
    /// The yaw equation's residual, fraction of the turning (RMS).
    pub track_residual: f64,
    /// Turning the track fit saw, rad.
    pub track_turn_rad: f64,
    /// Antenna in the vehicle frame (x forward, y left), m.
    pub antenna: [f64; 2],
    /// Formal 1σ of the antenna's x and y, m.
    pub antenna_sigma: [f64; 2],
    /// Receiver heading minus vehicle heading, degrees, when the receiver gives headings.
    pub heading_offset_deg: Option<f64>,
    /// Spread of the single heading differences (1σ), degrees, and how many.
    pub heading_spread_deg: f64,
    /// Headings averaged.
    pub headings: usize,
    /// RMS position residual per axis, m.
    pub residual_m: f64,
    /// Windows fitted.
    pub windows: usize,
    /// Fixes fitted.
    pub fixes: usize,
    /// Driving in the windows, s.
    pub driving_s: f64,
    /// Gauss-Newton rounds.
    pub iterations: usize,
    /// Each window's fit, for the plot: fix times, measured and fitted positions.
    pub fitted: Vec<FittedWindow>,
}

/// One window after the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedWindow {
    /// Measured antenna positions (east, north), m.
    pub measured: Vec<[f64; 2]>,
    /// The model's antenna positions, m.
    pub model: Vec<[f64; 2]>,
}

/// The gyro's yaw, integrated, and the wheel angles, both interpolated in time.
struct Tracks<'a> {
    data: &'a Dataset,
    /// IMU time and integrated yaw, rad.
    yaw: Vec<(f64, f64)>,
}

impl<'a> Tracks<'a> {
    /// The yaw integrated from the gyro, rotated into the vehicle frame by `mounting`, the
    /// sensor-frame `bias` taken off.
    fn new(data: &'a Dataset, bias: [f64; 3], mounting: UnitQuaternion<f64>) -> Self {
        let bias = Vector3::from(bias);
        let mut yaw = Vec::with_capacity(data.imu.len());
        let mut psi = 0.0;
        let mut last: Option<(f64, f64)> = None;
        for p in &data.imu {
            let wz = (mounting * (p.gyro - bias)).z;
            if let Some((t0, w0)) = last {
                psi += (w0 + wz) / 2.0 * (p.t - t0);
            }
            last = Some((p.t, wz));
            yaw.push((p.t, psi));
        }
        Self { data, yaw }
    }

    fn covers(&self, t: f64) -> bool {
        let imu = self.yaw.first().zip(self.yaw.last());
        let wheels = self.data.wheels.first().zip(self.data.wheels.last());
        matches!((imu, wheels), (Some((a, b)), Some((c, d))) if t >= a.0.max(c.t) && t <= b.0.min(d.t))
    }

    fn yaw_at(&self, t: f64) -> f64 {
        interpolate(&self.yaw, t, |p| p.0, |p| p.1)
    }

    fn wheels_at(&self, t: f64) -> (f64, f64) {
        let w = &self.data.wheels;
        (
            interpolate(w, t, |p| p.t, |p| p.left),
            interpolate(w, t, |p| p.t, |p| p.right),
        )
    }

    /// Wheel report times strictly inside `(t0, t1)`.
    fn wheel_times(&self, t0: f64, t1: f64) -> impl Iterator<Item = f64> + '_ {
        let w = &self.data.wheels;
        let start = w.partition_point(|p| p.t <= t0);
        w[start..].iter().map(|p| p.t).take_while(move |&t| t < t1)
    }
}

/// Linear interpolation in a time-sorted slice (held flat beyond its ends).
fn interpolate<T>(v: &[T], t: f64, time: impl Fn(&T) -> f64, value: impl Fn(&T) -> f64) -> f64 {
    let i = v.partition_point(|p| time(p) < t);
    match (i.checked_sub(1).and_then(|j| v.get(j)), v.get(i)) {
        (Some(a), Some(b)) => {
            let (ta, tb) = (time(a), time(b));
            if tb > ta {
                value(a) + (value(b) - value(a)) * (t - ta) / (tb - ta)
            } else {
                value(b)
            }
        }
        (None, Some(b)) => value(b),
        (Some(a), None) => value(a),
        (None, None) => 0.0,
    }
}

/// One fix in a window: what the model needs of it.
#[derive(Debug, Clone, Copy)]
struct Epoch {
    t: f64,
    p: Vector2<f64>,
    vl: Vector2<f64>,
    vr: Vector2<f64>,
    /// The gyro's yaw at the fix, rad.
    psi: f64,
}

#[derive(Debug, Clone)]
struct Window {
    epochs: Vec<Epoch>,
    /// The window's rotation, rad.
    phi: f64,
}

fn rotation(a: f64) -> Matrix2<f64> {
    let (s, c) = a.sin_cos();
    Matrix2::new(c, -s, s, c)
}

/// The RTK-fixed fixes, without those that disagree with both neighbours.
fn agreeing_fixes(fixes: &[FixPoint]) -> Vec<FixPoint> {
    let fixed: Vec<FixPoint> = fixes
        .iter()
        .filter(|f| f.quality == FixQuality::RtkFixed)
        .copied()
        .collect();
    let disagree = |a: &FixPoint, b: &FixPoint| {
        let reach = WILD_TOLERANCE_M + WILD_MAX_SPEED * (b.t - a.t).abs();
        (b.east - a.east).hypot(b.north - a.north) > reach
    };
    (0..fixed.len())
        .filter(|&i| {
            let f = &fixed[i];
            let before = i.checked_sub(1).and_then(|j| fixed.get(j));
            let after = fixed.get(i + 1);
            // Alone on a side, one disagreeing neighbour is enough.
            let wild = match (before, after) {
                (Some(b), Some(a)) => disagree(b, f) && disagree(f, a),
                (Some(n), None) | (None, Some(n)) => disagree(n, f),
                (None, None) => false,
            };
            !wild
        })
        .map(|i| fixed[i])
        .collect()
}

/// RTK-fixed fixes that agree with their neighbours, in runs without gaps, cut at
/// [`WINDOW_S`].
fn window_fixes(fixes: &[FixPoint], tracks: &Tracks) -> Vec<Vec<FixPoint>> {
    let mut windows: Vec<Vec<FixPoint>> = Vec::new();
    let mut current: Vec<FixPoint> = Vec::new();
    for f in agreeing_fixes(fixes).iter().filter(|f| tracks.covers(f.t)) {
        let breaks = current.last().is_some_and(|l| f.t - l.t > MAX_FIX_GAP_S)
            || current.first().is_some_and(|s| f.t - s.t > WINDOW_S);
        if breaks {
            windows.push(std::mem::take(&mut current));
        }
        current.push(*f);
    }
    windows.push(current);
    windows.retain(|w| w.len() >= MIN_WINDOW_FIXES);
    windows
}

/// The window's epochs with their wheel integrals, or `None` when it hardly moved.
fn build_window(fixes: &[FixPoint], tracks: &Tracks, mean_radius: f64) -> Option<Window> {
    let (first, last) = (fixes.first()?.t, fixes.last()?.t);
    let mut times: Vec<f64> = tracks.wheel_times(first, last).collect();
    times.extend(fixes.iter().map(|f| f.t));
    times.sort_by(f64::total_cmp);
    times.dedup();
    let (mut vl, mut vr) = (Vector2::zeros(), Vector2::zeros());
    let mut travel = 0.0;
    let mut previous = (first, tracks.wheels_at(first));
    let mut next_fix = fixes.iter().peekable();
    let mut epochs = Vec::with_capacity(fixes.len());
    for t in times {
        let wheels = tracks.wheels_at(t);
        let (dl, dr) = (wheels.0 - previous.1.0, wheels.1 - previous.1.1);
        let psi = tracks.yaw_at((t + previous.0) / 2.0);
        let dir = Vector2::new(psi.cos(), psi.sin());
        vl += dir * (dl / 2.0);
        vr += dir * (dr / 2.0);
        travel += (dl + dr).abs() / 2.0 * mean_radius;
        previous = (t, wheels);
        while let Some(f) = next_fix.next_if(|f| f.t <= t) {
            epochs.push(Epoch {
                t: f.t,
                p: Vector2::new(f.east, f.north),
                vl,
                vr,
                psi: tracks.yaw_at(f.t),
            });
        }
    }
    let turn = (tracks.yaw_at(last) - tracks.yaw_at(first)).abs();
    let moved = travel >= MIN_WINDOW_TRAVEL_M || turn >= MIN_WINDOW_TURN_RAD;
    (moved && epochs.len() >= MIN_WINDOW_FIXES).then_some(Window { epochs, phi: 0.0 })
}

/// The model's antenna positions of a window before its rotation and translation.
fn body_path(w: &Window, theta: &Vector4<f64>) -> Vec<Vector2<f64>> {
    let a = Vector2::new(theta[2], theta[3]);
    w.epochs
        .iter()
        .map(|e| e.vl * theta[0] + e.vr * theta[1] + rotation(e.psi) * a)
        .collect()
}

fn mean(v: &[Vector2<f64>]) -> Vector2<f64> {
    v.iter().sum::<Vector2<f64>>() / v.len().max(1) as f64
}

/// The rotation taking `model` onto `measured` best (both centred first).
fn best_rotation(model: &[Vector2<f64>], measured: &[Vector2<f64>]) -> f64 {
    let (mm, pm) = (mean(model), mean(measured));
    let (mut cross, mut dot) = (0.0, 0.0);
    for (w, p) in model.iter().zip(measured) {
        let (w, p) = (w - mm, p - pm);
        cross += w.x * p.y - w.y * p.x;
        dot += w.x * p.x + w.y * p.y;
    }
    cross.atan2(dot)
}

/// A fix's centred model before its window's rotation, `J θ` with `θ = (r_l, r_r, a_x,
/// a_y)`, and its centred position.
type Row = (Matrix2x4<f64>, Vector2<f64>);

/// A window's rows.
fn centred_rows(w: &Window) -> Vec<Row> {
    let n = w.epochs.len() as f64;
    let vl = w.epochs.iter().map(|e| e.vl).sum::<Vector2<f64>>() / n;
    let vr = w.epochs.iter().map(|e| e.vr).sum::<Vector2<f64>>() / n;
    let m = w
        .epochs
        .iter()
        .map(|e| rotation(e.psi))
        .sum::<Matrix2<f64>>()
        / n;
    let p = w.epochs.iter().map(|e| e.p).sum::<Vector2<f64>>() / n;
    w.epochs
        .iter()
        .map(|e| {
            let mut j = Matrix2x4::zeros();
            j.fixed_view_mut::<2, 1>(0, 0).copy_from(&(e.vl - vl));
            j.fixed_view_mut::<2, 1>(0, 1).copy_from(&(e.vr - vr));
            j.fixed_view_mut::<2, 2>(0, 2)
                .copy_from(&(rotation(e.psi) - m));
            (j, e.p - p)
        })
        .collect()
}

/// One second of the yaw equation: the wheels' angles and the gyro's turning.
#[derive(Debug, Clone, Copy)]
struct Span {
    left: f64,
    right: f64,
    turn: f64,
}

/// The yaw equation's spans over all the data.
fn yaw_spans(tracks: &Tracks) -> Vec<Span> {
    let (Some(first), Some(last)) = (tracks.yaw.first(), tracks.yaw.last()) else {
        return Vec::new();
    };
    let mut spans = Vec::new();
    let mut t = first.0;
    while t + TRACK_SPAN_S <= last.0 {
        let t1 = t + TRACK_SPAN_S;
        if tracks.covers(t) && tracks.covers(t1) {
            let (l0, r0) = tracks.wheels_at(t);
            let (l1, r1) = tracks.wheels_at(t1);
            spans.push(Span {
                left: l1 - l0,
                right: r1 - r0,
                turn: tracks.yaw_at(t1) - tracks.yaw_at(t),
            });
        }
        t = t1;
    }
    spans
}

/// Number of shared parameters: r_l, r_r, a_x, a_y, T.
const SHARED: usize = 5;

/// The joint problem: windows of positions and spans of the yaw equation.
struct Problem<'a> {
    /// Each window's rows and its number of fixes.
    windows: Vec<(Vec<Row>, usize)>,
    spans: &'a [Span],
}

/// Residual sums of a solution: positions (squared, count) and arcs (squared, count).
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    position: (f64, usize),
    arc: (f64, usize),
}

impl Problem<'_> {
    fn unknowns(&self) -> usize {
        SHARED + self.windows.len()
    }

    /// The weighted normal equations at `x`, and the residual sums.
    fn normal(&self, x: &DVector<f64>, weights: (f64, f64)) -> (DMatrix<f64>, DVector<f64>, Sums) {
        let n = self.unknowns();
        let (mut h, mut g) = (DMatrix::zeros(n, n), DVector::zeros(n));
        let mut sums = Sums::default();
        let theta = Vector4::new(x[0], x[1], x[2], x[3]);
        let quarter = Matrix2::new(0.0, -1.0, 1.0, 0.0);
        for (k, (rows, _)) in self.windows.iter().enumerate() {
            let col = SHARED + k;
            let r = rotation(x[col]);
            for (j, p) in rows {
                let model = r * (j * theta);
                let residual = p - model;
                sums.position.0 += residual.norm_squared();
                sums.position.1 += 2;
                // d residual / d θ = -R J, d residual / d φ = -R S J θ.
                let dtheta = -(r * j);
                let dphi = -(r * quarter * (j * theta));
                for row in 0..2 {
                    let mut jac = [0.0; SHARED + 1];
                    for c in 0..4 {
                        jac[c] = dtheta[(row, c)] * weights.0;
                    }
                    jac[SHARED] = dphi[row] * weights.0;
                    let res = residual[row] * weights.0;
                    let cols = [0, 1, 2, 3, col];
                    let vals = [jac[0], jac[1], jac[2], jac[3], jac[SHARED]];
                    for (a, &ca) in cols.iter().enumerate() {
                        g[ca] -= vals[a] * res;
                        for (b, &cb) in cols.iter().enumerate() {
                            h[(ca, cb)] += vals[a] * vals[b];
                        }
                    }
                }
            }
        }
        // The gyro's turning carries the slip the wheels do not see, so it is what the
        // wheels' arcs predict (`Δψ = u (r_r Δθ_r − r_l Δθ_l)` with `u = 1/T`): with the
        // turning as the predictor the slip would pull the track low.
        for s in self.spans {
            let arc = x[1] * s.right - x[0] * s.left;
            let residual = s.turn - x[4] * arc;
            sums.arc.0 += residual * residual;
            sums.arc.1 += 1;
            let jac = [x[4] * s.left, -x[4] * s.right, -arc].map(|v| v * weights.1);
            let cols = [0, 1, 4];
            let res = residual * weights.1;
            for (a, &ca) in cols.iter().enumerate() {
                g[ca] -= jac[a] * res;
                for (b, &cb) in cols.iter().enumerate() {
                    h[(ca, cb)] += jac[a] * jac[b];
                }
            }
        }
        (h, g, sums)
    }

    /// Gauss-Newton from `x` with the weights given; the rounds taken.
    fn solve(&self, x: &mut DVector<f64>, weights: (f64, f64)) -> Result<usize, Refusal> {
        for round in 1..=MAX_ITERATIONS {
            let (h, g, _) = self.normal(x, weights);
            let Some(step) = h.lu().solve(&g) else {
                return Err(refuse(
                    "the driving does not tell the radii, the track and the antenna apart",
                    "drive straight runs and turns on the spot both ways, as in the \
                     calibration pattern",
                ));
            };
            *x += &step;
            if step.amax() < CONVERGED_M {
                return Ok(round);
            }
        }
        Ok(MAX_ITERATIONS)
    }
}

/// Fits radii, antenna and track (starting from `radius`, `antenna` and `track`), then the
/// heading offset. `bias` and `mounting` turn the gyro into the vehicle's yaw rate.
pub fn fit(
    data: &Dataset,
    bias: [f64; 3],
    mounting: UnitQuaternion<f64>,
    radius: WheelRadius,
    antenna: [f64; 2],
    track: f64,
) -> Result<MotionResult, Refusal> {
    if data.wheels.is_empty() {
        return Err(refuse(
            "the data holds no wheel angles",
            "record with the drives connected (their encoders give the wheel angles)",
        ));
    }
    if data.imu.is_empty() {
        return Err(refuse(
            "the data holds no IMU samples",
            "record with the IMU connected: the yaw comes from its gyro",
        ));
    }
    let fixed = data
        .fixes
        .iter()
        .filter(|f| f.quality == FixQuality::RtkFixed)
        .count();
    if fixed * 2 < data.fixes.len() || fixed < MIN_WINDOW_FIXES {
        return Err(refuse(
            &format!(
                "RTK is not fixed: {fixed} of {} positions are RTK fixed",
                data.fixes.len()
            ),
            "drive where the receiver keeps RTK fixed (open sky, corrections arriving)",
        ));
    }
    let tracks = Tracks::new(data, bias, mounting);
    let mut windows: Vec<Window> = window_fixes(&data.fixes, &tracks)
        .iter()
        .filter_map(|f| build_window(f, &tracks, radius.mean()))
        .collect();
    let driving_s: f64 = windows
        .iter()
        .map(|w| w.epochs.last().map_or(0.0, |l| l.t) - w.epochs.first().map_or(0.0, |f| f.t))
        .sum();
    if driving_s < MIN_DRIVING_S {
        return Err(refuse(
            &format!(
                "the run is too short: {driving_s:.0} s of driving with RTK fixed, \
                 {MIN_DRIVING_S:.0} s are needed"
            ),
            "drive the calibration pattern (`chassisd sim --scenario calibration` shows it)",
        ));
    }
    let spans = yaw_spans(&tracks);
    let turn: f64 = spans.iter().map(|s| s.turn.abs()).sum();
    if turn < MIN_TRACK_TURN_RAD {
        return Err(refuse(
            &format!(
                "too little turning: {:.0}° in all, {:.0}° are needed",
                turn.to_degrees(),
                MIN_TRACK_TURN_RAD.to_degrees()
            ),
            "turn on the spot, a full turn each way",
        ));
    }
    // Each window's rotation starts where the configured values put it.
    let theta0 = Vector4::new(radius.left, radius.right, antenna[0], antenna[1]);
    for w in &mut windows {
        let model = body_path(w, &theta0);
        let measured: Vec<Vector2<f64>> = w.epochs.iter().map(|e| e.p).collect();
        w.phi = best_rotation(&model, &measured);
    }
    let problem = Problem {
        windows: windows
            .iter()
            .map(|w| (centred_rows(w), w.epochs.len()))
            .collect(),
        spans: &spans,
    };
    let mut x = DVector::zeros(problem.unknowns());
    x.rows_mut(0, SHARED).copy_from_slice(&[
        radius.left,
        radius.right,
        antenna[0],
        antenna[1],
        1.0 / track,
    ]);
    for (k, w) in windows.iter().enumerate() {
        x[SHARED + k] = w.phi;
    }
    // Weighted by each kind's own scatter: a first pass with typical figures (1 cm of
    // position, 0.01 rad of turning a second), then again with the scatter that pass left.
    let mut weights = (1.0 / 0.01, 1.0 / 0.01);
    let mut iterations = 0;
    for _ in 0..2 {
        iterations += problem.solve(&mut x, weights)?;
        let (_, _, sums) = problem.normal(&x, weights);
        let rms = |(sq, n): (f64, usize)| (sq / n.max(1) as f64).sqrt().max(1e-6);
        weights = (1.0 / rms(sums.position), 1.0 / rms(sums.arc));
    }
    let (h, _, sums) = problem.normal(&x, weights);
    let cov = h.try_inverse().unwrap_or_else(|| DMatrix::zeros(1, 1));
    let sd = |i: usize| cov.get((i, i)).map_or(f64::NAN, |v| v.sqrt());
    let residual_m = (sums.position.0 / sums.position.1.max(1) as f64).sqrt();
    if residual_m > MAX_RESIDUAL_M {
        return Err(refuse(
            &format!(
                "too much slip or a poor fix: the positions miss the wheels' path by \
                 {:.1} cm RMS",
                residual_m * 100.0
            ),
            "drive slower on firm, even ground with RTK fixed",
        ));
    }
    let turning: f64 = spans.iter().map(|s| s.turn * s.turn).sum();
    let track_residual = (sums.arc.0 / turning.max(1e-12)).sqrt();
    if track_residual > MAX_TRACK_RESIDUAL {
        return Err(refuse(
            &format!(
                "too much slip in the turns: the gyro's turning misses what the wheels' arcs \
                 predict by {:.0} %",
                track_residual * 100.0
            ),
            "turn on the spot slowly, on firm ground",
        ));
    }
    for (k, w) in windows.iter_mut().enumerate() {
        w.phi = x[SHARED + k];
    }
    let theta = Vector4::new(x[0], x[1], x[2], x[3]);
    let fitted = windows
        .iter()
        .map(|w| {
            let model = body_path(w, &theta);
            let r = rotation(w.phi);
            let measured: Vec<Vector2<f64>> = w.epochs.iter().map(|e| e.p).collect();
            let offset = mean(&measured) - r * mean(&model);
            FittedWindow {
                measured: measured.iter().map(|p| [p.x, p.y]).collect(),
                model: model
                    .iter()
                    .map(|m| {
                        let p = r * m + offset;
                        [p.x, p.y]
                    })
                    .collect(),
            }
        })
        .collect();
    let (heading_offset_deg, heading_spread_deg, headings) =
        heading_offset(data, &tracks, &windows);
    Ok(MotionResult {
        radius: WheelRadius {
            left: x[0],
            right: x[1],
        },
        radius_sigma: [sd(0), sd(1)],
        track_m: 1.0 / x[4],
        // σ(1/u) = σ(u) / u².
        track_sigma_m: sd(4) / (x[4] * x[4]),
        track_residual,
        track_turn_rad: turn,
        antenna: [x[2], x[3]],
        antenna_sigma: [sd(2), sd(3)],
        heading_offset_deg,
        heading_spread_deg,
        headings,
        residual_m,
        windows: windows.len(),
        fixes: problem.windows.iter().map(|w| w.1).sum(),
        driving_s,
        iterations,
        fitted,
    })
}

/// The receiver's heading less the fitted yaw over every heading inside a window: the
/// mean offset, degrees, the spread of single values and their count.
fn heading_offset(
    data: &Dataset,
    tracks: &Tracks,
    windows: &[Window],
) -> (Option<f64>, f64, usize) {
    let mut diffs = Vec::new();
    for w in windows {
        let (Some(first), Some(last)) = (w.epochs.first(), w.epochs.last()) else {
            continue;
        };
        let start = data.headings.partition_point(|h| h.t < first.t);
        for h in data.headings[start..].iter().take_while(|h| h.t <= last.t) {
            let yaw = tracks.yaw_at(h.t) + w.phi;
            let vehicle = 90.0 - yaw.to_degrees();
            diffs.push(wrap_deg(h.deg - vehicle));
        }
    }
    if diffs.is_empty() {
        return (None, 0.0, 0);
    }
    // Averaged about the median, so values either side of ±180° do not cancel.
    let mut sorted = diffs.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let n = diffs.len() as f64;
    let mean_dev = diffs.iter().map(|d| wrap_deg(d - median)).sum::<f64>() / n;
    let spread = (diffs
        .iter()
        .map(|d| (wrap_deg(d - median) - mean_dev).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    (Some(wrap_deg(median + mean_dev)), spread, diffs.len())
}

/// An angle in (−180°, 180°].
fn wrap_deg(a: f64) -> f64 {
    let w = a.rem_euclid(360.0);
    if w > 180.0 { w - 360.0 } else { w }
}

/// Rows of a window, for tests of the model.
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_holds_at_the_ends_and_is_linear_between() {
        let v = [(0.0, 0.0), (1.0, 2.0)];
        let f = |t| interpolate(&v, t, |p: &(f64, f64)| p.0, |p| p.1);
        assert_eq!(f(-1.0), 0.0);
        assert_eq!(f(0.25), 0.5);
        assert_eq!(f(3.0), 2.0);
    }

    #[test]
    fn the_best_rotation_undoes_a_rotation() {
        let model = vec![
            Vector2::new(0.0, 0.0),
            Vector2::new(1.0, 0.0),
            Vector2::new(1.0, 2.0),
        ];
        let measured: Vec<_> = model
            .iter()
            .map(|p| rotation(0.3) * p + Vector2::new(5.0, -2.0))
            .collect();
        assert!((best_rotation(&model, &measured) - 0.3).abs() < 1e-12);
    }

    #[test]
    fn a_wild_fix_is_dropped_and_its_neighbours_kept() {
        let fix = |t: f64, east: f64| FixPoint {
            t,
            east,
            north: 0.0,
            quality: FixQuality::RtkFixed,
        };
        let mut fixes: Vec<FixPoint> = (0..20)
            .map(|i| fix(f64::from(i) * 0.1, f64::from(i) * 0.1))
            .collect();
        fixes[7].east += 420.0;
        fixes[0].east -= 300.0;
        let kept = agreeing_fixes(&fixes);
        assert_eq!(kept.len(), 18);
        assert!(kept.iter().all(|f| f.east.abs() < 2.0));
    }

    #[test]
    fn angles_wrap_into_a_half_turn_either_side() {
        assert_eq!(wrap_deg(190.0), -170.0);
        assert_eq!(wrap_deg(-190.0), 170.0);
        assert_eq!(wrap_deg(180.0), 180.0);
    }
}
