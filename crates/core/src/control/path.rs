//! Following a path in the map frame (`start_task` of a saved trajectory, root COVERAGE):
//! a path-following law on the prepared [`Track`], turning on the spot at its corners.
//!
//! - The yaw rate is the path's curvature (read a response time ahead, where the vehicle
//!   will be when the drives have followed) plus a correction of the cross-track and
//!   heading errors, computed for the pose predicted a response time ahead. The correction
//!   settles over a distance that grows with the speed and the drives' response time, never
//!   under [`MIN_SETTLING_M`]: the gains come from the configuration and the learnt response,
//!   not from a plant's numbers.
//! - The speed follows the track's limits (curves, the end of each stretch), rising at the
//!   acceleration limit, led by the response time; it drops when the vehicle is off the
//!   path, and closes the last centimetres linearly like every move.
//! - At the start, at each corner and after a pause it turns on the spot to the path first.
//! - It needs the vehicle located and the GNSS fix at the configured quality. Below that it
//!   waits at rest and goes on when the quality is back, failing after the configured wait;
//!   lost localisation or leaving the path by more than `motion.max_cross_track_m` ends it.
//! - It reports the cross-track error: its RMS and maximum over the drive.

use super::moves::{RelativeMove, Step, led_speed, planning_limits, turn_on_the_spot};
use super::outcome::{AbortReason, LostDuring};
use super::track::{MAX_LENGTH_M, SAMPLE_M, Segment, Track, polyline_length};
use super::{Outcome, PoseView};
use crate::control::settings::{MinGnss, MotionSettings};
use crate::fusion::planar::wrap;
use crate::time::Timestamp;

/// The correction settles over at least this distance, m.
const MIN_SETTLING_M: f64 = 0.3;
/// ... and over at least this many response times' travel.
const SETTLING_RESPONSES: f64 = 4.0;
/// Damping of the correction.
const DAMPING: f64 = 0.9;
/// The correction's gains use at least this speed, m/s (it has no authority at rest).
const MIN_GAIN_SPEED: f64 = 0.1;
/// A heading this far off the path stops and turns on the spot first, rad.
const TURN_FIRST_RAD: f64 = 0.5;
/// While following, a heading further off than this turns on the spot again, rad.
const RETURN_RAD: f64 = 1.0;
/// The speed halves at this cross-track error, m.
const SLOW_OFF_PATH_M: f64 = 0.3;
/// Turns on the spot end within this, rad (the path law takes out the rest).
const TURN_TOLERANCE_RAD: f64 = 0.02;
/// The nearest sample is searched this many samples back ...
const SEARCH_BACK: usize = 20;
/// ... and this many ahead of the last one.
const SEARCH_AHEAD: usize = 60;
/// Turning towards the path aims this far along it, m.
const AIM_AHEAD_M: f64 = 0.5;

/// The cross-track error over a drive.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CrossTrack {
    /// Root mean square, m.
    pub rms_m: f64,
    /// Largest, m.
    pub max_m: f64,
}

#[derive(Debug, Clone)]
enum Phase {
    /// Turning on the spot onto the path (boxed: a path is mostly driving).
    Turn(Box<RelativeMove>),
    /// Driving along the segment.
    Follow,
    /// Held by the operator (PAUSE) until resumed.
    Paused,
    /// Waiting at rest for the GNSS quality, since then.
    WaitGnss(Timestamp),
}

/// Where the vehicle is relative to a segment.
#[derive(Debug, Clone, Copy)]
struct Projection {
    /// The nearest sample.
    index: usize,
    /// Distance along the segment, m.
    s: f64,
    /// Cross-track error, m (positive: the vehicle is left of the path).
    e: f64,
    /// The path's direction there, rad.
    yaw: f64,
    /// Distance left to the segment's end along its last direction, m (negative past it).
    left: f64,
}

/// A path task under way.
#[derive(Debug, Clone)]
pub struct PathFollow {
    track: Track,
    /// The speed asked for, m/s.
    speed_request: f64,
    settings: MotionSettings,
    segment: usize,
    index: usize,
    phase: Phase,
    started: Timestamp,
    planned_s: f64,
    allowance_s: f64,
    /// Time spent paused or waiting, s (not counted against the allowance), and since when
    /// the current hold lasts.
    held_s: f64,
    held_since: Option<Timestamp>,
    /// The speed planned now, m/s.
    speed: f64,
    last_step: Option<Timestamp>,
    sum_sq: f64,
    samples: u64,
    max_abs: f64,
    /// Distance to the end of the path at the last step, m.
    left_m: f64,
    events: Vec<String>,
}

/// Why a task did not start.
#[derive(Debug, Clone, PartialEq)]
pub enum StartRefusal {
    /// The vehicle is not located.
    NotLocated,
    /// The GNSS fix is below the configured quality.
    Gnss(MinGnss, MinGnss),
    /// The first point is too far away.
    TooFar(f64, f64),
    /// The path is longer than [`MAX_LENGTH_M`] (m).
    TooLong(f64),
}

impl std::fmt::Display for StartRefusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotLocated => write!(
                f,
                "not located: a path in the map frame needs a good position and heading \
                 (LOCATE_TRUE)"
            ),
            Self::Gnss(now, min) => write!(
                f,
                "GNSS quality {now} is below motion.task_min_gnss = {min:?}",
                min = min.to_string()
            ),
            Self::TooLong(length) => write!(
                f,
                "the path is {length:.0} m long, more than {MAX_LENGTH_M} m: split it"
            ),
            Self::TooFar(d, limit) => write!(
                f,
                "the vehicle is {d:.2} m from the path's first point (motion.task_max_approach_m \
                 = {limit} m)"
            ),
        }
    }
}

impl PathFollow {
    /// A task along `points` (map frame) at up to `speed` (m/s), starting at `t` from `view`:
    /// the way from the vehicle to the first point is driven first.
    pub fn new(
        t: Timestamp,
        points: &[(f64, f64)],
        speed: f64,
        view: &PoseView,
        settings: &MotionSettings,
    ) -> Result<Self, StartRefusal> {
        let (x, y, yaw) = view.map_pose().ok_or(StartRefusal::NotLocated)?;
        let min = settings.task.min_gnss;
        if view.gnss < min {
            return Err(StartRefusal::Gnss(view.gnss, min));
        }
        let first = points.first().copied().unwrap_or((x, y));
        let approach = (first.0 - x).hypot(first.1 - y);
        if approach > settings.task.max_approach_m {
            return Err(StartRefusal::TooFar(approach, settings.task.max_approach_m));
        }
        let mut all = Vec::with_capacity(points.len() + 1);
        all.push((x, y));
        all.extend_from_slice(points);
        let length = polyline_length(&all);
        if !length.is_finite() || length > MAX_LENGTH_M {
            return Err(StartRefusal::TooLong(length));
        }
        let track = Track::new(&all, speed, settings);
        let start_turn = track.segments.first().map_or(0.0, |s| {
            let yaw0 = s.samples[0].yaw;
            wrap(yaw0 - yaw)
        });
        let planned_s = track.planned_s(settings)
            + super::profile::Profile::plan(start_turn, settings.angular).duration();
        let mut follow = Self {
            track,
            speed_request: speed,
            settings: *settings,
            segment: 0,
            index: 0,
            phase: Phase::Follow,
            started: t,
            planned_s,
            allowance_s: planned_s * settings.time_allowance_factor + settings.time_allowance_s,
            held_s: 0.0,
            held_since: None,
            speed: 0.0,
            last_step: None,
            sum_sq: 0.0,
            samples: 0,
            max_abs: 0.0,
            left_m: 0.0,
            events: Vec::new(),
        };
        follow.left_m = follow.length_left(0.0);
        follow.phase = follow.onto_path(t, view, (x, y, yaw));
        Ok(follow)
    }

    /// When it started.
    pub fn started(&self) -> Timestamp {
        self.started
    }

    /// The time to drive it at the limits, s.
    pub fn planned_s(&self) -> f64 {
        self.planned_s
    }

    /// The speed asked for, m/s.
    pub fn requested_speed(&self) -> f64 {
        self.speed_request
    }

    /// The top speed it plans with: the one asked for, under the speed limit, m/s.
    pub fn top_speed(&self) -> f64 {
        self.speed_request
            .min(planning_limits(self.settings.linear).speed)
    }

    /// Its length from where it started, m.
    pub fn length(&self) -> f64 {
        self.track.length()
    }

    /// Distance left to its end at the last step, m.
    pub fn left_m(&self) -> f64 {
        self.left_m
    }

    /// The cross-track error so far.
    pub fn cross_track(&self) -> CrossTrack {
        CrossTrack {
            rms_m: if self.samples > 0 {
                (self.sum_sq / self.samples as f64).sqrt()
            } else {
                0.0
            },
            max_m: self.max_abs,
        }
    }

    /// What happened since the last call, for the log.
    pub fn take_events(&mut self) -> Vec<String> {
        std::mem::take(&mut self.events)
    }

    /// Whether the operator holds it.
    pub fn is_paused(&self) -> bool {
        matches!(self.phase, Phase::Paused)
    }

    /// The operator holds it (PAUSE) at `t`.
    pub fn pause(&mut self, t: Timestamp) {
        self.hold(t);
        self.phase = Phase::Paused;
    }

    /// Goes on at `t` from where it was paused.
    pub fn resume(&mut self, t: Timestamp, view: &PoseView) {
        self.release(t);
        if let Some(pose) = view.map_pose() {
            self.phase = self.onto_path(t, view, pose);
        } else {
            // The next step ends it: not located.
            self.phase = Phase::Follow;
        }
    }

    fn hold(&mut self, t: Timestamp) {
        self.held_since.get_or_insert(t);
        self.speed = 0.0;
    }

    fn release(&mut self, t: Timestamp) {
        if let Some(since) = self.held_since.take() {
            self.held_s += t.saturating_since(since).as_secs_f64();
        }
    }

    /// Distance left from `s` on the current segment to the path's end, m.
    fn length_left(&self, s: f64) -> f64 {
        let rest: f64 = self
            .track
            .segments
            .iter()
            .skip(self.segment + 1)
            .map(Segment::length)
            .sum();
        self.track
            .segments
            .get(self.segment)
            .map_or(0.0, |seg| (seg.length() - s).max(0.0))
            + rest
    }

    /// Follow from `pose`, turning on the spot first when heading too far off the path.
    fn onto_path(&mut self, t: Timestamp, view: &PoseView, pose: (f64, f64, f64)) -> Phase {
        self.speed = 0.0;
        let Some(seg) = self.track.segments.get(self.segment) else {
            return Phase::Follow;
        };
        let p = project(seg, self.index, pose.0, pose.1);
        self.index = p.index;
        let aim = seg.at(p.s + AIM_AHEAD_M);
        let towards = if (aim.x - pose.0).hypot(aim.y - pose.1) > SAMPLE_M {
            (aim.y - pose.1).atan2(aim.x - pose.0)
        } else {
            p.yaw
        };
        let turn = wrap(towards - pose.2);
        if turn.abs() <= TURN_FIRST_RAD {
            return Phase::Follow;
        }
        Phase::Turn(Box::new(turn_on_the_spot(
            t,
            turn,
            view,
            &self.settings,
            TURN_TOLERANCE_RAD,
        )))
    }

    /// One control step at `t`, the drives' response time being `response_s`.
    pub fn step(&mut self, t: Timestamp, view: &PoseView, response_s: f64) -> Step {
        let Some(pose) = view.map_pose() else {
            return Step::Done(
                Outcome::Aborted(AbortReason::LocalisationLost(LostDuring::Task)),
                self.left_m,
            );
        };
        let dt = self
            .last_step
            .map_or(0.0, |last| t.saturating_since(last).as_secs_f64());
        self.last_step = Some(t);
        let min = self.settings.task.min_gnss;
        match self.phase {
            Phase::Paused => return Step::Drive { v: 0.0, w: 0.0 },
            Phase::WaitGnss(since) => {
                if view.gnss >= min {
                    self.release(t);
                    self.events.push(format!(
                        "task: GNSS quality {} is back, going on",
                        view.gnss
                    ));
                    self.phase = self.onto_path(t, view, pose);
                    return Step::Drive { v: 0.0, w: 0.0 };
                }
                let waited = t.saturating_since(since).as_secs_f64();
                if waited > self.settings.task.gnss_wait_s {
                    return Step::Done(
                        Outcome::Aborted(AbortReason::GnssBelow {
                            quality: view.gnss,
                            min,
                            waited_s: waited,
                        }),
                        self.left_m,
                    );
                }
                return Step::Drive { v: 0.0, w: 0.0 };
            }
            _ if view.gnss < min => {
                self.events.push(format!(
                    "task: GNSS quality {} is below {min}; waiting at rest",
                    view.gnss
                ));
                self.hold(t);
                self.phase = Phase::WaitGnss(t);
                return Step::Drive { v: 0.0, w: 0.0 };
            }
            _ => {}
        }
        let elapsed = t.saturating_since(self.started).as_secs_f64() - self.held_s;
        if elapsed > self.allowance_s {
            return Step::Done(Outcome::TimedOut, self.left_m);
        }
        let turned = match &mut self.phase {
            Phase::Turn(turn) => turn.step(t, view, response_s),
            _ => return self.follow(t, view, pose, dt, response_s),
        };
        match turned {
            Step::Done(Outcome::Succeeded, _) => {
                self.phase = Phase::Follow;
                self.speed = 0.0;
                Step::Drive { v: 0.0, w: 0.0 }
            }
            Step::Done(outcome, _) => Step::Done(outcome, self.left_m),
            drive => drive,
        }
    }

    /// A step along the current segment.
    fn follow(
        &mut self,
        t: Timestamp,
        view: &PoseView,
        pose: (f64, f64, f64),
        dt: f64,
        response_s: f64,
    ) -> Step {
        let (x, y, yaw) = pose;
        let Some(seg) = self.track.segments.get(self.segment) else {
            return Step::Done(Outcome::Succeeded, 0.0);
        };
        let here = project(seg, self.index, x, y);
        self.index = here.index;
        self.left_m = self.length_left(here.s);
        self.sum_sq += here.e * here.e;
        self.samples += 1;
        self.max_abs = self.max_abs.max(here.e.abs());
        let limit_m = self.settings.task.max_cross_track_m;
        if here.e.abs() > limit_m {
            return Step::Done(
                Outcome::Aborted(AbortReason::OffPath {
                    off_m: here.e.abs(),
                    limit_m,
                }),
                self.left_m,
            );
        }
        if wrap(yaw - here.yaw).abs() > RETURN_RAD {
            self.phase = self.onto_path(t, view, pose);
            return Step::Drive { v: 0.0, w: 0.0 };
        }
        let gain = 1.0 / (2.0 * response_s);
        let coast = view.odom.v * response_s;
        let tolerance = self.settings.goal_position_tolerance_m;
        if (here.left - coast).abs() <= tolerance / 2.0 && coast.abs() <= tolerance / 2.0 {
            // At rest at the segment's end: on to the next, or arrived.
            if self.segment + 1 >= self.track.segments.len() {
                let end = seg.samples[seg.samples.len() - 1];
                return Step::Done(Outcome::Succeeded, (end.x - x).hypot(end.y - y));
            }
            self.segment += 1;
            self.index = 0;
            self.phase = self.onto_path(t, view, pose);
            return Step::Drive { v: 0.0, w: 0.0 };
        }
        let limits = planning_limits(self.settings.linear);
        // The pose a response time ahead: where the drives will have taken the vehicle.
        let v_now = view.odom.v;
        let ahead = (
            x + v_now * response_s * yaw.cos(),
            y + v_now * response_s * yaw.sin(),
            wrap(yaw + view.odom.w * response_s),
        );
        let pred = project(seg, self.index, ahead.0, ahead.1);
        let limit_here = seg.speed_limit(pred.s, limits.decel);
        let off_path = 1.0 / (1.0 + here.e.abs() / SLOW_OFF_PATH_M);
        let wanted = if here.left > 0.0 {
            (limit_here * off_path).min(gain * here.left)
        } else {
            gain * here.left
        };
        let (planned, v) = led_speed(self.speed, wanted, limits.accel, dt, response_s);
        self.speed = planned;
        if here.left <= 0.0 {
            // Past the end: back up straight.
            return Step::Drive { v, w: 0.0 };
        }
        let kappa = seg.at(pred.s).kappa;
        let theta = wrap(ahead.2 - pred.yaw);
        let settle = MIN_SETTLING_M.max(SETTLING_RESPONSES * self.speed.abs() * response_s);
        let (k_e, k_theta) = (1.0 / (settle * settle), 2.0 * DAMPING / settle);
        let v_gain = v_now.abs().max(self.speed.abs()).max(MIN_GAIN_SPEED);
        let sinc = if theta.abs() > 1e-6 {
            theta.sin() / theta
        } else {
            1.0
        };
        let feedforward = self.speed * kappa * theta.cos() / (1.0 - kappa * pred.e).max(0.5);
        let w = feedforward - v_gain * (k_e * pred.e * sinc + k_theta * theta.sin());
        Step::Drive { v, w }
    }
}

/// Where `(x, y)` is relative to `seg`, searching near sample `around`.
fn project(seg: &Segment, around: usize, x: f64, y: f64) -> Projection {
    let samples = &seg.samples;
    let last = samples.len() - 1;
    let lo = around.saturating_sub(SEARCH_BACK).min(last);
    let hi = (around + SEARCH_AHEAD).min(last);
    let d2 = |i: usize| (samples[i].x - x).powi(2) + (samples[i].y - y).powi(2);
    let index = (lo..=hi)
        .min_by(|&a, &b| d2(a).total_cmp(&d2(b)))
        .unwrap_or(lo);
    // The chord through the nearest sample that the point projects onto.
    let (a, b) = if index == last {
        (last.saturating_sub(1), last)
    } else if index > 0 && d2(index - 1) < d2(index + 1) {
        (index - 1, index)
    } else {
        (index, index + 1)
    };
    let (pa, pb) = (samples[a], samples[b]);
    let (cx, cy) = (pb.x - pa.x, pb.y - pa.y);
    let chord = cx.hypot(cy).max(1e-9);
    let (ux, uy) = (cx / chord, cy / chord);
    let (rx, ry) = (x - pa.x, y - pa.y);
    let along = rx * ux + ry * uy;
    let e = ux * ry - uy * rx;
    let s = (pa.s + along).clamp(0.0, samples[last].s);
    let end = samples[last];
    let left = if b == last {
        // Near the end: along the last chord, negative once past it.
        (end.x - x) * ux + (end.y - y) * uy
    } else {
        end.s - s
    };
    Projection {
        index,
        s,
        e,
        yaw: seg.at(s).yaw,
        left,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::moves::tests::settings;
    use crate::control::track::distance_to_polyline;
    use crate::fusion::odometry::OdomPose;
    use std::f64::consts::PI;

    fn view(p: OdomPose, t: Timestamp, gnss: MinGnss) -> PoseView {
        PoseView {
            odom: p,
            odom_at: t,
            yaw_rate_at: t,
            map_xy: Some((p.x, p.y)),
            map_yaw: Some(p.yaw),
            wheel_scale: None,
            gnss,
        }
    }

    /// A stadium: two straights joined by half circles of `radius`, starting at the origin
    /// heading east, points every 0.1 m.
    pub(crate) fn stadium(straight: f64, radius: f64) -> Vec<(f64, f64)> {
        let mut out = Vec::new();
        let n = (straight / 0.1).round() as usize;
        let arc = (PI * radius / 0.1).round() as usize;
        for i in 0..n {
            out.push((straight * i as f64 / n as f64, 0.0));
        }
        for i in 0..arc {
            let a = -PI / 2.0 + PI * i as f64 / arc as f64;
            out.push((straight + radius * a.cos(), radius + radius * a.sin()));
        }
        for i in 0..n {
            out.push((straight - straight * i as f64 / n as f64, 2.0 * radius));
        }
        for i in 0..=arc {
            let a = PI / 2.0 + PI * i as f64 / arc as f64;
            out.push((radius * a.cos(), radius + radius * a.sin()));
        }
        out
    }

    struct Run {
        outcome: Outcome,
        end: OdomPose,
        took: f64,
        worst_off: f64,
        reported: CrossTrack,
        planned: f64,
    }

    /// A unicycle following the command with lag `tau` (10 ms steps); `gnss` gives the
    /// quality at each second.
    fn run(
        path: &[(f64, f64)],
        speed: f64,
        start: OdomPose,
        tau: f64,
        gnss: impl Fn(f64) -> MinGnss,
    ) -> Run {
        let s = settings();
        let t0 = Timestamp::from_micros(0);
        let mut pose = start;
        let mut f = PathFollow::new(t0, path, speed, &view(pose, t0, MinGnss::RtkFixed), &s)
            .expect("starts");
        let dt = 0.01;
        let follow = 1.0 - (-dt / tau).exp();
        let mut worst_off: f64 = 0.0;
        let mut driving = false;
        for i in 1..100_000u64 {
            let t = Timestamp::from_micros(i * 10_000);
            let seconds = i as f64 * dt;
            match f.step(t, &view(pose, t, gnss(seconds)), tau) {
                Step::Drive { v, w } => {
                    let (v_max, w_max) = (s.linear.speed, s.angular.speed);
                    pose.v += (v.clamp(-v_max, v_max) - pose.v) * follow;
                    pose.w += (w.clamp(-w_max, w_max) - pose.w) * follow;
                    pose.x += pose.v * pose.yaw.cos() * dt;
                    pose.y += pose.v * pose.yaw.sin() * dt;
                    pose.yaw = wrap(pose.yaw + pose.w * dt);
                    // The way from the start onto the path is not part of it.
                    driving |= distance_to_polyline(path, pose.x, pose.y) < 0.01;
                    if driving {
                        worst_off = worst_off.max(distance_to_polyline(path, pose.x, pose.y));
                    }
                }
                Step::Done(outcome, _) => {
                    return Run {
                        outcome,
                        end: pose,
                        took: seconds,
                        worst_off,
                        reported: f.cross_track(),
                        planned: f.planned_s(),
                    };
                }
            }
        }
        panic!("the task never ended");
    }

    #[test]
    fn stadiums_with_1_to_5_m_curves_are_followed_within_centimetres() {
        for radius in [1.0, 2.0, 5.0] {
            let path = stadium(10.0, radius);
            for tau in [0.03, 0.1, 0.2] {
                for speed in [0.3, 0.5, 1.0] {
                    let r = run(&path, speed, OdomPose::default(), tau, |_| {
                        MinGnss::RtkFixed
                    });
                    let case = format!("{radius} m curves, τ {tau}, {speed} m/s");
                    assert_eq!(r.outcome, Outcome::Succeeded, "{case}");
                    let end = path[path.len() - 1];
                    let miss = (r.end.x - end.0).hypot(r.end.y - end.1);
                    assert!(miss <= 0.03, "{case}: ended {miss} m from the end");
                    assert!(
                        r.worst_off <= 0.05,
                        "{case}: {} m off the path",
                        r.worst_off
                    );
                    assert!(r.reported.max_m >= r.reported.rms_m, "{case}");
                    assert!(
                        r.took <= r.planned * 1.2 + 1.0,
                        "{case}: {} s for {}",
                        r.took,
                        r.planned
                    );
                }
            }
        }
    }

    /// A speed over the limit is driven at the limit, and said so where the task is logged.
    #[test]
    fn a_speed_over_the_limit_is_capped_and_reported_capped() {
        let s = settings();
        let t0 = Timestamp::from_micros(0);
        let view = view(OdomPose::default(), t0, MinGnss::RtkFixed);
        let line = [(0.0, 0.0), (4.0, 0.0)];
        let f = PathFollow::new(t0, &line, 1e9, &view, &s).expect("starts");
        let cap = s.linear.speed * 0.95;
        assert!((f.top_speed() - cap).abs() < 1e-12, "{}", f.top_speed());
        let kind = crate::control::MotionKind::Path {
            length_m: f.length(),
            speed: f.top_speed(),
            asked: f.requested_speed(),
        };
        assert_eq!(
            kind.to_string(),
            format!(
                "path of 4.00 m at up to {cap:.2} m/s (asked 1000000000 m/s: capped at 95 % \
                 of motion.max_speed_mps, which is chassis.max_speed_mps unless set)"
            )
        );
        let slow = PathFollow::new(t0, &line, 0.2, &view, &s).expect("starts");
        assert_eq!(slow.top_speed(), 0.2);
    }

    #[test]
    fn it_starts_facing_away_turns_at_corners_and_ends_at_the_last_point() {
        let square = [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0), (0.0, 0.0)];
        let start = OdomPose {
            x: -0.5,
            y: 0.3,
            yaw: PI,
            ..OdomPose::default()
        };
        let r = run(&square, 0.5, start, 0.1, |_| MinGnss::RtkFixed);
        assert_eq!(r.outcome, Outcome::Succeeded);
        assert!(r.end.x.hypot(r.end.y) <= 0.03, "{:?}", r.end);
        // Corners are turned on the spot: the square is driven on its sides.
        assert!(r.worst_off <= 0.03, "{} m off", r.worst_off);
    }

    #[test]
    fn it_waits_for_gnss_quality_and_goes_on_or_fails_after_the_wait() {
        let line = [(0.0, 0.0), (6.0, 0.0)];
        let float = |from: f64, to: f64| {
            move |s: f64| {
                if (from..to).contains(&s) {
                    MinGnss::RtkFloat
                } else {
                    MinGnss::RtkFixed
                }
            }
        };
        let r = run(&line, 1.0, OdomPose::default(), 0.1, float(2.0, 4.0));
        assert_eq!(r.outcome, Outcome::Succeeded);
        // The wait is not counted against the time allowance, but it takes its time.
        assert!(r.took > 8.0, "{}", r.took);
        // settings() waits 5 s at most.
        let r = run(&line, 1.0, OdomPose::default(), 0.1, float(2.0, 100.0));
        assert!(
            matches!(&r.outcome, Outcome::Aborted(AbortReason::GnssBelow { .. })),
            "{:?}",
            r.outcome
        );
        assert!((r.took - 7.0).abs() < 0.1, "{}", r.took);
    }

    #[test]
    fn a_task_that_strays_beyond_the_cross_track_limit_stops_with_the_reason() {
        let s = settings();
        let line = [(0.0, 0.0), (6.0, 0.0)];
        let t0 = Timestamp::from_micros(0);
        let at = |y: f64| OdomPose {
            x: 1.0,
            y,
            ..OdomPose::default()
        };
        for (off, stops) in [(0.25, false), (0.35, true), (-0.35, true)] {
            let start = view(OdomPose::default(), t0, MinGnss::RtkFixed);
            let mut f = PathFollow::new(t0, &line, 0.5, &start, &s).expect("starts");
            let t = Timestamp::from_micros(10_000);
            let step = f.step(t, &view(at(off), t, MinGnss::RtkFixed), 0.1);
            match step {
                Step::Done(Outcome::Aborted(AbortReason::OffPath { off_m, limit_m }), _) => {
                    assert!(stops, "{off} m off stopped it");
                    assert!((off_m - off.abs()).abs() < 1e-6 && limit_m == 0.3);
                }
                other => assert!(!stops, "{off} m off went on: {other:?}"),
            }
        }
    }

    #[test]
    fn a_task_is_refused_without_location_quality_or_when_too_far() {
        let s = settings();
        let t = Timestamp::from_micros(0);
        let line = [(0.0, 0.0), (6.0, 0.0)];
        let mut v = view(OdomPose::default(), t, MinGnss::RtkFloat);
        assert!(matches!(
            PathFollow::new(t, &line, 0.5, &v, &s),
            Err(StartRefusal::Gnss(MinGnss::RtkFloat, MinGnss::RtkFixed))
        ));
        v.gnss = MinGnss::RtkFixed;
        let far = [(10.0, 0.0), (16.0, 0.0)];
        assert!(matches!(
            PathFollow::new(t, &far, 0.5, &v, &s),
            Err(StartRefusal::TooFar(..))
        ));
        // Memory grows with the length: a path to the far side of the globe (or beyond any
        // number) is refused before it is sampled.
        for far_end in [2.5e4, 1.0e300] {
            assert!(matches!(
                PathFollow::new(t, &[(0.0, 0.0), (far_end, 0.0)], 0.5, &v, &s),
                Err(StartRefusal::TooLong(_))
            ));
        }
        v.map_xy = None;
        assert_eq!(
            PathFollow::new(t, &line, 0.5, &v, &s).err(),
            Some(StartRefusal::NotLocated)
        );
    }

    #[test]
    fn a_paused_task_holds_and_goes_on_from_where_it_was() {
        let s = settings();
        let line = [(0.0, 0.0), (4.0, 0.0)];
        let t0 = Timestamp::from_micros(0);
        let mut pose = OdomPose::default();
        let mut f = PathFollow::new(t0, &line, 0.5, &view(pose, t0, MinGnss::RtkFixed), &s)
            .expect("starts");
        let mut i = 0u64;
        let mut drive = |f: &mut PathFollow, pose: &mut OdomPose, steps: u64| {
            for _ in 0..steps {
                i += 1;
                let t = Timestamp::from_micros(i * 10_000);
                match f.step(t, &view(*pose, t, MinGnss::RtkFixed), 0.05) {
                    Step::Drive { v, .. } => {
                        pose.v = v;
                        pose.x += v * 0.01;
                    }
                    Step::Done(o, _) => return Some(o),
                }
            }
            None
        };
        assert_eq!(drive(&mut f, &mut pose, 300), None);
        let paused_at = pose.x;
        assert!(paused_at > 1.0, "{paused_at}");
        f.pause(Timestamp::from_micros(300 * 10_000));
        assert!(f.is_paused());
        pose.v = 0.0;
        assert_eq!(drive(&mut f, &mut pose, 3_000), None);
        assert_eq!(pose.x, paused_at);
        f.resume(
            Timestamp::from_micros(3_300 * 10_000),
            &view(pose, t0, MinGnss::RtkFixed),
        );
        assert_eq!(drive(&mut f, &mut pose, 3_000), Some(Outcome::Succeeded));
        assert!((pose.x - 4.0).abs() < 0.02, "{}", pose.x);
    }
}
