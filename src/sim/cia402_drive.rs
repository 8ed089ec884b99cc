//! A simulated CiA 402 drive node: NMT, heartbeat, an SDO server over its object
//! dictionary, TPDOs and RPDOs as configured over SDO, the power state machine, a motor that
//! follows the target velocity with an acceleration limit, encoder counts, EMCY on faults,
//! and the loss-of-master watchdog its profile names: a consumer heartbeat (0x1016:1) or SYNC
//! (0x1006) with the 0x6007 reaction, or a vendor timeout object fed by frames addressed to
//! the drive. A fault can be made sticky, so it survives a given number of reset edges.
//!
//! It is built from the same drive profile as the real driver, so it offers exactly the
//! objects the profile names and refuses others with the CiA 301 abort code.

use std::collections::BTreeMap;
use std::time::Duration;

use crate::devices::can::Frame;
use crate::devices::canopen::emcy::Emcy;
use crate::devices::canopen::nmt::{NmtState, heartbeat_frame};
use crate::devices::canopen::pdo::{PdoEntry, PdoMapping};
use crate::devices::canopen::sdo::{AbortCode, SdoData, SdoRequest, SdoResponse, decode_request};
use crate::devices::canopen::{Cob, DEVICE_TYPE, NodeId, ObjectAddress};
use crate::devices::cia402::DriveProfile;
use crate::devices::cia402::profile::{
    ABORT_CONNECTION_OPTION, COMMUNICATION_CYCLE, CONSUMER_HEARTBEAT, LossReaction, MasterLoss,
};
use crate::devices::cia402::state::DriveState;
use crate::time::Timestamp;

/// Physical parameters of the simulated motors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorModel {
    /// Acceleration limit, r/min per second.
    pub accel_rpm_per_s: f64,
    /// First-order lag of the speed loop, s (0: none, only the acceleration limit).
    pub time_constant_s: f64,
}

impl Default for MotorModel {
    fn default() -> Self {
        Self {
            accel_rpm_per_s: 3000.0,
            time_constant_s: 0.0,
        }
    }
}

/// What the simulated drive answers for its device type: profile 402 (0x0192), a servo
/// drive (additional information 0x0002).
const CIA402_DEVICE_TYPE: u32 = 0x0002_0192;

/// The quick-stop ramp is this many times the normal acceleration limit.
const QUICK_STOP_FACTOR: f64 = 2.0;

#[derive(Debug, Clone, Copy, Default)]
struct Axis {
    state: Option<DriveState>,
    /// Target, drive units.
    target: i32,
    /// Motor speed, r/min.
    rpm: f64,
    /// Encoder position, counts (fractional inside).
    counts: f64,
    /// Motor speed forced from outside (the wheel back-driven: a recorded motion played
    /// through the simulator), r/min, in place of the motor model.
    back_driven: Option<f64>,
}

#[derive(Debug, Clone)]
struct PdoSlot {
    cob_id: u32,
    transmission_type: u8,
    event_timer_ms: u16,
    entries: Vec<u32>,
    mapped: u8,
    next_send: Timestamp,
}

impl PdoSlot {
    fn new(cob_id: u32) -> Self {
        Self {
            // Disabled until configured.
            cob_id: cob_id | 0x8000_0000,
            transmission_type: 0xFF,
            event_timer_ms: 0,
            entries: vec![0; 8],
            mapped: 0,
            next_send: Timestamp::default(),
        }
    }

    fn enabled(&self) -> bool {
        self.cob_id & 0x8000_0000 == 0
    }

    fn mapping(&self) -> Option<PdoMapping> {
        let entries = self.entries[..usize::from(self.mapped).min(8)]
            .iter()
            .map(|v| PdoEntry {
                object: ObjectAddress::new((v >> 16) as u16, (v >> 8) as u8),
                bits: *v as u8,
            })
            .collect();
        PdoMapping::new(entries).ok()
    }
}

/// What the simulator reports about one axis.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AxisReport {
    /// Power state.
    pub state: String,
    /// Target, drive units.
    pub target: i32,
    /// Motor speed, r/min.
    pub rpm: f64,
    /// Encoder position, counts.
    pub counts: i64,
}

/// A simulated drive node.
#[derive(Debug, Clone)]
pub struct SimDrive {
    node: NodeId,
    profile: DriveProfile,
    model: MotorModel,
    nmt: NmtState,
    booted: bool,
    heartbeat_ms: u16,
    heartbeat_enabled: bool,
    next_heartbeat: Timestamp,
    controlword: u16,
    mode: i8,
    axes: Vec<Axis>,
    /// Vendor objects the profile writes at set-up, and their values.
    vendor: BTreeMap<ObjectAddress, u32>,
    tpdo: Vec<PdoSlot>,
    rpdo: Vec<PdoSlot>,
    /// 0x1016:1 as written: the master's node id (bits 16–23) and time in ms (bits 0–15).
    consumer_heartbeat: u32,
    /// 0x1006 as written, µs.
    cycle_period_us: u32,
    /// 0x6007 as written (CiA 402's default is 1, a fault).
    abort_option: i16,
    /// When the watched heartbeat, SYNC or addressed frame last came; monitoring starts with
    /// the first and stops after a loss until the next.
    master_heard: Option<Timestamp>,
    /// Losses of the master detected so far.
    master_losses: u32,
    /// Reset edges to ignore before a fault clears.
    refuse_resets: u32,
    /// Rising edges of controlword bit 7 received.
    reset_edges: u32,
    /// TPDOs are sent (false: they stop while the heartbeat goes on, as a half-failed node).
    tpdos_on: bool,
    last_step: Option<Timestamp>,
}

impl SimDrive {
    /// A drive that has just been powered: it sends its boot-up message on the first step.
    pub fn new(node: NodeId, profile: DriveProfile, model: MotorModel) -> Self {
        let vendor = profile.setup.iter().map(|w| (w.object, 0)).collect();
        // Power-up self-initialisation ends in "switch on disabled".
        let axes = vec![
            Axis {
                state: Some(DriveState::SwitchOnDisabled),
                ..Axis::default()
            };
            usize::from(profile.axes)
        ];
        Self {
            node,
            model,
            nmt: NmtState::PreOperational,
            booted: false,
            heartbeat_ms: 0,
            heartbeat_enabled: true,
            next_heartbeat: Timestamp::default(),
            controlword: 0,
            mode: 0,
            axes,
            vendor,
            tpdo: (1..=4)
                .map(|n| PdoSlot::new(crate::devices::canopen::tpdo_cob_id(n, node)))
                .collect(),
            rpdo: (1..=4)
                .map(|n| PdoSlot::new(crate::devices::canopen::rpdo_cob_id(n, node)))
                .collect(),
            consumer_heartbeat: 0,
            cycle_period_us: 0,
            abort_option: 1,
            master_heard: None,
            master_losses: 0,
            refuse_resets: 0,
            reset_edges: 0,
            tpdos_on: true,
            last_step: None,
            profile,
        }
    }

    /// The node id.
    pub fn node(&self) -> NodeId {
        self.node
    }

    /// Stops (or resumes) the heartbeat, as a failing node would.
    pub fn set_heartbeat(&mut self, on: bool) {
        self.heartbeat_enabled = on;
    }

    /// Makes the next fault survive `edges` reset edges (the drive stays in Fault).
    pub fn refuse_resets(&mut self, edges: u32) {
        self.refuse_resets = edges;
    }

    /// Stops (or resumes) the TPDOs while the heartbeat goes on.
    pub fn set_tpdos(&mut self, on: bool) {
        self.tpdos_on = on;
    }

    /// Rising edges of controlword bit 7 received so far.
    pub fn reset_edges(&self) -> u32 {
        self.reset_edges
    }

    /// Losses of the master detected so far.
    pub fn master_losses(&self) -> u32 {
        self.master_losses
    }

    /// Puts an axis into fault and sends the EMCY `code`.
    pub fn inject_fault(&mut self, axis: usize, code: u16, out: &mut Vec<Frame>) {
        if let Some(a) = self.axes.get_mut(axis) {
            a.state = Some(DriveState::Fault);
            a.target = 0;
        }
        out.push(
            Emcy {
                code,
                register: 0x01,
                vendor: [0; 5],
            }
            .frame(self.node),
        );
    }

    /// The NMT state.
    pub fn nmt_state(&self) -> NmtState {
        self.nmt
    }

    /// Each axis's motor speed, r/min.
    pub fn motor_rpm(&self) -> Vec<f64> {
        self.axes.iter().map(|a| a.rpm).collect()
    }

    /// A report of each axis.
    pub fn report(&self) -> Vec<AxisReport> {
        self.axes
            .iter()
            .map(|a| AxisReport {
                state: a.state.map_or("booting".into(), |s| s.to_string()),
                target: a.target,
                rpm: a.rpm,
                counts: a.counts.round() as i64,
            })
            .collect()
    }

    /// Whether every axis is commanded to stop: a zero target, or out of "operation
    /// enabled" (quick stop, fault, disabled).
    pub fn commanded_to_stop(&self) -> bool {
        self.axes
            .iter()
            .all(|a| a.target == 0 || a.state != Some(DriveState::OperationEnabled))
    }

    /// Handles a frame from the bus.
    pub fn on_frame(&mut self, t: Timestamp, frame: &Frame, out: &mut Vec<Frame>) {
        match Cob::of(frame) {
            Cob::Nmt => {
                let d = frame.data();
                if d.len() == 2 && (d[1] == 0 || d[1] == self.node.get()) {
                    self.heard(t, Watched::Addressed);
                    self.on_nmt(t, d[0], out);
                }
            }
            Cob::Heartbeat(n) if u32::from(n.get()) == (self.consumer_heartbeat >> 16) & 0xFF => {
                self.heard(t, Watched::Heartbeat);
            }
            Cob::Sync => self.heard(t, Watched::Sync),
            Cob::SdoRequest(n) if n == self.node => {
                self.heard(t, Watched::Addressed);
                let response = match decode_request(frame) {
                    Ok(SdoRequest::Read(addr)) => match self.read(addr) {
                        Ok(data) => SdoResponse::Data(addr, data),
                        Err(code) => SdoResponse::Abort(addr, code),
                    },
                    Ok(SdoRequest::Write(addr, data)) => match self.write(t, addr, data) {
                        Ok(()) => SdoResponse::Written(addr),
                        Err(code) => SdoResponse::Abort(addr, code),
                    },
                    // An abort from the client, or a transfer type this node lacks.
                    Err(_) => return,
                };
                out.push(response.frame(self.node));
            }
            _ => {
                if self.nmt == NmtState::Operational
                    && let Some(slot) = self
                        .rpdo
                        .iter()
                        .find(|s| s.enabled() && s.cob_id == frame.id() && !frame.is_extended())
                    && let Some(mapping) = slot.mapping()
                    && let Some(values) = mapping.unpack(frame.data())
                {
                    self.heard(t, Watched::Addressed);
                    for (object, value) in values {
                        let _ = self.write(t, object, SdoData::u32(value as u32));
                    }
                }
            }
        }
    }

    /// The master showed life in the way the profile's watchdog looks for.
    fn heard(&mut self, t: Timestamp, what: Watched) {
        let watched = match self.profile.master_loss {
            Some(MasterLoss::Heartbeat { .. }) => Watched::Heartbeat,
            Some(MasterLoss::Sync { .. }) => Watched::Sync,
            Some(MasterLoss::VendorTimeout { .. }) => Watched::Addressed,
            None => return,
        };
        if what == watched {
            self.master_heard = Some(t);
        }
    }

    /// The master-loss timeout in force, if the watchdog is configured.
    fn master_timeout(&self) -> Option<Duration> {
        let ms = match self.profile.master_loss? {
            MasterLoss::Heartbeat { .. } => u64::from(self.consumer_heartbeat & 0xFFFF),
            // Two missed cycles.
            MasterLoss::Sync { .. } => u64::from(self.cycle_period_us) * 2 / 1000,
            MasterLoss::VendorTimeout { object, .. } => {
                u64::from(self.vendor.get(&object).copied().unwrap_or(0))
            }
        };
        (ms > 0).then(|| Duration::from_millis(ms))
    }

    /// The master went silent: the reaction the profile's objects say.
    fn on_master_loss(&mut self, out: &mut Vec<Frame>) {
        self.master_heard = None;
        self.master_losses += 1;
        let reaction = match self.profile.master_loss {
            Some(MasterLoss::VendorTimeout { .. }) => Some(LossReaction::QuickStop),
            _ => LossReaction::from_code(self.abort_option),
        };
        for a in &mut self.axes {
            let Some(state) = a.state else { continue };
            let live = matches!(
                state,
                DriveState::OperationEnabled | DriveState::SwitchedOn | DriveState::ReadyToSwitchOn
            );
            a.state = Some(match reaction {
                Some(LossReaction::QuickStop) if state == DriveState::OperationEnabled => {
                    DriveState::QuickStopActive
                }
                Some(LossReaction::QuickStop | LossReaction::DisableVoltage) if live => {
                    DriveState::SwitchOnDisabled
                }
                Some(LossReaction::Fault) if live => DriveState::Fault,
                _ => state,
            });
            a.target = 0;
        }
        out.push(
            Emcy {
                code: 0x8130,
                register: 0x11,
                vendor: [0; 5],
            }
            .frame(self.node),
        );
    }

    fn on_nmt(&mut self, t: Timestamp, command: u8, out: &mut Vec<Frame>) {
        match command {
            0x01 => self.nmt = NmtState::Operational,
            0x02 => self.nmt = NmtState::Stopped,
            0x80 => self.nmt = NmtState::PreOperational,
            0x81 | 0x82 => {
                // Communication parameters go back to their defaults; an enabled motor
                // stops, as the abort-connection option asks.
                for slot in self.tpdo.iter_mut().chain(self.rpdo.iter_mut()) {
                    *slot = PdoSlot::new(slot.cob_id & 0x7FF);
                }
                self.heartbeat_ms = 0;
                self.consumer_heartbeat = 0;
                self.cycle_period_us = 0;
                self.master_heard = None;
                for a in &mut self.axes {
                    if command == 0x81 || a.state == Some(DriveState::OperationEnabled) {
                        a.state = Some(DriveState::SwitchOnDisabled);
                    }
                    a.target = 0;
                }
                self.nmt = NmtState::PreOperational;
                self.send_boot_up(t, out);
            }
            _ => {}
        }
    }

    fn send_boot_up(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        self.booted = true;
        if self.heartbeat_enabled {
            out.push(heartbeat_frame(self.node, NmtState::BootUp));
        }
        self.next_heartbeat = t;
    }

    fn statusword(&self, axis: usize) -> u16 {
        let state = self.axes.get(axis).and_then(|a| a.state);
        let mut sw = state.unwrap_or(DriveState::NotReadyToSwitchOn).statusword();
        if !matches!(state, None | Some(DriveState::SwitchOnDisabled)) {
            sw |= 1 << 4; // voltage enabled
        }
        sw | (1 << 9) // remote
    }

    fn read(&self, addr: ObjectAddress) -> Result<SdoData, AbortCode> {
        let objects = &self.profile.objects;
        if addr == objects.statusword {
            return Ok(if objects.statusword_bits == 32 {
                SdoData::u32(u32::from(self.statusword(0)) | (u32::from(self.statusword(1)) << 16))
            } else {
                SdoData::u16(self.statusword(0))
            });
        }
        if addr == objects.controlword {
            return Ok(SdoData::u16(self.controlword));
        }
        if addr == DEVICE_TYPE {
            return Ok(SdoData::u32(CIA402_DEVICE_TYPE));
        }
        if addr == objects.mode_of_operation || addr == ObjectAddress::new(0x6061, 0) {
            return Ok(SdoData::i8(self.mode));
        }
        if addr == objects.heartbeat_producer {
            return Ok(SdoData::u16(self.heartbeat_ms));
        }
        match (addr, self.profile.master_loss) {
            (CONSUMER_HEARTBEAT, Some(MasterLoss::Heartbeat { .. })) => {
                return Ok(SdoData::u32(self.consumer_heartbeat));
            }
            (COMMUNICATION_CYCLE, Some(MasterLoss::Sync { .. })) => {
                return Ok(SdoData::u32(self.cycle_period_us));
            }
            (
                ABORT_CONNECTION_OPTION,
                Some(MasterLoss::Heartbeat { .. } | MasterLoss::Sync { .. }),
            ) => return Ok(SdoData::u16(self.abort_option as u16)),
            _ => {}
        }
        for (a, axis) in self.axes.iter().enumerate() {
            if objects.actual_velocity.get(a) == Some(&addr) {
                let raw = axis.rpm * self.profile.units.actual_velocity_per_rpm;
                return Ok(SdoData::i32(raw.round() as i32));
            }
            if objects.actual_position.get(a) == Some(&addr) {
                return Ok(SdoData::i32(axis.counts.round() as i64 as i32));
            }
            if objects.target_velocity.get(a) == Some(&addr) {
                return Ok(SdoData::i32(axis.target));
            }
        }
        if let Some(v) = self.pdo_parameter(addr) {
            return v;
        }
        self.vendor
            .get(&addr)
            .map(|v| SdoData::u32(*v))
            .ok_or(AbortCode::NO_OBJECT)
    }

    fn write(&mut self, t: Timestamp, addr: ObjectAddress, data: SdoData) -> Result<(), AbortCode> {
        let objects = self.profile.objects.clone();
        if addr == objects.controlword {
            self.on_controlword(t, data.as_u32() as u16);
            return Ok(());
        }
        if addr == objects.statusword
            || objects.actual_velocity.contains(&addr)
            || objects.actual_position.contains(&addr)
        {
            return Err(AbortCode::READ_ONLY);
        }
        if addr == objects.mode_of_operation {
            self.mode = data.as_i32() as i8;
            return Ok(());
        }
        if addr == objects.heartbeat_producer {
            self.heartbeat_ms = data.as_u32() as u16;
            self.next_heartbeat = t;
            return Ok(());
        }
        match (addr, self.profile.master_loss) {
            (CONSUMER_HEARTBEAT, Some(MasterLoss::Heartbeat { .. })) => {
                self.consumer_heartbeat = data.as_u32();
                self.master_heard = None;
                return Ok(());
            }
            (COMMUNICATION_CYCLE, Some(MasterLoss::Sync { .. })) => {
                self.cycle_period_us = data.as_u32();
                self.master_heard = None;
                return Ok(());
            }
            (
                ABORT_CONNECTION_OPTION,
                Some(MasterLoss::Heartbeat { .. } | MasterLoss::Sync { .. }),
            ) => {
                self.abort_option = data.as_u32() as u16 as i16;
                return Ok(());
            }
            (object, Some(MasterLoss::VendorTimeout { object: timer, .. })) if object == timer => {
                self.vendor.insert(object, data.as_u32());
                self.master_heard = Some(t);
                return Ok(());
            }
            _ => {}
        }
        if Some(addr) == objects.combined_target_velocity {
            let v = data.as_u32();
            self.set_target(0, i32::from(v as u16 as i16));
            self.set_target(1, i32::from((v >> 16) as u16 as i16));
            return Ok(());
        }
        if let Some(a) = objects.target_velocity.iter().position(|o| *o == addr) {
            self.set_target(a, data.as_i32());
            return Ok(());
        }
        if self.write_pdo_parameter(addr, data)? {
            return Ok(());
        }
        match self.vendor.get_mut(&addr) {
            Some(v) => {
                *v = data.as_u32();
                Ok(())
            }
            None => Err(AbortCode::NO_OBJECT),
        }
    }

    fn set_target(&mut self, axis: usize, value: i32) {
        if let Some(a) = self.axes.get_mut(axis) {
            a.target = value;
        }
    }

    fn on_controlword(&mut self, t: Timestamp, cw: u16) {
        use DriveState::*;
        let rising_reset = cw & 0x80 != 0 && self.controlword & 0x80 == 0;
        self.controlword = cw;
        let _ = t;
        if rising_reset {
            self.reset_edges += 1;
        }
        let cleared = rising_reset && self.refuse_resets == 0;
        if rising_reset && self.axes.iter().any(|a| a.state == Some(DriveState::Fault)) {
            self.refuse_resets = self.refuse_resets.saturating_sub(1);
        }
        // The device control commands of CiA 402 §6.3.1.
        let disable_voltage = cw & 0x82 == 0x00;
        let quick_stop = cw & 0x86 == 0x02;
        let shutdown = cw & 0x87 == 0x06;
        let switch_on = cw & 0x8F == 0x07;
        let enable = cw & 0x8F == 0x0F;
        for a in &mut self.axes {
            let Some(state) = a.state else { continue };
            a.state = Some(match state {
                Fault if cleared => SwitchOnDisabled,
                Fault | FaultReactionActive | NotReadyToSwitchOn => state,
                OperationEnabled if quick_stop => QuickStopActive,
                // Braking on the quick-stop ramp; it ends in switch on disabled by itself.
                QuickStopActive if quick_stop => state,
                _ if disable_voltage || quick_stop => SwitchOnDisabled,
                SwitchOnDisabled if shutdown => ReadyToSwitchOn,
                ReadyToSwitchOn if switch_on => SwitchedOn,
                ReadyToSwitchOn | SwitchedOn if enable => OperationEnabled,
                SwitchedOn | OperationEnabled if shutdown => ReadyToSwitchOn,
                OperationEnabled if switch_on => SwitchedOn,
                _ => state,
            });
        }
    }

    /// PDO communication and mapping parameters.
    fn pdo_parameter(&self, addr: ObjectAddress) -> Option<Result<SdoData, AbortCode>> {
        let (slot, mapping) = self.slot(addr.index)?;
        Some(if mapping {
            match addr.sub {
                0 => Ok(SdoData::u8(slot.mapped)),
                1..=8 => Ok(SdoData::u32(slot.entries[usize::from(addr.sub - 1)])),
                _ => Err(AbortCode::NO_SUB_INDEX),
            }
        } else {
            match addr.sub {
                1 => Ok(SdoData::u32(slot.cob_id)),
                2 => Ok(SdoData::u8(slot.transmission_type)),
                5 => Ok(SdoData::u16(slot.event_timer_ms)),
                _ => Err(AbortCode::NO_SUB_INDEX),
            }
        })
    }

    fn slot(&self, index: u16) -> Option<(&PdoSlot, bool)> {
        let k = usize::from(index & 0x3);
        match index & 0xFFFC {
            0x1800 => Some((&self.tpdo[k], false)),
            0x1A00 => Some((&self.tpdo[k], true)),
            0x1400 => Some((&self.rpdo[k], false)),
            0x1600 => Some((&self.rpdo[k], true)),
            _ => None,
        }
    }

    /// Writes a PDO parameter; `Ok(false)` when `addr` is not one.
    fn write_pdo_parameter(
        &mut self,
        addr: ObjectAddress,
        data: SdoData,
    ) -> Result<bool, AbortCode> {
        let k = usize::from(addr.index & 0x3);
        let (slot, mapping) = match addr.index & 0xFFFC {
            0x1800 => (&mut self.tpdo[k], false),
            0x1A00 => (&mut self.tpdo[k], true),
            0x1400 => (&mut self.rpdo[k], false),
            0x1600 => (&mut self.rpdo[k], true),
            _ => return Ok(false),
        };
        let v = data.as_u32();
        if mapping {
            match addr.sub {
                0 => {
                    // The count may change only while the PDO is disabled, and the mapped
                    // objects must fit eight bytes.
                    if slot.enabled() {
                        return Err(AbortCode::DEVICE_STATE);
                    }
                    let count = v as u8;
                    let bits: u32 = slot.entries[..usize::from(count).min(8)]
                        .iter()
                        .map(|e| e & 0xFF)
                        .sum();
                    if count > 8 || bits > 64 {
                        return Err(AbortCode(0x0604_0042));
                    }
                    slot.mapped = count;
                }
                1..=8 => {
                    if slot.mapped != 0 {
                        return Err(AbortCode::DEVICE_STATE);
                    }
                    slot.entries[usize::from(addr.sub - 1)] = v;
                }
                _ => return Err(AbortCode::NO_SUB_INDEX),
            }
        } else {
            match addr.sub {
                1 => slot.cob_id = v,
                2 => slot.transmission_type = v as u8,
                5 => slot.event_timer_ms = v as u16,
                _ => return Err(AbortCode::NO_SUB_INDEX),
            }
        }
        Ok(true)
    }

    /// The value of a mappable object, for TPDOs.
    fn object_value(&self, addr: ObjectAddress) -> i64 {
        self.read(addr).map_or(0, |d| i64::from(d.as_i32()))
    }

    /// Forces `axis`'s motor speed (r/min) whatever the drive commands, or gives the motor
    /// back to the model (`None`). An axis the drive does not have is ignored.
    pub fn back_drive(&mut self, axis: usize, rpm: Option<f64>) {
        if let Some(a) = self.axes.get_mut(axis) {
            a.back_driven = rpm;
        }
    }

    /// Advances the motor model and sends what is due: boot-up, heartbeats, TPDOs.
    pub fn step(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if !self.booted {
            self.send_boot_up(t, out);
        }
        let dt = self
            .last_step
            .map_or(0.0, |last| t.saturating_since(last).as_secs_f64());
        self.last_step = Some(t);
        if let (Some(heard), Some(timeout)) = (self.master_heard, self.master_timeout())
            && t.saturating_since(heard) > timeout
        {
            self.on_master_loss(out);
        }
        let per_rpm = self.profile.units.target_velocity_per_rpm;
        let counts_per_rev = self.profile.units.counts_per_rev;
        let max_step = self.model.accel_rpm_per_s * dt;
        for a in &mut self.axes {
            let quick_stop = a.state == Some(DriveState::QuickStopActive);
            let wanted = if a.state == Some(DriveState::OperationEnabled) && self.mode == 3 {
                f64::from(a.target) / per_rpm
            } else {
                0.0
            };
            let max_step = if quick_stop {
                max_step * QUICK_STOP_FACTOR
            } else {
                max_step
            };
            // The speed loop's lag, then the acceleration limit.
            let lagged = if self.model.time_constant_s > 0.0 && !quick_stop {
                (wanted - a.rpm) * (1.0 - (-dt / self.model.time_constant_s).exp())
            } else {
                wanted - a.rpm
            };
            let change = match a.back_driven {
                Some(forced) => forced - a.rpm,
                None => lagged.clamp(-max_step, max_step),
            };
            // Average speed over the step moves the encoder.
            let rpm_before = a.rpm;
            a.rpm += change;
            a.counts += (rpm_before + a.rpm) / 2.0 / 60.0 * dt * counts_per_rev;
            if quick_stop && a.rpm == 0.0 {
                a.state = Some(DriveState::SwitchOnDisabled);
            }
        }
        if self.heartbeat_enabled && self.heartbeat_ms > 0 && t >= self.next_heartbeat {
            out.push(heartbeat_frame(self.node, self.nmt));
            self.next_heartbeat =
                t.saturating_add(Duration::from_millis(u64::from(self.heartbeat_ms)));
        }
        if self.nmt == NmtState::Operational && self.tpdos_on {
            for k in 0..self.tpdo.len() {
                let slot = &self.tpdo[k];
                if !slot.enabled() || slot.event_timer_ms == 0 || t < slot.next_send {
                    continue;
                }
                let Some(mapping) = slot.mapping() else {
                    continue;
                };
                let values: Vec<i64> = mapping
                    .entries()
                    .iter()
                    .map(|e| self.object_value(e.object))
                    .collect();
                let cob = slot.cob_id & 0x7FF;
                let period = Duration::from_millis(u64::from(slot.event_timer_ms));
                if let Some(frame) = Frame::standard(cob, &mapping.pack(&values)) {
                    out.push(frame);
                }
                self.tpdo[k].next_send = t.saturating_add(period);
            }
        }
    }
}

/// What shows the master is alive, for the loss watchdog.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Watched {
    /// A heartbeat from the consumed node.
    Heartbeat,
    /// A SYNC.
    Sync,
    /// A frame addressed to this node (SDO request, RPDO, NMT).
    Addressed,
}
