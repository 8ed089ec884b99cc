//! The safety supervisor: one explicit state machine that decides whether the drive train may
//! move. It runs the command and control-link watchdogs and watches the e-stop inputs; it
//! latches a stop with its reason on any fault, and it re-arms (and asks for drive fault
//! resets) only on a deliberate act once every cause has cleared (docs/safety.md).
//!
//! States and transitions (`t` is the core's time; nothing here reads a clock):
//!
//! | state     | event                                   | next      |
//! |-----------|-----------------------------------------|-----------|
//! | Standby   | velocity command (any), or a move's velocity | Armed |
//! | Standby, Armed | a cause becomes active             | Latched   |
//! | Armed     | operator stop                           | Latched   |
//! | Latched   | zero velocity or reset, no cause, no drive fault | Armed |
//! | Latched   | zero velocity or reset, no cause, drive faults   | Resetting |
//! | Latched   | non-zero velocity                       | Latched (refused) |
//! | Latched   | a move's velocity, zero or not          | Latched (refused) |
//! | Resetting | every drive fault cleared               | Armed     |
//! | Resetting | a cause, or the reset failed or timed out | Latched |
//!
//! A cause is a condition that holds on its own: a drive fault, a CAN interface down, a lost
//! control link, an e-stop input pressed or silent, the software e-stop engaged, a zone in
//! the braking way (which the core judges each tick, and which clears once the vehicle
//! stands or turns away). An operator stop latches without a lasting cause.

use std::fmt;
use std::time::Duration;

use super::feedback::ChassisFeedback;
pub use crate::devices::estop::EStopInput;
use crate::time::Timestamp;

/// How long a latched stop keeps the drives in quick stop before disabling them.
pub const DEFAULT_QUICK_STOP: Duration = Duration::from_secs(1);

/// Settings of the supervisor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyConfig {
    /// A velocity command older than this is void.
    pub cmd_timeout: Duration,
    /// After a latch, the drives stay in quick stop this long, then are disabled.
    pub quick_stop: Duration,
    /// A fault reset that has not cleared every drive fault by then has failed.
    pub reset_timeout: Duration,
    /// The controlling client's heartbeat, when a protocol has one.
    pub control_link: Option<ControlLinkConfig>,
    /// Power the drives (holding zero) before the first command.
    pub enable_on_start: bool,
}

/// The control-link watchdog.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlLinkConfig {
    /// Silence after which the link is lost.
    pub timeout: Duration,
    /// Watch from start: no heartbeat within `timeout` of start is a lost link too. Otherwise
    /// the watchdog starts with the first heartbeat.
    pub required_from_start: bool,
}

/// Why the supervisor holds the wheels at zero.
#[derive(Debug, Clone, PartialEq)]
pub enum Cause {
    /// A drive reports a fault (its own, a lost heartbeat, stale feedback, ...).
    Drive {
        /// The drive's name.
        name: String,
        /// The fault, described.
        fault: String,
    },
    /// A CAN interface carrying drives is down.
    BusDown,
    /// The controlling client's heartbeat stopped, or never came though it is required.
    ControlLink {
        /// Whether a heartbeat was ever received.
        ever_heard: bool,
    },
    /// An e-stop input is pressed, or silent for longer than its timeout.
    EStop {
        /// The input's name.
        name: String,
        /// Silent rather than pressed.
        silent: bool,
    },
    /// The software e-stop is engaged.
    SoftwareEStop,
    /// An operator asked for a stop (PAUSE, /navi_stop).
    Operator,
    /// The vehicle's braking way (its footprint grown by the position's σ) meets a zone.
    Zone {
        /// The zone's kind (`boundary`, `keep_out`, `wall`).
        kind: &'static str,
        /// Its name.
        name: String,
    },
    /// A fault reset did not clear a drive's fault.
    ResetFailed {
        /// The drive's name.
        name: String,
        /// The fault that stayed.
        fault: String,
    },
}

impl fmt::Display for Cause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Drive { name, fault } => write!(f, "{name}: {fault}"),
            Self::BusDown => write!(f, "CAN interface down"),
            Self::ControlLink { ever_heard: true } => write!(f, "control link heartbeat lost"),
            Self::ControlLink { ever_heard: false } => {
                write!(f, "no control link heartbeat yet (it is required)")
            }
            Self::EStop {
                name,
                silent: false,
            } => write!(f, "emergency stop {name} pressed"),
            Self::EStop { name, silent: true } => {
                write!(f, "emergency stop {name} silent (counts as pressed)")
            }
            Self::SoftwareEStop => write!(f, "software emergency stop engaged"),
            Self::Operator => write!(f, "stopped by the operator"),
            Self::Zone { kind, name } => {
                write!(f, "the {kind} zone {name:?} is in the braking way")
            }
            Self::ResetFailed { name, fault } => {
                write!(f, "{name}: fault reset failed, still {fault}")
            }
        }
    }
}

impl Cause {
    /// What clears the cause, so that a deliberate act may then re-arm (`None`: the act
    /// itself does, as it resets drive faults).
    pub fn remedy(&self) -> Option<&'static str> {
        match self {
            Self::Drive { .. } | Self::Operator | Self::ResetFailed { .. } => None,
            Self::BusDown => Some("bring the CAN interface up"),
            Self::ControlLink { ever_heard: true } => Some(
                "send heartbeats again (root heartbeat/set, with the clientId of \
                 mqtt.root.heartbeat_client_id when it is set)",
            ),
            Self::ControlLink { ever_heard: false } => Some(
                "send heartbeats (root heartbeat/set, with the clientId of \
                 mqtt.root.heartbeat_client_id when it is set)",
            ),
            Self::EStop { silent: false, .. } => Some("release the emergency stop"),
            Self::EStop { silent: true, .. } => Some("restore the emergency stop's signal"),
            Self::SoftwareEStop => Some("release the software emergency stop"),
            Self::Zone { .. } => Some("wait until the vehicle stands"),
        }
    }
}

/// Why a command was refused by the supervisor. Each says what to do, in order.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// Latched: only a zero velocity command or a reset re-arms, once what holds (`first`,
    /// its remedy) has cleared.
    #[error(
        "stopped ({reason}): {}send a zero velocity command or a reset to re-arm, then drive again",
        first.as_deref().map(|f| format!("{f}, then ")).unwrap_or_default()
    )]
    Latched {
        /// Why it latched.
        reason: String,
        /// What must clear first, when a cause still holds.
        first: Option<String>,
    },
    /// A deliberate act came while a cause is still there.
    #[error("cannot re-arm while {cause}: {remedy} first")]
    CauseActive {
        /// The cause that holds.
        cause: String,
        /// What clears it.
        remedy: &'static str,
    },
    /// A fault reset is under way.
    #[error("a fault reset is under way; drive again once it is done")]
    Resetting,
}

/// The drives' power stage as the supervisor wants it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Power {
    /// Switched on without torque (before the first command when not enabled on start).
    Standby,
    /// Operation enabled: the drives follow their targets.
    Enabled,
    /// Quick stop: the drives brake on their own quick-stop ramp.
    QuickStop,
    /// Power stage off (switch on disabled).
    Disabled,
}

/// The supervisor's state.
#[derive(Debug, Clone, PartialEq)]
pub enum State {
    /// Never commanded; the drives are not enabled.
    Standby,
    /// Motion allowed.
    Armed,
    /// Stopped for `reason` since `since`; needs every cause cleared and a deliberate act.
    Latched {
        /// The cause, the most recent one while several came.
        reason: Cause,
        /// When the stop latched.
        since: Timestamp,
    },
    /// A deliberate act came with drive faults left: the drives are being reset.
    Resetting {
        /// Why the vehicle was stopped.
        reason: Cause,
        /// When the stop latched.
        since: Timestamp,
        /// When the reset was asked for.
        started: Timestamp,
    },
}

/// What the supervisor decides at a control tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// The power stage wanted.
    pub power: Power,
    /// The velocity the vehicle may follow now (m/s, rad/s), when it may move.
    pub target: Option<(f64, f64)>,
    /// Why the vehicle is held at zero, when a command asked for motion and is not followed.
    pub stop: Option<StopKind>,
    /// Reset the drives' latched faults now (one tick, on a deliberate act).
    pub reset_faults: bool,
}

/// Why the wheels hold zero.
#[derive(Debug, Clone, PartialEq)]
pub enum StopKind {
    /// No fresh command within the command timeout (not a fault).
    CommandTimeout,
    /// A latched stop, or a reset under way.
    Latched(Cause),
}

/// The safety supervisor.
#[derive(Debug, Clone)]
pub struct Safety {
    config: SafetyConfig,
    state: State,
    /// The last velocity command accepted: time, m/s, rad/s.
    command: Option<(Timestamp, f64, f64)>,
    /// The first tick's time: the control-link watchdog of `required_from_start` runs from it.
    started: Option<Timestamp>,
    last_heartbeat: Option<Timestamp>,
    software_estop: bool,
    reset_request: bool,
    /// Causes found at the last tick, most important first.
    active: Vec<Cause>,
    /// Drive faults at the last tick: (drive, fault).
    drive_faults: Vec<(String, String)>,
    /// A drive that was not running at the last tick.
    not_running: Option<String>,
    /// Whether any drive was carrying out a fault reset at the last tick.
    drives_resetting: bool,
    /// The zone in the braking way, as the core found it for the next tick.
    zone: Option<Cause>,
}

impl Safety {
    /// A supervisor in standby (or armed, with `enable_on_start`).
    pub fn new(config: SafetyConfig) -> Self {
        Self {
            state: if config.enable_on_start {
                State::Armed
            } else {
                State::Standby
            },
            config,
            command: None,
            started: None,
            last_heartbeat: None,
            software_estop: false,
            reset_request: false,
            active: Vec::new(),
            drive_faults: Vec::new(),
            not_running: None,
            drives_resetting: false,
            zone: None,
        }
    }

    /// The state.
    pub fn state(&self) -> &State {
        &self.state
    }

    /// The latched stop's cause, while latched or resetting.
    pub fn latched(&self) -> Option<&Cause> {
        match &self.state {
            State::Latched { reason, .. } | State::Resetting { reason, .. } => Some(reason),
            State::Standby | State::Armed => None,
        }
    }

    /// Whether the software e-stop is engaged.
    pub fn software_estop(&self) -> bool {
        self.software_estop
    }

    /// Whether the control link's heartbeat is currently lost.
    pub fn control_link_lost(&self) -> bool {
        self.active
            .iter()
            .any(|c| matches!(c, Cause::ControlLink { .. }))
    }

    /// Whether an e-stop (input or software) holds the vehicle.
    pub fn estop_active(&self) -> bool {
        self.active
            .iter()
            .any(|c| matches!(c, Cause::EStop { .. } | Cause::SoftwareEStop))
    }

    /// The velocity command in force at `t` (m/s, rad/s): the last one, while fresh and
    /// followed (armed).
    pub fn command_in_force(&self, t: Timestamp) -> Option<(f64, f64)> {
        let armed = self.state == State::Armed;
        self.command
            .filter(|_| armed && self.command_fresh(t))
            .map(|(_, v, w)| (v, w))
    }

    /// The zone in the vehicle's braking way, judged for the next tick (`None`: none). It is
    /// a cause like the others: it latches, and a deliberate act re-arms only once it is
    /// gone.
    pub fn zone_ahead(&mut self, zone: Option<(&'static str, String)>) {
        self.zone = zone.map(|(kind, name)| Cause::Zone { kind, name });
    }

    /// Whether the last velocity command is younger than the timeout at `t`.
    pub fn command_fresh(&self, t: Timestamp) -> bool {
        self.command
            .is_some_and(|(at, _, _)| t.saturating_since(at) <= self.config.cmd_timeout)
    }

    /// A velocity command (m/s, rad/s), already checked for range. While latched only a zero
    /// command is taken, as the deliberate act that re-arms.
    pub fn velocity(&mut self, t: Timestamp, vx: f64, wz: f64) -> Result<(), Refusal> {
        let zero = vx == 0.0 && wz == 0.0;
        match &self.state {
            State::Standby | State::Armed => {
                self.state = State::Armed;
                self.command = Some((t, vx, wz));
                Ok(())
            }
            State::Latched { reason, .. } if !zero => Err(self.refuse_latched(reason)),
            State::Latched { .. } => {
                self.deliberate(t)?;
                self.command = Some((t, 0.0, 0.0));
                Ok(())
            }
            State::Resetting { .. } if zero => Ok(()),
            State::Resetting { .. } => Err(Refusal::Resetting),
        }
    }

    /// A velocity (m/s, rad/s) proposed by a closed-loop move, already checked for range.
    /// Starting a move is as deliberate as a velocity command, so it arms from standby; it
    /// never re-arms a latched stop, zero or not.
    pub fn autonomous(&mut self, t: Timestamp, vx: f64, wz: f64) -> Result<(), Refusal> {
        self.may_move()?;
        self.state = State::Armed;
        self.command = Some((t, vx, wz));
        Ok(())
    }

    /// Whether a move may drive now: not while latched or resetting.
    pub fn may_move(&self) -> Result<(), Refusal> {
        match &self.state {
            State::Standby | State::Armed => Ok(()),
            State::Latched { reason, .. } => Err(self.refuse_latched(reason)),
            State::Resetting { .. } => Err(Refusal::Resetting),
        }
    }

    /// An explicit reset: re-arms a latched stop once every cause has cleared.
    pub fn reset(&mut self, t: Timestamp) -> Result<(), Refusal> {
        match self.state {
            State::Latched { .. } => self.deliberate(t),
            State::Standby | State::Armed | State::Resetting { .. } => Ok(()),
        }
    }

    /// Forgets the last velocity command (a mode switch): the wheels hold zero.
    pub fn clear_command(&mut self) {
        self.command = None;
    }

    /// An operator's stop: latches at once.
    pub fn operator_stop(&mut self, t: Timestamp) {
        self.latch(t, Cause::Operator);
    }

    /// Engages (latching at once) or releases the software e-stop. Releasing does not re-arm.
    pub fn set_software_estop(&mut self, t: Timestamp, engaged: bool) {
        self.software_estop = engaged;
        if engaged {
            self.latch(t, Cause::SoftwareEStop);
        }
    }

    /// A heartbeat from the controlling client.
    pub fn control_heartbeat(&mut self, t: Timestamp) {
        self.last_heartbeat = Some(t);
    }

    fn latch(&mut self, t: Timestamp, reason: Cause) {
        self.command = None;
        self.reset_request = false;
        self.state = match &self.state {
            // Already stopped: the newest cause is what the operator needs to see.
            State::Latched { since, .. } | State::Resetting { since, .. } => State::Latched {
                reason,
                since: *since,
            },
            State::Standby | State::Armed => State::Latched { reason, since: t },
        };
    }

    /// The refusal of a move while latched for `reason`, naming what must clear first.
    fn refuse_latched(&self, reason: &Cause) -> Refusal {
        Refusal::Latched {
            reason: reason.to_string(),
            first: self
                .holding()
                .map(|(cause, remedy)| format!("{remedy} ({cause})")),
        }
    }

    /// The first cause a deliberate act cannot clear itself, and what clears it.
    fn holding(&self) -> Option<(String, &'static str)> {
        if let Some((cause, remedy)) = self
            .active
            .iter()
            .find_map(|c| c.remedy().map(|remedy| (c, remedy)))
        {
            return Some((cause.to_string(), remedy));
        }
        self.not_running.as_ref().map(|name| {
            (
                format!("drive {name} is not ready (booting or unreachable)"),
                "wait until it answers",
            )
        })
    }

    /// A deliberate act while latched: re-arm, or reset the drives first.
    fn deliberate(&mut self, t: Timestamp) -> Result<(), Refusal> {
        if let Some((cause, remedy)) = self.holding() {
            return Err(Refusal::CauseActive { cause, remedy });
        }
        let State::Latched { reason, since } = &self.state else {
            return Ok(());
        };
        if self.drive_faults.is_empty() {
            self.state = State::Armed;
        } else {
            self.state = State::Resetting {
                reason: reason.clone(),
                since: *since,
                started: t,
            };
            self.reset_request = true;
        }
        Ok(())
    }

    /// The causes that hold at `t`, most important first.
    fn causes(&self, t: Timestamp, feedback: &ChassisFeedback) -> Vec<Cause> {
        let mut causes = Vec::new();
        for input in &feedback.estops {
            let silent = input
                .heard
                .is_none_or(|heard| t.saturating_since(heard) > input.timeout);
            if silent || input.pressed != Some(false) {
                causes.push(Cause::EStop {
                    name: input.name.clone(),
                    silent: silent && input.pressed != Some(true),
                });
            }
        }
        if self.software_estop {
            causes.push(Cause::SoftwareEStop);
        }
        if let Some(zone) = &self.zone {
            causes.push(zone.clone());
        }
        if feedback.bus_down {
            causes.push(Cause::BusDown);
        }
        for d in &feedback.drives {
            if let Some(fault) = &d.fault {
                causes.push(Cause::Drive {
                    name: d.name.clone(),
                    fault: fault.clone(),
                });
            }
        }
        if let Some(link) = self.config.control_link {
            let since = match self.last_heartbeat {
                Some(last) => Some(last),
                None if link.required_from_start => self.started.or(Some(t)),
                None => None,
            };
            if since.is_some_and(|s| t.saturating_since(s) > link.timeout) {
                causes.push(Cause::ControlLink {
                    ever_heard: self.last_heartbeat.is_some(),
                });
            }
        }
        causes
    }

    /// One control tick at `t` with the drives' feedback: evaluates every cause, moves the
    /// state, and says what the drives may do.
    pub fn tick(&mut self, t: Timestamp, feedback: &ChassisFeedback) -> Verdict {
        self.started.get_or_insert(t);
        self.active = self.causes(t, feedback);
        self.drive_faults = feedback
            .drives
            .iter()
            .filter_map(|d| d.fault.clone().map(|f| (d.name.clone(), f)))
            .collect();
        self.not_running = feedback
            .drives
            .iter()
            .find(|d| !d.running)
            .map(|d| d.name.clone());
        let resetting_before = self.drives_resetting;
        self.drives_resetting = feedback.drives.iter().any(|d| d.resetting);
        let first = self.active.first().cloned();
        match self.state.clone() {
            State::Standby | State::Armed => {
                if let Some(cause) = first {
                    self.latch(t, cause);
                }
            }
            State::Latched { reason, since } => {
                // Show the cause that now keeps the vehicle stopped.
                if let Some(cause) =
                    first.filter(|c| !self.active.contains(&reason) && *c != reason)
                {
                    self.state = State::Latched {
                        reason: cause,
                        since,
                    };
                }
            }
            State::Resetting { started, .. } => {
                let other = self
                    .active
                    .iter()
                    .find(|c| !matches!(c, Cause::Drive { .. }))
                    .cloned();
                if let Some(cause) = other {
                    self.latch(t, cause);
                } else if self.drive_faults.is_empty() && self.not_running.is_none() {
                    self.state = State::Armed;
                } else if let Some((name, fault)) = self.drive_faults.first().cloned() {
                    // The drives gave up (they bound their own attempts), or the reset
                    // outlived its time.
                    let gave_up = !self.reset_request
                        && !self.drives_resetting
                        && !resetting_before
                        && t > started;
                    if gave_up || t.saturating_since(started) > self.config.reset_timeout {
                        self.latch(t, Cause::ResetFailed { name, fault });
                    }
                }
            }
        }
        let reset_faults = std::mem::take(&mut self.reset_request);
        let moving = |fb: &ChassisFeedback| {
            [fb.left.velocity_rad_s, fb.right.velocity_rad_s]
                .iter()
                .any(|v| v.is_some_and(|v| v.abs() > 1e-3))
        };
        match &self.state {
            State::Standby => Verdict {
                power: Power::Standby,
                target: None,
                stop: None,
                reset_faults,
            },
            State::Armed => {
                // An expired command, even a zero one still ramping down, stops at once.
                let expired = self.command.is_some() && !self.command_fresh(t);
                Verdict {
                    power: Power::Enabled,
                    target: Some(
                        self.command
                            .filter(|_| !expired)
                            .map_or((0.0, 0.0), |(_, v, w)| (v, w)),
                    ),
                    stop: expired.then_some(StopKind::CommandTimeout),
                    reset_faults,
                }
            }
            State::Latched { reason, since } => {
                let braking = t.saturating_since(*since) < self.config.quick_stop;
                Verdict {
                    power: if braking && moving(feedback) {
                        Power::QuickStop
                    } else {
                        Power::Disabled
                    },
                    target: None,
                    stop: Some(StopKind::Latched(reason.clone())),
                    reset_faults,
                }
            }
            State::Resetting { reason, .. } => Verdict {
                power: Power::Disabled,
                target: None,
                stop: Some(StopKind::Latched(reason.clone())),
                reset_faults,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::feedback::DriveSummary;

    fn config() -> SafetyConfig {
        SafetyConfig {
            cmd_timeout: Duration::from_millis(500),
            quick_stop: DEFAULT_QUICK_STOP,
            reset_timeout: Duration::from_secs(3),
            control_link: None,
            enable_on_start: true,
        }
    }

    fn ms(v: u64) -> Timestamp {
        Timestamp::from_micros(v * 1000)
    }

    fn feedback(fault: Option<&str>) -> ChassisFeedback {
        ChassisFeedback {
            drives: vec![DriveSummary {
                name: "d".into(),
                ready: fault.is_none(),
                running: true,
                enabled: fault.is_none(),
                fault: fault.map(str::to_owned),
                heartbeat_lost: false,
                resetting: false,
            }],
            ..ChassisFeedback::default()
        }
    }

    #[test]
    fn a_fault_latches_and_only_a_deliberate_act_resets_it() {
        let mut s = Safety::new(config());
        s.tick(ms(0), &feedback(None));
        s.velocity(ms(0), 0.5, 0.0).unwrap();
        assert_eq!(s.tick(ms(10), &feedback(None)).target, Some((0.5, 0.0)));
        let v = s.tick(ms(20), &feedback(Some("over-current")));
        assert_eq!(v.target, None);
        assert!(matches!(
            v.stop,
            Some(StopKind::Latched(Cause::Drive { .. }))
        ));
        // A non-zero stream is refused, however long it goes on.
        for i in 3..50 {
            assert!(matches!(
                s.velocity(ms(i * 10), 0.5, 0.0),
                Err(Refusal::Latched { .. })
            ));
            assert!(
                !s.tick(ms(i * 10), &feedback(Some("over-current")))
                    .reset_faults
            );
        }
        // A zero command starts the reset; the drive clears; armed again.
        s.velocity(ms(500), 0.0, 0.0).unwrap();
        let v = s.tick(ms(510), &feedback(Some("over-current")));
        assert!(v.reset_faults);
        assert!(matches!(s.state(), State::Resetting { .. }));
        s.tick(ms(520), &feedback(None));
        assert_eq!(s.state(), &State::Armed);
    }

    #[test]
    fn a_failed_reset_latches_with_its_reason() {
        let mut s = Safety::new(config());
        s.tick(ms(0), &feedback(Some("f")));
        s.reset(ms(5)).unwrap();
        assert!(s.tick(ms(10), &feedback(Some("f"))).reset_faults);
        let mut fb = feedback(Some("f"));
        fb.drives[0].resetting = true;
        s.tick(ms(20), &fb);
        assert!(matches!(s.state(), State::Resetting { .. }));
        // The drive gives up.
        s.tick(ms(30), &feedback(Some("f")));
        s.tick(ms(40), &feedback(Some("f")));
        assert_eq!(
            s.latched().map(ToString::to_string).as_deref(),
            Some("d: fault reset failed, still f")
        );
    }

    /// A supervisor watching a control link of 1 s, `required_from_start` or not.
    fn with_control_link(required_from_start: bool) -> Safety {
        let mut c = config();
        c.control_link = Some(ControlLinkConfig {
            timeout: Duration::from_secs(1),
            required_from_start,
        });
        Safety::new(c)
    }

    #[test]
    fn control_link_required_from_start() {
        let mut s = with_control_link(true);
        s.tick(ms(0), &feedback(None));
        s.tick(ms(1000), &feedback(None));
        assert_eq!(s.state(), &State::Armed);
        s.tick(ms(1010), &feedback(None));
        assert_eq!(s.latched(), Some(&Cause::ControlLink { ever_heard: false }));
        assert!(matches!(
            s.reset(ms(1020)),
            Err(Refusal::CauseActive { .. })
        ));
        s.control_heartbeat(ms(1100));
        s.tick(ms(1110), &feedback(None));
        s.reset(ms(1120)).unwrap();
        assert_eq!(s.state(), &State::Armed);
    }

    /// After a heartbeat loss, each refusal says what to do next, and doing it works.
    #[test]
    fn refusals_after_a_heartbeat_loss_give_advice_that_works() {
        let mut s = with_control_link(false);
        s.control_heartbeat(ms(0));
        s.tick(ms(0), &feedback(None));
        s.velocity(ms(0), 0.3, 0.0).unwrap();
        s.tick(ms(1010), &feedback(None));
        let drive = s.velocity(ms(1020), 0.3, 0.0).unwrap_err().to_string();
        let heartbeats = "send heartbeats again (root heartbeat/set, with the clientId of \
                          mqtt.root.heartbeat_client_id when it is set)";
        assert_eq!(
            drive,
            format!(
                "stopped (control link heartbeat lost): {heartbeats} (control link heartbeat \
                 lost), then send a zero velocity command or a reset to re-arm, then drive \
                 again"
            )
        );
        let rearm = s.velocity(ms(1030), 0.0, 0.0).unwrap_err().to_string();
        assert_eq!(
            rearm,
            format!("cannot re-arm while control link heartbeat lost: {heartbeats} first")
        );
        // As told: heartbeats, then a zero command, then drive.
        s.control_heartbeat(ms(1040));
        s.tick(ms(1050), &feedback(None));
        let drive = s.velocity(ms(1060), 0.3, 0.0).unwrap_err().to_string();
        assert!(
            drive
                .ends_with(": send a zero velocity command or a reset to re-arm, then drive again"),
            "{drive}"
        );
        s.velocity(ms(1070), 0.0, 0.0).unwrap();
        s.velocity(ms(1080), 0.3, 0.0).unwrap();
        assert_eq!(s.state(), &State::Armed);
    }

    #[test]
    fn silent_estop_counts_as_pressed_and_release_needs_an_act() {
        let mut s = Safety::new(config());
        let mut fb = feedback(None);
        fb.estops.push(EStopInput {
            name: "front".into(),
            pressed: None,
            heard: None,
            timeout: Duration::from_millis(200),
        });
        s.tick(ms(0), &fb);
        assert_eq!(
            s.latched(),
            Some(&Cause::EStop {
                name: "front".into(),
                silent: true
            })
        );
        fb.estops[0].pressed = Some(false);
        fb.estops[0].heard = Some(ms(100));
        s.tick(ms(110), &fb);
        assert!(s.latched().is_some(), "released, still latched");
        s.velocity(ms(120), 0.0, 0.0).unwrap();
        s.tick(ms(130), &fb);
        assert_eq!(s.state(), &State::Armed);
        // Silence again.
        s.tick(ms(301), &fb);
        assert!(s.estop_active());
    }
}
