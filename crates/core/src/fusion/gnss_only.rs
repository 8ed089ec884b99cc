//! The pose of a vehicle without wheels to reckon on (a GNSS-only configuration: no
//! `[chassis]`). There is no dead reckoning to carry the pose between fixes or to check a
//! fix against, so the pose is the latest fix less the antenna's lever arm along the latest
//! heading (dual-antenna, or the course over ground), and its uncertainty grows with the
//! fix's age as fast as such a vehicle may have moved.

use super::planar::wrap;
use crate::time::Timestamp;

/// How fast the position's 1σ grows with the fix's age, m/s: a vehicle this configuration
/// serves (a mower, a survey cart) moving at walking pace. A 1 Hz receiver's fix stays
/// within a 0.5 m bound for its period; a receiver silent for 2.5 s does not.
pub const AGE_GROWTH_MPS: f64 = 0.2;

/// Without any heading, its 1σ, rad.
const UNKNOWN_YAW_SIGMA: f64 = std::f64::consts::PI;

/// The latest fix and heading.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GnssOnly {
    /// Time, east/north of the antenna (m), 1σ (m).
    fix: Option<(Timestamp, (f64, f64), f64)>,
    /// Yaw (rad) and its 1σ.
    heading: Option<(f64, f64)>,
}

impl GnssOnly {
    /// A position fix of the antenna.
    pub fn fix(&mut self, t: Timestamp, en: (f64, f64), sigma: (f64, f64)) {
        let s = sigma.0.max(sigma.1);
        if en.0.is_finite() && en.1.is_finite() && s.is_finite() {
            self.fix = Some((t, en, s));
        }
    }

    /// A heading (or a course taken as one), yaw and 1σ, rad.
    pub fn heading(&mut self, yaw: f64, sigma: f64) {
        if yaw.is_finite() && sigma.is_finite() {
            self.heading = Some((wrap(yaw), sigma));
        }
    }

    /// The reference point's pose at `t` for an antenna at `antenna` (x forward, y left, m):
    /// x, y, yaw, and the position's and the yaw's 1σ.
    pub fn pose_at(
        &self,
        t: Timestamp,
        antenna: (f64, f64),
    ) -> Option<((f64, f64, f64), f64, f64)> {
        let (at, _, sigma) = self.fix?;
        let pose = self.pose(antenna)?;
        let yaw_sigma = self.heading.map_or(UNKNOWN_YAW_SIGMA, |(_, s)| s);
        let age = t.saturating_since(at).as_secs_f64();
        // The lever arm's direction is as uncertain as the heading.
        let lever = antenna.0.hypot(antenna.1) * yaw_sigma.min(1.0);
        let position_sigma = sigma.hypot(lever).hypot(AGE_GROWTH_MPS * age);
        Some((pose, position_sigma, yaw_sigma))
    }

    /// The reference point's pose at the latest fix: x, y, yaw.
    pub fn pose(&self, antenna: (f64, f64)) -> Option<(f64, f64, f64)> {
        let (_, (e, n), _) = self.fix?;
        let (yaw, _) = self.heading.unwrap_or((0.0, UNKNOWN_YAW_SIGMA));
        let (s, c) = yaw.sin_cos();
        Some((
            e - (c * antenna.0 - s * antenna.1),
            n - (s * antenna.0 + c * antenna.1),
            yaw,
        ))
    }

    /// The map frame moved by (dx, dy).
    pub fn shift(&mut self, dx: f64, dy: f64) {
        if let Some((_, en, _)) = &mut self.fix {
            *en = (en.0 + dx, en.1 + dy);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(s: f64) -> Timestamp {
        Timestamp::from_micros((s * 1e6) as u64)
    }

    #[test]
    fn the_pose_is_the_fix_less_the_lever_arm_and_ages() {
        let mut g = GnssOnly::default();
        assert_eq!(g.pose_at(at(1.0), (0.2, 0.0)), None);
        g.fix(at(1.0), (10.0, 5.0), (0.02, 0.02));
        // No heading yet: the position is known only to the lever arm.
        let (_, sigma, yaw_sigma) = g.pose_at(at(1.0), (0.2, 0.0)).unwrap();
        assert!(yaw_sigma > 3.0 && sigma > 0.2, "{sigma}");
        g.heading(std::f64::consts::FRAC_PI_2, 0.01);
        let ((x, y, yaw), sigma, _) = g.pose_at(at(1.0), (0.2, 0.0)).unwrap();
        assert!((x - 10.0).abs() < 1e-9 && (y - 4.8).abs() < 1e-9, "{x} {y}");
        assert!((yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(sigma < 0.03, "{sigma}");
        // Three seconds without a fix: beyond a 0.5 m bound.
        let (_, sigma, _) = g.pose_at(at(4.0), (0.2, 0.0)).unwrap();
        assert!(sigma > 0.5, "{sigma}");
    }

    #[test]
    fn non_finite_input_is_ignored() {
        let mut g = GnssOnly::default();
        g.fix(at(1.0), (f64::NAN, 0.0), (0.02, 0.02));
        g.heading(f64::INFINITY, 0.1);
        assert_eq!(g.pose((0.0, 0.0)), None);
    }
}
