//! A vehicle's recorded motion and fixes as a chassisd recording: the simulator's CiA 402
//! drives are back-driven at the wheel speeds the data gives and its IMU reads the data's
//! gyro, so wheels and gyro reach the core through the real decoders, and the receiver's
//! sentences are written as a receiver sends them, at the times they arrived. What
//! `chassisd import` writes from a bag, and the fusion benchmark from the shared data.

use std::path::Path;

use bytes::Bytes;

use super::InterchangeError;
use crate::devices::gnss::FixQuality;
use crate::devices::gnss::encode::{angle, quality_digit, sentence};
use crate::engine::EngineOutput;
use crate::record::{Payload, Record, RecordingWriter};
use crate::sim::lockstep::{self, Lockstep, PLANT_STEP, Sink};
use crate::sim::plant::{ForcedMotion, GnssCondition, PlantConfig};
use crate::time::Timestamp;

/// The drives boot, standing, before the data starts, s.
pub const BOOT_S: f64 = 3.0;

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
/// receiver) at `dir`; the drives boot at `start`, [`BOOT_S`] before the data's first moment.
pub fn write(
    dir: &Path,
    forced: &Forced,
    gnss: &[Record],
    start: Timestamp,
) -> Result<(), InterchangeError> {
    let plant = forced.plant.clone();
    let failed = |what: String| {
        move |e: &dyn std::fmt::Display| InterchangeError::Refused(format!("{what}: {e}"))
    };
    let mut sim = Lockstep::new(plant.clone(), 1, start)
        .map_err(|e| failed("the simulated drive train".into())(&e))?;
    // The simulator's drive train, IMU and receiver ports with chassisd's own localisation
    // defaults but for what the vehicle's integrator would set; the first fix is the datum.
    let mut config: toml::Table = toml::from_str(&sim.config().to_effective_toml())
        .map_err(|e| failed("the simulated vehicle's configuration".into())(&e))?;
    config.insert(
        "localization".into(),
        toml::Value::Table(forced.localization.clone()),
    );
    let config_text =
        toml::to_string(&config).map_err(|e| failed("the configuration".into())(&e))?;
    let writer = RecordingWriter::create(
        dir,
        &plant.name,
        start,
        Some(&config_text),
        lockstep::sources(&plant),
    )
    .map_err(|e| failed(format!("recording {}", dir.display()))(&e))?;
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
        return Err(failed(format!("recording {}", dir.display()))(&e));
    }
    // The recording ends where the lockstep stopped: a replay runs the control loop to its
    // end, and ticks past the last recorded one would transmit frames never recorded.
    sink.writer
        .finish(sim.time())
        .map_err(|e| failed(format!("recording {}", dir.display()))(&e))
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
