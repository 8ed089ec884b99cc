//! A real vehicle's wheels, gyro and GNSS as a chassisd recording (written by
//! `interchange::vehicle_recording`, as `chassisd import` writes a bag's), and its replay.
//!
//! A replay runs the recording through the library's engine with any set of GNSS
//! records in place of the recorded ones (a cut, a wild fix), and keeps every control tick's
//! poses.

use std::path::Path;
use std::time::Duration;

use crate::bench::error::{Result, invalid};
use crate::config::VehicleConfig;
use crate::engine::{Decoder, Engine, EngineOutput};
use crate::record::{Payload, Record, RecordingReader};
use crate::sim::lockstep;
use crate::time::Timestamp;

/// Recordings start here (2026-01-01T00:00:00Z).
pub const START: Timestamp = Timestamp::from_micros(1_767_225_600_000_000);
pub use crate::interchange::vehicle_recording::{BOOT_S, Epoch, Forced};

/// Writes the recording of `forced` with `gnss` at `dir`, starting at [`START`].
pub fn write(dir: &Path, forced: &Forced, gnss: &[Record]) -> Result<()> {
    crate::interchange::vehicle_recording::write(dir, forced, gnss, START)
        .map_err(|e| crate::bench::error::BenchError::Failed(e.to_string()))
}

/// The recording's time of a time `s` seconds into the data.
pub fn at(s: f64) -> Timestamp {
    START.saturating_add(Duration::from_secs_f64((BOOT_S + s).max(0.0)))
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
