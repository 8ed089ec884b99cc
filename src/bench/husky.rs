//! `chassisd bench husky`: the map filter on a real robot's data (`../shared/data/ekf/
//! husky-test1`: a Husky's SBAS fixes, wheel odometry and IMU, 395 s and 359 m). The wheels
//! and gyro go through chassisd's own `odom` frame, the fixes through the map filter, and
//! the figures are the ones the localisation is held to: the final error of GNSS outages
//! against the odom frame's dead reckoning from the same moment, the whole run's distance to
//! the fixes, the parked pose, and wild fixes put on every fix of a window.

use std::path::Path;

use crate::bench::error::BenchError;
use serde::Serialize;

use crate::fusion::map_filter::{Fix, MapFilter, MapFilterConfig, PointPair, Trust, rigid_fit};
use crate::fusion::odometry::{OdomPose, Odometry, WheelReading};
use crate::geodesy::{Enu, Geodetic};
use crate::time::Timestamp;

/// The Husky's track, m (its README).
pub const TRACK_M: f64 = 0.555;
/// GNSS cut at these times after the first fix, s.
pub const CUTS_S: [f64; 4] = [30.0, 60.0, 120.0, 250.0];
/// A naive dead reckoning's final error for each cut (the data's README), m.
pub const NAIVE_M: [f64; 4] = [17.3, 21.9, 19.1, 14.6];
/// The odom frame's dead reckoning is placed by fitting it to this much of the fixes before
/// a cut, s.
const PLACE_WINDOW_S: f64 = 30.0;
/// The standstill, s after the first fix.
pub const PARKED_S: (f64, f64) = (236.7, 246.2);
/// Wild fixes go on every fix of this window, s after the first fix.
pub const WILD_WINDOW_S: (f64, f64) = (100.0, 120.0);
/// The 1σ a DGPS (SBAS) fix gets in chassisd by quality, m.
const DGPS_SIGMA_M: f64 = 0.8;

/// One input, in time order.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Input {
    Wheels { v: f64, w: f64 },
    Gyro { wz: f64 },
    Fix { e: f64, n: f64 },
}

/// The recording, in the local frame of its first fix.
#[derive(Debug, Clone)]
pub struct HuskyData {
    inputs: Vec<(f64, Input)>,
}

pub use crate::bench::real::data::columns;

impl HuskyData {
    /// Loads `dir` (gps.csv, odom.csv, imu.csv). The IMU is mounted roll +90°, yaw −90°: the
    /// vehicle's yaw rate is the sensor's y axis.
    pub fn load(dir: &Path) -> crate::bench::error::Result<Self> {
        let gps = columns(
            &dir.join("gps.csv"),
            &["t", "latitude", "longitude", "altitude"],
        )?;
        let odom = columns(&dir.join("odom.csv"), &["t", "vx", "wz"])?;
        let imu = columns(&dir.join("imu.csv"), &["t", "wy"])?;
        let Some(first) = gps.first() else {
            return Err(BenchError::Failed(format!("{}: no fixes", dir.display())));
        };
        let t0 = first[0];
        let frame = Enu::new(Geodetic {
            lat_deg: first[1],
            lon_deg: first[2],
            h_m: first[3],
        });
        let mut inputs: Vec<(f64, Input)> = Vec::new();
        for g in &gps {
            let enu = frame.to_enu(&Geodetic {
                lat_deg: g[1],
                lon_deg: g[2],
                h_m: g[3],
            });
            inputs.push((g[0] - t0, Input::Fix { e: enu.x, n: enu.y }));
        }
        for o in &odom {
            inputs.push((o[0] - t0, Input::Wheels { v: o[1], w: o[2] }));
        }
        for i in &imu {
            inputs.push((i[0] - t0, Input::Gyro { wz: i[1] }));
        }
        inputs.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(Self { inputs })
    }

    /// The wheels' speed along the gyro's heading, the gyro's bias taken from the parked
    /// standstill, from the origin facing east: time, x, y at every wheel sample. A reference
    /// track for the fixes' errors (see `gnss_fit`).
    pub fn dead_reckoning(&self) -> Vec<(f64, f64, f64)> {
        let parked: Vec<f64> = self
            .inputs
            .iter()
            .filter(|(t, _)| (PARKED_S.0..=PARKED_S.1).contains(t))
            .filter_map(|(_, i)| match i {
                Input::Gyro { wz } => Some(*wz),
                _ => None,
            })
            .collect();
        let bias = parked.iter().sum::<f64>() / parked.len().max(1) as f64;
        let (mut x, mut y, mut yaw) = (0.0, 0.0, 0.0);
        let mut last_gyro: Option<(f64, f64)> = None;
        let mut last_wheels: Option<(f64, f64)> = None;
        let mut track = Vec::new();
        for &(t, input) in &self.inputs {
            match input {
                Input::Gyro { wz } => {
                    if let Some((t0, w0)) = last_gyro {
                        yaw += ((w0 + wz) / 2.0 - bias) * (t - t0);
                    }
                    last_gyro = Some((t, wz));
                }
                Input::Wheels { v, .. } => {
                    if let Some((t0, v0)) = last_wheels {
                        let d = (v0 + v) / 2.0 * (t - t0);
                        x += d * yaw.cos();
                        y += d * yaw.sin();
                    }
                    last_wheels = Some((t, v));
                    track.push((t, x, y));
                }
                Input::Fix { .. } => {}
            }
        }
        track
    }

    /// The fixes: time after the first, east, north.
    pub fn fixes(&self) -> Vec<(f64, f64, f64)> {
        self.inputs
            .iter()
            .filter_map(|(t, i)| match i {
                Input::Fix { e, n } => Some((*t, *e, *n)),
                _ => None,
            })
            .collect()
    }
}

/// What one run changes in the data.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Variant {
    /// No fix from this time on, s.
    pub cut_at: Option<f64>,
    /// The fix at this index moved by (east, north) m.
    pub wild: Option<(usize, (f64, f64))>,
}

/// One pose of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Time after the first fix, s.
    pub t: f64,
    /// The odom frame's pose.
    pub odom: OdomPose,
    /// The map pose, once placed.
    pub map: Option<(f64, f64, f64)>,
}

/// A run's poses, one per wheel reading, and the map filter at its end.
pub struct Run {
    /// The poses.
    pub samples: Vec<Sample>,
    /// The filter.
    pub filter: MapFilter,
    /// Before each fix was given: the map pose's distance to it (its time, metres).
    pub to_fixes: Vec<(f64, f64)>,
    /// When the heading was first known to 5° (1σ), s after the first fix.
    pub heading_known_at: Option<f64>,
}

fn at(t: f64) -> Timestamp {
    // Times after the first fix, offset so that a little before it is positive.
    Timestamp::from_micros(((t + 10.0) * 1e6).round().max(0.0) as u64)
}

/// Runs the data through chassisd's odom frame and the map filter.
pub fn run(data: &HuskyData, config: MapFilterConfig, variant: Variant) -> Run {
    let mut odometry = Odometry::new(TRACK_M, config.bias_walk);
    let mut filter = MapFilter::new(config);
    let mut samples = Vec::new();
    let mut to_fixes = Vec::new();
    let mut heading_known_at = None;
    let mut fix_index = 0;
    for &(t, input) in &data.inputs {
        match input {
            Input::Gyro { wz } => odometry.gyro(at(t), wz),
            Input::Wheels { v, w } => {
                let half = w * TRACK_M / 2.0;
                odometry.wheels(
                    at(t),
                    WheelReading {
                        speeds: (v - half, v + half),
                        travel: None,
                    },
                );
                if let Some(pose) = odometry.pose() {
                    filter.odom(at(t), pose);
                    samples.push(Sample {
                        t,
                        odom: pose,
                        map: filter.pose(),
                    });
                }
                if heading_known_at.is_none()
                    && filter.is_started()
                    && filter.yaw_sigma() <= 5f64.to_radians()
                {
                    heading_known_at = Some(t);
                }
            }
            Input::Fix { e, n } => {
                let index = fix_index;
                fix_index += 1;
                if variant.cut_at.is_some_and(|c| t >= c) {
                    continue;
                }
                let (e, n) = match variant.wild {
                    Some((i, (de, dn))) if i == index => (e + de, n + dn),
                    _ => (e, n),
                };
                if let Some(pose) = odometry.pose()
                    && let Some((x, y, _)) = filter.map_pose_of(&pose)
                {
                    to_fixes.push((t, (x - e).hypot(y - n)));
                }
                filter.fix(Fix {
                    t: at(t),
                    en: (e, n),
                    sigma: (DGPS_SIGMA_M, DGPS_SIGMA_M),
                    trust: Trust::UnderWheels,
                    corrected: true,
                });
            }
        }
    }
    Run {
        samples,
        filter,
        to_fixes,
        heading_known_at,
    }
}

/// The odom frame's dead reckoning from `cut`, placed by a rigid fit of its path over the
/// [`PLACE_WINDOW_S`] before the cut to the fixes there: its final position.
pub fn odom_from(run: &Run, fixes: &[(f64, f64, f64)], cut: f64) -> Option<(f64, f64)> {
    let from = (cut - PLACE_WINDOW_S).max(0.0);
    let mut pairs: Vec<PointPair> = Vec::new();
    for &(t, e, n) in fixes.iter().filter(|f| f.0 >= from && f.0 < cut) {
        let i = run.samples.partition_point(|s| s.t < t);
        let s = run.samples.get(i)?;
        pairs.push(((s.odom.x, s.odom.y), (e, n)));
    }
    let last = run.samples.last()?.odom;
    Some(rigid_fit(&pairs)?.apply((last.x, last.y)))
}

/// The odom frame's dead reckoning from the map pose after the last fix before `cut`: its
/// final position.
fn odom_from_map_pose(run: &Run, fixes: &[(f64, f64, f64)], cut: f64) -> Option<(f64, f64)> {
    let last_fix = fixes.iter().rev().find(|f| f.0 < cut)?.0;
    let i = run.samples.partition_point(|s| s.t <= last_fix);
    let at_cut = run.samples.get(i)?;
    let (mx, my, myaw) = at_cut.map?;
    let (o, end) = (at_cut.odom, run.samples.last()?.odom);
    // The odom increment from the cut to the end, in the vehicle frame at the cut.
    let (so, co) = o.yaw.sin_cos();
    let (dx, dy) = (end.x - o.x, end.y - o.y);
    let (fwd, left) = (co * dx + so * dy, -so * dx + co * dy);
    let (s, c) = myaw.sin_cos();
    Some((mx + c * fwd - s * left, my + s * fwd + c * left))
}

/// One outage's figures.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Outage {
    /// GNSS cut at, s after the first fix.
    pub cut_s: f64,
    /// The map pose's final distance to the last fix, m.
    pub map_m: f64,
    /// The odom frame's dead reckoning from the map pose at the cut, m: what the map pose
    /// must not be worse than.
    pub odom_m: f64,
    /// The odom frame's dead reckoning from the cut, placed by a rigid fit of its path to
    /// the fixes of the 30 s before it (the best start the fixes alone give), m.
    pub odom_fitted_m: f64,
    /// The naive figure of the data's README, m.
    pub naive_m: f64,
}

/// The figures.
#[derive(Debug, Clone, Serialize)]
pub struct HuskyReport {
    /// The outages.
    pub outages: Vec<Outage>,
    /// The map pose's RMS distance to the fixes, over the whole run once placed, m.
    pub rms_to_fixes_m: f64,
    /// How far the parked pose moved through the standstill, with GNSS, m.
    pub parked_with_gnss_m: f64,
    /// The same with GNSS cut as it stops, m.
    pub parked_without_gnss_m: f64,
    /// Wild fixes tried (one per replay).
    pub wild_runs: usize,
    /// The most any of them moved the pose from the clean run's, m.
    pub wild_max_m: f64,
    /// When the heading was first known (1σ ≤ 5°), s after the first fix.
    pub heading_known_s: Option<f64>,
    /// The fixes' mean normalised innovation squared per degree of freedom (1 when the
    /// noise model fits the data).
    pub mean_nis: Option<f64>,
    /// Fixes taken.
    pub taken: u64,
    /// Fixes dropped.
    pub dropped: u64,
    /// Fixes that widened the filter.
    pub widened: u64,
}

fn moved_while_parked(run: &Run) -> f64 {
    let parked: Vec<(f64, f64)> = run
        .samples
        .iter()
        .filter(|s| s.t >= PARKED_S.0 && s.t <= PARKED_S.1)
        .filter_map(|s| s.map.map(|(x, y, _)| (x, y)))
        .collect();
    let Some(first) = parked.first() else {
        return f64::NAN;
    };
    parked
        .iter()
        .map(|p| (p.0 - first.0).hypot(p.1 - first.1))
        .fold(0.0, f64::max)
}

/// Every figure on `data` with `config`.
pub fn report(data: &HuskyData, config: MapFilterConfig) -> HuskyReport {
    let fixes = data.fixes();
    let last_fix = fixes.last().copied().unwrap_or_default();
    let clean = run(data, config, Variant::default());
    let outages = CUTS_S
        .iter()
        .zip(NAIVE_M)
        .map(|(&cut_s, naive_m)| {
            let r = run(
                data,
                config,
                Variant {
                    cut_at: Some(cut_s),
                    ..Variant::default()
                },
            );
            let (x, y, _) =
                r.samples
                    .last()
                    .and_then(|s| s.map)
                    .unwrap_or((f64::NAN, f64::NAN, 0.0));
            let fitted = odom_from(&clean, &fixes, cut_s).unwrap_or((f64::NAN, f64::NAN));
            let from_map = odom_from_map_pose(&r, &fixes, cut_s).unwrap_or((f64::NAN, f64::NAN));
            Outage {
                cut_s,
                map_m: (x - last_fix.1).hypot(y - last_fix.2),
                odom_m: (from_map.0 - last_fix.1).hypot(from_map.1 - last_fix.2),
                odom_fitted_m: (fitted.0 - last_fix.1).hypot(fitted.1 - last_fix.2),
                naive_m,
            }
        })
        .collect();
    let placed: Vec<f64> = clean.to_fixes.iter().map(|(_, d)| *d).collect();
    let rms_to_fixes_m =
        (placed.iter().map(|d| d * d).sum::<f64>() / placed.len().max(1) as f64).sqrt();
    let parked_without = run(
        data,
        config,
        Variant {
            cut_at: Some(PARKED_S.0),
            ..Variant::default()
        },
    );
    let mut wild_max_m: f64 = 0.0;
    let mut wild_runs = 0;
    for (i, &(t, _, _)) in fixes.iter().enumerate() {
        if t < WILD_WINDOW_S.0 || t > WILD_WINDOW_S.1 {
            continue;
        }
        // 100 to 1000 m off, in turning directions.
        let k = wild_runs as f64;
        let distance = 100.0 + (k * 137.0) % 900.0;
        let angle = k * 2.399;
        let r = run(
            data,
            config,
            Variant {
                wild: Some((i, (distance * angle.cos(), distance * angle.sin()))),
                ..Variant::default()
            },
        );
        wild_runs += 1;
        for (a, b) in r.samples.iter().zip(&clean.samples) {
            if let (Some(p), Some(q)) = (a.map, b.map) {
                wild_max_m = wild_max_m.max((p.0 - q.0).hypot(p.1 - q.1));
            }
        }
    }
    let stats = clean.filter.stats();
    HuskyReport {
        outages,
        rms_to_fixes_m,
        parked_with_gnss_m: moved_while_parked(&clean),
        parked_without_gnss_m: moved_while_parked(&parked_without),
        wild_runs,
        wild_max_m,
        heading_known_s: clean.heading_known_at,
        mean_nis: clean.filter.mean_nis(),
        taken: stats.taken,
        dropped: stats.dropped,
        widened: stats.widened,
    }
}

impl std::fmt::Display for HuskyReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "| GNSS cut at | map pose | odom frame from the map pose | odom frame fitted to 30 s of fixes | naive |"
        )?;
        writeln!(f, "|---|---|---|---|---|")?;
        for o in &self.outages {
            writeln!(
                f,
                "| {:.0} s | {:.2} m | {:.2} m | {:.1} m | {:.1} m |",
                o.cut_s, o.map_m, o.odom_m, o.odom_fitted_m, o.naive_m
            )?;
        }
        writeln!(
            f,
            "RMS to the fixes {:.2} m; parked pose moved {:.3} m with GNSS, {:.3} m without; \
             {} wild fixes, the pose moved at most {:.3} m for them; heading known (1σ ≤ 5°) at \
             {}; fixes' mean NIS per degree of freedom {}; fixes taken {}, dropped {}, widened {}",
            self.rms_to_fixes_m,
            self.parked_with_gnss_m,
            self.parked_without_gnss_m,
            self.wild_runs,
            self.wild_max_m,
            self.heading_known_s
                .map_or("never".into(), |t| format!("{t:.1} s")),
            self.mean_nis.map_or("-".into(), |n| format!("{n:.2}")),
            self.taken,
            self.dropped,
            self.widened
        )
    }
}
