//! One CiA 402 node on the bus, sans-IO: boot, set-up over SDO, PDO configuration, NMT start,
//! the controlword sequence, target velocity out, feedback in, and the watchdogs.
//!
//! The node reaches "running" (NMT operational, set up, power stage switched on) by itself
//! and retries while the node is silent. It takes the power stage where the owner asks
//! (enabled, switched on, quick stop, disabled). A fault — a lost heartbeat, stale feedback,
//! a drive fault, an EMCY, a failed SDO — is latched and reported; the target drops to zero
//! and the drive is not enabled again until the owner resets the fault, which the safety
//! supervisor asks for only on a deliberate act (docs/safety.md). A drive in Fault is reset by
//! the CiA 402 handshake: bit 7 of the controlword low for a cycle, then the rising edge, on
//! every attempt; the fault stays latched until the statusword leaves Fault, and the attempts
//! are bounded.
//!
//! This file holds the node's state, what the owner asks of it, and the dispatch of frames
//! and timers; each job has its own submodule: `boot` (NMT), `setup` (the SDO set-up list),
//! `feedback` (TPDOs, SDO answers, listen-only decoding), `command` (RPDOs or SDO writes),
//! `fault` (faults and the reset handshake), `watchdog` and `stop`.

mod boot;
mod command;
mod fault;
mod feedback;
mod setup;
mod stop;
mod watchdog;

use std::time::Duration;

use command::period;

pub use fault::DriveFault;
use fault::FaultReset;

use super::profile::{DriveProfile, Transport};
use super::state::{DriveState, Goal, next_controlword};
use crate::devices::can::Frame;
use crate::devices::canopen::emcy::Emcy;
use crate::devices::canopen::nmt::{NmtCommand, NmtState};
use crate::devices::canopen::pdo::PdoMapping;
use crate::devices::canopen::sdo::{
    SdoClient, SdoOutcome, SdoRequest, SdoResponse, decode_response,
};
use crate::devices::canopen::{Cob, NodeId, rpdo_cob_id, tpdo_cob_id};
use crate::time::Timestamp;

/// Per-node settings from the vehicle configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeSettings {
    /// CANopen node id.
    pub node: NodeId,
    /// Heartbeat producer time written to the node, ms.
    pub heartbeat_producer_ms: u16,
    /// Silence after which the node counts as lost.
    pub heartbeat_timeout: Duration,
    /// How long each SDO answer may take.
    pub sdo_timeout: Duration,
    /// SDO retries after a timeout.
    pub sdo_retries: u8,
    /// How long to wait for the boot-up message before resetting the node again.
    pub boot_timeout: Duration,
    /// How long the enable sequence may take.
    pub enable_timeout: Duration,
    /// No feedback (TPDO or SDO poll answer) from an axis for this long is a fault.
    pub feedback_timeout: Duration,
    /// Fault reset attempts (rising edges) before giving up.
    pub reset_attempts: u8,
    /// How long each attempt waits for the statusword to leave Fault.
    pub reset_wait: Duration,
    /// chassisd's own node id: the heartbeat the drive consumes.
    pub master_node: NodeId,
    /// Silence from chassisd after which the drive stops by itself (written to the drive).
    pub master_timeout: Duration,
    /// The SYNC period chassisd produces (written to drives that watch SYNC).
    pub sync_period: Duration,
}

/// Where the node is in its life cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Not started, or the interface is down.
    Offline,
    /// Reset sent; waiting for the boot-up message.
    Booting {
        /// When the last reset was sent.
        since: Timestamp,
        /// Resets sent so far.
        attempts: u32,
    },
    /// Writing the set-up objects.
    Configuring,
    /// Operational: feedback flows and the controlword follows the enable request.
    Running,
}

/// Feedback of one axis, in the drive's own numbers.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AxisFeedback {
    /// Statusword.
    pub statusword: Option<u16>,
    /// Actual velocity, drive units.
    pub velocity: Option<i32>,
    /// Actual position, encoder counts.
    pub position: Option<i32>,
    /// When the last value arrived.
    pub rx: Option<Timestamp>,
    /// When the last actual velocity arrived.
    pub velocity_rx: Option<Timestamp>,
}

/// Counters of a node.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NodeStats {
    /// Heartbeats received.
    pub heartbeats: u64,
    /// TPDOs received.
    pub tpdos: u64,
    /// TPDOs shorter than their mapping.
    pub short_tpdos: u64,
    /// EMCY messages received.
    pub emcys: u64,
    /// Boot attempts (NMT resets sent).
    pub resets: u64,
    /// Fault reset edges sent.
    pub fault_resets: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tag {
    Setup(usize),
    Controlword(u16),
    Target,
    /// A read of statusword, velocity or position.
    Feedback,
}

/// A CiA 402 drive node.
#[derive(Debug, Clone)]
pub struct DriveNode {
    settings: NodeSettings,
    profile: DriveProfile,
    tpdos: Vec<(u32, PdoMapping)>,
    rpdos: Vec<(u32, PdoMapping)>,
    setup: Vec<SdoRequest>,
    sdo: SdoClient<Tag>,
    phase: Phase,
    fault: Option<DriveFault>,
    /// The fault reset handshake under way.
    reset: Option<FaultReset>,
    /// When the node last became running.
    running_since: Option<Timestamp>,
    nmt: Option<NmtState>,
    last_heartbeat: Option<Timestamp>,
    axes: Vec<AxisFeedback>,
    goal: Goal,
    enable_asked_at: Option<Timestamp>,
    targets: Vec<i32>,
    sent_targets: Option<Vec<i32>>,
    controlword: u16,
    /// Last controlword the node confirmed (SDO) or was sent (RPDO).
    sent_controlword: Option<u16>,
    /// A controlword write waiting for its SDO answer.
    queued_controlword: Option<u16>,
    next_poll: Timestamp,
    next_command: Timestamp,
    last_emcy: Option<Emcy>,
    /// Listen only: decode what passes on the bus, never transmit.
    monitor: bool,
    stats: NodeStats,
}

impl DriveNode {
    /// A node, offline until [`DriveNode::start`].
    pub fn new(settings: NodeSettings, profile: DriveProfile) -> Self {
        let node = settings.node;
        let tpdos = profile
            .tpdo_mappings()
            .into_iter()
            .filter(|_| profile.feedback.mode == Transport::Pdo)
            .map(|(n, m, _)| (tpdo_cob_id(n, node), m))
            .collect();
        let rpdos = profile
            .rpdo_mappings()
            .into_iter()
            .filter(|_| profile.command.mode == Transport::Pdo)
            .map(|(n, m)| (rpdo_cob_id(n, node), m))
            .collect();
        let setup = setup::setup_writes(&settings, &profile);
        let axes = usize::from(profile.axes);
        Self {
            sdo: SdoClient::new(node, settings.sdo_timeout, settings.sdo_retries),
            settings,
            tpdos,
            rpdos,
            setup,
            profile,
            phase: Phase::Offline,
            fault: None,
            reset: None,
            running_since: None,
            nmt: None,
            last_heartbeat: None,
            axes: vec![AxisFeedback::default(); axes],
            goal: Goal::Standby,
            enable_asked_at: None,
            targets: vec![0; axes],
            sent_targets: None,
            controlword: 0,
            sent_controlword: None,
            queued_controlword: None,
            next_poll: Timestamp::default(),
            next_command: Timestamp::default(),
            last_emcy: None,
            monitor: false,
            stats: NodeStats::default(),
        }
    }

    /// Listen-only mode: the node is never started and sends nothing; feedback is taken
    /// from whatever passes on the bus, SDO answers to another master included.
    pub fn set_monitor(&mut self, on: bool) {
        self.monitor = on;
    }

    /// The node id.
    pub fn node(&self) -> NodeId {
        self.settings.node
    }

    /// The profile.
    pub fn profile(&self) -> &DriveProfile {
        &self.profile
    }

    /// The life-cycle phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<DriveFault> {
        self.fault
    }

    /// The last EMCY received (also after it was reset).
    pub fn last_emcy(&self) -> Option<Emcy> {
        self.last_emcy
    }

    /// The NMT state from the last heartbeat.
    pub fn nmt_state(&self) -> Option<NmtState> {
        self.nmt
    }

    /// Feedback per axis.
    pub fn axes(&self) -> &[AxisFeedback] {
        &self.axes
    }

    /// The power state of the node: the least advanced axis, or fault if any axis faults.
    pub fn drive_state(&self) -> Option<DriveState> {
        let mut worst: Option<DriveState> = None;
        for axis in &self.axes {
            let state = DriveState::from_statusword(axis.statusword?);
            worst = Some(match worst {
                None => state,
                Some(w) if w.is_fault() => w,
                Some(_) if state.is_fault() => state,
                Some(w) if rank(state) < rank(w) => state,
                Some(w) => w,
            });
        }
        worst
    }

    /// Whether the power stage is enabled on every axis.
    pub fn is_enabled(&self) -> bool {
        self.drive_state() == Some(DriveState::OperationEnabled)
    }

    /// Whether the node is running and has no latched fault.
    pub fn is_ready(&self) -> bool {
        self.phase == Phase::Running && self.fault.is_none()
    }

    /// Whether a fault reset handshake is under way.
    pub fn is_resetting(&self) -> bool {
        self.reset.is_some()
    }

    /// Counters.
    pub fn stats(&self) -> NodeStats {
        self.stats
    }

    /// SDO counters.
    pub fn sdo_stats(&self) -> crate::devices::canopen::sdo::SdoStats {
        self.sdo.stats()
    }

    /// Sets what the owner wants: where the power stage should go, and each axis's target
    /// in motor r/min. Targets are ignored (zero is sent) unless enabled and fault-free; a
    /// latched fault turns an enable into a quick stop.
    pub fn command(&mut self, t: Timestamp, goal: Goal, motor_rpm: &[f64]) {
        let goal = match goal {
            Goal::Enabled if self.fault.is_some() => Goal::QuickStop,
            other => other,
        };
        let enable = goal == Goal::Enabled;
        // The enable sequence is timed from when the node could first carry it out.
        if enable
            && self.enable_asked_at.is_none()
            && self.phase == Phase::Running
            && self.drive_state().is_some()
        {
            self.enable_asked_at = Some(t);
        }
        if !enable {
            self.enable_asked_at = None;
        }
        self.goal = goal;
        let scale = self.profile.units.target_velocity_per_rpm;
        let combined = self.profile.objects.combined_target_velocity.is_some();
        for (i, target) in self.targets.iter_mut().enumerate() {
            let rpm = motor_rpm.get(i).copied().unwrap_or(0.0);
            let raw = if enable && rpm.is_finite() {
                rpm * scale
            } else {
                0.0
            };
            let (lo, hi) = if combined {
                (f64::from(i16::MIN), f64::from(i16::MAX))
            } else {
                (f64::from(i32::MIN), f64::from(i32::MAX))
            };
            *target = raw.round().clamp(lo, hi) as i32;
        }
    }

    /// Handles a frame from the bus.
    pub fn on_frame(&mut self, t: Timestamp, frame: &Frame, out: &mut Vec<Frame>) {
        match Cob::of(frame) {
            Cob::Heartbeat(n) if n == self.settings.node => self.on_heartbeat(t, frame, out),
            Cob::SdoResponse(n) if n == self.settings.node && self.monitor => {
                if let Ok(SdoResponse::Data(addr, data)) = decode_response(frame) {
                    self.observe(t, addr, data);
                }
            }
            Cob::SdoResponse(n) if n == self.settings.node => {
                if let Some(outcome) = self.sdo.on_response(t, frame, out) {
                    self.on_sdo(t, outcome, out);
                }
            }
            Cob::Emcy(n) if n == self.settings.node => {
                if let Ok(emcy) = Emcy::decode(frame) {
                    self.stats.emcys += 1;
                    self.last_emcy = Some(emcy);
                    if !emcy.is_reset() {
                        self.raise(DriveFault::Emcy(emcy));
                    }
                }
            }
            Cob::Tpdo(_, n) if n == self.settings.node => self.on_tpdo(t, frame),
            _ => {}
        }
    }

    fn on_sdo(&mut self, t: Timestamp, outcome: SdoOutcome<Tag>, out: &mut Vec<Frame>) {
        match outcome {
            SdoOutcome::Done { tag, data, .. } => match (tag, data) {
                (Tag::Setup(i), _) if i + 1 == self.setup.len() => self.finish_setup(t, out),
                (Tag::Controlword(cw), _) => {
                    self.sent_controlword = Some(cw);
                    self.queued_controlword = None;
                    // See at once where the drive went.
                    self.sdo.push(
                        SdoRequest::Read(self.profile.objects.statusword),
                        Tag::Feedback,
                    );
                }
                (Tag::Feedback, Some(d)) => {
                    if let SdoOutcome::Done { request, .. } = outcome {
                        self.observe(t, request.address(), d);
                    }
                }
                _ => {}
            },
            SdoOutcome::Aborted { tag, request, code } => {
                self.raise(DriveFault::SdoAbort {
                    object: request.address(),
                    code,
                });
                if let Tag::Controlword(_) = tag {
                    self.queued_controlword = None;
                }
                // A refused set-up write is reported; the node still goes on to run.
                if tag == Tag::Setup(self.setup.len() - 1) {
                    self.finish_setup(t, out);
                }
            }
            SdoOutcome::TimedOut { request, .. } => {
                self.raise(DriveFault::SdoTimeout {
                    object: request.address(),
                });
                // The node stopped answering: contact it again from the start.
                self.start(t, out);
            }
        }
    }

    /// Runs timers: heartbeat watchdog, boot retries, SDO timeouts, polling and commands.
    pub fn poll(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        self.poll_with(t, out, Commands::Send);
    }

    /// [`Self::poll`] without the commands' periodic refresh, for an owner that sets this
    /// tick's command next and sends it with [`Self::flush_command`]: a refresh sent first
    /// would repeat the last tick's targets on the bus in the very instant they change.
    pub fn poll_timers(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        self.poll_with(t, out, Commands::Hold);
    }

    fn poll_with(&mut self, t: Timestamp, out: &mut Vec<Frame>, commands: Commands) {
        match self.phase {
            Phase::Offline => return,
            Phase::Booting { since, attempts } => {
                if t.saturating_since(since) >= self.settings.boot_timeout {
                    self.stats.resets += 1;
                    out.push(NmtCommand::ResetCommunication.frame(Some(self.settings.node)));
                    self.phase = Phase::Booting {
                        since: t,
                        attempts: attempts.saturating_add(1),
                    };
                }
                return;
            }
            Phase::Configuring | Phase::Running => {}
        }
        if self.check_heartbeat(t, out) {
            return;
        }
        if self.phase == Phase::Running {
            self.run(t, out, commands);
        }
        self.poll_sdo(t, out);
    }

    /// Sends a command set by [`Self::command`] since the last poll now, rather than at the
    /// next poll a control period later. Timers are not advanced twice: at the poll's own
    /// time everything but a changed command is a no-op.
    pub fn flush_command(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if self.phase == Phase::Running {
            self.run(t, out, Commands::Send);
        }
    }

    fn poll_sdo(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if let Some(outcome) = self.sdo.poll(t, out) {
            self.on_sdo(t, outcome, out);
        }
    }

    fn run(&mut self, t: Timestamp, out: &mut Vec<Frame>, commands: Commands) {
        self.check_feedback(t);
        let state = self.drive_state();
        self.check_enable(t, state);
        if let Some(state) = state {
            match self.reset {
                Some(reset) => self.step_reset(t, state, reset),
                None => {
                    if let Some(cw) = next_controlword(state, self.goal) {
                        self.controlword = cw;
                    }
                }
            }
        }
        if self.goal != Goal::Enabled || !self.is_enabled() {
            self.targets.iter_mut().for_each(|x| *x = 0);
        }
        // Nothing is commanded until the drive's state is known.
        if state.is_some() && commands == Commands::Send {
            match self.profile.command.mode {
                Transport::Pdo => self.send_rpdos(t, out),
                Transport::Sdo => self.send_sdo_commands(t),
            }
        }
        if self.profile.feedback.mode == Transport::Sdo && t >= self.next_poll {
            self.next_poll = t.saturating_add(period(self.profile.feedback.poll_hz));
            // Skip a round rather than pile up requests when the node is slow.
            if self.sdo.backlog() <= 1 {
                self.request_feedback();
            }
        }
    }
}

/// Whether a poll sends the commands (due refreshes and changes) or leaves them to a flush.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Commands {
    Send,
    Hold,
}

/// Order of states on the way to operation enabled.
fn rank(state: DriveState) -> u8 {
    match state {
        DriveState::Fault | DriveState::FaultReactionActive => 0,
        DriveState::NotReadyToSwitchOn => 1,
        DriveState::SwitchOnDisabled | DriveState::QuickStopActive => 2,
        DriveState::ReadyToSwitchOn => 3,
        DriveState::SwitchedOn => 4,
        DriveState::OperationEnabled => 5,
    }
}
