//! `chassisd calibrate imu|odometry|gnss`: calibration from a recording. Each procedure
//! fits what it measures, refuses with the reason when the data cannot support a result,
//! and writes (or updates) the vehicle's calibration file
//! ([`crate::config::calibration`]).

pub mod data;
pub mod imu;
pub mod motion;
pub mod plot;

use std::collections::BTreeMap;

use crate::config::calibration::{CalibrationFile, Entry, Measured};
use crate::config::chassis::WheelRadius;
use data::Dataset;

/// Why a procedure gave no result, and what to do about it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("refused: {reason}. Fix: {fix}")]
pub struct Refusal {
    /// What the data lacks.
    pub reason: String,
    /// How to get data that serves.
    pub fix: String,
}

pub(crate) fn refuse(reason: &str, fix: &str) -> Refusal {
    Refusal {
        reason: reason.to_owned(),
        fix: fix.to_owned(),
    }
}

/// A calibration procedure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Procedure {
    /// Gyro bias and mounting roll and pitch, standing still.
    Imu,
    /// Wheel radii and track, driving.
    Odometry,
    /// Antenna position and heading offset, driving.
    Gnss,
}

impl Procedure {
    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Imu => "imu",
            Self::Odometry => "odometry",
            Self::Gnss => "gnss",
        }
    }
}

/// Settings of the procedures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Standing still must last this long, s.
    pub min_still_s: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Self { min_still_s: 20.0 }
    }
}

/// One line of the report: a key, what the configuration held, what was found.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportLine {
    /// The calibration file's key.
    pub key: &'static str,
    /// The configuration's value, as text.
    pub configured: String,
    /// The value found, as text.
    pub found: String,
    /// The fit's figures.
    pub figures: String,
}

/// What a procedure found.
#[derive(Debug, Clone, PartialEq)]
pub struct Found {
    /// Report lines.
    pub lines: Vec<ReportLine>,
    /// The verdict: "ok", or what makes the result doubtful.
    pub verdict: String,
    /// The IMU fit, when the procedure made one.
    pub imu: Option<imu::ImuResult>,
    /// The driving fit, when the procedure made one.
    pub motion: Option<motion::MotionResult>,
}

impl Found {
    /// The report as an aligned table.
    pub fn table(&self) -> String {
        let mut out = format!(
            "{:<24} {:<34} {:<34} {}\n",
            "key", "configured", "calibrated", "fit"
        );
        for l in &self.lines {
            out += &format!(
                "{:<24} {:<34} {:<34} {}\n",
                l.key, l.configured, l.found, l.figures
            );
        }
        out += &format!("verdict: {}\n", self.verdict);
        out
    }
}

/// Now, as the calibration file stamps it.
fn today() -> String {
    chrono::Utc::now().format("%Y-%m-%dT%H:%M:%SZ").to_string()
}

fn measured<T>(value: T, method: &str, residuals: &[(&str, f64)], verdict: &str) -> Entry<T> {
    Entry::Measured(Measured {
        value,
        date: today(),
        method: method.to_owned(),
        residuals: residuals
            .iter()
            .map(|(k, v)| ((*k).to_owned(), *v))
            .collect::<BTreeMap<_, _>>(),
        verdict: verdict.to_owned(),
    })
}

/// Runs `procedure` on `data`, putting its values into `file` (other keys kept).
pub fn run(
    procedure: Procedure,
    data: &Dataset,
    settings: &Settings,
    file: &mut CalibrationFile,
) -> Result<Found, Refusal> {
    match procedure {
        Procedure::Imu => run_imu(data, settings, file),
        Procedure::Odometry | Procedure::Gnss => run_motion(procedure, data, settings, file),
    }
}

fn run_imu(
    data: &Dataset,
    settings: &Settings,
    file: &mut CalibrationFile,
) -> Result<Found, Refusal> {
    let r = imu::calibrate(data, settings.min_still_s)?;
    let configured = data.vehicle.imu.as_ref();
    let bias0 = configured.map_or([0.0; 3], |i| i.gyro_bias_rps);
    let rpy0 = configured.map_or([0.0; 3], |i| i.mounting_rpy_deg);
    let method = format!(
        "mean rate and gravity over {:.1} s standing still ({} samples)",
        r.span.1 - r.span.0,
        r.samples
    );
    let verdict = "ok".to_owned();
    let sigma_dps = r.bias_sigma_rps.map(f64::to_degrees);
    file.imu.gyro_bias_rps = Some(measured(
        r.gyro_bias_rps,
        &method,
        &[
            ("sigma_x_rps", r.bias_sigma_rps[0]),
            ("sigma_y_rps", r.bias_sigma_rps[1]),
            ("sigma_z_rps", r.bias_sigma_rps[2]),
            ("spread_z_rps", r.gyro_std_rps[2]),
            ("still_from_s", r.span.0),
            ("still_to_s", r.span.1),
        ],
        &verdict,
    ));
    let mounting = [r.roll_deg, r.pitch_deg, rpy0[2]];
    file.imu.mounting_rpy_deg = Some(measured(
        mounting,
        &format!("{method}; yaw kept from the configuration"),
        &[],
        &verdict,
    ));
    let dps = |b: [f64; 3]| {
        format!(
            "[{:.4}, {:.4}, {:.4}] °/s",
            b[0].to_degrees(),
            b[1].to_degrees(),
            b[2].to_degrees()
        )
    };
    Ok(Found {
        lines: vec![
            ReportLine {
                key: "imu.gyro_bias_rps",
                configured: dps(bias0),
                found: dps(r.gyro_bias_rps),
                figures: format!("±{:.4} °/s (z, 1σ)", sigma_dps[2]),
            },
            ReportLine {
                key: "imu.mounting_rpy_deg",
                configured: format!("[{:.2}, {:.2}, {:.2}]°", rpy0[0], rpy0[1], rpy0[2]),
                found: format!(
                    "[{:.2}, {:.2}, {:.2}]°",
                    mounting[0], mounting[1], mounting[2]
                ),
                figures: "roll and pitch from gravity".into(),
            },
        ],
        verdict,
        imu: Some(r),
        motion: None,
    })
}

fn run_motion(
    procedure: Procedure,
    data: &Dataset,
    settings: &Settings,
    file: &mut CalibrationFile,
) -> Result<Found, Refusal> {
    let v = &data.vehicle;
    let Some(chassis) = v.chassis else {
        return Err(refuse(
            "the configuration has no [chassis]",
            "calibrate a vehicle with drives: its configuration gives wheel_radius_m and track_m",
        ));
    };
    let antenna0 = v
        .gnss
        .as_ref()
        .map_or([0.0; 2], |g| [g.antenna.x, g.antenna.y]);
    let offset0 = v.gnss.as_ref().map_or(0.0, |g| g.heading_offset_deg);
    let mounting = v
        .imu
        .as_ref()
        .map(|i| i.mounting().rotation)
        .unwrap_or_default();
    // The gyro's bias from standing still in the same data, else the configured one.
    let still = imu::calibrate(data, settings.min_still_s).ok();
    let (bias, bias_from) = match &still {
        Some(s) => (
            s.gyro_bias_rps,
            "the gyro bias from standing still in the run",
        ),
        None => (
            v.imu.as_ref().map_or([0.0; 3], |i| i.gyro_bias_rps),
            "the configured gyro bias (the run has no long standstill)",
        ),
    };
    let m = motion::fit(
        data,
        bias,
        mounting,
        chassis.wheel_radius_m,
        antenna0,
        chassis.track_m,
    )?;
    let method = format!(
        "{} windows, {:.0} s of RTK-fixed driving, yaw from the gyro with {bias_from}",
        m.windows, m.driving_s
    );
    let mut lines = Vec::new();
    let mut doubts = Vec::new();
    match procedure {
        Procedure::Odometry => {
            let rel = [
                m.radius_sigma[0] / m.radius.left,
                m.radius_sigma[1] / m.radius.right,
            ];
            if rel.iter().any(|r| *r > 5e-4) {
                doubts.push(format!(
                    "radius uncertainty ±{:.3} % (1σ)",
                    rel[0].max(rel[1]) * 100.0
                ));
            }
            if m.track_residual > 0.1 {
                doubts.push(format!("track residual {:.0} %", m.track_residual * 100.0));
            }
            let verdict = verdict(&doubts);
            file.chassis.wheel_radius_m = Some(measured(
                m.radius,
                &format!("straight runs and turns against RTK positions: {method}"),
                &[
                    ("position_rms_m", m.residual_m),
                    ("sigma_left_m", m.radius_sigma[0]),
                    ("sigma_right_m", m.radius_sigma[1]),
                    ("fixes", m.fixes as f64),
                ],
                &verdict,
            ));
            file.chassis.track_m = Some(measured(
                m.track_m,
                "wheel arcs against the gyro's turning over 1 s spans",
                &[
                    ("residual_fraction", m.track_residual),
                    ("turning_rad", m.track_turn_rad),
                ],
                &verdict,
            ));
            let r0 = chassis.wheel_radius_m;
            lines.push(ReportLine {
                key: "chassis.wheel_radius_m",
                configured: radius_text(r0),
                found: radius_text(m.radius),
                figures: format!(
                    "{:+.3} % / {:+.3} %, ±{:.3} % (1σ), RMS {:.1} mm",
                    (m.radius.left / r0.left - 1.0) * 100.0,
                    (m.radius.right / r0.right - 1.0) * 100.0,
                    rel[0].max(rel[1]) * 100.0,
                    m.residual_m * 1000.0
                ),
            });
            lines.push(ReportLine {
                key: "chassis.track_m",
                configured: format!("{:.5} m", chassis.track_m),
                found: format!("{:.5} m", m.track_m),
                figures: format!(
                    "{:+.3} %, residual {:.1} % over {:.0}° of turning",
                    (m.track_m / chassis.track_m - 1.0) * 100.0,
                    m.track_residual * 100.0,
                    m.track_turn_rad.to_degrees()
                ),
            });
            Ok(Found {
                lines,
                verdict,
                imu: still,
                motion: Some(m),
            })
        }
        Procedure::Gnss | Procedure::Imu => {
            if m.antenna_sigma.iter().any(|s| *s > 0.01) {
                doubts.push(format!(
                    "antenna uncertainty ±{:.1} cm (1σ)",
                    m.antenna_sigma[0].max(m.antenna_sigma[1]) * 100.0
                ));
            }
            let verdict = verdict(&doubts);
            file.gnss.antenna = Some(measured(
                m.antenna,
                &format!("antenna circles in turns against the wheels' path: {method}"),
                &[
                    ("position_rms_m", m.residual_m),
                    ("sigma_x_m", m.antenna_sigma[0]),
                    ("sigma_y_m", m.antenna_sigma[1]),
                ],
                &verdict,
            ));
            lines.push(ReportLine {
                key: "gnss.antenna",
                configured: format!("[{:.4}, {:.4}] m", antenna0[0], antenna0[1]),
                found: format!("[{:.4}, {:.4}] m", m.antenna[0], m.antenna[1]),
                figures: format!(
                    "±{:.1} mm (1σ), RMS {:.1} mm",
                    m.antenna_sigma[0].max(m.antenna_sigma[1]) * 1000.0,
                    m.residual_m * 1000.0
                ),
            });
            match m.heading_offset_deg {
                Some(offset) => {
                    let sigma = m.heading_spread_deg / (m.headings.max(1) as f64).sqrt();
                    file.gnss.heading_offset_deg = Some(measured(
                        offset,
                        "dual-antenna heading less the fitted axis of motion",
                        &[
                            ("spread_deg", m.heading_spread_deg),
                            ("headings", m.headings as f64),
                        ],
                        &verdict,
                    ));
                    lines.push(ReportLine {
                        key: "gnss.heading_offset_deg",
                        configured: format!("{offset0:.3}°"),
                        found: format!("{offset:.3}°"),
                        figures: format!(
                            "±{sigma:.3}° (1σ of the mean of {} headings)",
                            m.headings
                        ),
                    });
                }
                None => lines.push(ReportLine {
                    key: "gnss.heading_offset_deg",
                    configured: format!("{offset0:.3}°"),
                    found: "not measured".into(),
                    figures: "the receiver reported no dual-antenna heading".into(),
                }),
            }
            Ok(Found {
                lines,
                verdict,
                imu: still,
                motion: Some(m),
            })
        }
    }
}

fn verdict(doubts: &[String]) -> String {
    if doubts.is_empty() {
        "ok".into()
    } else {
        format!("doubtful: {}", doubts.join("; "))
    }
}

fn radius_text(r: WheelRadius) -> String {
    format!("[{:.5}, {:.5}] m", r.left, r.right)
}
