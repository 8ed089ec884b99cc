//! `husky-test1`: a Clearpath Husky's SBAS fixes (2.5 Hz), wheel odometry and IMU, 395 s
//! and 359 m on a campus, with one standstill (the data's README).
//!
//! The wheels' model comes from the data: the controller computed its yaw rate from the
//! wheel speeds over the Husky's 0.555 m track, and skid steering slips in turns, so the
//! wheels' yaw rate is a multiple of the gyro's. The configured track is 0.555 m times that
//! ratio (0.739): the effective track that turns the vehicle as the gyro saw it. The IMU is
//! mounted roll +90°, yaw −90°: the vehicle's yaw rate is the sensor's y axis. Each fix is a
//! GGA of quality 2 at its stamp; with [`Course::FromFixes`] an RMC follows with the speed
//! and course between it and the fix before, as a receiver without Doppler makes them.

use std::path::Path;

use crate::bench::error::{BenchError, Result};
use crate::config::chassis::WheelRadius;
use crate::devices::gnss::FixQuality;
use crate::geodesy::{Enu, Geodetic};
use crate::record::Record;
use crate::sim::plant::{ForcedMotion, PlantConfig};
use crate::time::Timestamp;

use super::data::{columns, sample_at, wheel_to_gyro_ratio};
use super::recording::{self, Epoch, Forced, Tick, at, distance, tick_at};
use super::{Figure, Options, Scratch, parallel};
use crate::fusion::planar::wrap;

/// The Husky's track, m (the data's README): the controller's separation.
const TRACK_M: f64 = 0.555;
/// Its wheel radius, m.
const WHEEL_RADIUS_M: f64 = 0.165;
/// GNSS cut at these times after the first fix, s, and a naive dead reckoning's final error
/// for each (the data's README), m.
const CUTS: [(f64, f64); 4] = [(30.0, 17.3), (60.0, 21.9), (120.0, 19.1), (250.0, 14.6)];
/// The standstill, s after the first fix.
const PARKED_S: (f64, f64) = (236.7, 246.2);
/// Wild fixes go on every fix of this window, s after the first fix.
const WILD_WINDOW_S: (f64, f64) = (100.0, 120.0);
/// The fixes' scatter bounds how close any filter follows them (the data's README), m.
const RMS_TARGET_M: f64 = 1.6;

/// Whether the receiver sends a course.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Course {
    /// GGA alone, as recorded.
    None,
    /// RMC with the speed and course between consecutive fixes.
    FromFixes,
}

/// One fix: s into the data, east and north of the first fix (m), its height and HDOP.
#[derive(Debug, Clone, Copy)]
struct Fix {
    s: f64,
    en: (f64, f64),
    h: f64,
    hdop: f64,
}

/// The data.
struct Data {
    /// s into the data, vx, wz (the wheels' yaw rate).
    odom: Vec<Vec<f64>>,
    /// s into the data, the vehicle's yaw rate.
    gyro: Vec<Vec<f64>>,
    fixes: Vec<Fix>,
    frame: Enu,
}

impl Data {
    fn load(dir: &Path) -> Result<Self> {
        let mut odom = columns(&dir.join("odom.csv"), &["t", "vx", "wz"])?;
        let mut gyro = columns(&dir.join("imu.csv"), &["t", "wy"])?;
        let gps = columns(
            &dir.join("gps.csv"),
            &["t", "latitude", "longitude", "altitude", "pos_cov_xx"],
        )?;
        let (Some(o), Some(i), Some(g)) = (odom.first(), gyro.first(), gps.first()) else {
            return Err(BenchError::Failed(format!(
                "{}: empty files",
                dir.display()
            )));
        };
        let t0 = o[0].min(i[0]).min(g[0]);
        let frame = Enu::new(Geodetic {
            lat_deg: g[1],
            lon_deg: g[2],
            h_m: g[3],
        });
        for row in odom.iter_mut().chain(gyro.iter_mut()) {
            row[0] -= t0;
        }
        let fixes = gps
            .iter()
            .map(|g| {
                let p = frame.to_enu(&Geodetic {
                    lat_deg: g[1],
                    lon_deg: g[2],
                    h_m: g[3],
                });
                Fix {
                    s: g[0] - t0,
                    en: (p.x, p.y),
                    h: g[3],
                    hdop: g[4].max(0.0).sqrt(),
                }
            })
            .collect();
        Ok(Self {
            odom,
            gyro,
            fixes,
            frame,
        })
    }

    fn first_fix_s(&self) -> f64 {
        self.fixes.first().map_or(0.0, |f| f.s)
    }

    /// The vehicle replaying the data; the effective track, m.
    fn forced(&self) -> Result<(Forced, f64)> {
        let ratio = wheel_to_gyro_ratio(&self.odom, &self.gyro);
        let track = TRACK_M * ratio;
        let mut plant = PlantConfig::builtin()?;
        plant.name = "husky-test1".into();
        let d = self.frame.datum();
        plant.datum = [d.lat_deg, d.lon_deg, d.h_m];
        plant.geometry.wheel_radius_m = WheelRadius::both(WHEEL_RADIUS_M);
        plant.geometry.track_m = track;
        plant.geometry.antenna = [0.0, 0.0];
        plant.imu.rate_hz = 30.0;
        // The drives' boot is a standstill before the data: the simulated gyro reads zero
        // there, so only the data's own standstill teaches the odom frame a bias.
        plant.imu.gyro_bias_rps = 0.0;
        plant.imu.gyro_noise_rps = 0.0;
        plant.slip.bias = [0.0, 0.0];
        plant.slip.sigma = 0.0;
        let mut times: Vec<f64> = self.odom.iter().chain(&self.gyro).map(|r| r[0]).collect();
        times.sort_by(f64::total_cmp);
        times.dedup();
        let motion = times
            .into_iter()
            .map(|s| {
                let o = sample_at(&self.odom, s);
                (
                    s,
                    ForcedMotion {
                        v: o[1],
                        wheel_yaw_rate: o[2] * TRACK_M / track,
                        gyro_z: sample_at(&self.gyro, s)[1],
                    },
                )
            })
            .collect();
        Ok((
            Forced {
                plant,
                localization: toml::Table::new(),
                motion,
            },
            track,
        ))
    }

    /// The receiver's records: every fix before `cut` (s after the first fix), `wild` moving
    /// one by (east, north) m.
    fn records(
        &self,
        course: Course,
        cut: Option<f64>,
        wild: Option<(usize, (f64, f64))>,
    ) -> Vec<Record> {
        let first = self.first_fix_s();
        self.fixes
            .iter()
            .enumerate()
            .filter(|(_, f)| cut.is_none_or(|c| f.s - first < c))
            .map(|(i, f)| {
                let moved = wild.filter(|(w, _)| *w == i).map_or((0.0, 0.0), |(_, d)| d);
                let en = (f.en.0 + moved.0, f.en.1 + moved.1);
                let g = self.frame.to_geodetic(&nalgebra::Vector3::new(
                    en.0,
                    en.1,
                    f.h - self.frame.datum().h_m,
                ));
                let velocity = match (course, i.checked_sub(1).map(|p| self.fixes[p])) {
                    (Course::FromFixes, Some(p)) if f.s > p.s => {
                        let (de, dn) = (f.en.0 - p.en.0, f.en.1 - p.en.1);
                        Some((de.hypot(dn) / (f.s - p.s), de.atan2(dn).to_degrees()))
                    }
                    _ => None,
                };
                let t = at(f.s);
                Epoch {
                    utc_us: t.as_micros() as i64,
                    quality: FixQuality::Dgps,
                    position: (g.lat_deg, g.lon_deg, g.h_m),
                    hdop: f.hdop,
                    velocity,
                }
                .record(t)
            })
            .collect()
    }

    /// The recording time of `s` seconds after the first fix.
    fn after_first(&self, s: f64) -> Timestamp {
        at(self.first_fix_s() + s)
    }
}

/// Largest distance the map pose moves within (from, to) from where it was at `from`.
fn moved_within(ticks: &[Tick], from: Timestamp, to: Timestamp) -> f64 {
    let Some(start) = tick_at(ticks, from).and_then(|k| k.map) else {
        return f64::INFINITY;
    };
    ticks
        .iter()
        .filter(|k| k.t >= from && k.t <= to)
        .filter_map(|k| k.map)
        .map(|p| distance((p.0, p.1), (start.0, start.1)))
        .fold(0.0, f64::max)
}

/// One outage's replay: the map pose's final distance to the last fix, and how far the map
/// heading ever turned after the cut from the odom frame's heading carried from the cut (in
/// an outage it turns exactly as the gyro does).
fn outage(ticks: &[Tick], cut: Timestamp, last_fix: (f64, f64)) -> (f64, f64) {
    let end = ticks
        .last()
        .and_then(|k| k.map)
        .map_or(f64::INFINITY, |p| distance((p.0, p.1), last_fix));
    let Some(rotation) = tick_at(ticks, cut).and_then(|k| k.correction).map(|c| c.2) else {
        return (end, f64::INFINITY);
    };
    let turned = ticks
        .iter()
        .filter(|k| k.t > cut)
        .filter_map(|k| Some(wrap(k.map?.2 - k.odom?.2 - rotation).abs()))
        .fold(0.0, f64::max);
    (end, turned)
}

/// Writes the data at `dir` with `course` as a recording folder at `out`; the receiver's
/// records it holds.
pub fn write_recording(dir: &Path, course: Course, out: &Path) -> Result<Vec<Record>> {
    let data = Data::load(dir)?;
    let (forced, _) = data.forced()?;
    let clean = data.records(course, None, None);
    recording::write(out, &forced, &clean)?;
    Ok(clean)
}

/// The figures of `dir` with `course`.
pub fn figures(dir: &Path, course: Course, options: &Options) -> Result<Vec<Figure>> {
    let workers = options.workers;
    let data = Data::load(dir)?;
    let vehicle = match course {
        Course::None => "husky-test1",
        Course::FromFixes => "husky-test1, course from the fixes",
    };
    let scratch = Scratch::new("husky")?;
    let clean = write_recording(dir, course, scratch.path())?;
    let dir = scratch.path();
    let Some(last_fix) = data.fixes.last().map(|f| f.en) else {
        return Err(BenchError::Failed("husky-test1: no fixes".into()));
    };
    let full = recording::replay(dir, &clean)?;
    if let Some(path) = options.trace_file(vehicle) {
        // Scored against the latest fix.
        let fixes: Vec<(Timestamp, (f64, f64))> =
            data.fixes.iter().map(|f| (at(f.s), f.en)).collect();
        recording::write_trace(&path, &full, data.after_first(0.0), (0.0, 0.0), |t| {
            let i = fixes.partition_point(|(ft, _)| *ft <= t);
            fixes.get(i.checked_sub(1)?).map(|(_, en)| *en)
        })?;
    }
    let figure = |name: String, value: f64, target: f64, naive: Option<f64>, unit| Figure {
        vehicle: vehicle.into(),
        name,
        value,
        target,
        naive,
        unit,
    };
    let mut out = Vec::new();
    // The whole run: the pose's distance to each fix before it is applied.
    let squares: Vec<f64> = clean
        .iter()
        .zip(&data.fixes)
        .skip(1)
        .filter_map(|(r, f)| {
            let p = tick_at(&full, r.t)?.map?;
            Some(distance((p.0, p.1), f.en).powi(2))
        })
        .collect();
    let rms = if squares.len() + 1 < data.fixes.len() * 9 / 10 {
        f64::INFINITY
    } else {
        (squares.iter().sum::<f64>() / squares.len() as f64).sqrt()
    };
    out.push(figure(
        "whole run: pose to each fix before it is applied, RMS".into(),
        rms,
        RMS_TARGET_M,
        None,
        "m",
    ));
    if course == Course::None {
        let known = full
            .iter()
            .find(|k| k.yaw_sigma.is_some_and(|s| s <= 5f64.to_radians()))
            .map_or(f64::INFINITY, |k| {
                k.t.saturating_since(data.after_first(0.0)).as_secs_f64()
            });
        out.push(figure(
            "heading known (1σ ≤ 5°), no course: after the first fix".into(),
            known,
            60.0,
            None,
            "s",
        ));
    }
    out.push(figure(
        "parked 9.5 s: the pose moved, with GNSS".into(),
        moved_within(
            &full,
            data.after_first(PARKED_S.0),
            data.after_first(PARKED_S.1),
        ),
        0.3,
        None,
        "m",
    ));

    // GNSS cut: one replay per cut, with the pose's move while parked when the cut comes
    // before the standstill.
    type Cut<'a> = Box<dyn FnOnce() -> Result<(f64, f64, Option<f64>)> + Send + 'a>;
    let cut_jobs: Vec<Cut> = CUTS
        .iter()
        .map(|&(cut_s, _)| {
            let data = &data;
            Box::new(move || {
                let cut = data.after_first(cut_s);
                let ticks = recording::replay(dir, &data.records(course, Some(cut_s), None))?;
                let (end, carried) = outage(&ticks, cut, last_fix);
                let parked = (cut_s < PARKED_S.0).then(|| {
                    moved_within(
                        &ticks,
                        data.after_first(PARKED_S.0),
                        data.after_first(PARKED_S.1),
                    )
                });
                Ok((end, carried, parked))
            }) as Cut
        })
        .collect();
    let mut parked_without: f64 = 0.0;
    let mut carried_max: f64 = 0.0;
    for (&(cut_s, naive), result) in CUTS.iter().zip(parallel(workers, cut_jobs)) {
        let (end, carried, parked) = result?;
        out.push(figure(
            format!("GNSS cut at {cut_s:.0} s: end to the last fix"),
            end,
            naive,
            Some(naive),
            "m",
        ));
        carried_max = carried_max.max(carried);
        if let Some(p) = parked {
            parked_without = parked_without.max(p);
        }
    }
    out.push(figure(
        "GNSS cut: the map heading off the gyro's (odom) turn since the cut, at most".into(),
        carried_max,
        1e-9,
        None,
        "rad",
    ));
    out.push(figure(
        "parked 9.5 s: the pose moved, without GNSS".into(),
        parked_without,
        0.05,
        None,
        "m",
    ));

    // Wild fixes: each fix of the window moved 100 to 1000 m, one replay each; the pose
    // never moves more than 0.5 m from the clean run's for it.
    let window: Vec<usize> = (0..data.fixes.len())
        .filter(|&i| {
            let s = data.fixes[i].s - data.first_fix_s();
            (WILD_WINDOW_S.0..=WILD_WINDOW_S.1).contains(&s)
        })
        .collect();
    type Wild<'a> = Box<dyn FnOnce() -> Result<f64> + Send + 'a>;
    let wild_jobs: Vec<Wild> = window
        .iter()
        .enumerate()
        .map(|(k, &i)| {
            let (data, full) = (&data, &full);
            Box::new(move || {
                // Distances 100–1000 m, directions by the golden angle.
                let far = 100.0 + 900.0 * ((k as f64 * 0.618_034) % 1.0);
                let (s, c) = (k as f64 * 2.399_963).sin_cos();
                let ticks = recording::replay(
                    dir,
                    &data.records(course, None, Some((i, (far * c, far * s)))),
                )?;
                Ok(ticks
                    .iter()
                    .zip(full)
                    .filter_map(|(a, b)| {
                        let (a, b) = (a.map?, b.map?);
                        Some(distance((a.0, a.1), (b.0, b.1)))
                    })
                    .fold(0.0, f64::max))
            }) as Wild
        })
        .collect();
    let mut wild_max: f64 = 0.0;
    for off in parallel(workers, wild_jobs) {
        wild_max = wild_max.max(off?);
    }
    out.push(figure(
        format!(
            "{} wild fixes (100–1000 m, one per replay, {:.0}–{:.0} s): the pose moved",
            window.len(),
            WILD_WINDOW_S.0,
            WILD_WINDOW_S.1
        ),
        if window.len() >= 45 {
            wild_max
        } else {
            f64::INFINITY
        },
        0.5,
        None,
        "m",
    ));
    Ok(out)
}
