//! `chassisd import`: a ROS bag's fixes, IMU and wheel odometry as the chassisd recording a
//! real receiver, IMU and pair of drives would have made of the same motion, so `chassisd
//! replay` runs the vehicle's own data through chassisd's fusion.
//!
//! - The receiver: each NavSatFix with a fix becomes GGA (and RMC when the bag has the
//!   receiver's velocity) at its stamp; NavSatStatus 2 is RTK fixed where σ ≤ 5 cm (or
//!   unknown) and RTK float otherwise, 1 is DGPS (SBAS), 0 a plain fix; HDOP carries the
//!   east σ (m) when the covariance is known, else 1.
//! - The drives: the simulator's CiA 402 drives are back-driven at the wheel speeds the
//!   odometry gives (its forward speed and yaw rate over the track it was computed with).
//! - The IMU: the simulator's IMU reads the bag's rate about the vehicle's z axis, the
//!   sensor's rates turned by its mounting.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Rotation3, Vector3};
use serde::Deserialize;

use super::InterchangeError;
use super::bag::messages::{self, FixSample, ImuSample, OdomSample, VelocitySample};
use super::bag::{self, BagKind, Topic};
use super::vehicle_recording::{self, BOOT_S, Epoch, Forced};
use crate::config::chassis::WheelRadius;
use crate::devices::gnss::FixQuality;
use crate::record::Record;
use crate::sim::plant::{ForcedMotion, PlantConfig};
use crate::time::Timestamp;

/// The vehicle and the topics, as `--config` (a small TOML) or the command line give them.
#[derive(Debug, Clone, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ImportSettings {
    /// The receiver's sensor_msgs/NavSatFix topic (found by its type when the bag has one).
    pub fix_topic: Option<String>,
    /// The sensor_msgs/Imu topic.
    pub imu_topic: Option<String>,
    /// The wheels' nav_msgs/Odometry topic.
    pub odometry_topic: Option<String>,
    /// The receiver's velocity (geometry_msgs/TwistWithCovarianceStamped or TwistStamped,
    /// x east, y north); optional.
    pub velocity_topic: Option<String>,
    /// The track the odometry's yaw rate was computed over (its controller's wheel
    /// separation), m.
    pub odometry_track_m: Option<f64>,
    /// The track chassisd's configuration gets, m (the odometry's unless given: what
    /// `chassisd calibrate` fits on a skid-steered vehicle).
    pub track_m: Option<f64>,
    /// The wheel radius, m.
    pub wheel_radius_m: Option<f64>,
    /// The GNSS antenna in base_link (x forward, y left), m.
    pub antenna_m: Option<[f64; 2]>,
    /// The IMU's orientation in base_link: roll, pitch, yaw, degrees (fixed axes x, y, z).
    pub imu_rpy_deg: Option<[f64; 3]>,
    /// The IMU's sample rate, Hz (the bag's median interval unless given).
    pub imu_rate_hz: Option<f64>,
    /// The receiver's latency, s (`localization.gnss_latency_s`).
    pub gnss_latency_s: Option<f64>,
}

impl ImportSettings {
    /// Reads `path` (TOML with the fields above).
    pub fn load(path: &Path) -> Result<Self, InterchangeError> {
        let text = crate::record::read_small(path, 1 << 20)
            .map_err(|e| InterchangeError::Refused(e.to_string()))?;
        toml::from_str(&text)
            .map_err(|e| InterchangeError::Refused(format!("{}: {}", path.display(), e.message())))
    }

    /// These settings with `over`'s where it has them.
    pub fn overridden_by(self, over: Self) -> Self {
        Self {
            fix_topic: over.fix_topic.or(self.fix_topic),
            imu_topic: over.imu_topic.or(self.imu_topic),
            odometry_topic: over.odometry_topic.or(self.odometry_topic),
            velocity_topic: over.velocity_topic.or(self.velocity_topic),
            odometry_track_m: over.odometry_track_m.or(self.odometry_track_m),
            track_m: over.track_m.or(self.track_m),
            wheel_radius_m: over.wheel_radius_m.or(self.wheel_radius_m),
            antenna_m: over.antenna_m.or(self.antenna_m),
            imu_rpy_deg: over.imu_rpy_deg.or(self.imu_rpy_deg),
            imu_rate_hz: over.imu_rate_hz.or(self.imu_rate_hz),
            gnss_latency_s: over.gnss_latency_s.or(self.gnss_latency_s),
        }
    }
}

/// What an import did: every choice it made, in words, and the counts.
#[derive(Debug, Clone, Default)]
pub struct ImportReport {
    /// The choices (a topic and why, a setting and where it came from), one line each.
    pub choices: Vec<String>,
    /// Messages that did not decode, by topic: count and the first reason.
    pub undecoded: BTreeMap<String, (u64, String)>,
    /// Fixes written, and those without a fix left out.
    pub fixes: (usize, usize),
    /// The recording's span, s.
    pub span_s: f64,
}

/// The longest span imported, s: the simulated drive train runs at 1 kHz through it.
const MAX_SPAN_S: f64 = 48.0 * 3600.0;
/// RTK with a horizontal σ up to this is fixed, m.
const RTK_FIXED_SIGMA_M: f64 = 0.05;
/// A velocity belongs to a fix this close to it, s.
const VELOCITY_WITHIN_S: f64 = 0.5;

/// Every message of the types an import reads, by topic.
#[derive(Default)]
struct Samples {
    topics: BTreeMap<String, (String, u64)>,
    fixes: BTreeMap<String, Vec<FixSample>>,
    imus: BTreeMap<String, Vec<ImuSample>>,
    odoms: BTreeMap<String, Vec<OdomSample>>,
    velocities: BTreeMap<String, Vec<VelocitySample>>,
    undecoded: BTreeMap<String, (u64, String)>,
}

impl Samples {
    fn read(file: &Path, kind: BagKind) -> Result<Self, InterchangeError> {
        let mut s = Self::default();
        bag::read(file, kind, &mut |topic: &Topic, logged, bytes| {
            let entry = s
                .topics
                .entry(topic.name.clone())
                .or_insert_with(|| (topic.msg_type.clone(), 0));
            entry.1 += 1;
            // A stamp of 0 (a driver that leaves it) is the time the bag logged it.
            let stamp = |t: u64| if t == 0 { logged } else { t };
            let name = &topic.name;
            let result = match topic.plain_type().as_str() {
                "sensor_msgs/NavSatFix" => messages::fix(kind, bytes).map(|mut m| {
                    m.t_ns = stamp(m.t_ns);
                    s.fixes.entry(name.clone()).or_default().push(m);
                }),
                "sensor_msgs/Imu" => messages::imu(kind, bytes).map(|mut m| {
                    m.t_ns = stamp(m.t_ns);
                    s.imus.entry(name.clone()).or_default().push(m);
                }),
                "nav_msgs/Odometry" => messages::odometry(kind, bytes).map(|mut m| {
                    m.t_ns = stamp(m.t_ns);
                    s.odoms.entry(name.clone()).or_default().push(m);
                }),
                "geometry_msgs/TwistWithCovarianceStamped" => {
                    messages::velocity_with_covariance(kind, bytes).map(|mut m| {
                        m.t_ns = stamp(m.t_ns);
                        s.velocities.entry(name.clone()).or_default().push(m);
                    })
                }
                "geometry_msgs/TwistStamped" => messages::velocity(kind, bytes).map(|mut m| {
                    m.t_ns = stamp(m.t_ns);
                    s.velocities.entry(name.clone()).or_default().push(m);
                }),
                _ => Ok(()),
            };
            if let Err(e) = result {
                let u = s
                    .undecoded
                    .entry(name.clone())
                    .or_insert_with(|| (0, e.to_string()));
                u.0 += 1;
            }
        })?;
        Ok(s)
    }

    /// The bag's topics, for a refusal: `name (type, N messages)`.
    fn listing(&self) -> String {
        let all: Vec<String> = self
            .topics
            .iter()
            .map(|(name, (ty, n))| format!("{name} ({ty}, {n} messages)"))
            .collect();
        if all.is_empty() {
            "no messages at all".into()
        } else {
            all.join(", ")
        }
    }
}

/// The topic of `what` (a type's samples by topic): the one named, or the only one.
fn choose<T>(
    what: &str,
    by_topic: &mut BTreeMap<String, Vec<T>>,
    named: Option<&str>,
    setting: &str,
    listing: &dyn Fn() -> String,
    choices: &mut Vec<String>,
) -> Result<Option<(String, Vec<T>)>, InterchangeError> {
    if let Some(name) = named {
        return match by_topic.remove(name) {
            Some(samples) => {
                choices.push(format!(
                    "{what}: {name} ({} messages, named by {setting})",
                    samples.len()
                ));
                Ok(Some((name.to_owned(), samples)))
            }
            None => Err(InterchangeError::Refused(format!(
                "{setting} names {name}, which holds no {what} in the bag; the bag has: {}",
                listing()
            ))),
        };
    }
    match by_topic.len() {
        0 => Ok(None),
        1 => {
            let (name, samples) = by_topic.pop_first().unwrap_or_default();
            choices.push(format!(
                "{what}: {name} ({} messages, the bag's only topic of its type)",
                samples.len()
            ));
            Ok(Some((name, samples)))
        }
        _ => Err(InterchangeError::Refused(format!(
            "several topics hold {what} ({}); name one with {setting}",
            by_topic.keys().cloned().collect::<Vec<_>>().join(", ")
        ))),
    }
}

/// Imports the bag at `bag_path` into a new recording folder `out`.
pub fn import(
    bag_path: &Path,
    out: &Path,
    settings: &ImportSettings,
) -> Result<ImportReport, InterchangeError> {
    let (file, kind) = bag::open(bag_path)?;
    let mut report = ImportReport::default();
    report.choices.push(format!(
        "bag: {} ({})",
        file.display(),
        match kind {
            BagKind::Ros1 => "ROS1",
            BagKind::Ros2 => "ROS 2, MCAP with CDR",
        }
    ));
    let mut s = Samples::read(&file, kind)?;
    let topics = s.topics.clone();
    let listing = move || {
        Samples {
            topics: topics.clone(),
            ..Default::default()
        }
        .listing()
    };
    let choices = &mut report.choices;
    let fix = choose(
        "fixes (sensor_msgs/NavSatFix)",
        &mut s.fixes,
        settings.fix_topic.as_deref(),
        "fix_topic",
        &listing,
        choices,
    )?;
    let imu = choose(
        "IMU samples (sensor_msgs/Imu)",
        &mut s.imus,
        settings.imu_topic.as_deref(),
        "imu_topic",
        &listing,
        choices,
    )?;
    let odom = choose(
        "wheel odometry (nav_msgs/Odometry)",
        &mut s.odoms,
        settings.odometry_topic.as_deref(),
        "odometry_topic",
        &listing,
        choices,
    )?;
    let velocity = choose(
        "the receiver's velocity (geometry_msgs/TwistWithCovarianceStamped or TwistStamped)",
        &mut s.velocities,
        settings.velocity_topic.as_deref(),
        "velocity_topic",
        &listing,
        choices,
    )?;
    report.undecoded = s.undecoded;
    let missing: Vec<&str> = [
        (
            fix.is_none(),
            "sensor_msgs/NavSatFix (the receiver's fixes)",
        ),
        (imu.is_none(), "sensor_msgs/Imu (the gyro)"),
        (odom.is_none(), "nav_msgs/Odometry (the wheels)"),
    ]
    .into_iter()
    .filter_map(|(gone, what)| gone.then_some(what))
    .collect();
    let (Some((_, mut fixes)), Some((_, mut imus)), Some((_, mut odoms))) = (fix, imu, odom) else {
        let undecoded: Vec<String> = report
            .undecoded
            .iter()
            .map(|(t, (n, why))| format!("{t}: {n} messages did not decode ({why})"))
            .collect();
        return Err(InterchangeError::Refused(format!(
            "the bag lacks {}; it has: {}{}",
            missing.join(", "),
            listing(),
            if undecoded.is_empty() {
                String::new()
            } else {
                format!("; {}", undecoded.join("; "))
            }
        )));
    };
    if velocity.is_none() {
        report.choices.push(
            "the receiver's velocity: none in the bag (GGA alone, as a receiver without RMC)"
                .into(),
        );
    }
    let mut velocities = velocity.map(|(_, v)| v).unwrap_or_default();
    fixes.sort_by_key(|f| f.t_ns);
    imus.sort_by_key(|i| i.t_ns);
    odoms.sort_by_key(|o| o.t_ns);
    velocities.sort_by_key(|v| v.t_ns);
    let t0 = [fixes[0].t_ns, imus[0].t_ns, odoms[0].t_ns]
        .into_iter()
        .min()
        .unwrap_or(0);
    let last = [
        fixes.last().map(|f| f.t_ns),
        imus.last().map(|i| i.t_ns),
        odoms.last().map(|o| o.t_ns),
    ]
    .into_iter()
    .flatten()
    .max()
    .unwrap_or(t0);
    let s_of = move |t: u64| seconds_since(t0, t);
    report.span_s = seconds_since(t0, last);
    if report.span_s > MAX_SPAN_S {
        return Err(InterchangeError::Refused(format!(
            "the bag spans {:.0} h; more than {:.0} h is not imported (cut it with `rosbag \
             filter` or `ros2 bag convert`)",
            report.span_s / 3600.0,
            MAX_SPAN_S / 3600.0
        )));
    }
    let start_ns = t0
        .checked_sub((BOOT_S * 1e9) as u64)
        .ok_or_else(|| InterchangeError::Refused("the bag's stamps start before 1970".into()))?;

    let forced = forced(settings, &fixes, &imus, &odoms, s_of, &mut report.choices)?;
    let records = receiver_records(&fixes, &velocities, &mut report);
    vehicle_recording::write(out, &forced, &records, Timestamp::from_nanos(start_ns))?;
    Ok(report)
}

/// The simulated vehicle and its motion through the data.
fn forced(
    settings: &ImportSettings,
    fixes: &[FixSample],
    imus: &[ImuSample],
    odoms: &[OdomSample],
    s_of: impl Fn(u64) -> f64,
    choices: &mut Vec<String>,
) -> Result<Forced, InterchangeError> {
    let mut plant = PlantConfig::builtin()
        .map_err(|e| InterchangeError::Refused(format!("the built-in vehicle: {e}")))?;
    let defaults = plant.geometry;
    let mut setting = |name: &str, given: Option<f64>, default: f64, unit: &str| {
        let value = given.unwrap_or(default);
        choices.push(match given {
            Some(_) => format!("{name}: {value} {unit} (given)"),
            None => format!("{name}: {value} {unit} (default; give {name} if it differs)"),
        });
        value
    };
    let odometry_track = setting(
        "odometry_track_m",
        settings.odometry_track_m,
        defaults.track_m,
        "m",
    );
    let track = setting("track_m", settings.track_m, odometry_track, "m");
    let radius = setting(
        "wheel_radius_m",
        settings.wheel_radius_m,
        defaults.wheel_radius_m.left,
        "m",
    );
    let positive = |name: &str, v: f64| {
        if v.is_finite() && v > 0.0 && v < 100.0 {
            Ok(v)
        } else {
            Err(InterchangeError::Refused(format!(
                "{name} must be a length above 0, not {v}"
            )))
        }
    };
    positive("odometry_track_m", odometry_track)?;
    positive("track_m", track)?;
    positive("wheel_radius_m", radius)?;
    let antenna = settings.antenna_m.unwrap_or([0.0, 0.0]);
    choices.push(format!(
        "antenna_m: [{}, {}] (x forward, y left)",
        antenna[0], antenna[1]
    ));
    let rpy = settings.imu_rpy_deg.unwrap_or([0.0, 0.0, 0.0]);
    choices.push(format!(
        "imu_rpy_deg: [{}, {}, {}] (the IMU's orientation in base_link)",
        rpy[0], rpy[1], rpy[2]
    ));
    let mount = Rotation3::from_euler_angles(
        rpy[0].to_radians(),
        rpy[1].to_radians(),
        rpy[2].to_radians(),
    );
    let rate = match settings.imu_rate_hz {
        Some(r) => r,
        None => median_rate_hz(imus.iter().map(|i| i.t_ns)),
    };
    if !(1.0..=1000.0).contains(&rate) {
        return Err(InterchangeError::Refused(format!(
            "the IMU's rate is {rate:.1} Hz; the simulated IMU runs 1–1000 Hz (give imu_rate_hz)"
        )));
    }
    choices.push(format!(
        "imu_rate_hz: {rate:.2} Hz{}",
        if settings.imu_rate_hz.is_some() {
            " (given)"
        } else {
            " (the bag's median interval)"
        }
    ));
    plant.name = "imported".into();
    if let Some(f) = fixes.iter().find(|f| f.status >= 0) {
        plant.datum = [f.position.0, f.position.1, f.position.2];
    }
    plant.geometry.wheel_radius_m = WheelRadius::both(radius);
    plant.geometry.track_m = track;
    plant.geometry.antenna = antenna;
    plant.imu.rate_hz = rate;
    // The bag's gyro is the truth the simulated IMU reads: no noise or bias of its own, and
    // no slip between the data's wheels and the drives'.
    plant.imu.gyro_bias_rps = 0.0;
    plant.imu.gyro_noise_rps = 0.0;
    plant.slip.bias = [0.0, 0.0];
    plant.slip.sigma = 0.0;
    let mut times: Vec<u64> = odoms
        .iter()
        .map(|o| o.t_ns)
        .chain(imus.iter().map(|i| i.t_ns))
        .collect();
    times.sort_unstable();
    times.dedup();
    let at_or_before = |t: u64, times: &[u64]| times.partition_point(|x| *x <= t).saturating_sub(1);
    let odom_times: Vec<u64> = odoms.iter().map(|o| o.t_ns).collect();
    let imu_times: Vec<u64> = imus.iter().map(|i| i.t_ns).collect();
    let motion = times
        .into_iter()
        .map(|t| {
            let o = odoms[at_or_before(t, &odom_times)];
            let i = imus[at_or_before(t, &imu_times)];
            let rate = mount * Vector3::new(i.rate[0], i.rate[1], i.rate[2]);
            (
                s_of(t),
                ForcedMotion {
                    v: o.vx,
                    wheel_yaw_rate: o.wz * odometry_track / track,
                    gyro_z: rate.z,
                },
            )
        })
        .collect();
    let mut localization = toml::Table::new();
    if let Some(latency) = settings.gnss_latency_s {
        localization.insert("gnss_latency_s".into(), latency.into());
        choices.push(format!("gnss_latency_s: {latency} s"));
    }
    Ok(Forced {
        plant,
        localization,
        motion,
    })
}

/// Seconds from `t0` to `t` (ns).
fn seconds_since(t0: u64, t: u64) -> f64 {
    t.saturating_sub(t0) as f64 * 1e-9
}

/// The median rate of samples at `times` (ns), Hz.
fn median_rate_hz(times: impl Iterator<Item = u64>) -> f64 {
    let times: Vec<u64> = times.collect();
    let mut gaps: Vec<u64> = times
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|g| *g > 0)
        .collect();
    gaps.sort_unstable();
    gaps.get(gaps.len() / 2).map_or(0.0, |g| 1e9 / *g as f64)
}

/// The receiver's serial records: an epoch for each fix with a fix.
fn receiver_records(
    fixes: &[FixSample],
    velocities: &[VelocitySample],
    report: &mut ImportReport,
) -> Vec<Record> {
    let mut records = Vec::with_capacity(fixes.len());
    let mut left_out = 0;
    for f in fixes {
        let sigma =
            (f.covariance_type > 0 && f.covariance[0] >= 0.0).then(|| f.covariance[0].sqrt());
        let quality = match f.status {
            2 if sigma.is_none_or(|s| s <= RTK_FIXED_SIGMA_M) => FixQuality::RtkFixed,
            2 => FixQuality::RtkFloat,
            1 => FixQuality::Dgps,
            0 => FixQuality::Single,
            _ => {
                left_out += 1;
                continue;
            }
        };
        let (lat, lon, h) = f.position;
        if !(lat.is_finite() && lon.is_finite() && (-90.0..=90.0).contains(&lat)) {
            left_out += 1;
            continue;
        }
        let i = velocities.partition_point(|v| v.t_ns <= f.t_ns);
        let velocity = velocities
            .get(i.saturating_sub(1))
            .filter(|v| f.t_ns.abs_diff(v.t_ns) as f64 * 1e-9 <= VELOCITY_WITHIN_S)
            .map(|v| {
                let (e, n) = v.east_north;
                (e.hypot(n), e.atan2(n).to_degrees())
            });
        let t = Timestamp::from_nanos(f.t_ns);
        records.push(
            Epoch {
                utc_us: t.as_micros() as i64,
                quality,
                position: (lat, lon, if h.is_finite() { h } else { 0.0 }),
                hdop: sigma.unwrap_or(1.0),
                velocity,
            }
            .record(t),
        );
    }
    report.fixes = (records.len(), left_out);
    report.choices.push(format!(
        "receiver: GGA{} per fix at its stamp; NavSatStatus 2 → RTK fixed (σ ≤ {} m) or float, \
         1 → DGPS, 0 → a plain fix; HDOP = the east σ (m) where the covariance is known, else 1",
        if velocities.is_empty() {
            ""
        } else {
            " and RMC"
        },
        RTK_FIXED_SIGMA_M
    ));
    records
}
