//! `chassisd bench fusion`: scripted drives of the simulated vehicle through the whole
//! decoding path and the core, scored against the simulator's truth. The fused pose (what
//! base_status publishes) is compared with two baselines: GNSS alone (each decoded fix's
//! antenna position at its epoch, and its heading) and wheel odometry alone (the status's
//! wheel distances, dead-reckoned from the true start).

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use bytes::Bytes;
use serde::Serialize;

use crate::config::ConfigError;
use crate::devices::gnss::GnssReceiver;
use crate::engine::EngineOutput;
use crate::fusion::localizer::yaw_of_heading_deg;
use crate::fusion::planar::wrap;
use crate::geodesy::{Enu, Geodetic};
use crate::record::{Payload, Record};
use crate::sim::lockstep::{GNSS_SOURCE, Lockstep, PLANT_STEP, Sink};
use crate::sim::plant::{PlantConfig, Truth};
use crate::sim::scenario::{Regime, Scenario, WARMUP_S};
use crate::time::Timestamp;
use crate::vehicle::status::{PoseCovariance, VehicleStatus};

/// Simulated sessions start here (2026-01-01T00:00:00Z), so receiver times are fixed too.
const START: Timestamp = Timestamp::from_micros(1_767_225_600_000_000);
/// The window after a jump in which the estimate must not follow it, s.
const JUMP_SETTLE_S: f64 = 5.0;
/// An estimate that stays this close to the truth through a jump has rejected it, m.
const JUMP_REJECTED_M: f64 = 0.3;
/// A fix this far from the antenna is a wild one, m.
const WILD_M: f64 = 50.0;
/// The window after a wild fix in which the pose must not follow it, s.
const WILD_WINDOW_S: f64 = 3.0;
/// Speed above which a single-antenna receiver's course stands in for its heading, m/s.
const COURSE_MIN_SPEED: f64 = 0.3;

/// The targets the figures are held to.
pub mod target {
    /// Fused position RMSE over GNSS-only RMSE in float, DGPS and single segments, at most.
    pub const DEGRADED_RATIO: f64 = 0.5;
    /// Fused position RMSE over GNSS-only RMSE while RTK-fixed, at most.
    pub const FIXED_RATIO: f64 = 1.2;
    /// Fused heading RMSE, under, degrees.
    pub const HEADING_RMSE_DEG: f64 = 1.0;
    /// Position error at the end of a 30 s outage at 1 m/s, under, m.
    pub const OUTAGE_DRIFT_M: f64 = 0.5;
    /// The mean normalised estimation error squared of position (2 DOF), within, in every
    /// scenario and regime.
    pub const NEES_POSITION: std::ops::RangeInclusive<f64> = 0.3..=3.0;
    /// The same for heading (1 DOF).
    pub const NEES_HEADING: std::ops::RangeInclusive<f64> = 0.2..=2.0;
    /// The most a wild fix may move the fused pose away from the truth, m.
    pub const WILD_MOVE_M: f64 = 0.5;
}

/// Sums of squared errors.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Errors {
    position: (f64, u64),
    heading: (f64, u64),
    nees_position: (f64, u64),
    nees_heading: (f64, u64),
}

impl Errors {
    fn position(&mut self, e: f64) {
        self.position.0 += e * e;
        self.position.1 += 1;
    }

    fn heading(&mut self, e: f64) {
        self.heading.0 += e * e;
        self.heading.1 += 1;
    }

    /// The normalised estimation errors squared of a position error (east, north) and a
    /// heading error against the estimate's covariance.
    fn nees(&mut self, e: (f64, f64), yaw_error: f64, cov: &PoseCovariance) {
        let det = cov.xx * cov.yy - cov.xy * cov.xy;
        if det > 0.0 {
            let q = (cov.yy * e.0 * e.0 - 2.0 * cov.xy * e.0 * e.1 + cov.xx * e.1 * e.1) / det;
            self.nees_position.0 += q;
            self.nees_position.1 += 1;
        }
        if cov.yaw > 0.0 {
            self.nees_heading.0 += yaw_error * yaw_error / cov.yaw;
            self.nees_heading.1 += 1;
        }
    }

    fn merge(&mut self, other: &Errors) {
        for (a, b) in [
            (&mut self.position, other.position),
            (&mut self.heading, other.heading),
            (&mut self.nees_position, other.nees_position),
            (&mut self.nees_heading, other.nees_heading),
        ] {
            a.0 += b.0;
            a.1 += b.1;
        }
    }

    fn figures(&self) -> Figures {
        let rms = |(sum, n): (f64, u64)| (n > 0).then(|| (sum / n as f64).sqrt());
        let mean = |(sum, n): (f64, u64)| (n > 0).then(|| sum / n as f64);
        Figures {
            position_rmse_m: rms(self.position),
            heading_rmse_deg: rms(self.heading).map(f64::to_degrees),
            nees_position: mean(self.nees_position),
            nees_heading: mean(self.nees_heading),
            samples: self.position.1,
        }
    }
}

/// Root-mean-square errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Figures {
    /// Position, m.
    pub position_rmse_m: Option<f64>,
    /// Heading, degrees.
    pub heading_rmse_deg: Option<f64>,
    /// Mean NEES of position (2 DOF; 2 for a consistent estimate), fused pose only.
    pub nees_position: Option<f64>,
    /// Mean NEES of heading (1 DOF; 1 for a consistent estimate), fused pose only.
    pub nees_heading: Option<f64>,
    /// Position samples.
    pub samples: u64,
}

/// One estimator's errors by GNSS regime.
type ByRegime = BTreeMap<Regime, Errors>;

/// The figures of one scenario.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScenarioFigures {
    /// Scenario name.
    pub name: String,
    /// Fused pose, by regime ("fixed", "degraded", "outage").
    pub fused: BTreeMap<&'static str, Figures>,
    /// GNSS alone, by regime.
    pub gnss_only: BTreeMap<&'static str, Figures>,
    /// Odometry alone, by regime.
    pub odometry_only: BTreeMap<&'static str, Figures>,
    /// Fused position error when the fix returns after the outage, m (RMS over the runs).
    pub outage_drift_m: Option<f64>,
    /// The worst run's, m.
    pub outage_drift_worst_m: Option<f64>,
    /// Odometry-only position error at the same moment, m (RMS over the runs).
    pub outage_drift_odometry_m: Option<f64>,
    /// Largest fused position error from the jump to 5 s after it, m.
    pub jump_max_error_m: Option<f64>,
    /// Largest GNSS-only position error in the jump, m.
    pub jump_gnss_max_error_m: Option<f64>,
    /// Wild fixes the receiver sent (more than [`WILD_M`] off).
    pub wild_fixes: usize,
    /// The most the fused error grew within [`WILD_WINDOW_S`] of a wild fix, m.
    pub wild_move_m: Option<f64>,
    /// Status lines scored.
    #[serde(skip)]
    errors: [ByRegime; 3],
    /// Each run's drift at the end of the outage: fused, odometry alone, m.
    #[serde(skip)]
    drifts: Vec<(f64, f64)>,
}

impl ScenarioFigures {
    /// This run and `other` (the same scenario) as one: errors over both runs' samples, the
    /// outage drift as the RMS over the runs (and the worst run's), the worse jump error.
    fn pooled_with(mut self, other: ScenarioFigures) -> ScenarioFigures {
        for (mine, theirs) in self.errors.iter_mut().zip(&other.errors) {
            for (r, e) in theirs {
                mine.entry(*r).or_default().merge(e);
            }
        }
        let worst = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
        self.drifts.extend(other.drifts);
        let rms = |values: &mut dyn Iterator<Item = f64>| {
            let (sum, n) = values.fold((0.0, 0u32), |(s, n), v| (s + v * v, n + 1));
            (n > 0).then(|| (sum / f64::from(n)).sqrt())
        };
        self.outage_drift_m = rms(&mut self.drifts.iter().map(|d| d.0));
        self.outage_drift_odometry_m = rms(&mut self.drifts.iter().map(|d| d.1));
        self.outage_drift_worst_m = self.drifts.iter().map(|d| d.0).reduce(f64::max);
        self.jump_max_error_m = worst(self.jump_max_error_m, other.jump_max_error_m);
        self.jump_gnss_max_error_m = worst(self.jump_gnss_max_error_m, other.jump_gnss_max_error_m);
        self.wild_fixes += other.wild_fixes;
        self.wild_move_m = worst(self.wild_move_m, other.wild_move_m);
        let [fused, gnss, odometry] = &self.errors;
        self.fused = by_regime_name(fused);
        self.gnss_only = by_regime_name(gnss);
        self.odometry_only = by_regime_name(odometry);
        self
    }
}

/// Each regime's figures, by its name.
fn by_regime_name(m: &ByRegime) -> BTreeMap<&'static str, Figures> {
    m.iter()
        .map(|(r, e)| (regime_name(*r), e.figures()))
        .collect()
}

/// The whole benchmark's result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FusionReport {
    /// Plant name.
    pub plant: String,
    /// Noise seed.
    pub seed: u64,
    /// Monte Carlo runs of each scenario.
    pub runs: u32,
    /// Each scenario.
    pub scenarios: Vec<ScenarioFigures>,
    /// Fused / GNSS-only position RMSE in float, DGPS and single segments.
    pub degraded_ratio: Option<f64>,
    /// Fused / GNSS-only position RMSE while RTK-fixed.
    pub fixed_ratio: Option<f64>,
    /// Fused heading RMSE over every scored moment, degrees.
    pub heading_rmse_deg: Option<f64>,
    /// Drift at the end of an outage (RMS over the runs; the worst scenario), m.
    pub outage_drift_m: Option<f64>,
    /// Whether every jump was rejected.
    pub jump_rejected: bool,
    /// Wild fixes over every run.
    pub wild_fixes: usize,
    /// The most any of them moved the fused pose, m.
    pub wild_move_m: Option<f64>,
    /// Scenario and regime pairs whose mean NEES misses its target.
    pub nees_misses: Vec<String>,
    /// Every target met.
    pub pass: bool,
}

fn regime_name(r: Regime) -> &'static str {
    match r {
        Regime::Fixed => "fixed",
        Regime::Degraded => "degraded",
        Regime::Outage => "outage",
    }
}

/// What a scenario run keeps for scoring.
#[derive(Default)]
struct Collector {
    statuses: Vec<VehicleStatus>,
    gnss: Vec<(Timestamp, Bytes)>,
    rejected_commands: u64,
}

impl Sink for Collector {
    fn record(&mut self, record: &Record) {
        if record.source == GNSS_SOURCE
            && let Payload::Serial(bytes) = &record.payload
        {
            self.gnss.push((record.t, bytes.clone()));
        }
    }

    fn output(&mut self, output: EngineOutput) {
        match output {
            EngineOutput::Status(s) => self.statuses.push(*s),
            EngineOutput::CommandResult { result: Err(_), .. } => self.rejected_commands += 1,
            _ => {}
        }
    }
}

/// The truth at every plant step.
struct TruthLog {
    steps: Vec<Truth>,
}

impl TruthLog {
    fn at(&self, t: Timestamp) -> Option<Truth> {
        let step = PLANT_STEP.as_nanos() as u64;
        let k = t.saturating_since(START).as_nanos() as u64;
        // Round to the nearest step.
        let i = ((k + step / 2) / step) as usize;
        self.steps.get(i).copied()
    }
}

fn seconds(t: Timestamp) -> f64 {
    t.saturating_since(START).as_secs_f64()
}

/// Runs every scenario `runs` times (Monte Carlo runs, each with its own noise) on `plant`,
/// spread over the machine's cores, and pools each scenario's runs: errors and NEES are over
/// every sample of every run (NEES averaged over runs is the standard consistency test; one
/// run of a few minutes holds too few independent samples of a slowly wandering error), and
/// the outage drift is the RMS over runs and the jump error the worst run's. Each run's seed
/// comes from `seed`, the scenario's place in the catalogue and the run's, so the figures do
/// not depend on the number of threads, and a scenario run alone gives the figures it gives
/// among all.
pub fn run(
    plant: &PlantConfig,
    scenarios: &[Scenario],
    seed: u64,
    runs: u32,
) -> Result<FusionReport, ConfigError> {
    let runs = runs.max(1) as usize;
    let catalogue = Scenario::all();
    let places: Vec<u64> = scenarios
        .iter()
        .enumerate()
        .map(|(i, s)| catalogue.iter().position(|c| c.name == s.name).unwrap_or(i) as u64)
        .collect();
    let jobs = scenarios.len() * runs;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<ScenarioFigures, ConfigError>>>> =
        Mutex::new((0..jobs).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..threads.min(jobs) {
            scope.spawn(|| {
                loop {
                    let job = next.fetch_add(1, Ordering::Relaxed);
                    if job >= jobs {
                        break;
                    }
                    let (i, k) = (job / runs, job % runs);
                    let run_seed = seed
                        .wrapping_mul(1_000_000)
                        .wrapping_add(k as u64 * 1000 + places[i]);
                    let figures = run_scenario(plant, &scenarios[i], run_seed);
                    if let Ok(mut slots) = results.lock() {
                        slots[job] = Some(figures);
                    }
                }
            });
        }
    });
    let results = results.into_inner().unwrap_or_default();
    let mut figures = Vec::with_capacity(scenarios.len());
    let mut pending = results.into_iter();
    for _ in scenarios {
        let mut pooled: Option<ScenarioFigures> = None;
        for r in pending.by_ref().take(runs).flatten() {
            let r = r?;
            pooled = Some(match pooled {
                None => r,
                Some(p) => p.pooled_with(r),
            });
        }
        figures.extend(pooled);
    }
    Ok(report(plant, seed, runs as u32, figures))
}

/// A ramping gyro bias is configured as the bias walk that matches it over this span, s.
const RAMP_HORIZON_S: f64 = 60.0;

/// Drives one scenario and scores it.
pub fn run_scenario(
    plant: &PlantConfig,
    scenario: &Scenario,
    seed: u64,
) -> Result<ScenarioFigures, ConfigError> {
    let mut plant = plant.clone();
    if scenario.gyro_bias_ramp != 0.0 && plant.configured.gyro_bias_walk.is_none() {
        // The integrator of a gyro whose bias ramps (warming up) states a bias walk that
        // covers the ramp over a minute: a·t equals b·√t at t = 60 s.
        let covering = scenario.gyro_bias_ramp.abs() * RAMP_HORIZON_S.sqrt();
        plant.configured.gyro_bias_walk = Some(plant.imu.gyro_bias_walk.max(covering));
    }
    let mut sim = Lockstep::new(plant.clone(), seed, START)?;
    let mut sink = Collector::default();
    let steps = (scenario.duration_s() / PLANT_STEP.as_secs_f64()).round() as u64;
    let mut truth = TruthLog {
        steps: Vec::with_capacity(steps as usize + 1),
    };
    truth.steps.push(sim.vehicle().truth());
    while sim.steps() < steps {
        sim.step_scripted(scenario, &mut sink);
        truth.steps.push(sim.vehicle().truth());
    }
    if sink.rejected_commands > 0 {
        tracing::warn!(
            scenario = scenario.name,
            rejected = sink.rejected_commands,
            "commands refused"
        );
    }
    Ok(score(&plant, scenario, &sink, &truth, &sim))
}

fn score(
    plant: &PlantConfig,
    scenario: &Scenario,
    sink: &Collector,
    truth: &TruthLog,
    sim: &Lockstep,
) -> ScenarioFigures {
    let mut fused = ByRegime::new();
    let mut gnss = ByRegime::new();
    let mut odometry = ByRegime::new();
    let mut outage_drift = None;
    let mut outage_drift_odometry = None;
    let mut jump_max: Option<f64> = None;
    let mut jump_gnss_max: Option<f64> = None;
    let in_jump = |s: f64| {
        scenario
            .jump
            .is_some_and(|j| s >= j.from_s && s <= j.to_s + JUMP_SETTLE_S)
    };
    let outage_end = scenario.outage_end_s();

    // GNSS alone: each decoded epoch against the antenna's true position at the epoch. Wild
    // fixes are counted apart: one would swamp the RMSE and flatter the fused ratio.
    let mut wild_fixes = Vec::new();
    let frame = Enu::new(plant.datum());
    let utc_zero = sim.vehicle().utc_at(START);
    let [ax, ay] = plant.geometry.antenna;
    let mut receiver = GnssReceiver::new();
    for (t, bytes) in &sink.gnss {
        receiver.push(*t, bytes, |_| {});
        let fix = receiver.fix();
        let (Some(position), Some(utc)) = (fix.position, fix.utc) else {
            continue;
        };
        if position.rx != *t || !fix.quality.is_valid() {
            continue;
        }
        let Ok(since) = (utc - utc_zero).to_std() else {
            continue;
        };
        let epoch = START.saturating_add(since);
        let s = seconds(epoch);
        let Some(tr) = truth.at(epoch) else { continue };
        let p = &position.value;
        let h = p.height_above_ellipsoid_m();
        let enu = frame.to_enu(&Geodetic {
            lat_deg: p.latitude_deg,
            lon_deg: p.longitude_deg,
            h_m: h,
        });
        let (sn, c) = tr.yaw.sin_cos();
        let antenna = (tr.x + c * ax - sn * ay, tr.y + sn * ax + c * ay);
        let error = (enu.x - antenna.0).hypot(enu.y - antenna.1);
        if error > WILD_M {
            wild_fixes.push(*t);
            continue;
        }
        if s < WARMUP_S {
            continue;
        }
        if in_jump(s) {
            jump_gnss_max = Some(jump_gnss_max.map_or(error, |m| m.max(error)));
            continue;
        }
        let g = gnss.entry(scenario.regime_at(s)).or_default();
        g.position(error);
        let heading = match (fix.heading_deg, fix.velocity) {
            (Some(h), _) if h.rx == *t => Some(yaw_of_heading_deg(h.value)),
            (_, Some(v)) if v.rx == *t && v.value.speed_mps > COURSE_MIN_SPEED && tr.v > 0.0 => {
                v.value.course_deg.map(yaw_of_heading_deg)
            }
            _ => None,
        };
        if let Some(yaw) = heading {
            g.heading(wrap(yaw - tr.yaw));
        }
    }

    // Fused pose and dead reckoning, at every status.
    let mut wild_before: Vec<Option<f64>> = vec![None; wild_fixes.len()];
    let mut wild_move = None;
    let track = plant.geometry.track_m;
    let mut dead_reckoning = (0.0, 0.0, 0.0);
    let mut last_wheels: Option<(f64, f64)> = None;
    for status in &sink.statuses {
        let s = seconds(status.time);
        let Some(tr) = truth.at(status.time) else {
            continue;
        };
        if let Some(chassis) = &status.chassis {
            let (l, r) = (chassis.odometry.left_m, chassis.odometry.right_m);
            if let Some((l0, r0)) = last_wheels {
                let (dl, dr) = (l - l0, r - r0);
                let (x, y, yaw) = &mut dead_reckoning;
                let mid = *yaw + (dr - dl) / track / 2.0;
                *x += (dl + dr) / 2.0 * mid.cos();
                *y += (dl + dr) / 2.0 * mid.sin();
                *yaw = wrap(*yaw + (dr - dl) / track);
            }
            last_wheels = Some((l, r));
        }
        if s < WARMUP_S {
            continue;
        }
        let pose = status.pose;
        let error = (pose.x - tr.x).hypot(pose.y - tr.y);
        // How far the pose moves away from the truth after a wild fix, against just before.
        for (&wild, before) in wild_fixes.iter().zip(&mut wild_before) {
            if status.time < wild {
                *before = Some(error);
            } else if seconds(status.time) - seconds(wild) <= WILD_WINDOW_S {
                let moved = error - before.unwrap_or(error);
                wild_move = Some(wild_move.map_or(moved, |m: f64| m.max(moved)));
            }
        }
        let (dx, dy, dyaw) = dead_reckoning;
        let odometry_error = (dx - tr.x).hypot(dy - tr.y);
        if outage_end.is_some_and(|end| (s - end).abs() < 0.05) {
            outage_drift = Some(error);
            outage_drift_odometry = Some(odometry_error);
        }
        if in_jump(s) {
            jump_max = Some(jump_max.map_or(error, |m| m.max(error)));
            continue;
        }
        let regime = scenario.regime_at(s);
        let f = fused.entry(regime).or_default();
        f.position(error);
        f.heading(wrap(pose.yaw - tr.yaw));
        if let Some(cov) = &status.pose_covariance {
            f.nees((pose.x - tr.x, pose.y - tr.y), wrap(pose.yaw - tr.yaw), cov);
        }
        let o = odometry.entry(regime).or_default();
        o.position(odometry_error);
        o.heading(wrap(dyaw - tr.yaw));
    }

    ScenarioFigures {
        name: scenario.name.to_owned(),
        fused: by_regime_name(&fused),
        gnss_only: by_regime_name(&gnss),
        odometry_only: by_regime_name(&odometry),
        outage_drift_m: outage_drift,
        outage_drift_worst_m: outage_drift,
        outage_drift_odometry_m: outage_drift_odometry,
        jump_max_error_m: jump_max,
        jump_gnss_max_error_m: jump_gnss_max,
        wild_fixes: wild_fixes.len(),
        wild_move_m: wild_move,
        errors: [fused, gnss, odometry],
        drifts: outage_drift
            .zip(outage_drift_odometry)
            .into_iter()
            .collect(),
    }
}

fn report(
    plant: &PlantConfig,
    seed: u64,
    runs: u32,
    scenarios: Vec<ScenarioFigures>,
) -> FusionReport {
    let mut fused = ByRegime::new();
    let mut gnss = ByRegime::new();
    for s in &scenarios {
        for (r, e) in &s.errors[0] {
            fused.entry(*r).or_default().merge(e);
        }
        for (r, e) in &s.errors[1] {
            gnss.entry(*r).or_default().merge(e);
        }
    }
    let ratio = |r: Regime| {
        let f = fused.get(&r)?.figures().position_rmse_m?;
        let g = gnss.get(&r)?.figures().position_rmse_m?;
        (g > 0.0).then_some(f / g)
    };
    let mut all = Errors::default();
    for e in fused.values() {
        all.merge(e);
    }
    let degraded_ratio = ratio(Regime::Degraded);
    let fixed_ratio = ratio(Regime::Fixed);
    let heading_rmse_deg = all.figures().heading_rmse_deg;
    let outage_drift_m = scenarios
        .iter()
        .filter_map(|s| s.outage_drift_m)
        .reduce(f64::max);
    let jumps: Vec<f64> = scenarios
        .iter()
        .filter_map(|s| s.jump_max_error_m)
        .collect();
    let jump_rejected = !jumps.is_empty() && jumps.iter().all(|e| *e < JUMP_REJECTED_M);
    let wild_fixes = scenarios.iter().map(|s| s.wild_fixes).sum();
    let wild_move_m = scenarios
        .iter()
        .filter_map(|s| s.wild_move_m)
        .reduce(f64::max);
    let mut nees_misses = Vec::new();
    for s in &scenarios {
        for (regime, f) in &s.fused {
            for (what, value, range) in [
                ("position", f.nees_position, &target::NEES_POSITION),
                ("heading", f.nees_heading, &target::NEES_HEADING),
            ] {
                if value.is_some_and(|v| !range.contains(&v)) {
                    nees_misses.push(format!(
                        "{} {regime} {what} {:.2}",
                        s.name,
                        value.unwrap_or_default()
                    ));
                }
            }
        }
    }
    let pass = nees_misses.is_empty()
        && degraded_ratio.is_some_and(|r| r <= target::DEGRADED_RATIO)
        && fixed_ratio.is_some_and(|r| r <= target::FIXED_RATIO)
        && heading_rmse_deg.is_some_and(|h| h < target::HEADING_RMSE_DEG)
        && outage_drift_m.is_some_and(|d| d < target::OUTAGE_DRIFT_M)
        && jump_rejected
        && wild_move_m.is_none_or(|m| m <= target::WILD_MOVE_M);
    FusionReport {
        plant: plant.name.clone(),
        seed,
        runs,
        scenarios,
        degraded_ratio,
        fixed_ratio,
        heading_rmse_deg,
        outage_drift_m,
        jump_rejected,
        wild_fixes,
        wild_move_m,
        nees_misses,
        pass,
    }
}

impl FusionReport {
    /// The table, a line per scenario and regime, then the targets.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut out = String::new();
        let num = |v: Option<f64>, digits: usize| {
            v.map_or_else(|| "-".to_owned(), |v| format!("{v:.digits$}"))
        };
        let _ = writeln!(
            out,
            "fusion benchmark: plant {}, seed {}, {} runs of each scenario",
            self.plant, self.seed, self.runs
        );
        let _ = writeln!(
            out,
            "{:<11} {:<9} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8} {:>7} {:>7} {:>6}",
            "scenario",
            "regime",
            "fused m",
            "GNSS m",
            "odom m",
            "fused °",
            "GNSS °",
            "odom °",
            "NEES p",
            "NEES h",
            "n"
        );
        for s in &self.scenarios {
            for (regime, f) in &s.fused {
                let g = s.gnss_only.get(regime);
                let o = s.odometry_only.get(regime);
                let _ = writeln!(
                    out,
                    "{:<11} {:<9} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8} {:>7} {:>7} {:>6}",
                    s.name,
                    regime,
                    num(f.position_rmse_m, 3),
                    num(g.and_then(|g| g.position_rmse_m), 3),
                    num(o.and_then(|o| o.position_rmse_m), 3),
                    num(f.heading_rmse_deg, 2),
                    num(g.and_then(|g| g.heading_rmse_deg), 2),
                    num(o.and_then(|o| o.heading_rmse_deg), 2),
                    num(f.nees_position, 2),
                    num(f.nees_heading, 2),
                    f.samples,
                );
            }
            if let Some(d) = s.outage_drift_m {
                let _ = writeln!(
                    out,
                    "{:<11} drift at the end of the outage (RMS of the runs): fused {} m (worst {} m), odometry alone {} m",
                    s.name,
                    num(Some(d), 3),
                    num(s.outage_drift_worst_m, 3),
                    num(s.outage_drift_odometry_m, 3),
                );
            }
            if let Some(j) = s.jump_max_error_m {
                let _ = writeln!(
                    out,
                    "{:<11} largest error from the jump to {JUMP_SETTLE_S} s after: fused {} m, GNSS alone {} m",
                    s.name,
                    num(Some(j), 3),
                    num(s.jump_gnss_max_error_m, 3),
                );
            }
        }
        let verdict = |ok: bool| if ok { "ok" } else { "MISSED" };
        let _ = writeln!(
            out,
            "target: float/DGPS/single fused/GNSS RMSE {} <= {}: {}",
            num(self.degraded_ratio, 3),
            target::DEGRADED_RATIO,
            verdict(
                self.degraded_ratio
                    .is_some_and(|r| r <= target::DEGRADED_RATIO)
            ),
        );
        let _ = writeln!(
            out,
            "target: RTK-fixed fused/GNSS RMSE {} <= {}: {}",
            num(self.fixed_ratio, 3),
            target::FIXED_RATIO,
            verdict(self.fixed_ratio.is_some_and(|r| r <= target::FIXED_RATIO)),
        );
        let _ = writeln!(
            out,
            "target: heading RMSE {}° < {}°: {}",
            num(self.heading_rmse_deg, 3),
            target::HEADING_RMSE_DEG,
            verdict(
                self.heading_rmse_deg
                    .is_some_and(|h| h < target::HEADING_RMSE_DEG)
            ),
        );
        let _ = writeln!(
            out,
            "target: drift after a 30 s outage (RMS of the runs) {} m < {} m: {}",
            num(self.outage_drift_m, 3),
            target::OUTAGE_DRIFT_M,
            verdict(
                self.outage_drift_m
                    .is_some_and(|d| d < target::OUTAGE_DRIFT_M)
            ),
        );
        let _ = writeln!(
            out,
            "target: 5 m jump rejected (error stays under {JUMP_REJECTED_M} m): {}",
            verdict(self.jump_rejected),
        );
        let _ = writeln!(
            out,
            "target: {} wild fixes move the pose at most {} m <= {} m: {}",
            self.wild_fixes,
            num(self.wild_move_m, 3),
            target::WILD_MOVE_M,
            verdict(self.wild_move_m.is_none_or(|m| m <= target::WILD_MOVE_M)),
        );
        let _ = writeln!(
            out,
            "target: mean NEES within {:?} (position) and {:?} (heading) in every scenario and regime: {}{}",
            target::NEES_POSITION,
            target::NEES_HEADING,
            verdict(self.nees_misses.is_empty()),
            if self.nees_misses.is_empty() {
                String::new()
            } else {
                format!(" ({})", self.nees_misses.join(", "))
            }
        );
        out
    }

    /// The one-line JSON summary.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|e| format!(r#"{{"error":"{e}"}}"#))
    }
}

/// How long the plant runs for `scenarios`, for the throughput figure.
pub fn simulated_time(scenarios: &[Scenario]) -> Duration {
    Duration::from_secs_f64(scenarios.iter().map(Scenario::duration_s).sum())
}
