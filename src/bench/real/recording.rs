//! A real vehicle's wheels, gyro and GNSS as a chassisd recording, and its replay.
//!
//! The simulator's CiA 402 drives are back-driven at the wheel speeds the data gives and its
//! IMU reads the data's gyro, so wheels and gyro reach the core through the real decoders;
//! the receiver's sentences are written as the receiver sent them, at the times they
//! arrived. A replay runs the recording through the library's engine with any set of GNSS
//! records in place of the recorded ones (a cut, a wild fix), and keeps every control tick's
//! poses.

use std::path::Path;
use std::time::Duration;

use bytes::Bytes;

use crate::bench::error::{Result, invalid};
use crate::config::VehicleConfig;
use crate::devices::gnss::FixQuality;
use crate::devices::gnss::encode::{angle, quality_digit, sentence};
use crate::engine::{Decoder, Engine, EngineOutput};
use crate::record::{Payload, Record, RecordingReader, RecordingWriter};
use crate::sim::lockstep::{self, Lockstep, PLANT_STEP, Sink};
use crate::sim::plant::{ForcedMotion, GnssCondition, PlantConfig};
use crate::time::Timestamp;

/// Recordings start here (2026-01-01T00:00:00Z).
pub const START: Timestamp = Timestamp::from_micros(1_767_225_600_000_000);
/// The drives boot, standing, before the data starts, s.
pub const BOOT_S: f64 = 3.0;

/// The recording's time of a time `s` seconds into the data.
pub fn at(s: f64) -> Timestamp {
    START.saturating_add(Duration::from_secs_f64((BOOT_S + s).max(0.0)))
}

/// A real vehicle's motion, as the simulated drive train and IMU are to replay it.
pub struct Forced {
    /// The simulated vehicle: the real one's wheels, track, antenna and IMU rate.
    pub plant: PlantConfig,
    /// `[localization]` keys set beside chassisd's defaults (the receiver's latency).
    pub localization: toml::Table,
    /// The motion through the data, sorted by time: (s into the data, motion).
    pub motion: Vec<(f64, ForcedMotion)>,
}

impl Forced {
    /// The motion in force at `s` (the last sample at or before it).
    fn motion_at(&self, s: f64) -> ForcedMotion {
        let i = self.motion.partition_point(|(t, _)| *t <= s);
        self.motion
            .get(i.saturating_sub(1))
            .map(|(_, m)| *m)
            .unwrap_or_default()
    }

    /// The data's length, s.
    fn span_s(&self) -> f64 {
        self.motion.last().map_or(0.0, |(t, _)| *t)
    }
}

/// Writes the records a lockstep run makes into a recording folder.
struct Writer {
    writer: RecordingWriter,
    failed: Option<String>,
}

impl Sink for Writer {
    fn record(&mut self, record: &Record) {
        if self.failed.is_none()
            && let Err(e) = self.writer.write(record)
        {
            self.failed = Some(e.to_string());
        }
    }

    fn output(&mut self, _: EngineOutput) {}
}

/// Writes the recording of `forced` with `gnss` (time-ordered serial records of the
/// receiver) at `dir`.
pub fn write(dir: &Path, forced: &Forced, gnss: &[Record]) -> Result<()> {
    let plant = forced.plant.clone();
    let mut sim = Lockstep::new(plant.clone(), 1, START)?;
    // The simulator's drive train, IMU and receiver ports with chassisd's own localisation
    // defaults but for what the vehicle's integrator would set; the first fix is the datum.
    let mut config: toml::Table = toml::from_str(&sim.config().to_effective_toml())
        .map_err(invalid("the simulated vehicle's configuration"))?;
    config.insert(
        "localization".into(),
        toml::Value::Table(forced.localization.clone()),
    );
    let config_text = toml::to_string(&config).map_err(invalid("the configuration"))?;
    let writer = RecordingWriter::create(
        dir,
        &plant.name,
        START,
        Some(&config_text),
        lockstep::sources(&plant),
    )
    .map_err(invalid(format!("recording {}", dir.display())))?;
    let mut sink = Writer {
        writer,
        failed: None,
    };
    let mut fixes = gnss.iter().peekable();
    let step = PLANT_STEP.as_secs_f64();
    let steps = ((BOOT_S + forced.span_s()) / step).round() as u64;
    let no_fix = GnssCondition {
        quality: None,
        offset: (0.0, 0.0),
    };
    for k in 0..steps {
        let s = k as f64 * step - BOOT_S;
        if s >= 0.0 {
            sim.vehicle_mut().force_motion(Some(forced.motion_at(s)));
        }
        while let Some(fix) = fixes.next_if(|f| f.t <= sim.time()) {
            sink.record(fix);
        }
        sim.step(no_fix, &mut sink);
    }
    if let Some(e) = sink.failed {
        return Err(crate::bench::error::BenchError::Failed(format!(
            "recording {}: {e}",
            dir.display()
        )));
    }
    // The recording ends where the lockstep stopped: a replay runs the control loop to its
    // end, and ticks past the last recorded one would transmit frames never recorded.
    sink.writer
        .finish(sim.time())
        .map_err(invalid(format!("recording {}", dir.display())))
}

/// One control tick of a replay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Its time.
    pub t: Timestamp,
    /// The map pose (x, y, yaw), once placed.
    pub map: Option<(f64, f64, f64)>,
    /// The map pose's 1σ heading, rad.
    pub yaw_sigma: Option<f64>,
    /// map→odom (x, y, yaw).
    pub correction: Option<(f64, f64, f64)>,
    /// The odom pose carried to the tick (x, y, yaw), once both frames exist.
    pub odom: Option<(f64, f64, f64)>,
    /// The odom frame's latest pose (x, y, yaw), with or without a map frame.
    pub odom_latest: Option<(f64, f64, f64)>,
}

impl Tick {
    /// Where the map pose puts a point `lever` (x forward, y left, m) of the vehicle.
    pub fn point(&self, lever: (f64, f64)) -> Option<(f64, f64)> {
        let (x, y, yaw) = self.map?;
        let (s, c) = yaw.sin_cos();
        Some((x + c * lever.0 - s * lever.1, y + s * lever.0 + c * lever.1))
    }
}

/// Replays the recording at `dir` through the library's engine with `gnss` in place of its
/// receiver's serial records; every control tick.
pub fn replay(dir: &Path, gnss: &[Record]) -> Result<Vec<Tick>> {
    let (meta, reader) =
        RecordingReader::open(dir).map_err(invalid(format!("recording {}", dir.display())))?;
    let file = meta.vehicle_config.as_deref().ok_or_else(|| {
        crate::bench::error::BenchError::Failed(format!(
            "recording {} holds no configuration",
            dir.display()
        ))
    })?;
    let config = VehicleConfig::load(&dir.join(file))?;
    // The serial ports' decoders, as the replay command takes them from the recording.
    let decoders = Decoder::of_recording(&meta);
    let mut engine = Engine::new(&config, &decoders);
    engine.emit_poses();
    if let Some(start) = meta.start_us {
        engine.start_at(Timestamp::from_micros(start));
    }
    let mut ticks = Vec::new();
    let mut out = Vec::new();
    let take = |out: &mut Vec<EngineOutput>, ticks: &mut Vec<Tick>| {
        for o in out.drain(..) {
            if let EngineOutput::Poses(t, r) = o {
                ticks.push(Tick {
                    t,
                    map: r.map.map(|(p, _)| (p.x, p.y, p.yaw)),
                    yaw_sigma: r.map.map(|(_, c)| c.yaw.max(0.0).sqrt()),
                    correction: r.frames.map(|f| {
                        let c = f.map_to_odom;
                        (c.x, c.y, c.yaw)
                    }),
                    odom: r.frames.map(|f| {
                        let o = f.odom_to_base;
                        (o.x, o.y, o.yaw)
                    }),
                    odom_latest: r.odom.map(|o| (o.x, o.y, o.yaw)),
                });
            }
        }
    };
    let mut fixes = gnss.iter().peekable();
    let recorded_fix =
        |r: &Record| r.source == lockstep::GNSS_SOURCE && matches!(r.payload, Payload::Serial(_));
    for record in reader {
        if recorded_fix(&record) {
            continue;
        }
        while let Some(fix) = fixes.next_if(|f| f.t <= record.t) {
            engine.handle(fix, &mut out);
        }
        engine.handle(&record, &mut out);
        take(&mut out, &mut ticks);
    }
    if let Some(end) = meta.end_us {
        engine.advance_to(Timestamp::from_micros(end), &mut out);
        take(&mut out, &mut ticks);
    }
    Ok(ticks)
}

/// Writes every tenth tick of a run as CSV at `path`: the time (s from `from`), the map pose
/// (x, y, yaw), its heading's 1σ, the point the run is scored at (`point` of the pose) and
/// what it is scored against (`truth` at the tick), for a person to plot.
pub fn write_trace(
    path: &Path,
    ticks: &[Tick],
    from: Timestamp,
    point: (f64, f64),
    truth: impl Fn(Timestamp) -> Option<(f64, f64)>,
) -> Result<()> {
    let mut text = String::from("t_s,x,y,yaw,yaw_sigma,point_x,point_y,truth_x,truth_y\n");
    for k in ticks.iter().step_by(10) {
        let (Some((x, y, yaw)), Some(p)) = (k.map, k.point(point)) else {
            continue;
        };
        let s = (k.t.as_micros() as f64 - from.as_micros() as f64) * 1e-6;
        let (tx, ty) = truth(k.t).unwrap_or((f64::NAN, f64::NAN));
        text += &format!(
            "{s:.3},{x:.4},{y:.4},{yaw:.6},{:.6},{:.4},{:.4},{tx:.4},{ty:.4}\n",
            k.yaw_sigma.unwrap_or(f64::NAN),
            p.0,
            p.1
        );
    }
    std::fs::write(path, text).map_err(invalid(format!("writing {}", path.display())))
}

/// The last tick at or before `t` (the first when `t` is earlier).
pub fn tick_at(ticks: &[Tick], t: Timestamp) -> Option<&Tick> {
    let i = ticks.partition_point(|k| k.t <= t);
    ticks.get(i.saturating_sub(1))
}

/// Distance between two points, m.
pub fn distance(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

/// `c` ∘ `o`: the position of pose `o` carried by transform `c`.
pub fn compose(c: (f64, f64, f64), o: (f64, f64, f64)) -> (f64, f64) {
    let (s, co) = c.2.sin_cos();
    (c.0 + co * o.0 - s * o.1, c.1 + s * o.0 + co * o.1)
}

/// One receiver epoch, as NMEA.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Epoch {
    /// Its UTC time, µs since 1970.
    pub utc_us: i64,
    /// Fix quality.
    pub quality: FixQuality,
    /// Latitude, longitude (degrees), height above the ellipsoid (m).
    pub position: (f64, f64, f64),
    /// HDOP.
    pub hdop: f64,
    /// Speed (m/s) and course over ground (degrees true), when the receiver sends RMC.
    pub velocity: Option<(f64, f64)>,
}

impl Epoch {
    /// GGA, then RMC when the epoch has a velocity: one serial chunk.
    pub fn sentences(&self) -> Bytes {
        let utc = chrono::DateTime::from_timestamp_micros(self.utc_us).unwrap_or_default();
        let time = utc.format("%H%M%S%.3f").to_string();
        // hhmmss.ss, as most receivers send.
        let time = &time[..time.len() - 1];
        let (lat, lon, h) = self.position;
        let mut out = String::with_capacity(200);
        sentence(
            &mut out,
            &format!(
                "GPGGA,{time},{},{},{},12,{:.2},{h:.3},M,0.000,M,,",
                angle(lat, true),
                angle(lon, false),
                quality_digit(self.quality),
                self.hdop
            ),
        );
        if let Some((speed, course)) = self.velocity {
            let mode = match self.quality {
                FixQuality::RtkFixed => 'R',
                FixQuality::RtkFloat => 'F',
                FixQuality::Dgps => 'D',
                _ => 'A',
            };
            sentence(
                &mut out,
                &format!(
                    "GPRMC,{time},A,{},{},{:.3},{:.2},{},,,{mode}",
                    angle(lat, true),
                    angle(lon, false),
                    speed / (1852.0 / 3600.0),
                    course.rem_euclid(360.0),
                    utc.format("%d%m%y")
                ),
            );
        }
        Bytes::from(out)
    }

    /// The epoch as the receiver's serial record at `t`.
    pub fn record(&self, t: Timestamp) -> Record {
        Record {
            t,
            source: lockstep::GNSS_SOURCE.to_owned(),
            payload: Payload::Serial(self.sentences()),
        }
    }
}
