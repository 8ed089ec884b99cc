//! The covariance of `/raw_odom`: wheel odometry alone, whose error grows while the wheels
//! turn and never shrinks (no absolute measurement enters the `odom` frame).
//!
//! The speeds carry the localiser's own odometry noise (1σ: a floor plus a fraction of the
//! speed for slip; the yaw rate from the gyro when there is one, else from the wheels), taken
//! as white noise over one control period, and the pose covariance integrates it along the
//! path (the usual dead-reckoning propagation, yaw error turning into cross-track error).
//! Nothing grows while the vehicle stands. Height, roll and pitch are not measured: they carry
//! a variance of 1e6, as ROS's planar odometry sources (diff_drive_controller) give them.

use nalgebra::{Matrix2, Matrix3, Matrix3x2};

use crate::fusion::odometry::OdomPose;
use crate::time::Timestamp;
use crate::vehicle::chassis::CONTROL_PERIOD;

/// The variance of what the odometry does not measure (z, roll, pitch and their rates).
pub const UNMEASURED: f64 = 1e6;
/// Below these speeds the vehicle stands, m/s and rad/s.
const STANDING: (f64, f64) = (1e-3, 1e-3);

/// The odometry's noise, 1σ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryNoise {
    /// Forward speed: m/s, plus this fraction of the speed.
    pub speed: (f64, f64),
    /// Yaw rate, rad/s.
    pub yaw_rate: f64,
}

impl OdometryNoise {
    /// The localiser's figures: its wheel-speed noise, and its gyro noise when an IMU gives
    /// the `odom` frame its yaw, else its wheel yaw-rate noise.
    pub fn from_localizer(config: &crate::fusion::localizer::LocalizerConfig, gyro: bool) -> Self {
        Self {
            speed: config.odometry_sigma,
            yaw_rate: if gyro {
                config.gyro_sigma
            } else {
                config.odometry_yaw_rate_sigma
            },
        }
    }
}

/// `/raw_odom`'s covariances, row-major 6×6 over (x, y, z, roll, pitch, yaw) and over
/// (vx, vy, vz, wx, wy, wz).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryCovariance {
    /// The pose's.
    pub pose: [f64; 36],
    /// The twist's.
    pub twist: [f64; 36],
}

/// Integrates the pose covariance from one odometry sample to the next.
#[derive(Debug, Clone)]
pub struct OdometryUncertainty {
    noise: OdometryNoise,
    /// x, y, yaw.
    p: Matrix3<f64>,
    last: Option<(Timestamp, OdomPose)>,
}

impl OdometryUncertainty {
    /// Nothing driven yet: a zero covariance at the `odom` frame's origin.
    pub fn new(noise: OdometryNoise) -> Self {
        Self {
            noise,
            p: Matrix3::zeros(),
            last: None,
        }
    }

    /// The covariances with `pose` at `t`.
    pub fn update(&mut self, t: Timestamp, pose: &OdomPose) -> OdometryCovariance {
        let speed_var = (self.noise.speed.0 + self.noise.speed.1 * pose.v.abs()).powi(2);
        let yaw_rate_var = self.noise.yaw_rate.powi(2);
        if let Some((t0, p0)) = self.last {
            let dt = t.saturating_since(t0).as_secs_f64();
            let moving = p0.v.abs() > STANDING.0 || p0.w.abs() > STANDING.1;
            if dt > 0.0 && moving {
                let (s, c) = p0.yaw.sin_cos();
                let d = p0.v * dt;
                let f = Matrix3::new(1.0, 0.0, -d * s, 0.0, 1.0, d * c, 0.0, 0.0, 1.0);
                let g = Matrix3x2::new(c * dt, 0.0, s * dt, 0.0, 0.0, dt);
                // White noise over one control period: the growth does not depend on how
                // often the odometry is sampled.
                let q = Matrix2::new(speed_var, 0.0, 0.0, yaw_rate_var)
                    * (CONTROL_PERIOD.as_secs_f64() / dt);
                self.p = f * self.p * f.transpose() + g * q * g.transpose();
            }
        }
        self.last = Some((t, *pose));
        let mut pose_cov = [0.0; 36];
        let axes = [0, 1, 5];
        for (i, a) in axes.iter().enumerate() {
            for (j, b) in axes.iter().enumerate() {
                pose_cov[a * 6 + b] = self.p[(i, j)];
            }
        }
        for k in [2, 3, 4] {
            pose_cov[k * 6 + k] = UNMEASURED;
        }
        let mut twist = [0.0; 36];
        twist[0] = speed_var;
        // Sideways: a wheeled vehicle only slips, at the forward speed's noise.
        twist[7] = speed_var;
        for k in [2, 3, 4] {
            twist[k * 6 + k] = UNMEASURED;
        }
        twist[35] = yaw_rate_var;
        OdometryCovariance {
            pose: pose_cov,
            twist,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOISE: OdometryNoise = OdometryNoise {
        speed: (0.01, 0.02),
        yaw_rate: 0.003,
    };

    fn drive(period_ms: u64, seconds: u64, v: f64, w: f64) -> OdometryCovariance {
        let mut u = OdometryUncertainty::new(NOISE);
        let mut pose = OdomPose {
            x: 0.0,
            y: 0.0,
            yaw: 0.0,
            v,
            w,
        };
        let mut cov = u.update(Timestamp::from_nanos(0), &pose);
        let dt = period_ms as f64 / 1000.0;
        for i in 1..=(seconds * 1000 / period_ms) {
            pose.x += v * pose.yaw.cos() * dt;
            pose.y += v * pose.yaw.sin() * dt;
            pose.yaw += w * dt;
            cov = u.update(Timestamp::from_nanos(i * period_ms * 1_000_000), &pose);
        }
        cov
    }

    #[test]
    fn standing_still_adds_nothing() {
        let cov = drive(10, 3600, 0.0, 0.0);
        assert_eq!((cov.pose[0], cov.pose[7], cov.pose[35]), (0.0, 0.0, 0.0));
        assert_eq!(cov.pose[14], UNMEASURED);
    }

    #[test]
    fn driving_grows_the_pose_covariance_and_yaw_error_spreads_sideways() {
        let cov = drive(10, 100, 1.0, 0.0);
        let along = cov.pose[0];
        let across = cov.pose[7];
        // σv = 0.03 m/s at 1 m/s, white over 10 ms: σv² × 0.01 s = 9e-6 m² a second.
        assert!((along - 9e-4).abs() < 1e-9, "{along}");
        assert!(
            across > 0.0,
            "yaw error becomes cross-track error: {across}"
        );
        assert!(cov.pose[35] > 0.0);
        let symmetric = (0..6).all(|i| (0..6).all(|j| cov.pose[i * 6 + j] == cov.pose[j * 6 + i]));
        assert!(symmetric);
        assert_eq!(cov.twist[0], 0.03 * 0.03);
        assert_eq!(cov.twist[35], 0.003 * 0.003);
    }

    #[test]
    fn the_growth_does_not_depend_on_the_sample_rate() {
        for period in [5, 20, 50] {
            let a = drive(10, 60, 0.5, 0.1).pose;
            let b = drive(period, 60, 0.5, 0.1).pose;
            for k in [0, 7, 35] {
                assert!(
                    (a[k] - b[k]).abs() <= 0.1 * a[k],
                    "{period} ms, [{k}]: {} against {}",
                    b[k],
                    a[k]
                );
            }
        }
    }
}
