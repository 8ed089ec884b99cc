//! Root MISSION: steps run in order. Each step asks the core for what it needs (a path, a
//! goal, the cutter) and ends on its motion's result, a timer or the BMS.
//!
//! - MOVE_TO_POSITION and COVERAGE follow their path (a path task at the mission speed).
//! - WAIT waits at rest for its seconds.
//! - OPEN_CUTTER and CLOSE_CUTTER switch the cutter, done at once.
//! - CHARGING goes to the dock pose, then waits for the BMS to report charging (for `time`
//!   seconds, or done as soon as it does when 0); it fails when the BMS has not reported
//!   charging for the charge timeout (after docking, or since it last did).
//!
//! A step whose motion does not succeed ends the mission with its outcome. PAUSE holds it
//! (the timers stop), CONTINUE goes on.

use std::fmt;

use super::goal::GoalPose;
use super::outcome::{AbortReason, CancelReason, StepAt};
use super::{MotionId, MotionTag, Outcome};
use crate::time::Timestamp;

/// Steps a mission may have: far beyond a day's work, few enough that its notifies (two per
/// step) cannot flood a link.
pub const MAX_STEPS: usize = 1000;
/// Steps that may start in one control tick: instant ones (WAIT 0, the cutter) run on in
/// the same tick up to this many, so a mission of many of them spreads its notifies over
/// ticks instead of emitting them all at once.
pub const MAX_STEPS_PER_TICK: usize = 8;

/// The settings missions run with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MissionSettings {
    /// Path speed, m/s.
    pub speed_mps: f64,
    /// The dock pose (map frame).
    pub dock: Option<GoalPose>,
    /// How long to wait for charging at the dock, s.
    pub charge_timeout_s: f64,
}

/// One step of a mission.
#[derive(Debug, Clone, PartialEq)]
pub enum MissionStep {
    /// Follow this path (map frame) to its end.
    MoveTo(Vec<(f64, f64)>),
    /// Wait at rest, s.
    Wait(f64),
    /// Cover along this path (map frame).
    Coverage(Vec<(f64, f64)>),
    /// Switch the cutter on or off.
    Cutter(bool),
    /// Go to the dock and charge for this long, s (0: until charging is reported).
    Charge(f64),
}

impl MissionStep {
    /// The spec's action name.
    pub fn action(&self) -> &'static str {
        match self {
            Self::MoveTo(_) => "MOVE_TO_POSITION",
            Self::Wait(_) => "WAIT",
            Self::Coverage(_) => "COVERAGE",
            Self::Cutter(true) => "OPEN_CUTTER",
            Self::Cutter(false) => "CLOSE_CUTTER",
            Self::Charge(_) => "CHARGING",
        }
    }
}

/// What the mission asks of the core now.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Follow a path at a speed.
    Path(Vec<(f64, f64)>, f64),
    /// Go to a pose.
    Goal(GoalPose),
    /// Switch the cutter.
    Cutter(bool),
}

/// Progress, for the requester's notifies.
#[derive(Debug, Clone, PartialEq)]
pub enum MissionEvent {
    /// Step `index` (its action) started.
    StepStarted(usize, &'static str),
    /// Step `index` is done.
    StepDone(usize, &'static str),
    /// The mission ended.
    Ended(Outcome),
}

impl fmt::Display for MissionEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::StepStarted(i, a) => write!(f, "mission step {i} ({a}) started"),
            Self::StepDone(i, a) => write!(f, "mission step {i} ({a}) done"),
            Self::Ended(o) => write!(f, "mission {o}"),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Phase {
    /// The step has not started.
    Start,
    /// Its motion (a path, or the way to the dock) runs.
    Motion(MotionId),
    /// Waiting, with this long left, s.
    Wait(f64),
    /// At the dock: not charging for this long (since docking, or since it last charged),
    /// and charged this long in all, s.
    Charging { idle: f64, charged: f64 },
}

/// A mission under way.
#[derive(Debug, Clone)]
pub struct Mission {
    steps: Vec<MissionStep>,
    settings: MissionSettings,
    tag: Option<MotionTag>,
    index: usize,
    phase: Phase,
    paused: bool,
    last_tick: Option<Timestamp>,
    /// Steps started in the tick at `last_tick`.
    started_this_tick: usize,
    events: Vec<MissionEvent>,
    ended: Option<Outcome>,
}

impl Mission {
    /// A mission of `steps`, for `tag`.
    pub fn new(steps: Vec<MissionStep>, settings: MissionSettings, tag: Option<MotionTag>) -> Self {
        Self {
            steps,
            settings,
            tag,
            index: 0,
            phase: Phase::Start,
            paused: false,
            last_tick: None,
            started_this_tick: 0,
            events: Vec::new(),
            ended: None,
        }
    }

    /// Who asked for it.
    pub fn tag(&self) -> Option<MotionTag> {
        self.tag
    }

    /// How it ended, once it has.
    pub fn ended(&self) -> Option<&Outcome> {
        self.ended.as_ref()
    }

    /// Whether the operator holds it.
    pub fn is_paused(&self) -> bool {
        self.paused
    }

    /// PAUSE.
    pub fn pause(&mut self) {
        self.paused = true;
    }

    /// CONTINUE.
    pub fn resume(&mut self) {
        self.paused = false;
    }

    /// Starts the current step again at the next tick (its motion was ended by a pause).
    pub fn restart_step(&mut self) {
        if matches!(self.phase, Phase::Motion(_)) {
            self.phase = Phase::Start;
        }
    }

    /// The motion it waits for, if any.
    pub fn motion(&self) -> Option<MotionId> {
        match self.phase {
            Phase::Motion(id) => Some(id),
            _ => None,
        }
    }

    /// Ends it with `outcome` (a cancel, a safety stop, a refused step).
    pub fn end(&mut self, outcome: Outcome) {
        if self.ended.is_none() {
            self.events.push(MissionEvent::Ended(outcome.clone()));
            self.ended = Some(outcome);
        }
    }

    /// Progress since the last call.
    pub fn take_events(&mut self) -> Vec<MissionEvent> {
        std::mem::take(&mut self.events)
    }

    /// Its motion `id` ended with `outcome`.
    pub fn motion_ended(&mut self, id: MotionId, outcome: &Outcome) {
        if self.phase != Phase::Motion(id) {
            return;
        }
        let (index, step) = (self.index, &self.steps[self.index]);
        let at = StepAt {
            index,
            action: step.action(),
        };
        match outcome {
            Outcome::Succeeded if matches!(step, MissionStep::Charge(_)) => {
                self.phase = Phase::Charging {
                    idle: 0.0,
                    charged: 0.0,
                };
            }
            Outcome::Succeeded => self.step_done(),
            Outcome::Cancelled(why) => {
                self.end(Outcome::Cancelled(CancelReason::Step(
                    at,
                    Box::new(why.clone()),
                )));
            }
            Outcome::TimedOut => self.end(Outcome::Aborted(AbortReason::StepTimedOut(at))),
            Outcome::Aborted(why) => {
                self.end(Outcome::Aborted(AbortReason::Step(
                    at,
                    Box::new(why.clone()),
                )));
            }
        }
    }

    /// The motion the core started for the current step.
    pub fn started(&mut self, id: MotionId) {
        self.phase = Phase::Motion(id);
    }

    /// Step `index` as reasons name it.
    fn step_at(&self, index: usize) -> StepAt {
        StepAt {
            index,
            action: self.steps[index].action(),
        }
    }

    fn step_done(&mut self) {
        let action = self.steps[self.index].action();
        self.events.push(MissionEvent::StepDone(self.index, action));
        self.index += 1;
        self.phase = Phase::Start;
        if self.index >= self.steps.len() {
            self.end(Outcome::Succeeded);
        }
    }

    /// One control tick at `t`, `charging` telling whether a fresh BMS reading says the pack
    /// charges: what to ask of the core now, if anything.
    pub fn tick(&mut self, t: Timestamp, charging: bool) -> Option<Request> {
        let dt = self
            .last_tick
            .map_or(0.0, |last| t.saturating_since(last).as_secs_f64());
        // The core calls again within a tick after an instant step (the cutter).
        if self.last_tick != Some(t) {
            self.started_this_tick = 0;
        }
        self.last_tick = Some(t);
        if self.ended.is_some() || self.paused {
            return None;
        }
        loop {
            let step = self.steps.get(self.index)?.clone();
            match (&self.phase, &step) {
                (Phase::Start, _) => {
                    if self.started_this_tick >= MAX_STEPS_PER_TICK {
                        return None;
                    }
                    self.started_this_tick += 1;
                    self.events
                        .push(MissionEvent::StepStarted(self.index, step.action()));
                    match step {
                        MissionStep::MoveTo(path) | MissionStep::Coverage(path) => {
                            return Some(Request::Path(path, self.settings.speed_mps));
                        }
                        MissionStep::Wait(seconds) => self.phase = Phase::Wait(seconds),
                        MissionStep::Cutter(on) => {
                            self.step_done();
                            return Some(Request::Cutter(on));
                        }
                        MissionStep::Charge(_) => {
                            let Some(dock) = self.settings.dock else {
                                let at = self.step_at(self.index);
                                self.end(Outcome::Aborted(AbortReason::Step(
                                    at,
                                    Box::new(AbortReason::NoDock),
                                )));
                                return None;
                            };
                            return Some(Request::Goal(dock));
                        }
                    }
                }
                (Phase::Wait(left), _) => {
                    let left = left - dt;
                    if left > 0.0 {
                        self.phase = Phase::Wait(left);
                        return None;
                    }
                    self.step_done();
                    if self.ended.is_some() {
                        return None;
                    }
                }
                (Phase::Charging { idle, charged }, MissionStep::Charge(seconds)) => {
                    // A charger that stops (a contact lost) counts as not charging again.
                    let (idle, charged) = if charging {
                        (0.0, charged + dt)
                    } else {
                        (idle + dt, *charged)
                    };
                    if charging && charged >= *seconds {
                        self.step_done();
                        return None;
                    }
                    if idle > self.settings.charge_timeout_s {
                        let why = AbortReason::NotCharging {
                            timeout_s: self.settings.charge_timeout_s,
                        };
                        let at = self.step_at(self.index);
                        self.end(Outcome::Aborted(AbortReason::Step(at, Box::new(why))));
                        return None;
                    }
                    self.phase = Phase::Charging { idle, charged };
                    return None;
                }
                _ => return None,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings(dock: bool) -> MissionSettings {
        MissionSettings {
            speed_mps: 0.5,
            dock: dock.then_some(GoalPose {
                x: 1.0,
                y: 2.0,
                yaw: 0.0,
            }),
            charge_timeout_s: 10.0,
        }
    }

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_micros(ms * 1000)
    }

    #[test]
    fn steps_run_in_order_on_results_timers_and_the_bms() {
        let steps = vec![
            MissionStep::MoveTo(vec![(1.0, 1.0)]),
            MissionStep::Wait(2.0),
            MissionStep::Cutter(true),
            MissionStep::Coverage(vec![(0.0, 0.0), (5.0, 0.0)]),
            MissionStep::Cutter(false),
            MissionStep::Charge(0.0),
        ];
        let mut m = Mission::new(steps, settings(true), None);
        assert_eq!(
            m.tick(at(0), false),
            Some(Request::Path(vec![(1.0, 1.0)], 0.5))
        );
        m.started(7);
        assert_eq!(m.tick(at(10), false), None);
        // Another motion's end is not this step's.
        m.motion_ended(6, &Outcome::Succeeded);
        assert_eq!(m.motion(), Some(7));
        m.motion_ended(7, &Outcome::Succeeded);
        assert_eq!(m.tick(at(20), false), None);
        assert_eq!(m.tick(at(1_000), false), None);
        // Paused, the wait stands still.
        m.pause();
        assert_eq!(m.tick(at(5_000), false), None);
        m.resume();
        assert_eq!(m.tick(at(5_010), false), None);
        assert_eq!(m.tick(at(6_100), false), Some(Request::Cutter(true)));
        assert_eq!(
            m.tick(at(6_110), false),
            Some(Request::Path(vec![(0.0, 0.0), (5.0, 0.0)], 0.5))
        );
        m.started(8);
        m.motion_ended(8, &Outcome::Succeeded);
        assert_eq!(m.tick(at(6_120), false), Some(Request::Cutter(false)));
        let Some(Request::Goal(dock)) = m.tick(at(6_130), false) else {
            panic!("to the dock");
        };
        assert_eq!((dock.x, dock.y), (1.0, 2.0));
        m.started(9);
        m.motion_ended(9, &Outcome::Succeeded);
        assert_eq!(m.tick(at(7_000), false), None);
        assert_eq!(m.ended(), None);
        assert_eq!(m.tick(at(8_000), true), None);
        assert_eq!(m.ended(), Some(&Outcome::Succeeded));
        let events: Vec<String> = m.take_events().iter().map(ToString::to_string).collect();
        assert_eq!(events.len(), 13, "{events:?}");
        assert_eq!(events[12], "mission succeeded");
    }

    #[test]
    fn instant_steps_spread_over_ticks_and_the_end_comes_last() {
        let n = 20;
        let mut m = Mission::new(vec![MissionStep::Wait(0.0); n], settings(false), None);
        let mut per_tick = Vec::new();
        for i in 0..10 {
            assert_eq!(m.tick(at(i * 10), false), None);
            // A second call in the same tick (after the cutter) starts nothing more.
            assert_eq!(m.tick(at(i * 10), false), None);
            per_tick.push(m.take_events());
            if m.ended().is_some() {
                break;
            }
        }
        let starts: Vec<usize> = per_tick
            .iter()
            .map(|e| {
                e.iter()
                    .filter(|e| matches!(e, MissionEvent::StepStarted(..)))
                    .count()
            })
            .collect();
        assert_eq!(starts, [8, 8, 4]);
        let last = per_tick.last().and_then(|e| e.last());
        assert_eq!(last, Some(&MissionEvent::Ended(Outcome::Succeeded)));
    }

    #[test]
    fn a_failed_step_ends_it_and_charging_times_out_without_the_bms() {
        let mut m = Mission::new(
            vec![
                MissionStep::MoveTo(vec![(1.0, 1.0)]),
                MissionStep::Wait(1.0),
            ],
            settings(true),
            None,
        );
        m.tick(at(0), false);
        m.started(1);
        let lost = AbortReason::LocalisationLost(super::super::outcome::LostDuring::Goal);
        m.motion_ended(1, &Outcome::Aborted(lost));
        assert_eq!(
            m.ended().map(ToString::to_string).as_deref(),
            Some("aborted: step 0 (MOVE_TO_POSITION): localisation lost during the goal")
        );
        assert_eq!(m.tick(at(10), false), None);

        let mut m = Mission::new(vec![MissionStep::Charge(30.0)], settings(true), None);
        assert!(matches!(m.tick(at(0), false), Some(Request::Goal(_))));
        m.started(2);
        m.motion_ended(2, &Outcome::Succeeded);
        for s in 1..=11 {
            m.tick(at(s * 1_000), false);
        }
        assert!(
            matches!(m.ended(), Some(Outcome::Aborted(why)) if matches!(why.root(), AbortReason::NotCharging { .. })),
            "{:?}",
            m.ended()
        );

        // Charging that stops half way (a contact lost) fails after the timeout too.
        let mut m = Mission::new(vec![MissionStep::Charge(30.0)], settings(true), None);
        m.tick(at(0), false);
        m.started(3);
        m.motion_ended(3, &Outcome::Succeeded);
        for s in 1..=5 {
            m.tick(at(s * 1_000), true);
        }
        for s in 6..=15 {
            m.tick(at(s * 1_000), false);
        }
        assert_eq!(
            m.ended(),
            None,
            "10 s without charging: still within the timeout"
        );
        m.tick(at(16_500), false);
        assert!(
            matches!(m.ended(), Some(Outcome::Aborted(why)) if matches!(why.root(), AbortReason::NotCharging { .. })),
            "{:?}",
            m.ended()
        );

        let mut m = Mission::new(vec![MissionStep::Charge(0.0)], settings(false), None);
        assert_eq!(m.tick(at(0), false), None);
        assert!(
            matches!(m.ended(), Some(Outcome::Aborted(why)) if *why.root() == AbortReason::NoDock),
            "{:?}",
            m.ended()
        );
    }
}
