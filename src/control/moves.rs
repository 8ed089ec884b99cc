//! Distance and angle moves (`set_navi_cmd`): "forward 50 cm", "turn left 90°", closed on
//! the vehicle's own pose relative to where the move started.
//!
//! - Distance is measured in the `odom` frame (wheels and gyro), along the heading at the
//!   start, corrected by the wheels' scale error the fusion has learnt against GNSS when the
//!   vehicle is located at the start (tyre wear and slip make wheels read long or short).
//!   The heading is held on the map's yaw when located at the start, else on the `odom`
//!   yaw. A turn counts its angle on the same heading source.
//! - The move follows a time-optimal profile ([`super::profile`]); the command is the
//!   profile's speed, led by the drives' response time times its acceleration, plus a
//!   correction proportional to the distance the vehicle lags the profile by. The gain comes
//!   from the learnt response time (damping about 0.7), not from a plant's figure.
//! - It has arrived once the profile has ended and the point where the vehicle comes to
//!   rest is within the tolerance: the position plus the speed times the response time (a
//!   first-order drive coasts that far once its command is zero), with that coast itself
//!   within the tolerance. It has timed out when the allowance is spent first.

use super::profile::{Limits, Profile};
use super::{MoveKind, Outcome, PoseView};
use crate::config::motion::MotionSettings;
use crate::fusion::ekf::wrap;
use crate::time::Timestamp;

/// The share of the acceleration limits the profile plans with: the rest is headroom for
/// the correction, which the drive train's ramps would otherwise clip.
const PROFILE_ACCEL_SHARE: f64 = 0.95;

/// What the heading is read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeadingSource {
    /// The fused (map) yaw: the vehicle was located when the move started.
    Map,
    /// The `odom` frame's yaw (wheels and gyro).
    Odom,
}

/// What a control step asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Drive at forward speed `v` (m/s) and yaw rate `w` (rad/s).
    Drive {
        /// m/s.
        v: f64,
        /// rad/s.
        w: f64,
    },
    /// The move is over: how, and the remaining error (m or rad) in its own frame.
    Done(Outcome, f64),
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Start {
    /// `odom` position and yaw.
    x: f64,
    y: f64,
    odom_yaw: f64,
    /// The heading source's yaw.
    yaw: f64,
}

/// A distance or angle move under way.
#[derive(Debug, Clone)]
pub struct RelativeMove {
    kind: MoveKind,
    profile: Profile,
    /// +1 forward or left, −1 back or right.
    sign: f64,
    heading: HeadingSource,
    start: Start,
    started: Timestamp,
    /// Turned so far on the heading source (unwrapped), rad.
    turned: f64,
    last_yaw: f64,
    /// Odometry distance per true distance (1 + the wheels' scale error).
    wheel_scale: f64,
    tolerance: f64,
    allowance_s: f64,
}

impl RelativeMove {
    /// A move of `kind` starting at `t` from the pose in `view`.
    pub fn new(t: Timestamp, kind: MoveKind, view: &PoseView, settings: &MotionSettings) -> Self {
        let (heading, yaw) = match view.map_yaw {
            Some(yaw) => (HeadingSource::Map, yaw),
            None => (HeadingSource::Odom, view.odom.yaw),
        };
        let share = |l: Limits| Limits {
            accel: l.accel * PROFILE_ACCEL_SHARE,
            decel: l.decel * PROFILE_ACCEL_SHARE,
            ..l
        };
        let (amount, limits, tolerance) = match kind {
            MoveKind::Straight { distance_m } => (
                distance_m,
                share(settings.linear),
                settings.position_tolerance_m,
            ),
            MoveKind::Turn { angle_rad } => (
                angle_rad,
                share(settings.angular),
                settings.angle_tolerance_rad,
            ),
        };
        let profile = Profile::plan(amount, limits);
        Self {
            kind,
            sign: if amount < 0.0 { -1.0 } else { 1.0 },
            allowance_s: profile.duration() * settings.time_allowance_factor
                + settings.time_allowance_s,
            profile,
            heading,
            start: Start {
                x: view.odom.x,
                y: view.odom.y,
                odom_yaw: view.odom.yaw,
                yaw,
            },
            started: t,
            turned: 0.0,
            last_yaw: yaw,
            wheel_scale: view.wheel_scale.unwrap_or(1.0),
            tolerance,
        }
    }

    /// What it is.
    pub fn kind(&self) -> MoveKind {
        self.kind
    }

    /// Where its heading comes from.
    pub fn heading_source(&self) -> HeadingSource {
        self.heading
    }

    /// The wheel scale its distance is corrected by.
    pub fn wheel_scale(&self) -> f64 {
        self.wheel_scale
    }

    /// The profile it follows.
    pub fn profile(&self) -> &Profile {
        &self.profile
    }

    /// When it started.
    pub fn started(&self) -> Timestamp {
        self.started
    }

    /// One control step at `t`, the drives' response time being `response_s`.
    pub fn step(&mut self, t: Timestamp, view: &PoseView, response_s: f64) -> Step {
        let yaw = match self.heading {
            HeadingSource::Odom => view.odom.yaw,
            HeadingSource::Map => match view.map_yaw {
                Some(yaw) => yaw,
                None => {
                    return Step::Done(
                        Outcome::Aborted(
                            "localisation lost during the move (its heading was the map's)".into(),
                        ),
                        self.remaining(view),
                    );
                }
            },
        };
        self.turned += wrap(yaw - self.last_yaw);
        self.last_yaw = yaw;
        let elapsed = t.saturating_since(self.started).as_secs_f64();
        // Damping ≈ 0.7 of the position loop around a first-order drive of this lag.
        let gain = 1.0 / (2.0 * response_s);
        let along = self.along(view);
        let (progress, speed_now) = match self.kind {
            MoveKind::Straight { .. } => (
                self.sign * along,
                self.sign * view.odom.v / self.wheel_scale,
            ),
            MoveKind::Turn { .. } => (self.sign * self.turned, self.sign * view.odom.w),
        };
        let plan = self.profile.sample(elapsed);
        let lag = plan.position - progress;
        let remaining = self.profile.distance() - progress;
        let ended = elapsed >= self.profile.duration();
        let coast = speed_now * response_s;
        if ended && (remaining - coast).abs() <= self.tolerance && coast.abs() <= self.tolerance {
            return Step::Done(Outcome::Succeeded, self.sign * (remaining - coast));
        }
        if elapsed > self.allowance_s {
            return Step::Done(Outcome::TimedOut, self.sign * remaining);
        }
        let speed = if ended {
            gain * remaining
        } else {
            plan.speed + response_s * plan.accel + gain * lag
        };
        let command = self.sign * speed;
        match self.kind {
            MoveKind::Straight { .. } => Step::Drive {
                v: command,
                // Hold the heading of the start.
                w: gain * wrap(self.start.yaw - yaw),
            },
            MoveKind::Turn { .. } => Step::Drive {
                // Turn on the spot: hold the start position.
                v: -gain * along,
                w: command,
            },
        }
    }

    /// Distance moved along the start heading in the `odom` frame, corrected by the wheel
    /// scale, m.
    fn along(&self, view: &PoseView) -> f64 {
        let (s, c) = self.start.odom_yaw.sin_cos();
        ((view.odom.x - self.start.x) * c + (view.odom.y - self.start.y) * s) / self.wheel_scale
    }

    /// What is left to go (m or rad, signed as the move).
    fn remaining(&self, view: &PoseView) -> f64 {
        match self.kind {
            MoveKind::Straight { distance_m } => distance_m - self.along(view),
            MoveKind::Turn { angle_rad } => angle_rad - self.turned,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::odometry::OdomPose;
    use std::f64::consts::PI;

    fn settings() -> MotionSettings {
        MotionSettings {
            linear: Limits {
                speed: 1.0,
                accel: 1.0,
                decel: 1.0,
                jerk: f64::INFINITY,
            },
            angular: Limits {
                speed: 1.0,
                accel: 2.0,
                decel: 2.0,
                jerk: f64::INFINITY,
            },
            position_tolerance_m: 0.001,
            angle_tolerance_rad: 0.1_f64.to_radians(),
            time_allowance_factor: 1.5,
            time_allowance_s: 1.0,
        }
    }

    /// A unicycle whose speeds follow the command with a first-order lag `tau`, stepped
    /// every 10 ms; returns the outcome, the true error and the time taken.
    fn run(kind: MoveKind, tau: f64, start_yaw: f64) -> (Outcome, f64, f64) {
        let s = settings();
        let mut pose = OdomPose {
            yaw: start_yaw,
            ..OdomPose::default()
        };
        let view = |p: OdomPose| PoseView {
            odom: p,
            map_yaw: None,
            wheel_scale: None,
        };
        let mut m = RelativeMove::new(Timestamp::from_micros(0), kind, &view(pose), &s);
        let dt = 0.01;
        for i in 1..2000u64 {
            let t = Timestamp::from_micros(i * 10_000);
            match m.step(t, &view(pose), tau) {
                Step::Drive { v, w } => {
                    let v = v.clamp(-s.linear.speed, s.linear.speed);
                    let w = w.clamp(-s.angular.speed, s.angular.speed);
                    pose.v += (v - pose.v) * (1.0 - (-dt / tau).exp());
                    pose.w += (w - pose.w) * (1.0 - (-dt / tau).exp());
                    pose.x += pose.v * pose.yaw.cos() * dt;
                    pose.y += pose.v * pose.yaw.sin() * dt;
                    pose.yaw = wrap(pose.yaw + pose.w * dt);
                }
                Step::Done(outcome, _) => {
                    let error = match kind {
                        MoveKind::Straight { distance_m } => {
                            distance_m - (pose.x * start_yaw.cos() + pose.y * start_yaw.sin())
                        }
                        MoveKind::Turn { angle_rad } => wrap(start_yaw + angle_rad - pose.yaw),
                    };
                    return (outcome, error, i as f64 * dt);
                }
            }
        }
        panic!("the move never ended");
    }

    #[test]
    fn moves_arrive_within_tolerance_on_lagging_drives() {
        for tau in [0.02, 0.05, 0.1, 0.2] {
            for kind in [
                MoveKind::Straight { distance_m: 1.0 },
                MoveKind::Straight { distance_m: -0.1 },
                MoveKind::Turn {
                    angle_rad: PI / 2.0,
                },
                MoveKind::Turn { angle_rad: -PI },
            ] {
                let (outcome, error, took) = run(kind, tau, 3.0);
                assert_eq!(outcome, Outcome::Succeeded, "{kind:?} τ {tau}");
                let tolerance = match kind {
                    MoveKind::Straight { .. } => 0.0015,
                    MoveKind::Turn { .. } => 0.15_f64.to_radians(),
                };
                assert!(error.abs() <= tolerance, "{kind:?} τ {tau}: error {error}");
                let planned = Profile::plan(
                    match kind {
                        MoveKind::Straight { distance_m } => distance_m,
                        MoveKind::Turn { angle_rad } => angle_rad,
                    },
                    match kind {
                        MoveKind::Straight { .. } => settings().linear,
                        MoveKind::Turn { .. } => settings().angular,
                    },
                )
                .duration();
                assert!(
                    took <= planned * 1.5 + 4.0 * tau,
                    "{kind:?} τ {tau}: {took} s"
                );
            }
        }
    }
}
