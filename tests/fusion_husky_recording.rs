//! Issue 33's figures through the whole core, on a real robot: `../shared/data/ekf/
//! husky-test1` (a Husky's SBAS fixes, wheel odometry and IMU, 395 s and 359 m) turned into a
//! recording folder and replayed.
//!
//! The recording: the simulator's CiA 402 drives are back-driven at the wheel speeds the data
//! implies and its HiPNUC IMU reads the data's gyro (the IMU is mounted roll +90°, yaw −90°:
//! the vehicle's yaw rate is the sensor's y axis), so wheels and gyro reach the core through
//! the real decoders; each fix becomes a GGA sentence of quality 2 (SBAS) at its time, and
//! there is no RMC (the data has no speed or course). The vehicle's configuration is the
//! simulator's drive train with chassisd's default localisation settings.
//!
//! The wheels' model, from the data: the controller computed its yaw rate from the wheel
//! speeds over the Husky's 0.555 m track, and skid steering slips in turns, so the wheels'
//! yaw rate is a multiple of the gyro's (least squares over turns faster than 0.2 rad/s).
//! The configured track is 0.555 m times that ratio: the effective track that makes the
//! wheels turn the vehicle as the gyro saw it (the odom frame takes its yaw from the gyro
//! anyway, and from the wheels only without one).
//!
//! Variants are replayed through the library's engine with the fixes rewritten: GNSS cut at
//! 30, 60, 120 and 250 s after the first fix, and a wild fix (100 to 1000 m off) put on each
//! fix of 100–120 s, one replay each. The binary replays the recording itself.

mod common;

use std::path::Path;
use std::sync::Mutex;

use bytes::Bytes;
use chassisd::config::VehicleConfig;
use chassisd::engine::{Decoder, Engine, EngineOutput};
use chassisd::fusion::geodesy::{Enu, Geodetic};
use chassisd::record::{Payload, Record, RecordingReader, RecordingWriter, SourceKind};
use chassisd::sim::lockstep::{self, Lockstep, PLANT_STEP};
use chassisd::sim::plant::{ForcedMotion, GnssCondition, PlantConfig};
use chassisd::time::Timestamp;
use common::lockstep::Recorder;
use common::{csv_columns, sample_at, wheel_to_gyro_ratio};

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
/// The drives boot before the data starts, s.
const BOOT_S: f64 = 3.0;
/// The recording starts here (2026-01-01T00:00:00Z).
const START: Timestamp = Timestamp::from_micros(1_767_225_600_000_000);

/// The data, in the order it describes.
struct Data {
    /// t, vx, wz (the wheels' yaw rate).
    odom: Vec<Vec<f64>>,
    /// t, wy (the vehicle's yaw rate).
    imu: Vec<Vec<f64>>,
    /// t, latitude, longitude, altitude, HDOP².
    gps: Vec<Vec<f64>>,
    /// The earliest time of any sample, s.
    t0: f64,
}

impl Data {
    fn load() -> Self {
        let dir = common::shared_data("ekf/husky-test1");
        let odom = csv_columns(&dir.join("odom.csv"), &["t", "vx", "wz"]);
        let imu = csv_columns(&dir.join("imu.csv"), &["t", "wy"]);
        let gps = csv_columns(
            &dir.join("gps.csv"),
            &["t", "latitude", "longitude", "altitude", "pos_cov_xx"],
        );
        let t0 = odom[0][0].min(imu[0][0]).min(gps[0][0]);
        Self { odom, imu, gps, t0 }
    }

    /// The recording's time of a data time.
    fn at(&self, t: f64) -> Timestamp {
        START.saturating_add(std::time::Duration::from_secs_f64(BOOT_S + t - self.t0))
    }

    /// The first fix's time, s.
    fn first_fix(&self) -> f64 {
        self.gps[0][0]
    }

    /// The local frame: the first fix is the datum.
    fn frame(&self) -> Enu {
        let g = &self.gps[0];
        Enu::new(Geodetic {
            lat_deg: g[1],
            lon_deg: g[2],
            h_m: g[3],
        })
    }

    /// The fixes east, north of the datum, m, with their recording times.
    fn fixes_enu(&self) -> Vec<(Timestamp, f64, f64)> {
        let frame = self.frame();
        self.gps
            .iter()
            .map(|g| {
                let p = frame.to_enu(&Geodetic {
                    lat_deg: g[1],
                    lon_deg: g[2],
                    h_m: g[3],
                });
                (self.at(g[0]), p.x, p.y)
            })
            .collect()
    }
}

/// The GGA sentence (quality 2) of fix `index`, `moved` by (east, north) m, stamped with its
/// recording time.
fn gga(data: &Data, index: usize, moved: (f64, f64)) -> Bytes {
    let g = &data.gps[index];
    let frame = data.frame();
    let here = frame.to_enu(&Geodetic {
        lat_deg: g[1],
        lon_deg: g[2],
        h_m: g[3],
    });
    let p = frame.to_geodetic(&nalgebra::Vector3::new(
        here.x + moved.0,
        here.y + moved.1,
        here.z,
    ));
    let utc_s = (data.at(g[0]).as_micros() % 86_400_000_000) as f64 * 1e-6;
    let (h, m, s) = (
        (utc_s / 3600.0).floor(),
        ((utc_s % 3600.0) / 60.0).floor(),
        utc_s % 60.0,
    );
    let angle = |v: f64, width: usize| {
        let deg = v.abs().trunc();
        format!(
            "{deg:0width$.0}{:011.8}",
            (v.abs() - deg) * 60.0,
            width = width
        )
    };
    let body = format!(
        "GPGGA,{h:02.0}{m:02.0}{s:05.2},{},{},{},{},2,10,{:.2},{:.3},M,0.000,M,1.0,0001",
        angle(p.lat_deg, 2),
        if p.lat_deg >= 0.0 { 'N' } else { 'S' },
        angle(p.lon_deg, 3),
        if p.lon_deg >= 0.0 { 'E' } else { 'W' },
        g[4].sqrt(),
        p.h_m
    );
    let mut out = String::new();
    chassisd::devices::gnss::encode::sentence(&mut out, &body);
    Bytes::from(out)
}

/// Every fix as its GGA record; `wild` moves one.
fn gnss_records(data: &Data, wild: Option<(usize, (f64, f64))>) -> Vec<Record> {
    (0..data.gps.len())
        .map(|i| Record {
            t: data.at(data.gps[i][0]),
            source: lockstep::GNSS_SOURCE.to_owned(),
            payload: Payload::Serial(gga(
                data,
                i,
                wild.filter(|(w, _)| *w == i).map_or((0.0, 0.0), |(_, d)| d),
            )),
        })
        .collect()
}

/// Writes the recording folder at `dir`; the effective track, m.
fn record(data: &Data, dir: &Path) -> f64 {
    let ratio = wheel_to_gyro_ratio(&data.odom, &data.imu);
    let track = TRACK_M * ratio;
    let g = &data.gps[0];
    let plant_text = std::fs::read_to_string(common::repo().join("devices/plant.mower.toml"))
        .expect("plant file")
        .replace("name = \"sim-mower\"", "name = \"husky-data\"")
        .replace(
            "datum = [47.397742, 8.545594, 488.0]",
            &format!("datum = [{}, {}, {}]", g[1], g[2], g[3]),
        )
        .replace(
            "wheel_radius_m = 0.11",
            &format!("wheel_radius_m = {WHEEL_RADIUS_M}"),
        )
        .replace("track_m = 0.42", &format!("track_m = {track}"))
        .replace("antenna = [0.20, 0.00]", "antenna = [0.0, 0.0]")
        .replace("rate_hz = 100.0", "rate_hz = 30.0")
        .replace("gyro_bias_rps = 0.003", "gyro_bias_rps = 0.0")
        // The drives' boot is a standstill before the data: the simulated gyro reads zero
        // there, so only the data's own standstill teaches the odom frame a bias.
        .replace("gyro_noise_rps = 0.002", "gyro_noise_rps = 0.0")
        .replace("bias = [0.006, 0.004]", "bias = [0.0, 0.0]");
    let plant = PlantConfig::from_toml(&plant_text, Path::new("husky-data")).expect("plant");
    let mut sim = Lockstep::new(plant.clone(), 1, START).expect("lockstep");
    // The simulator's drive train, IMU and receiver ports with chassisd's own localisation
    // defaults (fitted on this robot: docs/fusion.md), the first fix as the datum.
    let mut config: toml::Table =
        toml::from_str(&sim.config().to_effective_toml()).expect("effective configuration");
    config.insert("localization".into(), toml::Table::new().into());
    let config_text = toml::to_string(&config).expect("configuration");
    let mut sink = Recorder {
        writer: RecordingWriter::create(
            dir,
            "husky-data",
            START,
            Some(&config_text),
            lockstep::sources(&plant),
        )
        .expect("recording"),
    };
    let mut fixes = gnss_records(data, None).into_iter().peekable();
    let t_end = data.odom[data.odom.len() - 1][0];
    let steps = ((BOOT_S + t_end - data.t0) / PLANT_STEP.as_secs_f64()).round() as u64;
    let no_fix = GnssCondition {
        quality: None,
        offset: (0.0, 0.0),
    };
    for k in 0..steps {
        let s = k as f64 * PLANT_STEP.as_secs_f64();
        if s >= BOOT_S {
            let td = data.t0 + (s - BOOT_S);
            let o = sample_at(&data.odom, td);
            sim.vehicle_mut().force_motion(Some(ForcedMotion {
                v: o[1],
                wheel_yaw_rate: o[2] * TRACK_M / track,
                gyro_z: sample_at(&data.imu, td)[1],
            }));
        }
        while let Some(fix) = fixes.next_if(|f| f.t <= sim.time()) {
            sink.writer.write(&fix).expect("fix written");
        }
        sim.step(no_fix, &mut sink);
    }
    sink.writer.finish(sim.time()).expect("recording closed");
    track
}

/// One control tick of a replay.
#[derive(Debug, Clone, Copy)]
struct Tick {
    t: Timestamp,
    map: Option<(f64, f64, f64)>,
    /// The heading is known: its 1σ within 5°.
    heading_known: bool,
    /// map→odom composed with the odom pose at the tick, x and y.
    odom_carried: Option<(f64, f64)>,
    /// map→odom.
    correction: Option<(f64, f64, f64)>,
    /// The odom pose carried to the tick.
    odom: Option<(f64, f64, f64)>,
}

/// Replays the recording at `dir` through the library's engine with `gnss` in place of its
/// fixes; every control tick.
fn replay(dir: &Path, gnss: Vec<Record>) -> Vec<Tick> {
    let (meta, reader) = RecordingReader::open(dir).expect("recording opens");
    let file = meta.vehicle_config.as_deref().expect("configuration");
    let config = VehicleConfig::load(&dir.join(file)).expect("configuration loads");
    // The serial ports' decoders, as the replay command takes them from the recording.
    let decoders: Vec<(String, Decoder)> = meta
        .sources
        .iter()
        .filter(|s| s.kind == SourceKind::Serial)
        .filter_map(|s| {
            Some((
                s.name.clone(),
                Decoder::for_protocol(s.protocol.as_deref()?)?,
            ))
        })
        .collect();
    let mut engine = Engine::new(&config, &decoders);
    engine.emit_poses();
    if let Some(start) = meta.start_us {
        engine.start_at(Timestamp::from_micros(start));
    }
    let mut ticks = Vec::with_capacity(40_000);
    let mut out = Vec::new();
    let mut fixes = gnss.into_iter().peekable();
    let mut take = |out: &mut Vec<EngineOutput>| {
        for o in out.drain(..) {
            if let EngineOutput::Poses(t, r) = o {
                // The odom pose carried to the tick, as the map pose is.
                let odom = r.frames.map(|f| {
                    let o = f.odom_to_base;
                    (o.x, o.y, o.yaw)
                });
                let correction = r.frames.map(|f| {
                    let c = f.map_to_odom;
                    (c.x, c.y, c.yaw)
                });
                ticks.push(Tick {
                    t,
                    map: r.map.map(|(p, _)| (p.x, p.y, p.yaw)),
                    heading_known: r
                        .map
                        .is_some_and(|(_, c)| c.yaw.sqrt() <= 5f64.to_radians()),
                    odom_carried: correction.zip(odom).map(|(c, o)| compose(c, o)),
                    correction,
                    odom,
                });
            }
        }
    };
    // The recording's fixes give way to `gnss`; its receiver's link states stay.
    let recorded_fix =
        |r: &Record| r.source == lockstep::GNSS_SOURCE && matches!(r.payload, Payload::Serial(_));
    for record in reader.filter(|r| !recorded_fix(r)) {
        while let Some(fix) = fixes.next_if(|f| f.t <= record.t) {
            engine.handle(&fix, &mut out);
        }
        engine.handle(&record, &mut out);
        take(&mut out);
    }
    if let Some(end) = meta.end_us {
        engine.advance_to(Timestamp::from_micros(end), &mut out);
        take(&mut out);
    }
    ticks
}

/// `c` ∘ `o`: the position of pose `o` carried by transform `c`.
fn compose(c: (f64, f64, f64), o: (f64, f64, f64)) -> (f64, f64) {
    let (s, co) = c.2.sin_cos();
    (c.0 + co * o.0 - s * o.1, c.1 + s * o.0 + co * o.1)
}

/// The last tick at or before `t`.
fn tick_at(ticks: &[Tick], t: Timestamp) -> &Tick {
    let i = ticks.partition_point(|k| k.t <= t);
    &ticks[i.saturating_sub(1)]
}

fn distance(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

/// Largest distance the map pose moves within (from, to) from where it was at `from`.
fn moved_within(ticks: &[Tick], from: Timestamp, to: Timestamp) -> f64 {
    let start = tick_at(ticks, from).map.expect("placed");
    ticks
        .iter()
        .filter(|k| k.t >= from && k.t <= to)
        .filter_map(|k| k.map)
        .map(|p| distance((p.0, p.1), (start.0, start.1)))
        .fold(0.0, f64::max)
}

#[test]
fn the_husky_recording_holds_issue_33s_figures_through_the_core() {
    let data = Data::load();
    let dir = common::tempdir("husky").join("rec");
    let track = record(&data, &dir);
    let fixes = data.fixes_enu();
    let after_first = |s: f64| data.at(data.first_fix() + s);
    let (t_last, e_last, n_last) = *fixes.last().expect("fixes");
    let mut report = vec![format!(
        "husky-test1 as a recording: effective track {track:.3} m ({:.3} × 0.555 m)",
        track / TRACK_M
    )];

    // The whole run: distance from the pose to each fix before it is applied.
    let full = replay(&dir, gnss_records(&data, None));
    let squares: Vec<f64> = fixes
        .iter()
        .skip(1)
        .filter_map(|&(t, e, n)| {
            tick_at(&full, t)
                .map
                .map(|p| distance((p.0, p.1), (e, n)).powi(2))
        })
        .collect();
    let rms = (squares.iter().sum::<f64>() / squares.len() as f64).sqrt();
    let located_at = full
        .iter()
        .find(|k| k.heading_known)
        .map(|k| k.t.saturating_since(after_first(0.0)).as_secs_f64());
    let parked_with = moved_within(&full, after_first(PARKED_S.0), after_first(PARKED_S.1));
    report.push(format!(
        "whole run: {rms:.2} m RMS to {} fixes (target 1.6 m); heading known (1σ ≤ 5°, no \
         course in the data) {located_at:?} s after the first fix; parked pose moved \
         {parked_with:.3} m with GNSS (target 0.3 m)",
        squares.len()
    ));
    assert!(squares.len() > 900, "{} fixes compared", squares.len());
    assert!(rms <= 1.6, "{}", report.join("\n"));
    assert!(
        located_at.is_some_and(|s| s < 60.0),
        "{}",
        report.join("\n")
    );
    assert!(parked_with <= 0.3, "{}", report.join("\n"));
    // Located, the pose follows the fixes: the last ones are within metres.
    let end = tick_at(&full, t_last).map.expect("placed");
    assert!(distance((end.0, end.1), (e_last, n_last)) < 5.0);

    // GNSS cut: the final pose against the last fix, beside the odom frame's dead reckoning
    // from the map pose at the cut and the naive figure.
    let parked_without = Mutex::new(None);
    let outcomes = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for &(cut_s, naive) in &CUTS {
            let (data, dir, full, outcomes, parked_without) =
                (&data, &dir, &full, &outcomes, &parked_without);
            scope.spawn(move || {
                let cut = after_first(cut_s);
                let records: Vec<Record> = gnss_records(data, None)
                    .into_iter()
                    .filter(|r| r.t < cut)
                    .collect();
                let ticks = replay(dir, records);
                let last = ticks.last().expect("ticks");
                let end = last.map.expect("placed");
                let map_error = distance((end.0, end.1), (e_last, n_last));
                // The odom frame's dead reckoning from the map pose at the cut.
                let at_cut = tick_at(&ticks, cut);
                let dr = compose(
                    at_cut.correction.expect("frames at the cut"),
                    last.odom.expect("odom"),
                );
                let odom_error = distance(dr, (e_last, n_last));
                // Until the cut the run is the full one's.
                let before = tick_at(full, cut).map.expect("placed");
                let same = distance(
                    (before.0, before.1),
                    (at_cut.map.unwrap().0, at_cut.map.unwrap().1),
                );
                if cut_s < PARKED_S.0 {
                    *parked_without.lock().unwrap() = Some(moved_within(
                        &ticks,
                        after_first(PARKED_S.0),
                        after_first(PARKED_S.1),
                    ));
                }
                // The map pose moves exactly as the odom pose does after the cut.
                let carried = ticks
                    .iter()
                    .filter(|k| k.t > cut)
                    .filter_map(|k| Some(distance(k.odom_carried?, (k.map?.0, k.map?.1))))
                    .fold(0.0, f64::max);
                outcomes
                    .lock()
                    .unwrap()
                    .push((cut_s, naive, map_error, odom_error, same, carried));
            });
        }
    });
    let mut outcomes = outcomes.into_inner().unwrap();
    outcomes.sort_by(|a, b| a.0.total_cmp(&b.0));
    for &(cut_s, naive, map_error, odom_error, same, carried) in &outcomes {
        report.push(format!(
            "GNSS cut at {cut_s:.0} s: the map pose ends {map_error:.2} m from the last fix; \
             the odom frame from the map pose at the cut {odom_error:.2} m; naive {naive} m \
             (before the cut {same:.1e} m from the full run; the map pose after it off the \
             carried odom pose by at most {carried:.1e} m)"
        ));
    }
    let parked_without = parked_without
        .into_inner()
        .unwrap()
        .expect("a cut before the stop");
    report.push(format!(
        "parked pose moved {parked_without:.4} m without GNSS (target 0.05 m)"
    ));
    for &(_, naive, map_error, odom_error, same, carried) in &outcomes {
        assert!(map_error <= odom_error + 1e-6, "{}", report.join("\n"));
        assert!(map_error <= naive, "{}", report.join("\n"));
        assert!(same < 1e-9 && carried < 1e-6, "{}", report.join("\n"));
    }
    assert!(parked_without <= 0.05, "{}", report.join("\n"));

    // Wild fixes: each fix of the window moved 100 to 1000 m, one replay each; the pose never
    // moves more than 0.5 m from the clean run's for it.
    let window: Vec<usize> = (0..fixes.len())
        .filter(|&i| {
            let s = data.gps[i][0] - data.first_fix();
            s >= WILD_WINDOW_S.0 && s <= WILD_WINDOW_S.1
        })
        .collect();
    let next = Mutex::new(0usize);
    let worst = Mutex::new((0.0f64, 0usize));
    std::thread::scope(|scope| {
        for _ in 0..2 {
            let (data, dir, full, window, next, worst) =
                (&data, &dir, &full, &window, &next, &worst);
            scope.spawn(move || {
                loop {
                    let k = {
                        let mut n = next.lock().unwrap();
                        *n += 1;
                        *n - 1
                    };
                    let Some(&i) = window.get(k) else { return };
                    // Distances 100–1000 m, directions by the golden angle.
                    let far = 100.0 + 900.0 * ((k as f64 * 0.618_034) % 1.0);
                    let (s, c) = (k as f64 * 2.399_963).sin_cos();
                    let ticks = replay(dir, gnss_records(data, Some((i, (far * c, far * s)))));
                    let off = ticks
                        .iter()
                        .zip(full.iter())
                        .filter_map(|(a, b)| {
                            let (a, b) = (a.map?, b.map?);
                            Some(distance((a.0, a.1), (b.0, b.1)))
                        })
                        .fold(0.0, f64::max);
                    let mut w = worst.lock().unwrap();
                    if off > w.0 {
                        *w = (off, i);
                    }
                }
            });
        }
    });
    let (worst, at) = worst.into_inner().unwrap();
    report.push(format!(
        "{} wild fixes (100–1000 m off, one per replay, on every fix of {:.0}–{:.0} s): the \
         pose moved at most {worst:.3} m from the clean run's (fix {at}; target 0.5 m)",
        window.len(),
        WILD_WINDOW_S.0,
        WILD_WINDOW_S.1
    ));
    assert!(window.len() >= 45, "{}", report.join("\n"));
    assert!(worst <= 0.5, "{}", report.join("\n"));

    // The binary replays the recording to the same end.
    let out = common::replay(&dir);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last: serde_json::Value =
        serde_json::from_str(stdout.lines().last().expect("status lines")).expect("JSON");
    // SBAS fixes (1σ 0.8 m) never bring the position within `locate_bound_m` (0.5 m).
    assert_eq!(last["nav"]["locate"], "LOCATE_FALSE", "{last}");
    let binary_end = (
        last["pose"]["x"].as_f64().unwrap(),
        last["pose"]["y"].as_f64().unwrap(),
    );
    let library_end = full.last().unwrap().map.unwrap();
    assert!(
        distance(binary_end, (library_end.0, library_end.1)) < 0.05,
        "binary {binary_end:?}, library {library_end:?}"
    );
    println!("{}", report.join("\n"));
    std::fs::remove_dir_all(dir.parent().unwrap()).ok();
}
