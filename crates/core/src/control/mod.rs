//! Closed-loop motion: the moves the vehicle makes by itself, one at a time, and their
//! results. It proposes a velocity at each control tick; the drive train's arbiter, limits,
//! ramps and safety supervisor decide what reaches the wheels ([`crate::vehicle::chassis`]).

pub mod goal;
pub mod mission;
pub mod moves;
pub mod outcome;
pub mod path;
pub mod profile;
pub mod response;
pub mod settings;
pub mod track;

use std::fmt;

use crate::control::settings::{MinGnss, MotionSettings};
use crate::fusion::odometry::OdomPose;
use crate::time::Timestamp;
use goal::{GoalMove, GoalPose};
use moves::{RelativeMove, Step};
pub use outcome::{AbortReason, CancelReason, Outcome};
use path::{CrossTrack, PathFollow, StartRefusal};

/// Navigation task state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Navigation {
    /// No task.
    #[default]
    Idle,
    /// A task is running.
    Running,
    /// The last task succeeded.
    Succeeded,
    /// The last task failed.
    Failed,
}

/// Names one motion from its start to its result.
pub type MotionId = u64;

/// A distance or angle move relative to the pose at its start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MoveKind {
    /// Straight, m: positive forward, negative back.
    Straight {
        /// m.
        distance_m: f64,
    },
    /// On the spot, rad: positive left (counter-clockwise), negative right.
    Turn {
        /// rad.
        angle_rad: f64,
    },
}

impl fmt::Display for MoveKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Straight { distance_m } if distance_m < 0.0 => {
                write!(f, "back {:.3} m", -distance_m)
            }
            Self::Straight { distance_m } => write!(f, "forward {distance_m:.3} m"),
            Self::Turn { angle_rad } if angle_rad < 0.0 => {
                write!(f, "turn right {:.1}°", -angle_rad.to_degrees())
            }
            Self::Turn { angle_rad } => write!(f, "turn left {:.1}°", angle_rad.to_degrees()),
        }
    }
}

/// Who asked for a motion: a dialect's name and its own number for the request (it keeps
/// what the number stands for, such as a `msg_id`), so that it can answer at the end.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MotionTag {
    /// The dialect (`device`, `root`, ...).
    pub owner: &'static str,
    /// Its number for the request.
    pub id: u64,
}

/// What a motion does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotionKind {
    /// A distance or angle move.
    Move(MoveKind),
    /// To a pose in the map frame.
    Goal(GoalPose),
    /// Along a path in the map frame (a trajectory task, a coverage path).
    Path {
        /// Its length from where the vehicle started, m.
        length_m: f64,
        /// The top speed it planned with (the one asked for, under the limit), m/s.
        speed: f64,
        /// The speed asked for, m/s.
        asked: f64,
    },
}

impl fmt::Display for MotionKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Move(kind) => kind.fmt(f),
            Self::Goal(g) => write!(
                f,
                "goal x {:.3} m, y {:.3} m, heading {:.1}°",
                g.x,
                g.y,
                g.yaw.to_degrees()
            ),
            Self::Path {
                length_m,
                speed,
                asked,
            } => {
                write!(f, "path of {length_m:.2} m at up to {speed:.2} m/s")?;
                if asked > speed {
                    write!(
                        f,
                        " (asked {asked} m/s: capped at 95 % of motion.max_speed_mps, which is \
                         chassis.max_speed_mps unless set)"
                    )?;
                }
                Ok(())
            }
        }
    }
}

impl Outcome {
    /// The `nav.status` it leaves: a cancel is no failure, the vehicle is idle again.
    pub fn navigation(&self) -> Navigation {
        match self {
            Self::Succeeded => Navigation::Succeeded,
            Self::Cancelled(_) => Navigation::Idle,
            Self::TimedOut | Self::Aborted(_) => Navigation::Failed,
        }
    }
}

/// The end of a motion.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionResult {
    /// Which motion.
    pub id: MotionId,
    /// What it was.
    pub kind: MotionKind,
    /// Who asked for it, as the requester tagged it (a dialect and its request id).
    pub tag: Option<MotionTag>,
    /// How it ended.
    pub outcome: Outcome,
    /// From acceptance to the end, s.
    pub duration_s: f64,
    /// The time-optimal profile's duration, s.
    pub planned_s: f64,
    /// What was left to go where the vehicle comes to rest, in the frame it closed on (m
    /// or rad; a goal's distance in m); for a motion that ended early, what was left at
    /// its last step.
    pub error: f64,
    /// A goal's heading left to turn at its end, rad.
    pub heading_error: Option<f64>,
    /// Where its heading came from.
    pub heading: moves::HeadingSource,
    /// The wheel scale its distance was corrected by (odometry per true distance).
    pub wheel_scale: f64,
    /// A path's cross-track error.
    pub cross_track: Option<CrossTrack>,
}

impl fmt::Display for MotionResult {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let error = match self.kind {
            MotionKind::Move(MoveKind::Turn { .. }) => format!("{:.2}°", self.error.to_degrees()),
            _ => format!("{:.1} mm", self.error * 1000.0),
        };
        let error = match self.heading_error {
            Some(h) => format!("{error} and {:.2}°", h.to_degrees()),
            None => error,
        };
        let error = match self.cross_track {
            Some(c) => format!(
                "{error}; cross-track RMS {:.1} mm, max {:.1} mm",
                c.rms_m * 1000.0,
                c.max_m * 1000.0
            ),
            None => error,
        };
        write!(
            f,
            "move {} ({}): {} after {:.2} s (profile {:.2} s), left to go {error}",
            self.id, self.kind, self.outcome, self.duration_s, self.planned_s
        )
    }
}

/// The vehicle's pose as a move sees it at a control tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseView {
    /// The `odom` frame's pose and speeds.
    pub odom: OdomPose,
    /// When `odom` was measured (the last wheel reading): drives report less often than
    /// the control loop runs, so it is up to a feedback period old.
    pub odom_at: Timestamp,
    /// When `odom.w` applies (a gyro mean over the last wheel interval applies at its
    /// middle).
    pub yaw_rate_at: Timestamp,
    /// The map position (east, north; m), while the vehicle is located.
    pub map_xy: Option<(f64, f64)>,
    /// The map yaw (rad), while the vehicle is located.
    pub map_yaw: Option<f64>,
    /// Odometry distance per true distance (1 + the wheels' scale error the fusion has
    /// learnt), while the vehicle is located.
    pub wheel_scale: Option<f64>,
    /// The quality level of the current GNSS fix (`None` without a fresh valid one).
    pub gnss: MinGnss,
}

impl PoseView {
    /// The map pose (x, y, yaw), while located.
    pub fn map_pose(&self) -> Option<(f64, f64, f64)> {
        let (x, y) = self.map_xy?;
        Some((x, y, self.map_yaw?))
    }
}

/// A motion under way.
#[derive(Debug, Clone)]
enum Active {
    Move(RelativeMove),
    Goal(GoalMove),
    Path(Box<PathFollow>),
}

/// The path of the motion under way, in the map frame (east, north; m): a path task's
/// points; a goal's start and goal; a straight move's start and end; a turn's place. Shared,
/// so a status carries it without a copy.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The motion it belongs to.
    pub id: MotionId,
    /// Its points.
    pub points: std::sync::Arc<Vec<(f64, f64)>>,
}

/// The motion under way, if any, and the last result.
#[derive(Debug, Clone)]
pub struct Motion {
    settings: MotionSettings,
    /// Its id, what it is and who tagged it.
    active: Option<(MotionId, Active, Option<MotionTag>)>,
    /// Its path in the map frame, when the vehicle was located at its start.
    plan: Option<Plan>,
    last_id: MotionId,
    results: Vec<MotionResult>,
    navigation: Navigation,
}

impl Motion {
    /// No motion yet.
    pub fn new(settings: MotionSettings) -> Self {
        Self {
            settings,
            active: None,
            plan: None,
            last_id: 0,
            results: Vec::new(),
            navigation: Navigation::Idle,
        }
    }

    /// Whether a motion is under way.
    pub fn is_active(&self) -> bool {
        self.active.is_some()
    }

    /// Whether the motion under way depends on the map frame (a goal in it, or a heading
    /// held on its yaw): moving the frame would move its goal.
    pub fn uses_map_frame(&self) -> bool {
        self.active.as_ref().is_some_and(|(_, m, _)| match m {
            Active::Move(m) => m.heading_source() == moves::HeadingSource::Map,
            Active::Goal(_) | Active::Path(_) => true,
        })
    }

    /// Whether a path task is under way.
    pub fn is_task(&self) -> bool {
        matches!(self.active, Some((_, Active::Path(_), _)))
    }

    /// Whether the operator holds the task under way.
    pub fn is_paused(&self) -> bool {
        matches!(&self.active, Some((_, Active::Path(p), _)) if p.is_paused())
    }

    /// Holds the task under way at `t` (PAUSE); `false` when none is under way.
    pub fn pause(&mut self, t: Timestamp) -> bool {
        match &mut self.active {
            Some((_, Active::Path(p), _)) => {
                p.pause(t);
                true
            }
            _ => false,
        }
    }

    /// Goes on with the paused task at `t` from `view`; `false` when none is paused.
    pub fn resume(&mut self, t: Timestamp, view: &PoseView) -> bool {
        match &mut self.active {
            Some((_, Active::Path(p), _)) if p.is_paused() => {
                p.resume(t, view);
                true
            }
            _ => false,
        }
    }

    /// What the motion under way reported since the last call, for the log.
    pub fn take_events(&mut self) -> Vec<String> {
        match &mut self.active {
            Some((_, Active::Path(p), _)) => p.take_events(),
            _ => Vec::new(),
        }
    }

    /// The path of the motion under way, in the map frame.
    pub fn plan(&self) -> Option<&Plan> {
        self.plan.as_ref()
    }

    /// Starts a move at `t` from `view`, replacing (cancelling) the one under way.
    pub fn start(&mut self, t: Timestamp, kind: MoveKind, view: &PoseView) -> MotionId {
        let m = Active::Move(RelativeMove::new(t, kind, view, &self.settings));
        let points = view.map_pose().map(|(x, y, yaw)| match kind {
            MoveKind::Straight { distance_m } => vec![
                (x, y),
                (x + distance_m * yaw.cos(), y + distance_m * yaw.sin()),
            ],
            MoveKind::Turn { .. } => vec![(x, y)],
        });
        self.begin_with_plan(t, m, None, points)
    }

    /// Starts a goal at `t` from `view`, replacing (cancelling) the motion under way; `None`
    /// (and nothing replaced) when the vehicle is not located.
    pub fn start_goal(
        &mut self,
        t: Timestamp,
        goal: GoalPose,
        view: &PoseView,
        tag: Option<MotionTag>,
    ) -> Option<MotionId> {
        let g = GoalMove::new(t, goal, view, &self.settings)?;
        let points = view.map_xy.map(|start| vec![start, (goal.x, goal.y)]);
        Some(self.begin_with_plan(t, Active::Goal(g), tag, points))
    }

    /// Starts a path task along `points` (map frame) at `speed` at `t` from `view`,
    /// replacing (cancelling) the motion under way; refused (nothing replaced) when the
    /// vehicle is not located, the GNSS quality is too low or the path is too far.
    pub fn start_path(
        &mut self,
        t: Timestamp,
        points: &[(f64, f64)],
        speed: f64,
        view: &PoseView,
        tag: Option<MotionTag>,
    ) -> Result<MotionId, StartRefusal> {
        let p = PathFollow::new(t, points, speed, view, &self.settings)?;
        let plan = Some(points.to_vec());
        Ok(self.begin_with_plan(t, Active::Path(Box::new(p)), tag, plan))
    }

    fn begin_with_plan(
        &mut self,
        t: Timestamp,
        m: Active,
        tag: Option<MotionTag>,
        points: Option<Vec<(f64, f64)>>,
    ) -> MotionId {
        self.end(t, Outcome::Cancelled(CancelReason::NewMotion), None);
        self.last_id += 1;
        self.active = Some((self.last_id, m, tag));
        self.plan = points.map(|points| Plan {
            id: self.last_id,
            points: std::sync::Arc::new(points),
        });
        self.navigation = Navigation::Running;
        self.last_id
    }

    /// Ends the motion under way (if any) with `outcome`; `error` when known.
    pub fn end(&mut self, t: Timestamp, outcome: Outcome, error: Option<f64>) {
        let Some((id, m, tag)) = self.active.take() else {
            return;
        };
        self.plan = None;
        self.navigation = outcome.navigation();
        let result = match m {
            Active::Move(m) => MotionResult {
                id,
                kind: MotionKind::Move(m.kind()),
                tag,
                outcome,
                duration_s: t.saturating_since(m.started()).as_secs_f64(),
                planned_s: m.profile().duration(),
                error: error.unwrap_or_else(|| m.left()),
                heading_error: None,
                heading: m.heading_source(),
                wheel_scale: m.wheel_scale(),
                cross_track: None,
            },
            Active::Goal(g) => {
                MotionResult {
                    id,
                    kind: MotionKind::Goal(g.goal()),
                    tag,
                    duration_s: t.saturating_since(g.started()).as_secs_f64(),
                    planned_s: g.planned_s(),
                    // A goal has no coast left at its end: what is left is where it is (at
                    // its last step, when it ended early).
                    error: g.left().0,
                    heading_error: Some(g.left().1),
                    heading: moves::HeadingSource::Map,
                    wheel_scale: 1.0,
                    cross_track: None,
                    outcome,
                }
            }
            Active::Path(p) => MotionResult {
                id,
                kind: MotionKind::Path {
                    length_m: p.length(),
                    speed: p.top_speed(),
                    asked: p.requested_speed(),
                },
                tag,
                duration_s: t.saturating_since(p.started()).as_secs_f64(),
                planned_s: p.planned_s(),
                error: error.unwrap_or_else(|| p.left_m()),
                heading_error: None,
                heading: moves::HeadingSource::Map,
                wheel_scale: 1.0,
                cross_track: Some(p.cross_track()),
                outcome,
            },
        };
        self.results.push(result);
    }

    /// One control step at `t`: the velocity (m/s, rad/s) the motion asks for, or `None`
    /// when none is under way (or it just ended). Without a pose the motion is aborted.
    pub fn step(
        &mut self,
        t: Timestamp,
        view: Option<&PoseView>,
        response_s: f64,
    ) -> Option<(f64, f64)> {
        let (_, m, _) = self.active.as_mut()?;
        let Some(view) = view else {
            self.end(t, Outcome::Aborted(AbortReason::NoOdometry), None);
            return None;
        };
        let step = match m {
            Active::Move(m) => m.step(t, view, response_s),
            Active::Goal(g) => g.step(t, view, response_s),
            // Held by the operator: the drive train holds zero under its stop.
            Active::Path(p) if p.is_paused() => return None,
            Active::Path(p) => p.step(t, view, response_s),
        };
        match step {
            Step::Drive { v, w } => Some((v, w)),
            Step::Done(outcome, error) => {
                self.end(t, outcome, Some(error));
                None
            }
        }
    }

    /// The results since the last call.
    pub fn take_results(&mut self) -> Vec<MotionResult> {
        std::mem::take(&mut self.results)
    }

    /// Sets `nav.status` (a mission's, which spans several motions).
    pub fn set_navigation(&mut self, navigation: Navigation) {
        self.navigation = navigation;
    }

    /// `nav.status`: running, or how the last motion ended.
    pub fn navigation(&self) -> Navigation {
        self.navigation
    }
}
