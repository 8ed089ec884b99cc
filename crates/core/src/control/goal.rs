//! Going to a pose in the map frame (`device/{serial}/goal`, root MOVE_TO_POSITION): face
//! the goal, drive to it on a smooth arc, then turn to the goal's heading.
//!
//! - Facing and the final turn are angle moves ([`super::moves`]) on the map's yaw.
//! - The drive pursues the goal point: the yaw rate puts the vehicle on the circular arc
//!   through the goal tangent to its heading (curvature 2·sin α / ρ), which straightens as
//!   it closes in, plus a term that turns it onto the line to the goal. Inside a final
//!   radius it holds the bearing the goal had on entering it and closes the distance along
//!   it, so the position's noise cannot swing the heading at the end.
//! - The speed rises at the acceleration limit, cruises, and brakes on the deceleration
//!   limit (95 % of each, as the distance moves plan) for the distance left (v = √(2·d·s)), led by the drives' response time like every
//!   move; near the goal it closes linearly with the same gain as the distance moves.
//! - It needs the vehicle located (the goal is in the map frame) and aborts when the
//!   localisation is lost. A drive that ends outside the position tolerance (an arc cut short
//!   by slip) faces the goal and tries again, a few times.

use super::moves::{RelativeMove, Step, led_speed, planning_limits, turn_on_the_spot};
use super::outcome::{AbortReason, LostDuring};
use super::profile::Profile;
use super::{Outcome, PoseView};
use crate::control::settings::MotionSettings;
use crate::fusion::planar::wrap;
use crate::time::Timestamp;

/// Facing the goal is good enough within this, rad (the arc takes out the rest).
const FACE_TOLERANCE_RAD: f64 = 0.035;
/// A drive whose goal swings further than this off the heading faces it again, rad.
const REFACE_RAD: f64 = 1.0;
/// Inside this distance (m) the heading is held and only the distance along it closed ...
const FINAL_RADIUS_M: f64 = 0.3;
/// ... or inside this many position tolerances, if that is more.
const FINAL_RADIUS_TOLERANCES: f64 = 5.0;
/// Attempts at the position before the goal fails.
const MAX_APPROACHES: u32 = 3;

/// Where a goal is: map frame (ENU from the datum), m and rad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoalPose {
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Heading, rad, counter-clockwise from east.
    pub yaw: f64,
}

#[derive(Debug, Clone)]
enum Phase {
    /// Turning on the spot towards the goal (boxed: a goal is mostly driving).
    Face(Box<RelativeMove>),
    /// Driving to it; the heading held inside the final radius.
    Drive { hold_yaw: Option<f64> },
    /// Turning on the spot to the goal's heading.
    Align(Box<RelativeMove>),
}

/// A goal under way.
#[derive(Debug, Clone)]
pub struct GoalMove {
    goal: GoalPose,
    settings: MotionSettings,
    phase: Phase,
    started: Timestamp,
    planned_s: f64,
    allowance_s: f64,
    /// The approach's planned speed, m/s.
    speed: f64,
    last_step: Option<Timestamp>,
    approaches: u32,
    /// Distance (m) and heading (rad) left at the end.
    left: (f64, f64),
}

impl GoalMove {
    /// A goal starting at `t` from `view`; `None` when the vehicle is not located.
    pub fn new(
        t: Timestamp,
        goal: GoalPose,
        view: &PoseView,
        settings: &MotionSettings,
    ) -> Option<Self> {
        let (x, y, yaw) = view.map_pose()?;
        let (dx, dy) = (goal.x - x, goal.y - y);
        let distance = dx.hypot(dy);
        let bearing = dy.atan2(dx);
        let (face, last_turn) = if distance > settings.goal_position_tolerance_m {
            (wrap(bearing - yaw), wrap(goal.yaw - bearing))
        } else {
            (0.0, wrap(goal.yaw - yaw))
        };
        let planned_s = Profile::plan(face, settings.angular).duration()
            + Profile::plan(distance, settings.linear).duration()
            + Profile::plan(last_turn, settings.angular).duration();
        let mut g = Self {
            goal,
            settings: *settings,
            phase: Phase::Drive { hold_yaw: None },
            started: t,
            planned_s,
            allowance_s: planned_s * settings.time_allowance_factor + settings.time_allowance_s,
            speed: 0.0,
            last_step: None,
            approaches: 0,
            left: (distance, wrap(goal.yaw - yaw)),
        };
        g.phase = g.approach_or_align(t, view, (x, y, yaw));
        Some(g)
    }

    /// Where it goes.
    pub fn goal(&self) -> GoalPose {
        self.goal
    }

    /// When it started.
    pub fn started(&self) -> Timestamp {
        self.started
    }

    /// Turn, drive and turn under the configured limits, s.
    pub fn planned_s(&self) -> f64 {
        self.planned_s
    }

    /// Distance (m) and heading (rad) from the goal at the last step.
    pub fn left(&self) -> (f64, f64) {
        self.left
    }

    /// The next phase from `pose`: face the goal and drive to it, or (there already) turn to
    /// its heading.
    fn approach_or_align(&mut self, t: Timestamp, view: &PoseView, pose: (f64, f64, f64)) -> Phase {
        let (x, y, yaw) = pose;
        let (dx, dy) = (self.goal.x - x, self.goal.y - y);
        if dx.hypot(dy) <= self.settings.goal_position_tolerance_m {
            return Phase::Align(Box::new(turn_on_the_spot(
                t,
                wrap(self.goal.yaw - yaw),
                view,
                &self.settings,
                self.settings.goal_angle_tolerance_rad,
            )));
        }
        self.approaches += 1;
        self.speed = 0.0;
        let face = wrap(dy.atan2(dx) - yaw);
        if face.abs() <= FACE_TOLERANCE_RAD {
            return Phase::Drive { hold_yaw: None };
        }
        Phase::Face(Box::new(turn_on_the_spot(
            t,
            face,
            view,
            &self.settings,
            FACE_TOLERANCE_RAD / 2.0,
        )))
    }

    /// One control step at `t`, the drives' response time being `response_s`.
    pub fn step(&mut self, t: Timestamp, view: &PoseView, response_s: f64) -> Step {
        let Some(pose) = view.map_pose() else {
            return Step::Done(
                Outcome::Aborted(AbortReason::LocalisationLost(LostDuring::Goal)),
                self.left.0,
            );
        };
        let (x, y, yaw) = pose;
        let (dx, dy) = (self.goal.x - x, self.goal.y - y);
        self.left = (dx.hypot(dy), wrap(self.goal.yaw - yaw));
        let elapsed = t.saturating_since(self.started).as_secs_f64();
        if elapsed > self.allowance_s {
            return Step::Done(Outcome::TimedOut, self.left.0);
        }
        let dt = self
            .last_step
            .map_or(0.0, |last| t.saturating_since(last).as_secs_f64());
        self.last_step = Some(t);
        let aligning = matches!(self.phase, Phase::Align(_));
        let turned = match &mut self.phase {
            Phase::Face(turn) | Phase::Align(turn) => turn.step(t, view, response_s),
            Phase::Drive { .. } => return self.drive(t, view, pose, dt, response_s),
        };
        match turned {
            Step::Done(Outcome::Succeeded, _) if aligning => {
                Step::Done(Outcome::Succeeded, self.left.0)
            }
            Step::Done(Outcome::Succeeded, _) => {
                self.phase = Phase::Drive { hold_yaw: None };
                Step::Drive { v: 0.0, w: 0.0 }
            }
            Step::Done(outcome, _) => Step::Done(outcome, self.left.0),
            drive => drive,
        }
    }

    /// A step of the drive to the goal from `pose`.
    fn drive(
        &mut self,
        t: Timestamp,
        view: &PoseView,
        pose: (f64, f64, f64),
        dt: f64,
        response_s: f64,
    ) -> Step {
        let (x, y, yaw) = pose;
        let (dx, dy) = (self.goal.x - x, self.goal.y - y);
        let distance = self.left.0;
        let alpha = wrap(dy.atan2(dx) - yaw);
        let tolerance = self.settings.goal_position_tolerance_m;
        let final_radius = FINAL_RADIUS_M.max(FINAL_RADIUS_TOLERANCES * tolerance);
        // Inside the final radius: hold the bearing the goal had on entering it.
        let held = match self.phase {
            Phase::Drive {
                hold_yaw: Some(held),
            } => Some(held),
            _ if distance <= final_radius => Some(wrap(yaw + alpha)),
            _ => None,
        };
        self.phase = Phase::Drive { hold_yaw: held };
        if held.is_none() && alpha.abs() > REFACE_RAD {
            self.phase = self.approach_or_align(t, view, pose);
            return Step::Drive { v: 0.0, w: 0.0 };
        }
        // Distance left along the heading (negative once past the goal).
        let along = distance * alpha.cos();
        let gain = 1.0 / (2.0 * response_s);
        let coast = view.odom.v * response_s;
        if held.is_some()
            && (along - coast).abs() <= tolerance / 2.0
            && coast.abs() <= tolerance / 2.0
        {
            // At rest on the heading it held: there (turn to the goal's heading), or off to
            // the side (face the goal and try again).
            if distance > tolerance && self.approaches >= MAX_APPROACHES {
                return Step::Done(
                    Outcome::Aborted(AbortReason::GoalMissed {
                        distance_m: distance,
                        approaches: self.approaches,
                        tolerance_m: tolerance,
                    }),
                    distance,
                );
            }
            self.phase = self.approach_or_align(t, view, pose);
            return Step::Drive { v: 0.0, w: 0.0 };
        }
        let limits = planning_limits(self.settings.linear);
        // Brake for what is left, close linearly at the end (backing up if past it), never
        // faster than the limit; the speed rises no faster than the acceleration limit.
        let wanted = if along > 0.0 {
            limits
                .speed
                .min((2.0 * limits.decel * along).sqrt())
                .min(gain * along)
        } else {
            gain * along
        };
        let (planned, v) = led_speed(self.speed, wanted, limits.accel, dt, response_s);
        self.speed = planned;
        let w = match held {
            Some(held) => gain * wrap(held - yaw),
            // On the arc through the goal tangent to the heading, turning onto the line to
            // the goal as quickly as the drives follow (a lagging turn leaves the arc).
            None => 2.0 * self.speed * alpha.sin() / distance.max(1e-6) + gain * alpha,
        };
        Step::Drive { v, w }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::moves::tests::settings;
    use crate::fusion::odometry::OdomPose;
    use std::f64::consts::PI;

    fn view(p: OdomPose, t: Timestamp, located: bool) -> PoseView {
        PoseView {
            odom: p,
            odom_at: t,
            yaw_rate_at: t,
            map_xy: located.then_some((p.x, p.y)),
            map_yaw: located.then_some(p.yaw),
            wheel_scale: None,
            gnss: crate::control::settings::MinGnss::RtkFixed,
        }
    }

    /// A unicycle whose speeds follow the command with lag `tau` (10 ms steps), located
    /// until `lost_at` s; the outcome, the pose at rest and the time taken.
    fn run(goal: GoalPose, start: OdomPose, tau: f64, lost_at: f64) -> (Outcome, OdomPose, f64) {
        let s = settings();
        let t0 = Timestamp::from_micros(0);
        let mut pose = start;
        let mut g = GoalMove::new(t0, goal, &view(pose, t0, true), &s).expect("located");
        let dt = 0.01;
        let follow = 1.0 - (-dt / tau).exp();
        for i in 1..10_000u64 {
            let t = Timestamp::from_micros(i * 10_000);
            let located = (i as f64) * dt < lost_at;
            match g.step(t, &view(pose, t, located), tau) {
                Step::Drive { v, w } => {
                    let (v_max, w_max) = (s.linear.speed, s.angular.speed);
                    pose.v += (v.clamp(-v_max, v_max) - pose.v) * follow;
                    pose.w += (w.clamp(-w_max, w_max) - pose.w) * follow;
                    pose.x += pose.v * pose.yaw.cos() * dt;
                    pose.y += pose.v * pose.yaw.sin() * dt;
                    pose.yaw = wrap(pose.yaw + pose.w * dt);
                }
                Step::Done(outcome, _) => return (outcome, pose, i as f64 * dt),
            }
        }
        panic!("the goal never ended");
    }

    #[test]
    fn goals_in_every_direction_are_reached_within_tolerance() {
        for tau in [0.03, 0.1, 0.2] {
            for bearing in [0.0, 0.7, 2.0, -2.5, PI] {
                for (distance, heading) in [(10.0, 1.2), (0.5, -3.0), (0.01, 1.0)] {
                    let start = OdomPose {
                        x: 3.0,
                        y: -2.0,
                        yaw: 0.4,
                        ..OdomPose::default()
                    };
                    let goal = GoalPose {
                        x: start.x + distance * (start.yaw + bearing).cos(),
                        y: start.y + distance * (start.yaw + bearing).sin(),
                        yaw: wrap(heading),
                    };
                    let (outcome, end, took) = run(goal, start, tau, f64::INFINITY);
                    let case = format!("τ {tau}, bearing {bearing}, {distance} m");
                    assert_eq!(outcome, Outcome::Succeeded, "{case}");
                    let off = (end.x - goal.x).hypot(end.y - goal.y);
                    assert!(off <= 0.025, "{case}: {off} m off");
                    let turn = wrap(end.yaw - goal.yaw).abs();
                    assert!(turn <= 1.5_f64.to_radians(), "{case}: {turn} rad off");
                    let s = settings();
                    let planned = Profile::plan(bearing, s.angular).duration()
                        + Profile::plan(distance, s.linear).duration()
                        + Profile::plan(PI, s.angular).duration();
                    assert!(took <= planned * 1.5 + 2.0, "{case}: {took} s");
                }
            }
        }
    }

    #[test]
    fn a_goal_needs_a_location_and_ends_when_it_is_lost() {
        let s = settings();
        let t = Timestamp::from_micros(0);
        let goal = GoalPose {
            x: 5.0,
            y: 0.0,
            yaw: 0.0,
        };
        assert!(GoalMove::new(t, goal, &view(OdomPose::default(), t, false), &s).is_none());
        let (outcome, _, took) = run(goal, OdomPose::default(), 0.1, 1.0);
        assert!(
            matches!(&outcome, Outcome::Aborted(AbortReason::LocalisationLost(_))),
            "{outcome:?}"
        );
        assert!((took - 1.0).abs() < 0.02, "{took}");
    }
}
