//! The map frame of REP-105 stood on the `odom` frame: the map pose is the odom pose carried
//! by a map→odom correction, and GNSS estimates that correction.
//!
//! - The state is the map pose (x, y, yaw) and the slowly wandering part of the GNSS error
//!   (east, north). It moves only by the odom frame's increments: between fixes, and through
//!   an outage, the map pose moves exactly as the odom pose does, so its drift is the odom
//!   frame's. The increments' uncertainty grows with the distance driven and the angle turned
//!   (and with time while moving, for the gyro's bias), never while the wheels stand still.
//! - A fix is taken only when it agrees with a neighbour: the displacement between two fixes
//!   must match the odom frame's between their times, within their noise and the wheels' slip.
//!   A fix that disagrees with the run before it is held; it is taken once enough later fixes
//!   agree with it (a relocation starts from them all), and dropped otherwise. A lone wild fix
//!   is never taken, at any time.
//! - RTK fixed fixes that agree with each other are believed over the wheels: when they fail
//!   the filter's gate the wheels slipped, and the position's uncertainty is widened until
//!   they pass. Fixes of a lesser quality (RTK float, DGPS, SBAS, single) that step away
//!   together are a new realisation of their slow error, which the GNSS-error state absorbs,
//!   so a step turns neither the heading nor anything the dead reckoning uses.
//! - With one antenna and no course the heading comes from the motion between fixes: the odom
//!   path is fitted to the agreeing fixes (a rigid 2-D fit) once they span enough distance
//!   against their σ.
//! - Late fixes are placed through the odom frame's recorded poses: no rewinding.

use std::collections::VecDeque;
use std::time::Duration;

use nalgebra::{SMatrix, SVector};

use super::odometry::OdomPose;
use super::planar::{largest_sigma, wrap};
use crate::time::Timestamp;

const N: usize = 7;
const X: usize = 0;
const Y: usize = 1;
const YAW: usize = 2;
const GE: usize = 3;
const GN: usize = 4;
/// The odom heading's drift rate (the gyro bias's error since it was last learnt), rad/s: a
/// consider state. Its mean stays zero (the map pose never turns by it, so in an outage it
/// moves exactly as the odom pose does); its variance makes the heading's uncertainty grow as
/// a bias error turns it, with the correlation that implies.
const DRIFT: usize = 5;
/// The wheels' scale error: the true distance is (1 + it) times the odom frame's. Tyres'
/// radii change with pressure, load and wear and slip with the ground, by percents, and at
/// speed that is metres a minute; GNSS shows it over the distance driven.
const SCALE: usize = 6;
/// The scale error's 1σ before anything has shown it.
const SCALE_SIGMA: f64 = 0.03;
/// A scale error beyond this is no tyre's: a wrong radius in the configuration.
const MAX_SCALE_ERROR: f64 = 0.2;

type State = SVector<f64, N>;
type Cov = SMatrix<f64, N, N>;

/// χ² gate, 2 degrees of freedom, 99.9 %.
const GATE_2: f64 = 13.82;
/// χ² gate, 1 degree of freedom, 99.9 %.
const GATE_1: f64 = 10.83;
/// The heading's 1σ before anything has shown it, rad.
const UNKNOWN_YAW_SIGMA: f64 = std::f64::consts::PI;
/// The fit of the odom path to the fixes sets the heading once its 1σ is within this, rad.
const FIT_YAW_SIGMA: f64 = 0.1;
/// A heading within this 1σ is known: fixes inform it, and the direction of the motion
/// between two fixes is checked, not only its length; a heading or course sets a heading
/// less certain than this outright, rad.
const HEADING_KNOWN_RAD: f64 = 0.3;
/// Fixes a heading fit keeps (the latest ones), bounding its memory.
const FIT_FIXES: usize = 256;
/// Odom poses kept to place late fixes.
const ODOM_HISTORY: usize = 1024;
/// A held run of fixes is taken once it has this many (and, when it jumped away from the
/// accepted run, once it has lasted `relocate_after`: wheels cannot slip metres between two
/// fixes, so a jump is the receiver's until it persists).
pub const MIN_RUN: usize = 3;
/// Fixes a held run keeps (the latest), bounding its memory at any rate.
const MAX_HELD: usize = 256;
/// Two fixes agree when their displacement matches the odom frame's within this χ²
/// (2 degrees of freedom, 99.99 %) ...
const AGREE_GATE: f64 = 18.4;
/// ... where the wheels may have slipped by this fraction of the distance between them ...
const SLIP_FRACTION: f64 = 0.1;
/// ... and the odom frame's heading may have turned by this much per second between them, rad
/// (an unknown gyro bias).
const AGREE_YAW_RATE: f64 = 0.01;

/// How far a fix of one quality is trusted over the wheels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trust {
    /// RTK fixed: when such fixes agree with each other and not with the filter, the wheels
    /// slipped.
    OverWheels,
    /// RTK float, DGPS, SBAS or single point: fixes that step away together stepped in their
    /// slow error (a float solution's ambiguities move it by decimetres at a time).
    UnderWheels,
}

/// Settings of the map filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapFilterConfig {
    /// GNSS antenna in the vehicle frame (x forward, y left), m.
    pub antenna: (f64, f64),
    /// Odom distance error, variance per metre driven along the heading, m²/m.
    pub along_per_m: f64,
    /// The same across the heading (sideways slip), m²/m.
    pub across_per_m: f64,
    /// Odom heading error, variance per radian turned, rad²/rad.
    pub yaw_per_rad: f64,
    /// Odom heading error, variance per second while moving (the gyro's angle random walk),
    /// rad²/s.
    pub yaw_per_s: f64,
    /// The gyro bias's random walk, rad/s per √s: how fast the bias leaves what the last
    /// standstill taught.
    pub bias_walk: f64,
    /// How fast the wheels' scale may change, 1σ per √m driven (the ground changes under
    /// a mower; a car's tyres on asphalt change with temperature and wear only).
    pub scale_walk: f64,
    /// The slowly wandering part of a fix's error, as a fraction of its 1σ (RTK float, DGPS,
    /// SBAS, single: SBAS wanders almost wholly, the Husky shows).
    pub gnss_correlated_fraction: f64,
    /// The same for RTK-fixed fixes (multipath).
    pub rtk_correlated_fraction: f64,
    /// That part's correlation time, s: how long it lasts while the antenna stands.
    pub gnss_correlation_s: f64,
    /// That part's correlation distance, m: multipath and the corrections' errors
    /// decorrelate as the antenna moves, so it lasts `exp(-dt/time - ds/distance)`.
    pub gnss_correlation_m: f64,
    /// Fixes disagreeing with the filter for this long (and at least [`MIN_RUN`] of them,
    /// agreeing with each other) mean the vehicle is elsewhere, whatever their quality.
    pub relocate_after: Duration,
}

impl MapFilterConfig {
    /// How much of the slow error is left after `dt` seconds and, for a corrected fix, `ds`
    /// metres of the antenna's travel.
    pub fn slow_correlation(&self, dt: f64, ds: f64, corrected: bool) -> f64 {
        let moved = if corrected {
            ds.max(0.0) / self.gnss_correlation_m.max(1e-3)
        } else {
            0.0
        };
        (-dt.max(0.0) / self.gnss_correlation_s.max(1e-3) - moved).exp()
    }

    /// The slow fraction of a fix's error, by how far it is trusted (RTK fixed or not).
    pub fn slow_fraction(&self, trust: Trust) -> f64 {
        match trust {
            Trust::OverWheels => self.rtk_correlated_fraction,
            Trust::UnderWheels => self.gnss_correlated_fraction,
        }
    }
}

impl Default for MapFilterConfig {
    fn default() -> Self {
        Self {
            antenna: (0.0, 0.0),
            along_per_m: 1e-2,
            across_per_m: 4e-3,
            yaw_per_rad: 4e-4,
            yaw_per_s: 2e-5,
            bias_walk: 2e-5,
            scale_walk: 1e-3,
            gnss_correlated_fraction: 0.95,
            rtk_correlated_fraction: 0.3,
            gnss_correlation_s: 60.0,
            gnss_correlation_m: 20.0,
            relocate_after: Duration::from_secs(3),
        }
    }
}

/// One GNSS position fix of the antenna, in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fix {
    /// The epoch it describes.
    pub t: Timestamp,
    /// East, north, m.
    pub en: (f64, f64),
    /// 1σ east, north, m.
    pub sigma: (f64, f64),
    /// How far it is trusted over the wheels.
    pub trust: Trust,
    /// Whether differential corrections shaped it (DGPS/SBAS, RTK): what is left of its slow
    /// error is their residuals and multipath, which change as the antenna moves. An
    /// uncorrected fix's slow error is the atmosphere's and the satellites' orbits and
    /// clocks, which only time changes.
    pub corrected: bool,
}

/// What became of a fix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FixOutcome {
    /// Applied (with the fixes it released, if any).
    Taken,
    /// Held until later fixes agree with it.
    Held,
    /// Not a position (not finite): counted and dropped.
    Dropped,
    /// Before the first odom pose: nothing to place it on.
    NoOdom,
}

/// Counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MapFilterStats {
    /// Fixes applied.
    pub taken: u64,
    /// Fixes dropped for disagreeing with their neighbours.
    pub dropped: u64,
    /// Agreeing fixes that failed the filter's gate and widened it (wheels slipped, or a
    /// relocation).
    pub widened: u64,
    /// Headings or courses applied.
    pub headings: u64,
    /// Headings or courses rejected by the gate.
    pub headings_rejected: u64,
    /// Heading fits of the odom path to the fixes.
    pub fits: u64,
}

/// A fix with the odom pose at its time.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Placed {
    fix: Fix,
    odom: OdomPose,
}

/// The map filter.
#[derive(Debug, Clone)]
pub struct MapFilter {
    config: MapFilterConfig,
    x: State,
    p: Cov,
    started: bool,
    /// The odom pose the state stands on, and its time.
    odom: Option<(Timestamp, OdomPose)>,
    history: VecDeque<(Timestamp, OdomPose)>,
    /// The last fix taken.
    last_accepted: Option<Placed>,
    /// Fixes that disagreed with the last accepted one, agreeing among themselves.
    held: Vec<Placed>,
    /// A fix that disagreed with the held run, until the next shows which was wrong.
    stray: Option<Placed>,
    /// Accepted fixes for a heading fit, while the heading is unknown.
    fit: VecDeque<Placed>,
    /// Agreeing fixes that failed the gate without a break: first time and count.
    disagreeing: Option<(Timestamp, u32)>,
    last_sigma: Option<f64>,
    /// The heading random walk that stands for the odom heading's drift measured but not yet
    /// corrected, rad²/s.
    drift_walk: f64,
    /// The gyro bias's walk (rad²/s³) shown by the last proven drift, when faster than the
    /// configured one.
    shown_bias_walk: f64,
    /// Sum and count of the fixes' normalised innovations squared (2 DOF), to check the
    /// noise model: their mean is 2 when it is right.
    nis: (f64, u64),
    stats: MapFilterStats,
    events: Vec<String>,
}

impl MapFilter {
    /// A filter with nothing known.
    pub fn new(config: MapFilterConfig) -> Self {
        Self {
            config,
            x: State::zeros(),
            p: {
                let mut p = Cov::zeros();
                p[(SCALE, SCALE)] = SCALE_SIGMA * SCALE_SIGMA;
                p
            },
            started: false,
            odom: None,
            history: VecDeque::new(),
            last_accepted: None,
            held: Vec::new(),
            stray: None,
            fit: VecDeque::new(),
            disagreeing: None,
            last_sigma: None,
            drift_walk: 0.0,
            shown_bias_walk: 0.0,
            nis: (0.0, 0),
            stats: MapFilterStats::default(),
            events: Vec::new(),
        }
    }

    /// Counters.
    pub fn stats(&self) -> MapFilterStats {
        self.stats
    }

    /// The fixes' mean normalised innovation squared per degree of freedom (1 when the
    /// noise model is right), once the heading is known.
    pub fn mean_nis(&self) -> Option<f64> {
        (self.nis.1 > 0).then(|| self.nis.0 / self.nis.1 as f64 / 2.0)
    }

    /// Takes what happened that an operator should read in the log.
    pub fn take_events(&mut self) -> Vec<String> {
        std::mem::take(&mut self.events)
    }

    /// Whether a fix has placed the map pose.
    pub fn is_started(&self) -> bool {
        self.started
    }

    /// The map pose at the latest odom pose: x, y (m), yaw (rad).
    pub fn pose(&self) -> Option<(f64, f64, f64)> {
        self.started.then(|| (self.x[X], self.x[Y], self.x[YAW]))
    }

    /// var x, cov xy, var y (m²), var yaw (rad²).
    pub fn covariance(&self) -> [f64; 4] {
        [
            self.p[(X, X)],
            self.p[(X, Y)],
            self.p[(Y, Y)],
            self.p[(YAW, YAW)],
        ]
    }

    /// The 1σ position uncertainty (largest axis), m.
    pub fn position_sigma(&self) -> f64 {
        largest_sigma(self.p[(X, X)], self.p[(Y, Y)], self.p[(X, Y)])
    }

    /// The 1σ yaw uncertainty, rad.
    pub fn yaw_sigma(&self) -> f64 {
        self.p[(YAW, YAW)].max(0.0).sqrt()
    }

    /// The map→odom correction: the odom frame's origin and rotation in the map frame
    /// (x, y, yaw), so that map pose = correction ∘ odom pose.
    pub fn map_to_odom(&self) -> Option<(f64, f64, f64)> {
        let (_, o) = self.odom?;
        let (x, y, yaw) = self.pose()?;
        let rot = wrap(yaw - o.yaw);
        let (s, c) = rot.sin_cos();
        Some((x - (c * o.x - s * o.y), y - (s * o.x + c * o.y), rot))
    }

    /// The map pose of an odom pose, through the current correction.
    pub fn map_pose_of(&self, o: &OdomPose) -> Option<(f64, f64, f64)> {
        let (tx, ty, rot) = self.map_to_odom()?;
        let (s, c) = rot.sin_cos();
        Some((
            tx + c * o.x - s * o.y,
            ty + s * o.x + c * o.y,
            wrap(rot + o.yaw),
        ))
    }

    /// The heading random walk (rad²/s) that stands for the odom heading's drift against GNSS
    /// headings, measured but not (yet) proven and corrected in the gyro's bias: the heading's
    /// uncertainty grows by it while moving, on top of the configured walk.
    pub fn set_heading_drift(&mut self, walk: f64) {
        self.drift_walk = if walk.is_finite() { walk.max(0.0) } else { 0.0 };
    }

    /// The gyro bias's walk a proven drift showed, rad²/s³ (a bias change over the time it
    /// took): the drift's uncertainty grows at least so; zero when a standstill taught it.
    pub fn set_bias_walk(&mut self, variance_rate: f64) {
        self.shown_bias_walk = if variance_rate.is_finite() {
            variance_rate.max(0.0)
        } else {
            0.0
        };
    }

    /// The headings show the odom heading's drift rate within `variance` (rad²/s²): the
    /// drift's variance is brought down to it when larger, its correlations kept.
    pub fn bound_drift(&mut self, variance: f64) {
        let now = self.p[(DRIFT, DRIFT)];
        if !(variance.is_finite() && variance >= 0.0 && now > variance) {
            return;
        }
        let k = (variance / now).sqrt();
        for i in 0..N {
            self.p[(DRIFT, i)] *= k;
            self.p[(i, DRIFT)] *= k;
        }
    }

    /// A state that knows nothing but the wheels' scale (a new start of the pose keeps it).
    fn fresh_state(&self) -> State {
        let mut x = State::zeros();
        x[SCALE] = self.x[SCALE];
        x
    }

    /// A covariance that knows nothing but the drift's and the scale's variances.
    fn fresh_covariance(&self) -> Cov {
        let mut p = Cov::zeros();
        p[(DRIFT, DRIFT)] = self.p[(DRIFT, DRIFT)];
        p[(SCALE, SCALE)] = self.p[(SCALE, SCALE)];
        p
    }

    /// The gyro's bias was just learnt (a standstill) or corrected: the odom heading's drift
    /// rate is known to 1σ `sigma` rad/s, and uncorrelated with the rest.
    pub fn reset_drift(&mut self, sigma: f64) {
        self.reset_state(DRIFT, if sigma.is_finite() { sigma } else { 0.0 });
    }

    /// State `i` known afresh to 1σ `sigma`, uncorrelated with the rest.
    fn reset_state(&mut self, i: usize, sigma: f64) {
        for j in 0..N {
            self.p[(i, j)] = 0.0;
            self.p[(j, i)] = 0.0;
        }
        self.p[(i, i)] = sigma * sigma;
    }

    /// The odom frame's pose at `t`: the state moves by its increment.
    pub fn odom(&mut self, t: Timestamp, pose: OdomPose) {
        if let Some((t0, o0)) = self.odom.filter(|(t0, _)| t >= *t0) {
            if self.started {
                self.propagate(&o0, &pose, t.saturating_since(t0).as_secs_f64());
            }
        } else if self.odom.is_some() {
            // An odom pose older than the last: out of order, ignored.
            return;
        }
        self.odom = Some((t, pose));
        self.history.push_back((t, pose));
        while self.history.len() > ODOM_HISTORY {
            self.history.pop_front();
        }
    }

    /// Moves the state by the odom increment from `a` to `b`.
    fn propagate(&mut self, a: &OdomPose, b: &OdomPose, dt: f64) {
        let (sa, ca) = a.yaw.sin_cos();
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        // The increment in the vehicle frame at `a`.
        let (fwd, left) = (ca * dx + sa * dy, -sa * dx + ca * dy);
        let turn = wrap(b.yaw - a.yaw);
        let ds = fwd.hypot(left);
        if ds == 0.0 && turn == 0.0 {
            return;
        }
        let (s, c) = self.x[YAW].sin_cos();
        // The increment in the map frame, as the odom frame measured it.
        let (mx, my) = (c * fwd - s * left, s * fwd + c * left);
        let k = 1.0 + self.x[SCALE];
        self.x[X] += k * mx;
        self.x[Y] += k * my;
        self.x[YAW] = wrap(self.x[YAW] + turn);
        let mut f = Cov::identity();
        f[(X, YAW)] = -k * my;
        f[(Y, YAW)] = k * mx;
        f[(X, SCALE)] = mx;
        f[(Y, SCALE)] = my;
        f[(YAW, DRIFT)] = dt;
        let mut q = Cov::zeros();
        q[(DRIFT, DRIFT)] = self.config.bias_walk.powi(2).max(self.shown_bias_walk) * dt;
        q[(SCALE, SCALE)] = self.config.scale_walk.powi(2) * ds;
        let along = self.config.along_per_m * ds;
        let across = self.config.across_per_m * ds;
        // Along and across the direction of the increment, in the map frame.
        let (sh, ch) = (self.x[YAW] - turn / 2.0).sin_cos();
        q[(X, X)] = along * ch * ch + across * sh * sh;
        q[(Y, Y)] = along * sh * sh + across * ch * ch;
        q[(X, Y)] = (along - across) * sh * ch;
        q[(Y, X)] = q[(X, Y)];
        q[(YAW, YAW)] =
            self.config.yaw_per_rad * turn.abs() + (self.config.yaw_per_s + self.drift_walk) * dt;
        self.p = f * self.p * f.transpose() + q;
        // The GNSS error's slow part decays with time (while moving or not: handled in
        // `decay_gnss_error` at each fix).
    }

    /// The white part of a fix's variance (per axis, the larger), m².
    fn white_var(&self, fix: &Fix) -> f64 {
        let slow = self.config.slow_fraction(fix.trust);
        (1.0 - slow * slow).max(0.0) * fix.sigma.0.max(fix.sigma.1).powi(2)
    }

    fn decay_gnss_error(&mut self, dt: f64, ds: f64, sigma: (f64, f64), corrected: bool) {
        if dt <= 0.0 && ds <= 0.0 {
            return;
        }
        let phi = self.config.slow_correlation(dt, ds, corrected);
        let mut f = Cov::identity();
        f[(GE, GE)] = phi;
        f[(GN, GN)] = phi;
        self.x[GE] *= phi;
        self.x[GN] *= phi;
        let mut q = Cov::zeros();
        q[(GE, GE)] = sigma.0.powi(2) * (1.0 - phi * phi);
        q[(GN, GN)] = sigma.1.powi(2) * (1.0 - phi * phi);
        self.p = f * self.p * f.transpose() + q;
    }

    /// The slow error may have stepped by `step` (east, north, m) beyond what its walk allows.
    fn widen_gnss_error(&mut self, step: (f64, f64)) {
        if !(step.0.is_finite() && step.1.is_finite()) {
            return;
        }
        self.p[(GE, GE)] += step.0 * step.0;
        self.p[(GN, GN)] += step.1 * step.1;
        self.p[(GE, GN)] += step.0 * step.1;
        self.p[(GN, GE)] += step.0 * step.1;
    }

    fn reset_gnss_error(&mut self, sigma: (f64, f64)) {
        for g in [GE, GN] {
            self.x[g] = 0.0;
            for i in 0..N {
                self.p[(i, g)] = 0.0;
                self.p[(g, i)] = 0.0;
            }
        }
        self.p[(GE, GE)] = sigma.0.powi(2);
        self.p[(GN, GN)] = sigma.1.powi(2);
    }

    /// The odom pose at `t`, interpolated from the history (the latest when `t` is newer).
    pub fn odom_pose_at(&self, t: Timestamp) -> Option<OdomPose> {
        let at = self.history.partition_point(|(ht, _)| *ht <= t);
        if at == 0 {
            return self.history.front().map(|(_, o)| *o);
        }
        let (t0, o0) = self.history.get(at - 1)?;
        let Some((t1, o1)) = self.history.get(at) else {
            return Some(*o0);
        };
        let span = t1.saturating_since(*t0).as_secs_f64();
        if span <= 0.0 {
            return Some(*o0);
        }
        let k = t.saturating_since(*t0).as_secs_f64() / span;
        Some(OdomPose {
            x: o0.x + (o1.x - o0.x) * k,
            y: o0.y + (o1.y - o0.y) * k,
            yaw: wrap(o0.yaw + wrap(o1.yaw - o0.yaw) * k),
            v: o0.v + (o1.v - o0.v) * k,
            w: o0.w + (o1.w - o0.w) * k,
        })
    }

    /// The fastest turn rate of the odom poses kept from `from` to `to`, rad/s (0 with
    /// none there).
    pub fn max_turn_rate(&self, from: Timestamp, to: Timestamp) -> f64 {
        let start = self.history.partition_point(|(t, _)| *t < from);
        self.history
            .range(start..)
            .take_while(|(t, _)| *t <= to)
            .map(|(_, o)| o.w.abs())
            .fold(0.0, f64::max)
    }

    /// The antenna's position in the odom frame at odom pose `o`.
    fn antenna_in_odom(&self, o: &OdomPose) -> (f64, f64) {
        let (ax, ay) = self.config.antenna;
        let (s, c) = o.yaw.sin_cos();
        (o.x + c * ax - s * ay, o.y + s * ax + c * ay)
    }

    /// How far the antenna moved between two fixes' times, m (along the odom frame).
    fn travelled(&self, a: &Placed, b: &Placed) -> f64 {
        let (pa, pb) = (self.antenna_in_odom(&a.odom), self.antenna_in_odom(&b.odom));
        (pb.0 - pa.0).hypot(pb.1 - pa.1)
    }

    /// Whether fix `b` agrees with fix `a`: their displacement matches the odom frame's.
    /// With the heading unknown only the lengths are compared.
    fn agree(&self, a: &Placed, b: &Placed) -> bool {
        self.disagreement(a, b) <= 1.0
    }

    /// How far fix `b` is from agreeing with fix `a`: the squared distance between their
    /// displacement and the odom frame's, over the agreement's gate (at most 1: they agree).
    fn disagreement(&self, a: &Placed, b: &Placed) -> f64 {
        let dist = self.travelled(a, b);
        let dt = b.fix.t.saturating_since(a.fix.t).as_secs_f64();
        let fix_var = self.white_var(&a.fix)
            + self.white_var(&b.fix)
            // The slow part moves little between neighbours, but it moves.
            + self.slow_change_var(a, b);
        let slip_var = (SLIP_FRACTION * dist).powi(2);
        let turn_var = (AGREE_YAW_RATE * dt * dist).powi(2);
        if let Some((sx, sy)) = self.step(a, b) {
            let var = fix_var + slip_var + turn_var + (self.yaw_sigma() * dist).powi(2);
            (sx * sx + sy * sy) / var / AGREE_GATE
        } else {
            let var = fix_var + slip_var + turn_var;
            let fixes_apart = (b.fix.en.0 - a.fix.en.0).hypot(b.fix.en.1 - a.fix.en.1);
            let d = fixes_apart - dist;
            d * d / var / (AGREE_GATE / 2.0)
        }
    }

    /// The antenna's displacement between two fixes' times as the odom frame measured it,
    /// turned into the map frame by the correction; `None` until the heading is known.
    fn odom_displacement_in_map(&self, a: &Placed, b: &Placed) -> Option<(f64, f64)> {
        if !(self.started && self.yaw_sigma() <= HEADING_KNOWN_RAD) {
            return None;
        }
        let (pa, pb) = (self.antenna_in_odom(&a.odom), self.antenna_in_odom(&b.odom));
        let (ox, oy) = (pb.0 - pa.0, pb.1 - pa.1);
        let rot = self.map_to_odom().map_or(0.0, |(_, _, r)| r);
        let (s, c) = rot.sin_cos();
        Some((c * ox - s * oy, s * ox + c * oy))
    }

    /// How far fix `b` stepped from fix `a` beyond the motion between them (east, north, m);
    /// `None` until the heading is known.
    fn step(&self, a: &Placed, b: &Placed) -> Option<(f64, f64)> {
        let (mx, my) = self.odom_displacement_in_map(a, b)?;
        Some((b.fix.en.0 - a.fix.en.0 - mx, b.fix.en.1 - a.fix.en.1 - my))
    }

    fn slow_change_var(&self, a: &Placed, b: &Placed) -> f64 {
        let dt = b.fix.t.saturating_since(a.fix.t).as_secs_f64();
        let phi = self.config.slow_correlation(
            dt,
            self.travelled(a, b),
            a.fix.corrected && b.fix.corrected,
        );
        let sa = self.config.slow_fraction(a.fix.trust) * a.fix.sigma.0.max(a.fix.sigma.1);
        let sb = self.config.slow_fraction(b.fix.trust) * b.fix.sigma.0.max(b.fix.sigma.1);
        sa * sa + sb * sb - 2.0 * phi * sa * sb
    }

    /// A GNSS position fix.
    pub fn fix(&mut self, fix: Fix) -> FixOutcome {
        if !fix.en.0.is_finite() || !fix.en.1.is_finite() {
            self.stats.dropped += 1;
            return FixOutcome::Dropped;
        }
        let Some(odom) = self.odom_pose_at(fix.t) else {
            return FixOutcome::NoOdom;
        };
        let placed = Placed { fix, odom };
        // Continues the accepted run? Not when it agrees better with a run held since: the
        // accepted run's last fix may lie seconds back, where the wheels' slip allows much,
        // and a jump that lasts would creep in through that allowance.
        let from_accepted = self
            .last_accepted
            .map_or(f64::INFINITY, |last| self.disagreement(&last, &placed));
        let from_held = self
            .held
            .last()
            .map_or(f64::INFINITY, |last| self.disagreement(last, &placed));
        if from_accepted <= 1.0 && from_accepted <= from_held {
            self.drop_held();
            self.take(placed);
            return FixOutcome::Taken;
        }
        // Continues the held run? A fix that disagrees with it is a stray: a second stray that
        // agrees with the first starts a new run (the old one is dropped); a lone stray is
        // dropped when the next fix disagrees with it, so one wild fix never breaks a run.
        match self.held.last().copied() {
            Some(_) if from_held <= 1.0 => {
                if self.stray.take().is_some() {
                    self.stats.dropped += 1;
                }
                self.held.push(placed);
            }
            Some(_) => match self.stray.take() {
                Some(stray) if self.agree(&stray, &placed) => {
                    self.drop_held();
                    self.held.push(stray);
                    self.held.push(placed);
                }
                Some(_) => {
                    self.stats.dropped += 1;
                    self.stray = Some(placed);
                }
                None => self.stray = Some(placed),
            },
            None => self.held.push(placed),
        }
        if self.held.len() > MAX_HELD {
            self.held.remove(0);
            self.stats.dropped += 1;
        }
        let lasted = match (self.held.first(), self.held.last()) {
            (Some(a), Some(b)) => b.fix.t.saturating_since(a.fix.t),
            _ => Duration::ZERO,
        };
        if self.held.len() >= MIN_RUN
            && (self.last_accepted.is_none() || lasted >= self.config.relocate_after)
        {
            let run = std::mem::take(&mut self.held);
            // A lesser receiver's run that stepped away from the accepted one and lasted: its
            // slow error stepped (a change of satellites or corrections), and may be that far
            // from what the filter holds of it.
            if let (Some(last), Some(first)) = (self.last_accepted, run.first())
                && first.fix.trust == Trust::UnderWheels
                && let Some(step) = self.step(&last, first)
            {
                self.widen_gnss_error(step);
            }
            for p in run {
                self.take(p);
            }
            return FixOutcome::Taken;
        }
        FixOutcome::Held
    }

    /// Drops the held run and the stray: they disagreed with what was taken.
    fn drop_held(&mut self) {
        self.stats.dropped += self.held.len() as u64 + u64::from(self.stray.is_some());
        self.held.clear();
        self.stray = None;
    }

    /// Applies an agreeing fix.
    fn take(&mut self, p: Placed) {
        self.stats.taken += 1;
        let previous = self.last_accepted.replace(p);
        if !self.started {
            self.start(&p);
            return;
        }
        let sigma_now = p.fix.sigma.0.max(p.fix.sigma.1);
        let slow = self.config.slow_fraction(p.fix.trust);
        let slow_sigma = (p.fix.sigma.0 * slow, p.fix.sigma.1 * slow);
        let new_quality = self
            .last_sigma
            .is_none_or(|before| sigma_now < before * 0.5 || sigma_now * 0.5 > before);
        if new_quality {
            self.reset_gnss_error(slow_sigma);
        }
        self.last_sigma = Some(sigma_now);
        if let Some(previous) = previous {
            self.decay_gnss_error(
                p.fix.t.saturating_since(previous.fix.t).as_secs_f64(),
                self.travelled(&previous, &p),
                slow_sigma,
                p.fix.corrected,
            );
        }
        if self.yaw_sigma() > FIT_YAW_SIGMA {
            self.fit.push_back(p);
            while self.fit.len() > FIT_FIXES {
                self.fit.pop_front();
            }
            if self.try_fit_heading() {
                return;
            }
        } else {
            self.fit.clear();
            self.fit.push_back(p);
        }
        self.update_position(&p, slow);
    }

    /// The first accepted fix places the map pose; its heading is unknown.
    fn start(&mut self, p: &Placed) {
        let Some((_, now)) = self.odom else {
            return;
        };
        let (ax, ay) = self.config.antenna;
        let lever = ax * ax + ay * ay;
        // Heading unknown: the map yaw reads the odom yaw until the motion shows it, and the
        // fix is carried to now along the odom path as it is.
        let (nx, ny) = (now.x - p.odom.x, now.y - p.odom.y);
        let (s0, c0) = p.odom.yaw.sin_cos();
        self.x = self.fresh_state();
        self.x[X] = p.fix.en.0 - (c0 * ax - s0 * ay) + nx;
        self.x[Y] = p.fix.en.1 - (s0 * ax + c0 * ay) + ny;
        self.x[YAW] = now.yaw;
        self.p = self.fresh_covariance();
        let distance = nx.hypot(ny);
        self.p[(X, X)] = p.fix.sigma.0.powi(2) + lever + distance * distance;
        self.p[(Y, Y)] = p.fix.sigma.1.powi(2) + lever + distance * distance;
        self.p[(YAW, YAW)] = UNKNOWN_YAW_SIGMA.powi(2);
        let slow = self.config.slow_fraction(p.fix.trust);
        for (i, g, sd) in [(X, GE, p.fix.sigma.0), (Y, GN, p.fix.sigma.1)] {
            self.p[(g, g)] = (slow * sd).powi(2);
            self.p[(i, g)] = -(slow * sd).powi(2);
            self.p[(g, i)] = -(slow * sd).powi(2);
        }
        self.started = true;
        self.last_sigma = Some(p.fix.sigma.0.max(p.fix.sigma.1));
        self.fit.clear();
        self.fit.push_back(*p);
        self.events.push(format!(
            "localisation started: position from agreeing fixes with 1σ {:.2} m; heading \
             unknown until the motion between fixes, a course or a second antenna shows it",
            p.fix.sigma.0.max(p.fix.sigma.1)
        ));
    }

    /// The odom path fitted to the accepted fixes (a rigid 2-D fit, the antenna's odom
    /// positions onto the fixes): the heading once the fixes span enough distance.
    fn try_fit_heading(&mut self) -> bool {
        let n = self.fit.len();
        if n < MIN_RUN {
            return false;
        }
        let pairs: Vec<PointPair> = self
            .fit
            .iter()
            .map(|p| (self.antenna_in_odom(&p.odom), p.fix.en))
            .collect();
        let Some(fit) = rigid_fit(&pairs) else {
            return false;
        };
        // The fixes' error is partly slow (common to neighbours): count it whole, to be safe.
        let sigma = self
            .fit
            .iter()
            .map(|p| p.fix.sigma.0.max(p.fix.sigma.1))
            .fold(0.0, f64::max);
        if fit.spread <= 0.0 {
            return false;
        }
        let yaw_sigma = sigma / fit.spread.sqrt();
        if yaw_sigma > FIT_YAW_SIGMA {
            return false;
        }
        let Some((_, now)) = self.odom else {
            return false;
        };
        let (x, y) = fit.apply((now.x, now.y));
        self.x[X] = x;
        self.x[Y] = y;
        self.x[YAW] = wrap(fit.rotation + now.yaw);
        self.x[GE] = 0.0;
        self.x[GN] = 0.0;
        let fraction = self
            .fit
            .iter()
            .map(|p| self.config.slow_fraction(p.fix.trust))
            .fold(0.0, f64::max);
        let slow = fraction * sigma;
        let from_centroid = (now.x - fit.centroid.0).hypot(now.y - fit.centroid.1);
        let pos_var = sigma * sigma / n as f64 + slow * slow + (yaw_sigma * from_centroid).powi(2);
        self.p = self.fresh_covariance();
        self.p[(X, X)] = pos_var;
        self.p[(Y, Y)] = pos_var;
        self.p[(YAW, YAW)] = yaw_sigma * yaw_sigma;
        for (i, g) in [(X, GE), (Y, GN)] {
            self.p[(g, g)] = slow * slow;
            self.p[(i, g)] = -slow * slow * 0.5;
            self.p[(g, i)] = -slow * slow * 0.5;
        }
        self.stats.fits += 1;
        self.events.push(format!(
            "heading from the motion between {n} fixes: {:.1}° (1σ {:.1}°)",
            super::planar::heading_deg_of_yaw(self.x[YAW]),
            yaw_sigma.to_degrees()
        ));
        true
    }

    /// The Kalman update of one fix, placed through the odom frame's poses.
    fn update_position(&mut self, p: &Placed, slow: f64) {
        let Some((_, now)) = self.odom else {
            return;
        };
        // The fix's antenna in the vehicle frame of now: back along the odom increment (as
        // long as the wheels' scale makes it), then out along the lever arm.
        let (sn, cn) = now.yaw.sin_cos();
        let (dx, dy) = (p.odom.x - now.x, p.odom.y - now.y);
        let back = (cn * dx + sn * dy, -sn * dx + cn * dy);
        let (ax, ay) = self.config.antenna;
        let (sl, cl) = wrap(p.odom.yaw - now.yaw).sin_cos();
        let k = 1.0 + self.x[SCALE];
        let v = (
            k * back.0 + cl * ax - sl * ay,
            k * back.1 + sl * ax + cl * ay,
        );
        let travelled = dx.hypot(dy);
        let (s, c) = self.x[YAW].sin_cos();
        let hx = SVector::<f64, 2>::new(
            self.x[X] + c * v.0 - s * v.1 + self.x[GE],
            self.x[Y] + s * v.0 + c * v.1 + self.x[GN],
        );
        let mut h = SMatrix::<f64, 2, N>::zeros();
        h[(0, X)] = 1.0;
        h[(1, Y)] = 1.0;
        h[(0, YAW)] = -s * v.0 - c * v.1;
        h[(1, YAW)] = c * v.0 - s * v.1;
        h[(0, GE)] = 1.0;
        h[(1, GN)] = 1.0;
        h[(0, SCALE)] = c * back.0 - s * back.1;
        h[(1, SCALE)] = s * back.0 + c * back.1;
        let white = (1.0 - slow * slow).max(0.0);
        // The odom increment back to the fix carries its own uncertainty.
        let back = self.config.along_per_m * travelled;
        let mut r = SMatrix::<f64, 2, 2>::zeros();
        r[(0, 0)] = p.fix.sigma.0.powi(2) * white + back;
        r[(1, 1)] = p.fix.sigma.1.powi(2) * white + back;
        let z = SVector::<f64, 2>::new(p.fix.en.0, p.fix.en.1);
        let y = z - hx;
        let heading_known = self.yaw_sigma() <= HEADING_KNOWN_RAD;
        // Until the heading is known, the fixes place the vehicle but say nothing of the
        // heading or of the wheels' scale along it.
        let kept: &[usize] = if heading_known { &[] } else { &[YAW, SCALE] };
        let s_mat = h * self.p * h.transpose() + r;
        let nis = s_mat
            .try_inverse()
            .map_or(f64::INFINITY, |inv| (y.transpose() * inv * y)[(0, 0)]);
        if heading_known && nis.is_finite() {
            self.nis.0 += nis;
            self.nis.1 += 1;
        }
        if nis > GATE_2 {
            let (since, count) = self.disagreeing.map_or((p.fix.t, 1), |(s, n)| (s, n + 1));
            self.disagreeing = Some((since, count));
            let persistent = count as usize >= MIN_RUN
                && p.fix.t.saturating_since(since) >= self.config.relocate_after;
            // Who is wrong: trusted fixes over slipping wheels; a lesser fix's step is its
            // slow error; fixes that disagree for long mean the vehicle is elsewhere.
            let widen = |me: &mut Self| {
                let extra = y.norm_squared() / 2.0;
                me.p[(X, X)] += extra;
                me.p[(Y, Y)] += extra;
                me.stats.widened += 1;
            };
            match p.fix.trust {
                Trust::OverWheels => widen(self),
                Trust::UnderWheels if persistent => {
                    widen(self);
                    self.disagreeing = None;
                }
                Trust::UnderWheels => {
                    let slow_sigma = (p.fix.sigma.0 * slow, p.fix.sigma.1 * slow);
                    // A new realisation of the slow error: wide enough to take the step.
                    let step = y.norm();
                    self.reset_gnss_error((slow_sigma.0.max(step), slow_sigma.1.max(step)));
                }
            }
        } else {
            self.disagreeing = None;
        }
        self.apply(y, &h, &r, kept);
    }

    /// Kalman update with the Joseph form; `kept` states, and the drift always, are not
    /// changed (Schmidt).
    fn apply<const M: usize>(
        &mut self,
        y: SVector<f64, M>,
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
        kept: &[usize],
    ) -> bool {
        let s = h * self.p * h.transpose() + r;
        let Some(s_inv) = s.try_inverse() else {
            return false;
        };
        let mut k = self.p * h.transpose() * s_inv;
        for &i in kept.iter().chain(&[DRIFT]) {
            k.row_mut(i).fill(0.0);
        }
        self.x += k * y;
        self.x[YAW] = wrap(self.x[YAW]);
        self.x[SCALE] = self.x[SCALE].clamp(-MAX_SCALE_ERROR, MAX_SCALE_ERROR);
        let i_kh = Cov::identity() - k * h;
        self.p = i_kh * self.p * i_kh.transpose() + k * r * k.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
        true
    }

    /// A heading of the vehicle (dual antenna, or a course turned into the heading), ENU rad.
    pub fn heading(&mut self, yaw: f64, sigma: f64) -> bool {
        if !self.started || !yaw.is_finite() {
            return false;
        }
        if self.yaw_sigma() > HEADING_KNOWN_RAD {
            // Unknown: the measurement sets it.
            self.reset_heading(yaw, sigma);
            self.stats.headings += 1;
            return true;
        }
        let y = SVector::<f64, 1>::new(wrap(yaw - self.x[YAW]));
        let mut h = SMatrix::<f64, 1, N>::zeros();
        h[(0, YAW)] = 1.0;
        let r = SMatrix::<f64, 1, 1>::new(sigma * sigma);
        let s = self.p[(YAW, YAW)] + sigma * sigma;
        if y[0] * y[0] / s > GATE_1 {
            self.stats.headings_rejected += 1;
            return false;
        }
        self.stats.headings += 1;
        self.apply(y, &h, &r, &[])
    }

    /// Replaces the heading (a run of rejected headings showed it wrong), ENU rad with 1σ.
    pub fn reset_heading(&mut self, yaw: f64, sigma: f64) {
        self.x[YAW] = wrap(yaw);
        self.reset_state(YAW, sigma);
        self.fit.clear();
    }

    /// A course over ground (the direction the antenna moves, ENU rad) as the vehicle's
    /// heading: the antenna moves at (v − ω·ay, ω·ax) in the vehicle frame, off the heading
    /// while turning and behind it when reversing. `None` when the antenna barely moves.
    pub fn heading_of_course(&self, course: f64, v: f64, w: f64) -> Option<f64> {
        let (ax, ay) = self.config.antenna;
        let (along, across) = (v - w * ay, w * ax);
        if along.hypot(across) < 0.1 {
            return None;
        }
        Some(wrap(course - across.atan2(along)))
    }

    /// Places the map pose by hand (x, y in m, yaw in rad, with their 1σ), forgetting the
    /// fixes held or fitted so far.
    pub fn set_pose(&mut self, pose: (f64, f64, f64), sigma: (f64, f64)) {
        self.x = self.fresh_state();
        self.x[X] = pose.0;
        self.x[Y] = pose.1;
        self.x[YAW] = wrap(pose.2);
        self.p = self.fresh_covariance();
        self.p[(X, X)] = sigma.0 * sigma.0;
        self.p[(Y, Y)] = sigma.0 * sigma.0;
        self.p[(YAW, YAW)] = sigma.1 * sigma.1;
        self.started = true;
        self.forget_fixes();
    }

    /// Moves the map pose by (dx, dy) m without changing what is known of it: the local
    /// frame's origin moved. Fixes held or fitted were in the old frame and are forgotten.
    pub fn shift(&mut self, dx: f64, dy: f64) {
        self.x[X] += dx;
        self.x[Y] += dy;
        self.forget_fixes();
    }

    fn forget_fixes(&mut self) {
        self.held.clear();
        self.stray = None;
        self.fit.clear();
        self.last_accepted = None;
        self.disagreeing = None;
    }

    /// The number of odom poses and fixes kept (bounded).
    pub fn memory(&self) -> (usize, usize) {
        (self.history.len(), self.fit.len() + self.held.len())
    }
}

/// A point and where it should go.
pub type PointPair = ((f64, f64), (f64, f64));

/// The rotation and translation that carry the first points of pairs onto their second in
/// the least-squares sense (a rigid 2-D fit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidFit {
    /// Rotation, rad.
    pub rotation: f64,
    /// Translation after the rotation, m.
    pub translation: (f64, f64),
    /// The centroid of the first points.
    pub centroid: (f64, f64),
    /// The sum of the first points' squared distances to their centroid, m²: the fit's
    /// rotation has 1σ of about the points' σ over its square root.
    pub spread: f64,
}

impl RigidFit {
    /// Where the fit carries `p`.
    pub fn apply(&self, p: (f64, f64)) -> (f64, f64) {
        let (s, c) = self.rotation.sin_cos();
        (
            self.translation.0 + c * p.0 - s * p.1,
            self.translation.1 + s * p.0 + c * p.1,
        )
    }
}

/// The rigid fit of `pairs`; `None` for fewer than two.
pub fn rigid_fit(pairs: &[PointPair]) -> Option<RigidFit> {
    if pairs.len() < 2 {
        return None;
    }
    let n = pairs.len() as f64;
    let (mut px, mut py, mut qx, mut qy) = (0.0, 0.0, 0.0, 0.0);
    for ((a, b), (c, d)) in pairs {
        px += a / n;
        py += b / n;
        qx += c / n;
        qy += d / n;
    }
    let (mut sxx, mut sxy, mut spread) = (0.0, 0.0, 0.0);
    for ((a, b), (c, d)) in pairs {
        let (ax, ay, bx, by) = (a - px, b - py, c - qx, d - qy);
        sxx += ax * bx + ay * by;
        sxy += ax * by - ay * bx;
        spread += ax * ax + ay * ay;
    }
    let rotation = sxy.atan2(sxx);
    let (s, c) = rotation.sin_cos();
    Some(RigidFit {
        rotation,
        translation: (qx - (c * px - s * py), qy - (s * px + c * py)),
        centroid: (px, py),
        spread,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rigid_fit_recovers_a_rotation_and_a_shift() {
        let pairs: Vec<PointPair> = [(0.0, 0.0), (10.0, 0.0), (10.0, 5.0)]
            .iter()
            .map(|&(x, y): &(f64, f64)| {
                let (s, c) = 0.7f64.sin_cos();
                ((x, y), (3.0 + c * x - s * y, -2.0 + s * x + c * y))
            })
            .collect();
        let fit = rigid_fit(&pairs).expect("fit");
        assert!((fit.rotation - 0.7).abs() < 1e-12);
        let (x, y) = fit.apply((1.0, 1.0));
        let (s, c) = 0.7f64.sin_cos();
        assert!((x - (3.0 + c - s)).abs() < 1e-9 && (y - (-2.0 + s + c)).abs() < 1e-9);
    }

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_micros(1_000_000_000 + ms * 1000)
    }

    /// Drives straight east at 1 m/s in the odom frame, whose yaw is `odom_yaw` off the map's,
    /// with fixes from `fix_of(k, true_east)` at 5 Hz; odom at 50 Hz.
    fn drive(
        f: &mut MapFilter,
        seconds: u64,
        start_ms: u64,
        mut fix_of: impl FnMut(u64, (f64, f64)) -> Option<Fix>,
    ) {
        let map_yaw = 0.3f64;
        for k in 0..seconds * 50 {
            let ms = start_ms + k * 20;
            let s = ms as f64 / 1000.0;
            // The vehicle heads along map yaw 0.3; the odom frame started at yaw 0.
            let odom = OdomPose {
                x: s,
                y: 0.0,
                yaw: 0.0,
                v: 1.0,
                w: 0.0,
            };
            f.odom(at(ms), odom);
            if k % 10 == 0 {
                let truth = (s * map_yaw.cos(), s * map_yaw.sin());
                if let Some(fix) = fix_of(ms, truth) {
                    f.fix(fix);
                }
            }
        }
    }

    fn rtk(ms: u64, en: (f64, f64)) -> Fix {
        Fix {
            t: at(ms),
            en,
            sigma: (0.02, 0.02),
            trust: Trust::OverWheels,
            corrected: true,
        }
    }

    #[test]
    fn the_heading_comes_from_the_motion_between_fixes() {
        let mut f = MapFilter::new(MapFilterConfig::default());
        drive(&mut f, 10, 0, |ms, truth| Some(rtk(ms, truth)));
        let (_, _, yaw) = f.pose().expect("placed");
        assert!((yaw - 0.3).abs() < 0.01, "{yaw}");
        assert!(f.yaw_sigma() < 2f64.to_radians(), "{}", f.yaw_sigma());
    }

    #[test]
    fn in_an_outage_the_map_pose_moves_exactly_as_the_odom_pose() {
        let mut f = MapFilter::new(MapFilterConfig::default());
        drive(&mut f, 10, 0, |ms, truth| Some(rtk(ms, truth)));
        let before = f.map_to_odom().expect("correction");
        drive(&mut f, 30, 10_000, |_, _| None);
        let after = f.map_to_odom().expect("correction");
        // Equal but for rounding: 30 m of increments carried the pose as they carried odom.
        assert!((after.0 - before.0).abs() < 1e-9, "{before:?} {after:?}");
        assert!((after.1 - before.1).abs() < 1e-9, "{before:?} {after:?}");
        assert!((after.2 - before.2).abs() < 1e-12, "{before:?} {after:?}");
    }

    #[test]
    fn a_lone_wild_fix_is_never_taken_and_a_run_elsewhere_relocates_from_its_fixes() {
        let mut f = MapFilter::new(MapFilterConfig::default());
        drive(&mut f, 10, 0, |ms, truth| Some(rtk(ms, truth)));
        let mut wild_seen = 0;
        drive(&mut f, 5, 10_000, |ms, truth| {
            if ms == 12_000 {
                wild_seen += 1;
                return Some(rtk(ms, (truth.0 + 422.0, truth.1)));
            }
            Some(rtk(ms, truth))
        });
        assert_eq!(wild_seen, 1);
        let (x, y, _) = f.pose().expect("placed");
        let s = 14.98f64;
        assert!((x - s * 0.3f64.cos()).hypot(y - s * 0.3f64.sin()) < 0.05);
        assert_eq!(f.stats().dropped, 1);
        // A 5 m jump for 1 s (five agreeing fixes) is the receiver's: never taken.
        drive(&mut f, 2, 15_000, |ms, truth| {
            let jumped = (15_000..16_000).contains(&ms);
            Some(rtk(
                ms,
                (
                    truth.0 + if jumped { 3.0 } else { 0.0 },
                    truth.1 + if jumped { 4.0 } else { 0.0 },
                ),
            ))
        });
        let (x, y, _) = f.pose().expect("placed");
        let s = 16.98f64;
        assert!((x - s * 0.3f64.cos()).hypot(y - s * 0.3f64.sin()) < 0.05);
        // Carried 50 m north: once the agreeing fixes there have lasted `relocate_after`, the
        // pose moves to them.
        drive(&mut f, 4, 17_000, |ms, truth| {
            Some(rtk(ms, (truth.0, truth.1 + 50.0)))
        });
        let (x, y, _) = f.pose().expect("placed");
        let s = 20.98f64;
        assert!(
            (x - s * 0.3f64.cos()).hypot(y - 50.0 - s * 0.3f64.sin()) < 0.1,
            "{x} {y}"
        );
    }

    /// A car at 10 m/s with RTK fixes at 1 Hz: 10 m between fixes, where a 5 m jump must
    /// not pass for the wheels' slip (it did when 30 % of the distance was allowed).
    #[test]
    fn at_road_speed_and_1_hz_a_5_m_jump_is_not_slip() {
        let mut f = MapFilter::new(MapFilterConfig::default());
        let yaw = 0.3f64;
        let mut off = 0.0f64;
        for k in 0..40 * 50u64 {
            let ms = k * 20;
            let d = 10.0 * ms as f64 / 1000.0;
            f.odom(
                at(ms),
                OdomPose {
                    x: d,
                    y: 0.0,
                    yaw: 0.0,
                    v: 10.0,
                    w: 0.0,
                },
            );
            let truth = (d * yaw.cos(), d * yaw.sin());
            if ms % 1000 == 0 {
                let jump = if ms == 30_000 { (3.0, 4.0) } else { (0.0, 0.0) };
                f.fix(rtk(ms, (truth.0 + jump.0, truth.1 + jump.1)));
            }
            if ms >= 30_000
                && let Some((x, y, _)) = f.pose()
            {
                off = off.max((x - truth.0).hypot(y - truth.1));
            }
        }
        assert!(f.yaw_sigma() < 1f64.to_radians(), "{}", f.yaw_sigma());
        assert!(off < 0.3, "the pose followed the jump: {off} m");
        assert_eq!(f.stats().dropped, 1);
    }

    /// A DGPS receiver's solution steps 3 m (a change of satellites or corrections) and
    /// stays: the step is its slow error's, which the wheels show, not a move. The stepped
    /// fixes disagree with the accepted run, are held, and are taken once they have lasted.
    #[test]
    fn a_dgps_step_that_lasts_is_taken_as_the_receivers_error() {
        // Nearly all of the receiver's error is slow (the Husky's SBAS: 99.8 %).
        let mut f = MapFilter::new(MapFilterConfig {
            gnss_correlated_fraction: 0.998,
            ..MapFilterConfig::default()
        });
        drive(&mut f, 10, 0, |ms, truth| Some(rtk(ms, truth)));
        let dgps = |ms: u64, en: (f64, f64)| Fix {
            t: at(ms),
            en,
            sigma: (1.8, 1.8),
            trust: Trust::UnderWheels,
            corrected: true,
        };
        drive(&mut f, 20, 10_000, |ms, truth| Some(dgps(ms, truth)));
        drive(&mut f, 4, 30_000, |ms, truth| {
            Some(dgps(
                ms,
                (truth.0 - 3.0 * 0.3f64.sin(), truth.1 + 3.0 * 0.3f64.cos()),
            ))
        });
        let (x, y, _) = f.pose().expect("placed");
        let s = 33.98f64;
        let off = (x - s * 0.3f64.cos()).hypot(y - s * 0.3f64.sin());
        // 0.08 m; 0.18 m when the step did not widen the slow error's uncertainty.
        assert!(off < 0.12, "the pose followed the step: {off} m");
        assert!(f.stats().dropped == 0, "{:?}", f.stats());
    }

    #[test]
    fn agreeing_rtk_fixes_are_believed_over_slipping_wheels() {
        let mut f = MapFilter::new(MapFilterConfig::default());
        drive(&mut f, 10, 0, |ms, truth| Some(rtk(ms, truth)));
        // The wheels read 1 m/s, the vehicle makes 0.8 (20 % slip) for 5 s.
        let along = |ms: u64| 10.0 + (ms as f64 / 1000.0 - 10.0) * 0.8;
        drive(&mut f, 5, 10_000, |ms, _| {
            let s = along(ms);
            Some(rtk(ms, (s * 0.3f64.cos(), s * 0.3f64.sin())))
        });
        // Where the last fix (14.8 s) put it, plus the wheels' 0.18 m since.
        let s = along(14_800) + 0.18;
        let (x, y, _) = f.pose().expect("placed");
        let off = (x - s * 0.3f64.cos()).hypot(y - s * 0.3f64.sin());
        assert!(off < 0.05, "{off}");
        assert_eq!(f.stats().dropped, 0);
    }

    #[test]
    fn a_course_sets_an_unknown_heading_and_reversing_points_it_back() {
        let mut f = MapFilter::new(MapFilterConfig {
            antenna: (0.3, 0.0),
            ..MapFilterConfig::default()
        });
        f.odom(at(0), OdomPose::default());
        for k in 0..3 {
            f.fix(rtk(k * 200, (0.0, 0.0)));
        }
        assert!(f.yaw_sigma() > 1.0);
        // Reversing at 1 m/s: the antenna moves along yaw + π.
        let h = f.heading_of_course(1.0 + std::f64::consts::PI, -1.0, 0.0);
        assert!(f.heading(h.expect("moving"), 0.05));
        assert!((f.pose().expect("placed").2 - 1.0).abs() < 1e-9);
        // Turning on the spot, the antenna ahead of the axle moves sideways.
        let h = f.heading_of_course(1.0 + std::f64::consts::FRAC_PI_2, 0.0, 1.0);
        assert!((h.expect("moving") - 1.0).abs() < 1e-9);
        assert_eq!(f.heading_of_course(0.0, 0.01, 0.0), None);
    }

    proptest::proptest! {
        /// Issue 33's finding 4: a wild fix, wherever it falls (in a run that agrees with the
        /// pose, or among the first fixes after the vehicle was carried, as a relocation
        /// gathers them), never moves the pose towards it.
        #[test]
        fn a_wild_fix_never_moves_the_pose(
            at_fix in 0u64..25,
            carried in proptest::bool::ANY,
            off in 100.0f64..1000.0,
            angle in 0.0f64..std::f64::consts::TAU,
        ) {
            let mut f = MapFilter::new(MapFilterConfig::default());
            drive(&mut f, 10, 0, |ms, truth| Some(rtk(ms, truth)));
            let shift = if carried { 20.0 } else { 0.0 };
            let wild_ms = 10_000 + at_fix * 200;
            let mut worst: f64 = 0.0;
            for k in 0..25u64 {
                let ms = 10_000 + k * 200;
                let g = |ms: u64, truth: (f64, f64)| {
                    let truth = (truth.0, truth.1 + shift);
                    if ms == wild_ms {
                        return Some(rtk(ms, (truth.0 + off * angle.cos(), truth.1 + off * angle.sin())));
                    }
                    Some(rtk(ms, truth))
                };
                for j in 0..10u64 {
                    let t = ms + j * 20;
                    let s = t as f64 / 1000.0;
                    f.odom(at(t), OdomPose { x: s, v: 1.0, ..OdomPose::default() });
                    if j == 0 {
                        let truth = (s * 0.3f64.cos(), s * 0.3f64.sin());
                        if let Some(fix) = g(t, truth) {
                            f.fix(fix);
                        }
                    }
                    let (x, y, _) = f.pose().expect("placed");
                    let (tx, ty) = (s * 0.3f64.cos(), s * 0.3f64.sin());
                    // Distance from the old place or the new one, whichever is nearer.
                    let d = (x - tx).hypot(y - ty).min((x - tx).hypot(y - ty - shift));
                    worst = worst.max(d);
                }
            }
            proptest::prop_assert!(worst < 0.5, "pose {worst} m from both places");
            let (x, y, _) = f.pose().expect("placed");
            let s = 14.98f64;
            let settled = (x - s * 0.3f64.cos()).hypot(y - shift - s * 0.3f64.sin());
            proptest::prop_assert!(settled < 0.1, "ends {settled} m from the fixes");
        }
    }

    #[test]
    fn a_hand_set_pose_and_a_moved_origin_forget_the_fixes_of_before() {
        let mut f = MapFilter::new(MapFilterConfig::default());
        f.odom(at(0), OdomPose::default());
        f.set_pose((5.0, 6.0, 1.0), (0.05, 0.01));
        assert_eq!(f.pose(), Some((5.0, 6.0, 1.0)));
        // One fix is held, then the origin moves: the held fix was in the old frame.
        assert_eq!(f.fix(rtk(0, (9.0, 9.0))), FixOutcome::Held);
        f.shift(-5.0, -6.0);
        assert_eq!(f.pose(), Some((0.0, 0.0, 1.0)));
        assert_eq!(f.memory().1, 0);
        assert_eq!(
            f.fix(Fix {
                en: (f64::NAN, 0.0),
                ..rtk(200, (0.0, 0.0))
            }),
            FixOutcome::Dropped
        );
    }

    #[test]
    fn memory_is_bounded() {
        let mut f = MapFilter::new(MapFilterConfig::default());
        drive(&mut f, 120, 0, |ms, truth| {
            Some(Fix {
                t: at(ms),
                en: truth,
                sigma: (50.0, 50.0),
                trust: Trust::UnderWheels,
                corrected: true,
            })
        });
        let (odom, fixes) = f.memory();
        assert!(
            odom <= ODOM_HISTORY && fixes <= FIT_FIXES + MIN_RUN,
            "{odom} {fixes}"
        );
    }
}
