//! The task executive: the closed-loop motion under way (a move, a goal, a path task), the
//! root MISSION that sequences them, and the cutter a mission switches. It decides what the
//! drives are asked for; the drive train's supervisor ([`super::chassis`]) decides what
//! reaches the wheels, and the envelope ([`super::envelope`]) may refuse or pause the work.

use super::chassis::{Chassis, CommandRejected, DriveMode};
use super::core_config::CoreConfig;
use super::envelope::{self, Envelope};
use super::event::Event;
use super::gate::{GateChange, GateReason, GateSignals};
use super::localisation::Localisation;
use super::messages::{Output, PathPoints, PathRequest};
use super::safety::{self, Cause};
use super::status::Navigation;
use crate::config::mission::MissionSettings;
use crate::config::motion::{MotionSettings, Reach};
use crate::control::goal::GoalPose;
use crate::control::mission::{Mission, MissionStep, Request};
use crate::control::outcome::{AbortReason, CancelReason, Replacement};
use crate::control::path::StartRefusal;
use crate::control::{Motion, MotionId, MotionResult, MotionTag, MoveKind, Outcome, PoseView};
use crate::geodesy::Geodetic;
use crate::time::Timestamp;

/// The key of the goal reach, named in refusals.
const GOAL_KEY: &str = "motion.max_goal_distance_m";
/// The key of the path reach.
const PATH_KEY: &str = "motion.max_path_radius_m";

/// What the executive works with and on, borrowed from the vehicle for one call.
pub(super) struct Plant<'a> {
    /// The drive train, when the vehicle has drives.
    pub chassis: Option<&'a mut Chassis>,
    /// Where the vehicle is.
    pub place: &'a Localisation,
    /// The zones and the GNSS gate, when zones are configured.
    pub envelope: Option<&'a mut Envelope>,
}

impl Plant<'_> {
    /// Runs `f` on the drive train; refused without one.
    fn with_chassis(
        &mut self,
        f: impl FnOnce(&mut Chassis) -> Result<(), CommandRejected>,
    ) -> Result<(), CommandRejected> {
        match self.chassis.as_deref_mut() {
            Some(c) => f(c),
            None => Err(CommandRejected::NoDrives),
        }
    }
}

/// What the executive takes from the core's settings.
#[derive(Debug, Clone, Copy)]
struct Settings {
    motion: Option<MotionSettings>,
    mission: MissionSettings,
    has_cutter: bool,
    has_bms: bool,
}

/// What a motion's way is, from where the vehicle stands.
enum Way {
    /// Straight to each point in turn (map frame), at a speed (m/s).
    Through(Vec<(f64, f64)>, f64),
    /// A straight move along the heading, or a turn on the spot.
    Move(MoveKind),
}

/// The motion, the mission and the cutter.
#[derive(Debug, Clone)]
pub struct Executive {
    settings: Settings,
    /// Closed-loop moves; `None` without drives.
    motion: Option<Motion>,
    /// The root MISSION under way.
    mission: Option<Mission>,
    /// Whether a mission switched the cutter on (and nothing has switched it off since).
    cutter_on: bool,
    /// Whether the blade was last told to run: only while the cutter is on and nothing is
    /// latched, so a stop or a pause stops the blade and only a deliberate act restarts it.
    blade_running: bool,
}

impl Executive {
    /// Nothing under way.
    pub fn new(config: &CoreConfig) -> Self {
        Self {
            settings: Settings {
                motion: config.motion,
                mission: config.mission,
                has_cutter: config.has_cutter,
                has_bms: config.bms_stale_after.is_some(),
            },
            motion: config.motion.map(Motion::new),
            mission: None,
            cutter_on: false,
            blade_running: false,
        }
    }

    /// The navigation state the status reports.
    pub fn navigation(&self) -> Navigation {
        self.motion
            .as_ref()
            .map_or(Navigation::Idle, Motion::navigation)
    }

    /// The path of the motion under way, when it has one.
    pub fn plan(&self) -> Option<&crate::control::Plan> {
        self.motion.as_ref().and_then(Motion::plan)
    }

    /// Whether the motion under way steers by the map frame (its goal or heading is in it).
    pub fn uses_map_frame(&self) -> bool {
        self.motion.as_ref().is_some_and(Motion::uses_map_frame)
    }

    /// An operator's velocity: taken (manual mode), it takes over from a move and a
    /// mission; refused (navigation mode, a bad value), they go on.
    pub(super) fn velocity(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        vx: f64,
        wz: f64,
    ) -> Result<(), CommandRejected> {
        plant.with_chassis(|c| c.command(t, vx, wz))?;
        self.end_motion(t, Outcome::Cancelled(CancelReason::VelocityCommand));
        self.cancel_mission(CancelReason::VelocityCommand);
        Ok(())
    }

    /// A distance or angle move, replacing the motion and the mission under way.
    pub(super) fn start_move(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        kind: MoveKind,
    ) -> Result<(), CommandRejected> {
        let finite = match kind {
            MoveKind::Straight { distance_m } => distance_m.is_finite(),
            MoveKind::Turn { angle_rad } => angle_rad.is_finite(),
        };
        if finite {
            self.check_way(t, plant, Way::Move(kind))?;
        }
        self.start_motion(t, plant, finite, |motion, view| {
            Ok(motion.start(t, kind, view))
        })?;
        self.cancel_mission(CancelReason::Replaced(Replacement::Move));
        Ok(())
    }

    /// A goal (`goal`, MOVE_TO_POSITION), replacing the motion and the mission under way.
    pub(super) fn goal(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        goal: GoalPose,
        tag: Option<MotionTag>,
    ) -> Result<(), CommandRejected> {
        self.start_goal(t, plant, goal, tag)?;
        self.cancel_mission(CancelReason::Replaced(Replacement::Goal));
        Ok(())
    }

    /// A path task, replacing the motion and the mission under way.
    pub(super) fn follow_path(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        path: &PathRequest,
        tag: Option<MotionTag>,
    ) -> Result<(), CommandRejected> {
        self.start_path(t, plant, path, tag)?;
        self.cancel_mission(CancelReason::Replaced(Replacement::Task));
        Ok(())
    }

    /// The operator's PAUSE: a task holds where it is (a goal or a move ends; a mission's
    /// step starts again on CONTINUE), and the operator's stop latches.
    pub(super) fn pause(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
    ) -> Result<(), CommandRejected> {
        if let Some(m) = &mut self.mission {
            m.pause();
        }
        let mission = self.mission.is_some();
        let held = self.motion.as_mut().is_some_and(|m| m.pause(t));
        if mission
            && !held
            && let Some(m) = &mut self.mission
        {
            m.restart_step();
        }
        if !held {
            self.end_motion(t, Outcome::Cancelled(CancelReason::PausedByOperator));
        }
        plant.with_chassis(|c| {
            c.operator_stop(t);
            Ok(())
        })
    }

    /// CONTINUE: re-arms the operator's stop and goes on with the paused task.
    pub(super) fn resume(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
    ) -> Result<(), CommandRejected> {
        let task = self.motion.as_ref().is_some_and(Motion::is_paused);
        let mission = self.mission.as_ref().is_some_and(Mission::is_paused);
        if !task && !mission {
            return Err(CommandRejected::NothingPaused);
        }
        envelope::may_start(plant.envelope.as_deref())?;
        plant.with_chassis(|c| c.reset(t))?;
        if task {
            let view = plant
                .place
                .pose_view(t)
                .ok_or(CommandRejected::NoOdometry)?;
            if let Some(m) = &mut self.motion {
                m.resume(t, &view);
            }
        }
        if let Some(m) = &mut self.mission {
            m.resume();
        }
        Ok(())
    }

    /// Ends what runs and brings the vehicle to rest without latching (`set_navi_cmd` 5).
    pub(super) fn cancel_motion(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
    ) -> Result<(), CommandRejected> {
        self.cancel_mission(CancelReason::StopRequested);
        self.end_motion(t, Outcome::Cancelled(CancelReason::StopRequested));
        plant.with_chassis(|c| {
            c.hold_zero(t);
            Ok(())
        })
    }

    /// The operator's stop: what runs ends and the stop latches.
    pub(super) fn stop(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
    ) -> Result<(), CommandRejected> {
        self.cancel_mission(CancelReason::StoppedByOperator);
        self.end_motion(t, Outcome::Cancelled(CancelReason::StoppedByOperator));
        plant.with_chassis(|c| {
            c.operator_stop(t);
            Ok(())
        })
    }

    /// Switches who may drive; a switch ends what runs.
    pub(super) fn set_mode(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        mode: DriveMode,
    ) -> Result<(), CommandRejected> {
        if plant.chassis.as_deref().is_some_and(|c| c.mode() != mode) {
            self.cancel_mission(CancelReason::ModeSwitched);
            self.end_motion(t, Outcome::Cancelled(CancelReason::ModeSwitched));
        }
        plant.with_chassis(|c| {
            c.set_mode(mode);
            Ok(())
        })
    }

    /// Starts a mission, replacing the one (and the motion) under way.
    pub(super) fn start_mission(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        steps: &[MissionStep],
        tag: Option<MotionTag>,
    ) -> Result<(), CommandRejected> {
        let (Some(chassis), Some(_)) = (plant.chassis.as_deref(), &self.motion) else {
            return Err(CommandRejected::NoDrives);
        };
        chassis.ready_to_move()?;
        if steps.is_empty() {
            return Err(CommandRejected::Task(
                "a mission needs at least one step".into(),
            ));
        }
        // Where the vehicle is now: MOVE_TO_POSITION points within the goal reach, COVERAGE
        // within the path reach (each step checks again when it starts).
        let view = plant.place.pose_view(t);
        let reach = self.reach();
        for step in steps {
            let (points, limit, key) = match step {
                MissionStep::MoveTo(p) => (p, reach.map(|r| r.goal_m), GOAL_KEY),
                MissionStep::Coverage(p) => (p, reach.map(|r| r.path_m), PATH_KEY),
                _ => continue,
            };
            if points.iter().any(|(x, y)| !x.is_finite() || !y.is_finite()) {
                return Err(CommandRejected::NotFinite);
            }
            if let Some(view) = &view {
                within_reach(view, points, limit, key)?;
            }
        }
        // The paths one after the other, from where the vehicle stands (the dock is left
        // out: it often lies on a boundary).
        let way: Vec<(f64, f64)> = steps
            .iter()
            .flat_map(|step| match step {
                MissionStep::MoveTo(p) | MissionStep::Coverage(p) => p.as_slice(),
                _ => &[],
            })
            .copied()
            .collect();
        if !way.is_empty() {
            self.check_way(t, plant, Way::Through(way, self.settings.mission.speed_mps))?;
        }
        for (i, step) in steps.iter().enumerate() {
            let problem = match step {
                MissionStep::Cutter(_) if !self.settings.has_cutter => {
                    Some("needs a [cutter] in the configuration")
                }
                MissionStep::Charge(_) if self.settings.mission.dock.is_none() => {
                    Some("needs a dock pose (mission.dock)")
                }
                MissionStep::Charge(_) if !self.settings.has_bms => {
                    Some("needs a BMS to report charging ([bms])")
                }
                _ => None,
            };
            if let Some(problem) = problem {
                return Err(CommandRejected::Task(format!(
                    "step {i} ({}) {problem}",
                    step.action()
                )));
            }
        }
        self.cancel_mission(CancelReason::NewMission);
        self.end_motion(
            t,
            Outcome::Cancelled(CancelReason::Replaced(Replacement::Mission)),
        );
        self.mission = Some(Mission::new(steps.to_vec(), self.settings.mission, tag));
        if let Some(m) = &mut self.motion {
            m.set_navigation(Navigation::Running);
        }
        Ok(())
    }

    /// One control step: the gate's change (with `gate` signals, when zones are
    /// configured), a latched stop ends the move under way, the move proposes a velocity,
    /// the zones check the braking way, and the drive train decides what reaches the wheels;
    /// then the mission and the cutter follow. A stop that latches during this tick ends the
    /// move at the next.
    pub(super) fn control_tick(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        gate: Option<&GateSignals>,
        charging: bool,
    ) -> Vec<Output> {
        if plant.chassis.is_none() {
            return Vec::new();
        }
        let mut out = Vec::new();
        if let Some(signals) = gate {
            self.gate_tick(t, plant, signals, &mut out);
        }
        // Only a move needs the pose (two filter predictions).
        let moving = self.motion.as_ref().is_some_and(Motion::is_active);
        let view = if moving {
            plant.place.pose_view(t)
        } else {
            None
        };
        let Some(chassis) = plant.chassis.as_deref_mut() else {
            return out;
        };
        let mut results = Vec::new();
        if let Some(motion) = &mut self.motion {
            // A task the operator paused waits under the operator's stop; any other stop
            // ends the motion.
            let held = motion.is_paused() || self.mission.as_ref().is_some_and(Mission::is_paused);
            match chassis.safety().latched() {
                Some(Cause::Operator) if held => {}
                Some(cause) => {
                    motion.end(
                        t,
                        Outcome::Aborted(AbortReason::SafetyStop(cause.to_string())),
                        None,
                    );
                    if let Some(m) = &mut self.mission {
                        m.end(Outcome::Aborted(AbortReason::SafetyStop(cause.to_string())));
                    }
                }
                None => {}
            }
            if motion.is_active() {
                match motion.step(t, view.as_ref(), chassis.response_time()) {
                    Some((v, w)) => {
                        if let Err(e) = chassis.autonomous(t, v, w) {
                            motion.end(
                                t,
                                Outcome::Aborted(AbortReason::DrivesRefused(e.to_string())),
                                None,
                            );
                        }
                    }
                    // Just ended: hold zero rather than let the last speed run to the timeout.
                    None => chassis.hold_zero(t),
                }
            }
            out.extend(
                motion
                    .take_events()
                    .into_iter()
                    .map(|e| Output::Event(Event::Motion(e))),
            );
            results = motion.take_results();
        }
        if let Some(envelope) = plant.envelope.as_deref_mut() {
            let mut events = Vec::new();
            envelope::zone_tick(envelope, plant.place.localizer(), chassis, t, &mut events);
            out.extend(events.into_iter().map(|e| Output::Event(Event::Zone(e))));
        }
        out.insert(0, Output::Wheels(chassis.tick(t)));
        self.mission_tick(t, plant, &results, charging, &mut out);
        self.cutter_tick(plant, &mut out);
        for result in results {
            out.push(Output::Event(Event::MotionEnded(result.clone())));
            out.push(Output::MotionEnded(result));
        }
        out
    }

    /// The gate's part of a control tick, before any motion steps: pauses the work when it
    /// closes, and goes on with it when it opens.
    fn gate_tick(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        signals: &GateSignals,
        out: &mut Vec<Output>,
    ) {
        let Some(envelope) = plant.envelope.as_deref_mut() else {
            return;
        };
        match envelope.update_gate(t, signals) {
            Some(GateChange::Closed(reason)) => {
                out.push(Output::Event(Event::GateClosed(reason.clone())));
                let paused = self.pause_for_gate(t, &reason);
                envelope.hold_paused(paused);
            }
            Some(GateChange::Opened) => {
                out.push(Output::Event(Event::GateOpened));
                if envelope.take_paused() {
                    self.resume_after_gate(t, plant);
                }
            }
            None => {}
        }
    }

    /// Holds what runs: a task or a mission pauses at rest; a goal or a move ends (a
    /// mission's step starts again when the gate opens). Returns whether anything waits
    /// for the gate to open.
    fn pause_for_gate(&mut self, t: Timestamp, reason: &GateReason) -> bool {
        let mission = self.mission.is_some();
        if let Some(m) = &mut self.mission {
            m.pause();
        }
        let held = self.motion.as_mut().is_some_and(|m| m.pause(t));
        if !held {
            if let Some(m) = &mut self.mission {
                m.restart_step();
            }
            self.end_motion(
                t,
                Outcome::Aborted(AbortReason::GnssGate(reason.to_string())),
            );
        }
        held || mission
    }

    /// Goes on with what the gate paused, unless a stop latched meanwhile (the operator's
    /// CONTINUE, or a reset and a new start, go on from there).
    fn resume_after_gate(&mut self, t: Timestamp, plant: &Plant<'_>) {
        if plant
            .chassis
            .as_deref()
            .is_some_and(|c| c.safety().latched().is_some())
        {
            return;
        }
        if let Some(view) = plant.place.pose_view(t)
            && let Some(m) = &mut self.motion
        {
            m.resume(t, &view);
        }
        if let Some(m) = &mut self.mission {
            m.resume();
        }
    }

    /// Starts a goal, once the drives can take it and the vehicle is located.
    fn start_goal(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        goal: GoalPose,
        tag: Option<MotionTag>,
    ) -> Result<MotionId, CommandRejected> {
        let finite = goal.x.is_finite() && goal.y.is_finite() && goal.yaw.is_finite();
        if finite {
            self.check_way(
                t,
                plant,
                Way::Through(vec![(goal.x, goal.y)], self.cruise_mps()),
            )?;
        }
        let reach = self.reach();
        self.start_motion(t, plant, finite, |motion, view| {
            within_reach(view, &[(goal.x, goal.y)], reach.map(|r| r.goal_m), GOAL_KEY)?;
            motion
                .start_goal(t, goal, view, tag)
                .ok_or(CommandRejected::NotLocated)
        })
    }

    /// Starts a path task, once the drives can take it, the vehicle is located and the fix
    /// is good enough. Geodetic points are placed with the datum in force now.
    fn start_path(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        path: &PathRequest,
        tag: Option<MotionTag>,
    ) -> Result<MotionId, CommandRejected> {
        let points: Vec<(f64, f64)> = match &path.points {
            PathPoints::Map(points) => points.clone(),
            PathPoints::Geodetic(points) => {
                let Some(frame) = plant.place.localizer().frame() else {
                    return Err(CommandRejected::NotLocated);
                };
                points
                    .iter()
                    .map(|&(lat_deg, lon_deg)| {
                        let enu = frame.to_enu(&Geodetic {
                            lat_deg,
                            lon_deg,
                            h_m: frame.datum().h_m,
                        });
                        (enu.x, enu.y)
                    })
                    .collect()
            }
        };
        let finite = path.speed.is_finite()
            && path.speed > 0.0
            && !points.is_empty()
            && points.iter().all(|(x, y)| x.is_finite() && y.is_finite());
        let speed = path.speed;
        if finite {
            self.check_way(t, plant, Way::Through(points.clone(), speed))?;
        }
        let reach = self.reach();
        self.start_motion(t, plant, finite, |motion, view| {
            within_reach(view, &points, reach.map(|r| r.path_m), PATH_KEY)?;
            motion
                .start_path(t, &points, speed, view, tag)
                .map_err(|refusal| match refusal {
                    StartRefusal::NotLocated => CommandRejected::NotLocated,
                    other => CommandRejected::Task(other.to_string()),
                })
        })
    }

    /// Cancels the mission under way, if any: `why`.
    fn cancel_mission(&mut self, why: CancelReason) {
        if let Some(m) = &mut self.mission {
            m.end(Outcome::Cancelled(why));
        }
    }

    /// Runs the blade while the cutter is on and the supervisor is armed. A stop other than the
    /// operator's pause of a task switches the cutter off for good; the pause only holds it.
    fn cutter_tick(&mut self, plant: &Plant<'_>, out: &mut Vec<Output>) {
        let Some(safety) = plant.chassis.as_deref().map(|c| c.safety()) else {
            return;
        };
        let latched = safety.latched().cloned();
        // Armed: the drives are enabled (not in standby before the first arm, nor latched).
        let armed = matches!(safety.state(), safety::State::Armed);
        let paused = self.motion.as_ref().is_some_and(Motion::is_paused)
            || self.mission.as_ref().is_some_and(Mission::is_paused);
        match latched {
            Some(Cause::Operator) if paused => {}
            Some(_) => self.cutter_on = false,
            None => {}
        }
        let run = self.cutter_on && armed && envelope::lets_blade_run(plant.envelope.as_deref());
        if run != self.blade_running {
            self.blade_running = run;
            out.push(Output::Cutter(run));
        }
    }

    /// The mission's part of a control tick: the ends of its motions, its timers (`charging`:
    /// the BMS says the vehicle charges), what it asks for next, and its progress out.
    fn mission_tick(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        results: &[MotionResult],
        charging: bool,
        out: &mut Vec<Output>,
    ) {
        let Some(mission) = &mut self.mission else {
            return;
        };
        for r in results {
            mission.motion_ended(r.id, &r.outcome);
        }
        // Instant steps (the cutter) run in the same tick as the next one starts.
        while let Some(request) = self.mission.as_mut().and_then(|m| m.tick(t, charging)) {
            let started = match request {
                Request::Path(points, speed) => {
                    let path = PathRequest {
                        points: PathPoints::Map(points),
                        speed,
                    };
                    self.start_path(t, plant, &path, None)
                }
                Request::Goal(goal) => self.start_goal(t, plant, goal, None),
                Request::Cutter(on) => {
                    self.cutter_on = on;
                    self.cutter_tick(plant, out);
                    continue;
                }
            };
            if let Some(m) = &mut self.mission {
                match started {
                    Ok(id) => m.started(id),
                    Err(e) => m.end(Outcome::Aborted(AbortReason::StepNotStarted(e.to_string()))),
                }
            }
        }
        let Some(mission) = &mut self.mission else {
            return;
        };
        let tag = mission.tag();
        for event in mission.take_events() {
            out.push(Output::Event(Event::Mission(event.clone())));
            out.push(Output::Mission { tag, event });
        }
        let ended = mission.ended().cloned();
        let Some(motion) = &mut self.motion else {
            return;
        };
        match ended {
            None => motion.set_navigation(Navigation::Running),
            Some(outcome) => {
                if outcome != Outcome::Succeeded {
                    motion.end(t, Outcome::Cancelled(CancelReason::MissionEnded), None);
                    // The blade stops with a mission that did not finish.
                    self.cutter_on = false;
                }
                motion.set_navigation(outcome.navigation());
                self.mission = None;
            }
        }
    }

    /// Starts a motion with `start` once its values are `finite`, the drives can take it
    /// and the odometry runs.
    fn start_motion(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        finite: bool,
        start: impl FnOnce(&mut Motion, &PoseView) -> Result<MotionId, CommandRejected>,
    ) -> Result<MotionId, CommandRejected> {
        if !finite {
            return Err(CommandRejected::NotFinite);
        }
        let view = plant.place.pose_view(t);
        let (Some(chassis), Some(motion)) = (plant.chassis.as_deref(), &mut self.motion) else {
            return Err(CommandRejected::NoDrives);
        };
        chassis.ready_to_move()?;
        let Some(view) = view else {
            return Err(CommandRejected::NoOdometry);
        };
        start(motion, &view)
    }

    /// Refuses a motion whose way meets a zone, or any while the GNSS gate is closed (when
    /// zones are configured): the way from where the vehicle stands in the map frame.
    fn check_way(
        &mut self,
        t: Timestamp,
        plant: &mut Plant<'_>,
        way: Way,
    ) -> Result<(), CommandRejected> {
        let speed = match &way {
            Way::Through(_, speed) => *speed,
            Way::Move(MoveKind::Straight { .. }) => self.cruise_mps(),
            Way::Move(MoveKind::Turn { .. }) => 0.0,
        };
        let localizer = plant.place.localizer();
        // What the run-time check will take at that speed: σ and the braking way.
        let run_time = match (plant.chassis.as_deref(), envelope::map_sigma(localizer, t)) {
            (Some(chassis), Some(sigma)) => sigma + envelope::braking(chassis).distance(speed),
            _ => 0.0,
        };
        let Some(envelope) = plant.envelope.as_deref_mut() else {
            return Ok(());
        };
        let here = plant
            .place
            .pose_view(t)
            .and_then(|v| Some((v.map_xy?, v.map_yaw?)));
        let Some(((x, y), yaw)) = here else {
            return Err(CommandRejected::ZonesUnplaced);
        };
        let points = match way {
            Way::Through(points, _) => std::iter::once((x, y)).chain(points).collect(),
            Way::Move(MoveKind::Straight { distance_m }) => vec![
                (x, y),
                (x + distance_m * yaw.cos(), y + distance_m * yaw.sin()),
            ],
            // On the spot: the footprint's disc where it stands.
            Way::Move(MoveKind::Turn { .. }) => vec![(x, y)],
        };
        // The way first: it is the request's own fault, the gate only the moment's.
        envelope
            .guard()
            .check_way(localizer.map_placement(), &points, run_time)?;
        envelope.may_start()
    }

    /// The speed goals and straight moves cruise at, m/s (0 without drives).
    fn cruise_mps(&self) -> f64 {
        self.settings.motion.map_or(0.0, |m| m.linear.speed)
    }

    /// How far a motion may lead, when the vehicle has drives.
    fn reach(&self) -> Option<Reach> {
        self.settings.motion.map(|m| m.reach)
    }

    /// Ends the motion under way, if any.
    fn end_motion(&mut self, t: Timestamp, outcome: Outcome) {
        if let Some(m) = &mut self.motion {
            m.end(t, outcome, None);
        }
    }
}

/// Refuses `points` when one lies farther than `limit` from the vehicle (when it is
/// located; a motion that needs the map refuses an unlocated vehicle by itself).
fn within_reach(
    view: &PoseView,
    points: &[(f64, f64)],
    limit: Option<f64>,
    key: &'static str,
) -> Result<(), CommandRejected> {
    let (Some(limit), Some((x, y))) = (limit, view.map_xy) else {
        return Ok(());
    };
    let farthest = points
        .iter()
        .map(|(px, py)| (px - x).hypot(py - y))
        .fold(0.0, f64::max);
    if farthest > limit {
        return Err(CommandRejected::BeyondLimit {
            what: "distance from the vehicle",
            value: farthest,
            limit,
            unit: "m",
            key,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::chassis::WheelRadius;
    use crate::config::motion::MotionConfig;
    use crate::control::outcome::CancelReason;
    use crate::vehicle::safety::SafetyConfig;
    use crate::vehicle::test_rig::{self, at, drives_at_rest};

    /// The executive with real parts around it: a drive train of two ready drives and the
    /// localisation of its wheels.
    struct Rig {
        executive: Executive,
        chassis: Option<Chassis>,
        place: Localisation,
    }

    impl Rig {
        fn new(has_cutter: bool) -> Self {
            let chassis = test_rig::chassis();
            let config = CoreConfig {
                chassis: Some(chassis),
                motion: Some(MotionConfig::default().settings(&chassis)),
                has_cutter,
                ..CoreConfig::default()
            };
            let mut drives = Chassis::new(
                chassis,
                SafetyConfig {
                    cmd_timeout: chassis.cmd_timeout(),
                    quick_stop: chassis.quick_stop(),
                    reset_timeout: chassis.reset_timeout(),
                    control_link: None,
                    enable_on_start: true,
                },
            );
            drives.feedback(drives_at_rest(0));
            Self {
                executive: Executive::new(&config),
                chassis: Some(drives),
                place: Localisation::new(&config),
            }
        }

        fn without_drives() -> Self {
            let config = CoreConfig::default();
            Self {
                executive: Executive::new(&config),
                chassis: None,
                place: Localisation::new(&config),
            }
        }

        /// The drives report standing wheels at `ms`.
        fn wheels(&mut self, ms: u64) {
            let f = drives_at_rest(ms);
            if let Some(c) = &mut self.chassis {
                c.feedback(f.clone());
            }
            self.place.wheels(at(ms), &f, WheelRadius::both(0.1));
        }

        fn run<R>(&mut self, f: impl FnOnce(&mut Executive, &mut Plant<'_>) -> R) -> R {
            let mut plant = Plant {
                chassis: self.chassis.as_mut(),
                place: &self.place,
                envelope: None,
            };
            f(&mut self.executive, &mut plant)
        }

        fn control_tick(&mut self, ms: u64) -> Vec<Output> {
            self.run(|e, p| e.control_tick(at(ms), p, None, false))
        }
    }

    fn ended(out: &[Output]) -> Vec<Outcome> {
        out.iter()
            .filter_map(|o| match o {
                Output::MotionEnded(r) => Some(r.outcome.clone()),
                _ => None,
            })
            .collect()
    }

    fn blade(out: &[Output]) -> Vec<bool> {
        out.iter()
            .filter_map(|o| match o {
                Output::Cutter(on) => Some(*on),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn without_drives_every_motion_is_refused() {
        let mut rig = Rig::without_drives();
        let t = at(0);
        let turn = MoveKind::Turn { angle_rad: 1.0 };
        let goal = GoalPose {
            x: 1.0,
            y: 0.0,
            yaw: 0.0,
        };
        for result in [
            rig.run(|e, p| e.start_move(t, p, turn)),
            rig.run(|e, p| e.goal(t, p, goal, None)),
            rig.run(|e, p| e.start_mission(t, p, &[MissionStep::Wait(1.0)], None)),
            rig.run(|e, p| e.velocity(t, p, 0.1, 0.0)),
            rig.run(|e, p| e.stop(t, p)),
        ] {
            assert_eq!(result, Err(CommandRejected::NoDrives));
        }
        assert!(
            rig.control_tick(10).is_empty(),
            "no drives, no wheels to command"
        );
    }

    #[test]
    fn a_move_waits_for_odometry_and_an_operator_velocity_takes_over() {
        let mut rig = Rig::new(false);
        let turn = MoveKind::Turn { angle_rad: 1.0 };
        assert_eq!(
            rig.run(|e, p| e.start_move(at(0), p, turn)),
            Err(CommandRejected::NoOdometry)
        );
        rig.wheels(10);
        assert_eq!(rig.run(|e, p| e.start_move(at(10), p, turn)), Ok(()));
        assert_eq!(rig.executive.navigation(), Navigation::Running);
        assert!(ended(&rig.control_tick(20)).is_empty());
        assert_eq!(rig.run(|e, p| e.velocity(at(30), p, 0.1, 0.0)), Ok(()));
        assert_eq!(
            ended(&rig.control_tick(40)),
            vec![Outcome::Cancelled(CancelReason::VelocityCommand)]
        );
    }

    #[test]
    fn a_step_the_vehicle_cannot_do_is_refused_by_its_index_before_anything_changes() {
        let mut rig = Rig::new(false);
        rig.wheels(0);
        let steps = [MissionStep::Wait(1.0), MissionStep::Cutter(true)];
        let refused = rig.run(|e, p| e.start_mission(at(0), p, &steps, None));
        assert_eq!(
            refused,
            Err(CommandRejected::Task(
                "step 1 (OPEN_CUTTER) needs a [cutter] in the configuration".into()
            ))
        );
        let charge = rig.run(|e, p| e.start_mission(at(0), p, &[MissionStep::Charge(0.0)], None));
        assert!(
            matches!(&charge, Err(CommandRejected::Task(why)) if why.contains("mission.dock")),
            "{charge:?}"
        );
        assert_eq!(rig.executive.navigation(), Navigation::Idle);
    }

    #[test]
    fn a_stop_switches_the_blade_off_for_good_and_a_pause_only_holds_it() {
        let mut rig = Rig::new(true);
        rig.wheels(0);
        let steps = [MissionStep::Cutter(true), MissionStep::Wait(600.0)];
        assert_eq!(
            rig.run(|e, p| e.start_mission(at(0), p, &steps, None)),
            Ok(())
        );
        let mut on = Vec::new();
        for ms in (10..=200).step_by(10) {
            rig.wheels(ms);
            on.extend(blade(&rig.control_tick(ms)));
        }
        assert_eq!(on, vec![true], "the blade runs once the drives are armed");

        // PAUSE holds the mission and stops the blade; CONTINUE re-arms and it runs again.
        assert_eq!(rig.run(|e, p| e.pause(at(210), p)), Ok(()));
        assert_eq!(blade(&rig.control_tick(220)), vec![false]);
        assert_eq!(rig.run(|e, p| e.resume(at(230), p)), Ok(()));
        let mut again = Vec::new();
        for ms in (240..=600).step_by(10) {
            rig.wheels(ms);
            again.extend(blade(&rig.control_tick(ms)));
        }
        assert_eq!(again, vec![true]);
        assert_eq!(
            rig.run(|e, p| e.resume(at(610), p)),
            Err(CommandRejected::NothingPaused)
        );

        // A stop ends the mission: the blade stops and stays off through a reset.
        assert_eq!(rig.run(|e, p| e.stop(at(620), p)), Ok(()));
        let mut after = blade(&rig.control_tick(630));
        let reset = rig.run(|_, p| p.with_chassis(|c| c.reset(at(640))));
        assert_eq!(reset, Ok(()));
        for ms in (650..=1_000).step_by(10) {
            rig.wheels(ms);
            after.extend(blade(&rig.control_tick(ms)));
        }
        assert_eq!(after, vec![false]);
        assert_eq!(rig.executive.navigation(), Navigation::Idle);
    }
}
