//! One CiA 402 node on the bus, sans-IO: boot, set-up over SDO, PDO configuration, NMT start,
//! the controlword sequence, target velocity out, feedback in, and the watchdogs.
//!
//! The node reaches "running" (NMT operational, set up, power stage switched on) by itself
//! and retries while the node is silent. It takes the power stage where the owner asks
//! (enabled, switched on, quick stop, disabled). A fault — a lost heartbeat, stale feedback,
//! a drive fault, an EMCY, a failed SDO — is latched and reported; the target drops to zero
//! and the drive is not enabled again until the owner resets the fault, which the safety
//! supervisor asks for only on a deliberate act (DESIGN.md §5). A drive in Fault is reset by
//! the CiA 402 handshake: bit 7 of the controlword low for a cycle, then the rising edge, on
//! every attempt; the fault stays latched until the statusword leaves Fault, and the attempts
//! are bounded.

use std::fmt;
use std::time::Duration;

use super::profile::{
    ABORT_CONNECTION_OPTION, COMMUNICATION_CYCLE, CONSUMER_HEARTBEAT, DriveProfile, MasterLoss,
    Transport, ValueType,
};
use super::state::{DriveState, Goal, controlword, next_controlword};
use crate::devices::can::Frame;
use crate::devices::canopen::emcy::Emcy;
use crate::devices::canopen::nmt::{NmtCommand, NmtState};
use crate::devices::canopen::pdo::{PdoMapping, TpdoTrigger};
use crate::devices::canopen::sdo::{
    AbortCode, SdoClient, SdoData, SdoOutcome, SdoRequest, SdoResponse, decode_response,
};
use crate::devices::canopen::{Cob, NodeId, ObjectAddress, rpdo_cob_id, tpdo_cob_id};
use crate::time::Timestamp;

/// Profile velocity mode.
const PROFILE_VELOCITY_MODE: i8 = 3;

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

/// Why a drive stopped. Latched until the owner resets it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DriveFault {
    /// The CAN interface went down.
    LinkDown,
    /// No heartbeat within the timeout.
    HeartbeatLost,
    /// The node rebooted (unexpected boot-up) and lost its set-up.
    Rebooted,
    /// The drive reports a fault in its statusword.
    Drive {
        /// Axis, 0-based.
        axis: usize,
        /// The statusword.
        statusword: u16,
    },
    /// An emergency message.
    Emcy(Emcy),
    /// An SDO transfer was aborted.
    SdoAbort {
        /// The object.
        object: ObjectAddress,
        /// The abort code.
        code: AbortCode,
    },
    /// An SDO transfer got no answer.
    SdoTimeout {
        /// The object.
        object: ObjectAddress,
    },
    /// The enable sequence did not reach operation enabled in time.
    EnableTimeout {
        /// Where it stopped.
        state: DriveState,
    },
    /// No feedback from an axis within the feedback timeout, though the node may still send
    /// heartbeats.
    FeedbackStale {
        /// Axis, 0-based.
        axis: usize,
    },
}

impl DriveFault {
    /// Whether communication with the node is in doubt (as opposed to the drive refusing).
    pub fn is_communication(&self) -> bool {
        matches!(
            self,
            Self::LinkDown | Self::HeartbeatLost | Self::Rebooted | Self::SdoTimeout { .. }
        )
    }
}

impl fmt::Display for DriveFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::LinkDown => write!(f, "CAN interface down"),
            Self::HeartbeatLost => write!(f, "heartbeat lost"),
            Self::Rebooted => write!(f, "node rebooted unexpectedly"),
            Self::Drive { axis, statusword } => {
                write!(
                    f,
                    "drive fault on axis {} (statusword 0x{statusword:04X})",
                    axis + 1
                )
            }
            Self::Emcy(e) => write!(f, "{e}"),
            Self::SdoAbort { object, code } => write!(f, "SDO {object} aborted: {code}"),
            Self::SdoTimeout { object } => write!(f, "SDO {object} timed out"),
            Self::EnableTimeout { state } => write!(f, "enable timed out in state {state}"),
            Self::FeedbackStale { axis } => write!(f, "no feedback from axis {}", axis + 1),
        }
    }
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

/// A fault reset under way: bit 7 low for at least a cycle, then the rising edge, then the
/// statusword must leave Fault within the wait; else the next attempt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct FaultReset {
    /// 1-based.
    attempt: u8,
    step: ResetStep,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ResetStep {
    /// Bit 7 low, since this tick.
    Low(Timestamp),
    /// Bit 7 high (the edge) since this tick.
    Edge(Timestamp),
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
        let setup = setup_writes(&settings, &profile);
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

    /// Starts (or restarts) the node: NMT reset communication, then set-up on boot-up.
    pub fn start(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        self.sdo.clear();
        self.reset = None;
        self.running_since = None;
        self.controlword = 0;
        self.nmt = None;
        self.axes
            .iter_mut()
            .for_each(|a| *a = AxisFeedback::default());
        self.sent_controlword = None;
        self.queued_controlword = None;
        self.sent_targets = None;
        self.phase = Phase::Booting {
            since: t,
            attempts: 1,
        };
        self.stats.resets += 1;
        out.push(NmtCommand::ResetCommunication.frame(Some(self.settings.node)));
    }

    /// The interface went down.
    pub fn link_down(&mut self) {
        if self.phase == Phase::Running && self.fault.is_none() {
            self.fault = Some(DriveFault::LinkDown);
        }
        self.phase = Phase::Offline;
        self.sdo.clear();
        self.last_heartbeat = None;
    }

    /// The interface is (back) up: contact the node again. A latched fault stays latched.
    pub fn link_up(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if self.phase == Phase::Offline {
            self.start(t, out);
        }
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

    /// Resets a latched fault (the owner's deliberate act). A drive in Fault gets the reset
    /// handshake and its fault stays latched until the statusword leaves Fault; other faults
    /// clear at once if their condition is gone. Only a running node can be reset; returns
    /// whether the fault is cleared or being reset.
    pub fn reset_fault(&mut self, t: Timestamp) -> bool {
        if self.phase != Phase::Running {
            return self.fault.is_none();
        }
        if self.drive_state().is_some_and(DriveState::is_fault) {
            if self.reset.is_none() {
                self.reset = Some(FaultReset {
                    attempt: 1,
                    step: ResetStep::Low(t),
                });
            }
            return true;
        }
        if let Some(DriveFault::FeedbackStale { axis }) = self.fault
            && self.feedback_age(t, axis) > self.settings.feedback_timeout
        {
            return false;
        }
        self.fault = None;
        true
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

    fn on_heartbeat(&mut self, t: Timestamp, frame: &Frame, out: &mut Vec<Frame>) {
        let Some(state) = frame
            .data()
            .first()
            .and_then(|b| NmtState::from_heartbeat(*b))
        else {
            return;
        };
        self.stats.heartbeats += 1;
        self.nmt = Some(state);
        self.last_heartbeat = Some(t);
        match (self.phase, state) {
            (Phase::Booting { .. }, _) => self.configure(t, out),
            // A second boot-up while setting up (a repeated reset): start the set-up over.
            (Phase::Configuring, NmtState::BootUp) => self.configure(t, out),
            (Phase::Running, NmtState::BootUp) => {
                // It lost its set-up while running: stop, and set it up again.
                self.raise(DriveFault::Rebooted);
                self.configure(t, out);
            }
            _ => {}
        }
    }

    fn configure(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        self.sdo.clear();
        self.queued_controlword = None;
        self.sent_controlword = None;
        self.phase = Phase::Configuring;
        for (i, request) in self.setup.iter().enumerate() {
            self.sdo.push(*request, Tag::Setup(i));
        }
        self.poll_sdo(t, out);
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

    /// Takes an object value seen on the bus (listen-only mode).
    fn observe(&mut self, t: Timestamp, addr: ObjectAddress, data: SdoData) {
        let objects = &self.profile.objects;
        if addr == objects.statusword {
            let value = data.as_u32();
            if objects.statusword_bits == 32 {
                self.set_statusword(0, (value & 0xFFFF) as u16, t);
                self.set_statusword(1, (value >> 16) as u16, t);
            } else {
                self.set_statusword(0, value as u16, t);
            }
            return;
        }
        for (a, axis) in self.axes.iter_mut().enumerate() {
            if objects.actual_velocity.get(a) == Some(&addr) {
                axis.velocity = Some(data.as_i32());
                axis.rx = Some(t);
            }
            if objects.actual_position.get(a) == Some(&addr) {
                axis.position = Some(data.as_i32());
                axis.rx = Some(t);
            }
        }
    }

    fn finish_setup(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        out.push(NmtCommand::Start.frame(Some(self.settings.node)));
        self.phase = Phase::Running;
        self.running_since = Some(t);
        self.next_poll = t;
        self.next_command = t;
        // Feedback first, so the controlword follows the drive's real state.
        self.request_feedback();
    }

    fn set_statusword(&mut self, axis: usize, sw: u16, t: Timestamp) {
        if let Some(a) = self.axes.get_mut(axis) {
            a.statusword = Some(sw);
            a.rx = Some(t);
        }
        if DriveState::from_statusword(sw).is_fault() {
            self.raise(DriveFault::Drive {
                axis,
                statusword: sw,
            });
        }
    }

    fn on_tpdo(&mut self, t: Timestamp, frame: &Frame) {
        let Some((_, mapping)) = self.tpdos.iter().find(|(cob, _)| *cob == frame.id()) else {
            return;
        };
        let Some(values) = mapping.unpack(frame.data()) else {
            self.stats.short_tpdos += 1;
            return;
        };
        self.stats.tpdos += 1;
        let objects = self.profile.objects.clone();
        for (object, value) in values {
            if object == objects.statusword {
                if objects.statusword_bits == 32 {
                    self.set_statusword(0, (value & 0xFFFF) as u16, t);
                    self.set_statusword(1, ((value >> 16) & 0xFFFF) as u16, t);
                } else {
                    self.set_statusword(0, value as u16, t);
                }
            }
            for (a, axis) in self.axes.iter_mut().enumerate() {
                if objects.actual_velocity.get(a) == Some(&object) {
                    axis.velocity = Some(value as i32);
                    axis.rx = Some(t);
                }
                if objects.actual_position.get(a) == Some(&object) {
                    axis.position = Some(value as i32);
                    axis.rx = Some(t);
                }
            }
        }
    }

    fn raise(&mut self, fault: DriveFault) {
        if self.fault.is_none() {
            self.fault = Some(fault);
        }
        if self.goal == Goal::Enabled {
            self.goal = Goal::QuickStop;
        }
        self.enable_asked_at = None;
        self.targets.iter_mut().for_each(|t| *t = 0);
    }

    /// Runs timers: heartbeat watchdog, boot retries, SDO timeouts, polling and commands.
    pub fn poll(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
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
        if let Some(last) = self.last_heartbeat
            && t.saturating_since(last) > self.settings.heartbeat_timeout
        {
            self.raise(DriveFault::HeartbeatLost);
            self.phase = Phase::Booting {
                since: t,
                attempts: 0,
            };
            // Command standstill in case only the heartbeat is missing, then keep trying
            // to reach the node.
            self.send_stop(out);
            self.sdo.clear();
            return;
        }
        if self.phase == Phase::Running {
            self.run(t, out);
        }
        self.poll_sdo(t, out);
    }

    /// Sends a command set by [`Self::command`] since the last poll now, rather than at the
    /// next poll a control period later. Timers are not advanced twice: at the poll's own
    /// time everything but a changed command is a no-op.
    pub fn flush_command(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if self.phase == Phase::Running {
            self.run(t, out);
        }
    }

    fn poll_sdo(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if let Some(outcome) = self.sdo.poll(t, out) {
            self.on_sdo(t, outcome, out);
        }
    }

    /// How long since `axis` last reported (since running, if it never did).
    fn feedback_age(&self, t: Timestamp, axis: usize) -> Duration {
        let last = self
            .axes
            .get(axis)
            .and_then(|a| a.rx)
            .into_iter()
            .chain(self.running_since)
            .max();
        last.map_or(Duration::ZERO, |last| t.saturating_since(last))
    }

    fn run(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if let Some(axis) =
            (0..self.axes.len()).find(|&a| self.feedback_age(t, a) > self.settings.feedback_timeout)
        {
            self.raise(DriveFault::FeedbackStale { axis });
        }
        let state = self.drive_state();
        if let (Some(state), Some(asked)) = (state, self.enable_asked_at)
            && state != DriveState::OperationEnabled
            && t.saturating_since(asked) > self.settings.enable_timeout
        {
            self.raise(DriveFault::EnableTimeout { state });
        }
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
        if state.is_some() {
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

    fn request_feedback(&mut self) {
        if self.profile.feedback.mode != Transport::Sdo {
            return;
        }
        let objects = &self.profile.objects;
        self.sdo
            .push(SdoRequest::Read(objects.statusword), Tag::Feedback);
        for object in objects
            .actual_velocity
            .iter()
            .chain(&objects.actual_position)
        {
            self.sdo.push(SdoRequest::Read(*object), Tag::Feedback);
        }
    }

    fn send_sdo_commands(&mut self, t: Timestamp) {
        // One controlword write at a time; the next waits for the drive's answer.
        if self.sent_controlword != Some(self.controlword) && self.queued_controlword.is_none() {
            self.queued_controlword = Some(self.controlword);
            self.sdo.push(
                SdoRequest::Write(
                    self.profile.objects.controlword,
                    SdoData::u16(self.controlword),
                ),
                Tag::Controlword(self.controlword),
            );
        }
        let changed = self.sent_targets.as_deref() != Some(self.targets.as_slice());
        if (changed || t >= self.next_command) && self.sdo.backlog() <= 2 {
            self.next_command = t.saturating_add(period(self.profile.command.rate_hz));
            for request in target_writes(&self.profile, &self.targets) {
                self.sdo.push(request, Tag::Target);
            }
            self.sent_targets = Some(self.targets.clone());
        }
    }

    /// Sends the RPDOs when something changed or the command period elapsed.
    fn send_rpdos(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        let changed = self.sent_controlword != Some(self.controlword)
            || self.sent_targets.as_deref() != Some(self.targets.as_slice());
        if !changed && t < self.next_command {
            return;
        }
        self.next_command = t.saturating_add(period(self.profile.command.rate_hz));
        for (cob, mapping) in &self.rpdos {
            let values: Vec<i64> = mapping
                .entries()
                .iter()
                .map(|e| self.value_of(e.object))
                .collect();
            if let Some(frame) = Frame::standard(*cob, &mapping.pack(&values)) {
                out.push(frame);
            }
        }
        self.sent_controlword = Some(self.controlword);
        self.sent_targets = Some(self.targets.clone());
    }

    /// The value chassisd writes to `object` in an RPDO.
    fn value_of(&self, object: ObjectAddress) -> i64 {
        let objects = &self.profile.objects;
        if object == objects.controlword {
            return i64::from(self.controlword);
        }
        if Some(object) == objects.combined_target_velocity {
            return i64::from(combine(&self.targets));
        }
        objects
            .target_velocity
            .iter()
            .position(|o| *o == object)
            .and_then(|a| self.targets.get(a))
            .map_or(0, |v| i64::from(*v))
    }

    /// The frames that quick-stop this drive with zero targets, whatever its state: the
    /// RPDOs, or SDO writes of the controlword and targets (sent without waiting for
    /// answers). For the last act on exit or panic; empty in listen-only mode.
    pub fn stop_frames(&self) -> Vec<Frame> {
        if self.monitor {
            return Vec::new();
        }
        let node = self.settings.node;
        let zero = vec![0; self.targets.len()];
        match self.profile.command.mode {
            Transport::Pdo => self
                .rpdos
                .iter()
                .filter_map(|(cob, mapping)| {
                    let values: Vec<i64> = mapping
                        .entries()
                        .iter()
                        .map(|e| {
                            if e.object == self.profile.objects.controlword {
                                i64::from(controlword::QUICK_STOP)
                            } else {
                                0
                            }
                        })
                        .collect();
                    Frame::standard(*cob, &mapping.pack(&values))
                })
                .collect(),
            Transport::Sdo => std::iter::once(SdoRequest::Write(
                self.profile.objects.controlword,
                SdoData::u16(controlword::QUICK_STOP),
            ))
            .chain(target_writes(&self.profile, &zero))
            .map(|r| r.frame(node))
            .collect(),
        }
    }

    /// Quick stop now, zero targets, and stay stopped: the daemon is exiting. The frames
    /// go to `out`.
    pub fn shut_down(&mut self, out: &mut Vec<Frame>) {
        self.goal = Goal::QuickStop;
        self.enable_asked_at = None;
        self.targets.iter_mut().for_each(|x| *x = 0);
        if self.phase == Phase::Running && !self.monitor {
            self.send_stop(out);
        }
    }

    /// One step of the fault reset handshake in `state`.
    fn step_reset(&mut self, t: Timestamp, state: DriveState, reset: FaultReset) {
        let low = controlword::DISABLE_VOLTAGE;
        if !state.is_fault() {
            // Out of Fault: the reset worked.
            tracing::info!(
                node = self.settings.node.get(),
                attempt = reset.attempt,
                "fault reset"
            );
            self.reset = None;
            self.fault = None;
            self.controlword = next_controlword(state, self.goal).unwrap_or(low);
            return;
        }
        self.reset = match reset.step {
            // Bit 7 must be seen low for a cycle before the edge.
            ResetStep::Low(since) if self.sent_controlword == Some(low) && t > since => {
                self.controlword = controlword::FAULT_RESET;
                self.stats.fault_resets += 1;
                Some(FaultReset {
                    step: ResetStep::Edge(t),
                    ..reset
                })
            }
            ResetStep::Low(_) => {
                self.controlword = low;
                Some(reset)
            }
            ResetStep::Edge(since) if t.saturating_since(since) <= self.settings.reset_wait => {
                Some(reset)
            }
            ResetStep::Edge(_) if reset.attempt < self.settings.reset_attempts => {
                self.controlword = low;
                Some(FaultReset {
                    attempt: reset.attempt + 1,
                    step: ResetStep::Low(t),
                })
            }
            ResetStep::Edge(_) => {
                tracing::warn!(
                    node = self.settings.node.get(),
                    attempts = reset.attempt,
                    "fault reset failed: the drive stays in fault"
                );
                self.controlword = low;
                None
            }
        };
    }

    /// Zero targets and a quick stop, sent straight away.
    fn send_stop(&mut self, out: &mut Vec<Frame>) {
        self.targets.iter_mut().for_each(|x| *x = 0);
        self.controlword = controlword::QUICK_STOP;
        out.extend(self.stop_frames());
        self.sent_controlword = Some(self.controlword);
        self.sent_targets = Some(self.targets.clone());
    }
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

fn period(hz: f64) -> Duration {
    Duration::from_secs_f64(1.0 / hz.max(0.001))
}

/// Two i16 targets packed as the ZLAC8015D's 0x60FF:3 takes them: axis 1 low, axis 2 high.
fn combine(targets: &[i32]) -> u32 {
    let lo = targets.first().copied().unwrap_or(0) as i16 as u16;
    let hi = targets.get(1).copied().unwrap_or(0) as i16 as u16;
    (u32::from(hi) << 16) | u32::from(lo)
}

fn target_writes(profile: &DriveProfile, targets: &[i32]) -> Vec<SdoRequest> {
    match profile.objects.combined_target_velocity {
        Some(object) => vec![SdoRequest::Write(object, SdoData::u32(combine(targets)))],
        None => profile
            .objects
            .target_velocity
            .iter()
            .zip(targets)
            .map(|(o, v)| SdoRequest::Write(*o, SdoData::i32(*v)))
            .collect(),
    }
}

/// The writes that make the drive stop by itself when chassisd is gone (the profile's
/// `[master_loss]`).
fn master_loss_writes(settings: &NodeSettings, profile: &DriveProfile) -> Vec<SdoRequest> {
    let timeout_ms = settings
        .master_timeout
        .as_millis()
        .min(u128::from(u16::MAX)) as u16;
    match profile.master_loss {
        Some(MasterLoss::Heartbeat { reaction }) => vec![
            SdoRequest::Write(
                CONSUMER_HEARTBEAT,
                SdoData::u32((u32::from(settings.master_node.get()) << 16) | u32::from(timeout_ms)),
            ),
            SdoRequest::Write(
                ABORT_CONNECTION_OPTION,
                SdoData::u16(reaction.code() as u16),
            ),
        ],
        Some(MasterLoss::Sync { reaction }) => vec![
            SdoRequest::Write(
                COMMUNICATION_CYCLE,
                SdoData::u32(settings.sync_period.as_micros().min(u128::from(u32::MAX)) as u32),
            ),
            SdoRequest::Write(
                ABORT_CONNECTION_OPTION,
                SdoData::u16(reaction.code() as u16),
            ),
        ],
        Some(MasterLoss::VendorTimeout { object, value_type }) => {
            let data = match value_type {
                ValueType::U32 => SdoData::u32(u32::from(timeout_ms)),
                _ => SdoData::u16(timeout_ms),
            };
            vec![SdoRequest::Write(object, data)]
        }
        // Profiles without one are refused at load.
        None => Vec::new(),
    }
}

/// The set-up writes, in order: heartbeat producer, the loss-of-master watchdog, profile
/// velocity mode, zero targets, PDO configuration, then the profile's own writes.
fn setup_writes(settings: &NodeSettings, profile: &DriveProfile) -> Vec<SdoRequest> {
    let node = settings.node;
    let objects = &profile.objects;
    let mut writes = vec![SdoRequest::Write(
        objects.heartbeat_producer,
        SdoData::u16(settings.heartbeat_producer_ms),
    )];
    writes.extend(master_loss_writes(settings, profile));
    writes.extend([SdoRequest::Write(
        objects.mode_of_operation,
        SdoData::i8(PROFILE_VELOCITY_MODE),
    )]);
    writes.extend(target_writes(profile, &vec![0; usize::from(profile.axes)]));
    if profile.feedback.mode == Transport::Pdo {
        for (n, mapping, spec) in profile.tpdo_mappings() {
            writes.extend(mapping.tpdo_setup(
                n,
                tpdo_cob_id(n, node),
                TpdoTrigger {
                    transmission_type: spec.transmission_type,
                    event_timer_ms: spec.event_timer_ms,
                },
            ));
        }
    }
    if profile.command.mode == Transport::Pdo {
        for (n, mapping) in profile.rpdo_mappings() {
            writes.extend(mapping.rpdo_setup(n, rpdo_cob_id(n, node)));
        }
    }
    writes.extend(
        profile
            .setup
            .iter()
            .filter_map(|w| w.data().map(|d| SdoRequest::Write(w.object, d))),
    );
    writes
}
