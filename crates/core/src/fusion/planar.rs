//! Planar helpers the frames and filters share: angle wrapping and a covariance's largest σ.

use std::f64::consts::PI;

/// Wraps an angle into (-π, π].
pub fn wrap(a: f64) -> f64 {
    let mut a = a % (2.0 * PI);
    if a > PI {
        a -= 2.0 * PI;
    } else if a <= -PI {
        a += 2.0 * PI;
    }
    a
}

/// The 1σ along the major axis of a 2-D covariance (var x, var y, cov xy): the square root
/// of its largest eigenvalue.
pub fn largest_sigma(xx: f64, yy: f64, xy: f64) -> f64 {
    let mean = (xx + yy) / 2.0;
    let spread = (((xx - yy) / 2.0).powi(2) + xy * xy).sqrt();
    (mean + spread).max(0.0).sqrt()
}

/// True heading (degrees, 0–360, clockwise from north) of an ENU yaw.
pub fn heading_deg_of_yaw(yaw: f64) -> f64 {
    (90.0 - yaw.to_degrees()).rem_euclid(360.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wraps_angles() {
        assert!((wrap(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap(-3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap(0.5) - 0.5).abs() < 1e-15);
        assert!((wrap(2.0 * PI + 0.1) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn the_largest_sigma_is_the_major_axis() {
        assert!((largest_sigma(4.0, 1.0, 0.0) - 2.0).abs() < 1e-12);
        // A covariance along the diagonal: eigenvalues 2 and 0.
        assert!((largest_sigma(1.0, 1.0, 1.0) - 2f64.sqrt()).abs() < 1e-12);
    }
}
