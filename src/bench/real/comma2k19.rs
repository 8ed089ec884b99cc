//! `comma2k19-rav4`: a Toyota RAV4 on a highway (comma2k19), 60 s and 1 km at 8–20 m/s: a
//! plain u-blox receiver's single fixes at 10 Hz with its own speed and course (Doppler),
//! four wheel speeds, a phone-grade gyro, and the dataset's post-processed pose to score
//! against (the data's README).
//!
//! The rear wheels are the drive train: a rear axle turns like two wheels of a
//! differential drive 1.57 m apart, and the vehicle's reference point is its centre. The
//! gyro is the bias-corrected one (its axes forward, right, down: the yaw rate is minus z).
//! The receiver's antenna (the recording device, and the reference's point) sits on the
//! windscreen about 1.3 m ahead of the rear axle. Each fix becomes a GGA of quality 1 and an
//! RMC with the receiver's speed and course, written when it arrived; its position is true
//! about 0.085 s before that (the README's measurement), which the vehicle's configuration
//! says as `gnss_latency_s`, as an integrator would after measuring it.

use std::path::Path;

use nalgebra::Vector3;

use crate::bench::error::{BenchError, Result};
use crate::config::chassis::WheelRadius;
use crate::devices::gnss::FixQuality;
use crate::geodesy::{Enu, Geodetic};
use crate::record::Record;
use crate::sim::plant::{ForcedMotion, PlantConfig};

use super::data::{columns, sample_at};
use super::recording::{self, Epoch, Forced, Tick, at, distance};
use super::{Figure, Options, Scratch, parallel};

/// The rear track, m (the README).
const TRACK_M: f64 = 1.57;
/// The tyres' radius, m (225/65R17).
const WHEEL_RADIUS_M: f64 = 0.362;
/// The antenna ahead of the rear axle, m.
const ANTENNA_X_M: f64 = 1.3;
/// How long before its arrival a fix is true, s (the README's measurement).
const LATENCY_S: f64 = 0.085;
/// GNSS cut at these times after the first fix, s.
const CUTS_S: [f64; 3] = [20.0, 30.0, 40.0];
/// Wild fixes go on every fix of this window, s after the first fix.
const WILD_WINDOW_S: (f64, f64) = (10.0, 14.0);

/// One fix as it arrived: s into the data, east and north of the first fix (m), height (m),
/// the receiver's speed (m/s) and course (degrees), and its UTC time (ms).
#[derive(Debug, Clone, Copy)]
struct Fix {
    s: f64,
    en: (f64, f64),
    h: f64,
    speed: f64,
    course: f64,
    utc_ms: f64,
}

/// The data.
struct Data {
    /// s into the data, rear left, rear right (m/s).
    wheels: Vec<Vec<f64>>,
    /// s into the data, the yaw rate (rad/s, counter-clockwise).
    gyro: Vec<Vec<f64>>,
    fixes: Vec<Fix>,
    /// s into the data, the reference point's east, north (m) and its yaw from its
    /// velocity (rad).
    reference: Vec<Vec<f64>>,
    frame: Enu,
}

impl Data {
    fn load(dir: &Path) -> Result<Self> {
        let mut wheels = columns(
            &dir.join("wheel_speed.csv"),
            &["t", "rear_left_mps", "rear_right_mps"],
        )?;
        let mut gyro = columns(&dir.join("imu.csv"), &["t", "gyro_z"])?;
        let gnss = columns(
            &dir.join("gnss.csv"),
            &[
                "t",
                "latitude",
                "longitude",
                "altitude_m",
                "speed_mps",
                "bearing_deg",
                "utc_ms",
            ],
        )?;
        let reference = columns(
            &dir.join("reference.csv"),
            &[
                "t",
                "ecef_x",
                "ecef_y",
                "ecef_z",
                "vel_ecef_x",
                "vel_ecef_y",
                "vel_ecef_z",
            ],
        )?;
        let (Some(w), Some(i), Some(g)) = (wheels.first(), gyro.first(), gnss.first()) else {
            return Err(BenchError::Failed(format!(
                "{}: empty files",
                dir.display()
            )));
        };
        if reference.len() < 2 {
            return Err(BenchError::Failed(format!(
                "{}: no reference",
                dir.display()
            )));
        }
        let t0 = w[0].min(i[0]).min(g[0]);
        let frame = Enu::new(Geodetic {
            lat_deg: g[1],
            lon_deg: g[2],
            h_m: g[3],
        });
        // The data ends with the reference: what follows cannot be scored.
        let end = reference.last().map_or(0.0, |r| r[0]);
        wheels.retain(|w| w[0] <= end);
        gyro.retain(|g| g[0] <= end);
        for row in wheels.iter_mut() {
            row[0] -= t0;
        }
        for row in gyro.iter_mut() {
            row[0] -= t0;
            // Axes forward, right, down: counter-clockwise about up is minus z.
            row[1] = -row[1];
        }
        let fixes = gnss
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
                    speed: g[4],
                    course: g[5],
                    utc_ms: g[6],
                }
            })
            .collect();
        let reference = reference
            .iter()
            .map(|r| {
                let p = frame.to_enu(&Geodetic::from_ecef(&Vector3::new(r[1], r[2], r[3])));
                let d = frame.datum();
                // The velocity turned into east, north at the datum (1 km: the frames
                // differ by 0.01°).
                let (slat, clat) = d.lat_deg.to_radians().sin_cos();
                let (slon, clon) = d.lon_deg.to_radians().sin_cos();
                let (vx, vy, vz) = (r[4], r[5], r[6]);
                let ve = -slon * vx + clon * vy;
                let vn = -slat * clon * vx - slat * slon * vy + clat * vz;
                vec![r[0] - t0, p.x, p.y, vn.atan2(ve)]
            })
            .collect();
        Ok(Self {
            wheels,
            gyro,
            fixes,
            reference,
            frame,
        })
    }

    fn first_fix_s(&self) -> f64 {
        self.fixes.first().map_or(0.0, |f| f.s)
    }

    /// The reference point (east, north) at `s` into the data, interpolated; `None` outside
    /// the reference.
    fn reference_at(&self, s: f64) -> Option<(f64, f64)> {
        let i = self.reference.partition_point(|r| r[0] <= s);
        let (a, b) = (
            self.reference.get(i.checked_sub(1)?)?,
            self.reference.get(i)?,
        );
        let k = (s - a[0]) / (b[0] - a[0]);
        Some((a[1] + (b[1] - a[1]) * k, a[2] + (b[2] - a[2]) * k))
    }

    /// The reference's heading at `s`, rad.
    fn reference_yaw_at(&self, s: f64) -> f64 {
        sample_at(&self.reference, s)[3]
    }

    /// The vehicle replaying the data.
    fn forced(&self) -> Result<Forced> {
        let mut plant = PlantConfig::builtin()?;
        plant.name = "comma2k19-rav4".into();
        let d = self.frame.datum();
        plant.datum = [d.lat_deg, d.lon_deg, d.h_m];
        plant.geometry.wheel_radius_m = WheelRadius::both(WHEEL_RADIUS_M);
        plant.geometry.track_m = TRACK_M;
        plant.geometry.gear_ratio = 10.0;
        plant.geometry.antenna = [ANTENNA_X_M, 0.0];
        plant.imu.gyro_bias_rps = 0.0;
        plant.imu.gyro_noise_rps = 0.0;
        plant.slip.bias = [0.0, 0.0];
        plant.slip.sigma = 0.0;
        let mut times: Vec<f64> = self
            .wheels
            .iter()
            .chain(&self.gyro)
            .map(|r| r[0])
            .filter(|s| *s >= 0.0)
            .collect();
        times.sort_by(f64::total_cmp);
        times.dedup();
        let motion = times
            .into_iter()
            .map(|s| {
                let w = sample_at(&self.wheels, s);
                (
                    s,
                    ForcedMotion {
                        v: (w[1] + w[2]) / 2.0,
                        wheel_yaw_rate: (w[2] - w[1]) / TRACK_M,
                        gyro_z: sample_at(&self.gyro, s)[1],
                    },
                )
            })
            .collect();
        let mut localization = toml::Table::new();
        localization.insert("gnss_latency_s".into(), LATENCY_S.into());
        Ok(Forced {
            plant,
            localization,
            motion,
        })
    }

    /// The receiver's records: every fix before `cut` (s after the first fix), `wild` moving
    /// one by (east, north) m.
    fn records(&self, cut: Option<f64>, wild: Option<(usize, (f64, f64))>) -> Vec<Record> {
        let first = self.first_fix_s();
        self.fixes
            .iter()
            .enumerate()
            .filter(|(_, f)| cut.is_none_or(|c| f.s - first < c))
            .map(|(i, f)| {
                let moved = wild.filter(|(w, _)| *w == i).map_or((0.0, 0.0), |(_, d)| d);
                let g = self.frame.to_geodetic(&Vector3::new(
                    f.en.0 + moved.0,
                    f.en.1 + moved.1,
                    f.h - self.frame.datum().h_m,
                ));
                Epoch {
                    utc_us: (f.utc_ms * 1000.0) as i64,
                    quality: FixQuality::Single,
                    position: (g.lat_deg, g.lon_deg, g.h_m),
                    hdop: 1.0,
                    velocity: Some((f.speed, f.course)),
                }
                .record(at(f.s))
            })
            .collect()
    }

    /// The data's time (s) of a recording time.
    fn s_of(&self, t: crate::time::Timestamp) -> f64 {
        t.as_micros() as f64 * 1e-6 - at(0.0).as_micros() as f64 * 1e-6
    }

    /// The antenna's distance from the reference at a tick.
    fn error_at(&self, tick: &Tick) -> Option<f64> {
        let antenna = tick.point((ANTENNA_X_M, 0.0))?;
        Some(distance(antenna, self.reference_at(self.s_of(tick.t))?))
    }

    /// The fixes' own RMS distance from the reference, each placed `LATENCY_S` before it
    /// arrived.
    fn fixes_rms(&self) -> f64 {
        let squares: Vec<f64> = self
            .fixes
            .iter()
            .filter_map(|f| Some(distance(f.en, self.reference_at(f.s - LATENCY_S)?).powi(2)))
            .collect();
        (squares.iter().sum::<f64>() / squares.len().max(1) as f64).sqrt()
    }

    /// A naive dead reckoning (the rear wheels' mean speed along the integrated gyro) from
    /// the reference's pose at `s`: the antenna's final distance from the reference.
    fn naive_from(&self, s: f64) -> Option<f64> {
        let mut yaw = self.reference_yaw_at(s);
        let (ax, ay) = self.reference_at(s)?;
        let (mut x, mut y) = (ax - ANTENNA_X_M * yaw.cos(), ay - ANTENNA_X_M * yaw.sin());
        let start = self.wheels.partition_point(|w| w[0] < s);
        let mut last = s;
        for w in self.wheels.get(start..)? {
            let dt = w[0] - last;
            let rate = sample_at(&self.gyro, last)[1];
            let v = (w[1] + w[2]) / 2.0;
            let mid = yaw + rate * dt / 2.0;
            x += v * dt * mid.cos();
            y += v * dt * mid.sin();
            yaw += rate * dt;
            last = w[0];
        }
        let end = self.reference_at(last)?;
        Some(distance(
            (x + ANTENNA_X_M * yaw.cos(), y + ANTENNA_X_M * yaw.sin()),
            end,
        ))
    }
}

/// Writes the data at `dir` as a recording folder at `out`; the receiver's records it holds.
pub fn write_recording(dir: &Path, out: &Path) -> Result<Vec<Record>> {
    let data = Data::load(dir)?;
    let clean = data.records(None, None);
    recording::write(out, &data.forced()?, &clean)?;
    Ok(clean)
}

/// The figures of `dir`.
pub fn figures(dir: &Path, options: &Options) -> Result<Vec<Figure>> {
    let workers = options.workers;
    let data = Data::load(dir)?;
    let forced = data.forced()?;
    let scratch = Scratch::new("comma")?;
    let clean = data.records(None, None);
    recording::write(scratch.path(), &forced, &clean)?;
    let dir = scratch.path();
    let full = recording::replay(dir, &clean)?;
    if let Some(path) = options.trace_file("comma2k19-rav4") {
        recording::write_trace(
            &path,
            &full,
            at(data.first_fix_s()),
            (ANTENNA_X_M, 0.0),
            |t| data.reference_at(data.s_of(t)),
        )?;
    }
    let figure = |name: String, value: f64, target: f64, naive: Option<f64>| Figure {
        vehicle: "comma2k19-rav4".into(),
        name,
        value,
        target,
        naive,
        unit: "m",
    };
    let mut out = Vec::new();
    // The whole run, every control tick from the first fix on: the antenna's distance from
    // the reference, against the fixes' own.
    let first = at(data.first_fix_s());
    let squares: Vec<f64> = full
        .iter()
        .filter(|k| k.t >= first)
        .filter_map(|k| data.error_at(k))
        .map(|e| e * e)
        .collect();
    let span = full.last().map_or(0.0, |k| data.s_of(k.t)) - data.first_fix_s();
    let rms = if (squares.len() as f64) < span * 90.0 {
        f64::INFINITY
    } else {
        (squares.iter().sum::<f64>() / squares.len() as f64).sqrt()
    };
    let fixes_rms = data.fixes_rms();
    out.push(figure(
        "whole run: pose to the reference, RMS (target: the fixes' own)".into(),
        rms,
        fixes_rms,
        None,
    ));

    type Job<'a> = Box<dyn FnOnce() -> Result<f64> + Send + 'a>;
    let cut_jobs: Vec<Job> = CUTS_S
        .iter()
        .map(|&cut_s| {
            let data = &data;
            Box::new(move || {
                let ticks = recording::replay(dir, &data.records(Some(cut_s), None))?;
                Ok(ticks
                    .last()
                    .and_then(|k| data.error_at(k))
                    .unwrap_or(f64::INFINITY))
            }) as Job
        })
        .collect();
    for (&cut_s, end) in CUTS_S.iter().zip(parallel(workers, cut_jobs)) {
        let naive = data
            .naive_from(data.first_fix_s() + cut_s)
            .unwrap_or(f64::NAN);
        out.push(figure(
            format!("GNSS cut at {cut_s:.0} s: end to the reference"),
            end?,
            naive,
            Some(naive),
        ));
    }

    let window: Vec<usize> = (0..data.fixes.len())
        .filter(|&i| {
            let s = data.fixes[i].s - data.first_fix_s();
            (WILD_WINDOW_S.0..=WILD_WINDOW_S.1).contains(&s)
        })
        .collect();
    let wild_jobs: Vec<Job> = window
        .iter()
        .enumerate()
        .map(|(k, &i)| {
            let (data, full) = (&data, &full);
            Box::new(move || {
                let far = 100.0 + 900.0 * ((k as f64 * 0.618_034) % 1.0);
                let (s, c) = (k as f64 * 2.399_963).sin_cos();
                let ticks =
                    recording::replay(dir, &data.records(None, Some((i, (far * c, far * s)))))?;
                Ok(ticks
                    .iter()
                    .zip(full)
                    .filter_map(|(a, b)| {
                        let (a, b) = (a.map?, b.map?);
                        Some(distance((a.0, a.1), (b.0, b.1)))
                    })
                    .fold(0.0, f64::max))
            }) as Job
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
        if window.len() >= 30 {
            wild_max
        } else {
            f64::INFINITY
        },
        0.5,
        None,
    ));
    Ok(out)
}
