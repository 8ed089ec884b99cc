//! What a calibration fits, gathered from a recording: the IMU's raw samples, the wheel
//! angles and the receiver's positions and headings, on one time axis. The recording goes
//! through the same engine (decoders, CANopen drives) as a replay.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use crate::config::{ConfigError, VehicleConfig};
use crate::devices::gnss::{FixQuality, GnssFix};
use crate::engine::{EngineOutput, Measured};
use crate::geodesy::{Enu, Geodetic};
use crate::record::RecordError;
use crate::replay::{self, Consumer, ReplayError, ReplayOptions};
use crate::time::Timestamp;

/// At most this much of a recording is gathered (the memory of a calibration is bounded;
/// an hour is far more than any procedure needs), s.
pub const MAX_SPAN_S: f64 = 3600.0;

/// One IMU sample in the sensor frame, the configured bias not taken off.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuPoint {
    /// s since the start of the data.
    pub t: f64,
    /// Angular rate, rad/s.
    pub gyro: Vector3<f64>,
    /// Specific force, m/s².
    pub accel: Vector3<f64>,
}

/// Both wheels' angles as the drives reported them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelPoint {
    /// s since the start of the data.
    pub t: f64,
    /// Left wheel angle, rad, positive forward.
    pub left: f64,
    /// Right wheel angle, rad, positive forward.
    pub right: f64,
}

/// A position of the antenna in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixPoint {
    /// The epoch: s since the start of the data (arrival less the configured latency).
    pub t: f64,
    /// East, m.
    pub east: f64,
    /// North, m.
    pub north: f64,
    /// Fix quality.
    pub quality: FixQuality,
}

/// A dual-antenna heading as the receiver reported it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingPoint {
    /// The epoch: s since the start of the data.
    pub t: f64,
    /// Degrees, 0 north, clockwise.
    pub deg: f64,
}

/// Everything a calibration fits.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The vehicle's configuration (what it believed when recorded).
    pub vehicle: VehicleConfig,
    /// IMU samples in time order.
    pub imu: Vec<ImuPoint>,
    /// Wheel angles in time order.
    pub wheels: Vec<WheelPoint>,
    /// Positions in time order.
    pub fixes: Vec<FixPoint>,
    /// Headings in time order.
    pub headings: Vec<HeadingPoint>,
    /// Whether the recording was longer than [`MAX_SPAN_S`] and its end left out.
    pub truncated: bool,
}

/// Gathers the engine's measurements.
struct Gather {
    latency_s: f64,
    start: Option<Timestamp>,
    imu: Vec<ImuPoint>,
    wheels: Vec<WheelPoint>,
    positions: Vec<(f64, Geodetic, FixQuality)>,
    headings: Vec<HeadingPoint>,
    last_position: Option<Timestamp>,
    last_heading: Option<Timestamp>,
    last_wheels: Option<Timestamp>,
    truncated: bool,
}

impl Gather {
    fn seconds(&mut self, t: Timestamp) -> f64 {
        let start = *self.start.get_or_insert(t);
        t.as_nanos() as f64 * 1e-9 - start.as_nanos() as f64 * 1e-9
    }

    fn gnss(&mut self, fix: &GnssFix) {
        if let Some(p) = fix.position
            && self.last_position != Some(p.rx)
        {
            self.last_position = Some(p.rx);
            let t = self.seconds(p.rx) - self.latency_s;
            let height = p.value.height_above_ellipsoid_m();
            let at = Geodetic {
                lat_deg: p.value.latitude_deg,
                lon_deg: p.value.longitude_deg,
                h_m: height,
            };
            self.positions.push((t, at, fix.quality));
            // A recording without IMU or wheels is bounded by its fixes.
            self.truncated = t > MAX_SPAN_S;
        }
        if let Some(h) = fix.heading_deg
            && self.last_heading != Some(h.rx)
        {
            self.last_heading = Some(h.rx);
            let t = self.seconds(h.rx) - self.latency_s;
            self.headings.push(HeadingPoint { t, deg: h.value });
        }
    }
}

impl Consumer for Gather {
    fn take(&mut self, outputs: &mut Vec<EngineOutput>, _offset_ns: i128) -> std::io::Result<()> {
        for output in outputs.drain(..) {
            let EngineOutput::Measured(m) = output else {
                continue;
            };
            if self.truncated {
                continue;
            }
            match m {
                Measured::Imu(s) => {
                    let t = self.seconds(s.rx);
                    self.imu.push(ImuPoint {
                        t,
                        gyro: s.gyro,
                        accel: s.accel,
                    });
                    self.truncated = t > MAX_SPAN_S;
                }
                Measured::Gnss(_, fix) => self.gnss(&fix),
                Measured::Wheels { left, right } => {
                    let (Some(l), Some(r)) = (left.angle_rad, right.angle_rad) else {
                        continue;
                    };
                    let Some(at) = left.received.max(right.received) else {
                        continue;
                    };
                    if self.last_wheels == Some(at) {
                        continue;
                    }
                    self.last_wheels = Some(at);
                    let t = self.seconds(at);
                    self.wheels.push(WheelPoint {
                        t,
                        left: l,
                        right: r,
                    });
                    self.truncated = t > MAX_SPAN_S;
                }
            }
        }
        Ok(())
    }
}

/// Why a recording's measurements could not be gathered.
#[derive(Debug, thiserror::Error)]
pub enum GatherError {
    /// The recording does not open.
    #[error("cannot open the recording {}: {error}", .path.display())]
    Open {
        /// Its folder.
        path: PathBuf,
        /// Why.
        error: RecordError,
    },
    /// It stores no configuration, and none was given.
    #[error(
        "the recording {} stores no vehicle configuration; give one with --config",
        .0.display()
    )]
    NoConfiguration(PathBuf),
    /// The configuration stored with it, or given, does not load.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Replaying it failed.
    #[error(transparent)]
    Replay(#[from] ReplayError),
}

impl Dataset {
    /// Gathers the measurements of the recording at `path` (the configuration stored with
    /// it, or `config`), with a progress bar on stderr when `progress`.
    pub fn from_recording(
        path: &Path,
        config: Option<VehicleConfig>,
        progress: bool,
    ) -> Result<Self, GatherError> {
        let stored = stored_config(path)?;
        let vehicle = match (config, stored) {
            (Some(c), _) => c,
            (None, Some(c)) => c,
            (None, None) => return Err(GatherError::NoConfiguration(path.to_owned())),
        };
        let latency_s = vehicle.localization.map_or(0.0, |l| l.gnss_latency_s);
        let mut gather = Gather {
            latency_s,
            start: None,
            imu: Vec::new(),
            wheels: Vec::new(),
            positions: Vec::new(),
            headings: Vec::new(),
            last_position: None,
            last_heading: None,
            last_wheels: None,
            truncated: false,
        };
        let options = ReplayOptions {
            config: Some(vehicle.clone()),
            progress,
            ..ReplayOptions::default()
        };
        replay::replay_into(path, &options, |e| e.emit_measurements(), &mut gather)?;
        let datum = vehicle
            .localization
            .and_then(|l| l.datum)
            .map(|[lat_deg, lon_deg, h_m]| Geodetic {
                lat_deg,
                lon_deg,
                h_m,
            })
            .or_else(|| {
                let fixed = gather.positions.iter();
                fixed
                    .clone()
                    .find(|p| p.2 == FixQuality::RtkFixed)
                    .or(gather.positions.first())
                    .map(|p| p.1)
            });
        let fixes = match datum {
            Some(d) => {
                let frame = Enu::new(d);
                gather
                    .positions
                    .iter()
                    .map(|&(t, at, quality)| {
                        let enu = frame.to_enu(&at);
                        FixPoint {
                            t,
                            east: enu.x,
                            north: enu.y,
                            quality,
                        }
                    })
                    .collect()
            }
            None => Vec::new(),
        };
        Ok(Self {
            vehicle,
            imu: gather.imu,
            wheels: gather.wheels,
            fixes,
            headings: gather.headings,
            truncated: gather.truncated,
        })
    }
}

/// The configuration stored with the recording at `path`.
fn stored_config(path: &Path) -> Result<Option<VehicleConfig>, GatherError> {
    let (meta, _) =
        crate::record::RecordingReader::open(path).map_err(|error| GatherError::Open {
            path: path.to_owned(),
            error,
        })?;
    let config = meta
        .vehicle_config
        .map(|file| VehicleConfig::load_within(&path.join(file), path))
        .transpose()?;
    Ok(config)
}
