//! Daly smart BMS over CAN (Daly CAN protocol V1.0, 250 kbit/s): the host polls with
//! extended ids `0x18 cmd bms host`, the BMS answers on `0x18 cmd host bms`, eight bytes,
//! big-endian.

use std::time::Duration;

use super::{BmsReading, ChargeState, alarm};
use crate::devices::can::Frame;
use crate::time::Timestamp;

/// Pack voltage, current and SOC.
pub const CMD_SOC: u8 = 0x90;
/// Highest and lowest cell voltage.
pub const CMD_CELL_VOLTAGE_RANGE: u8 = 0x91;
/// Highest and lowest temperature.
pub const CMD_TEMPERATURE_RANGE: u8 = 0x92;
/// Charge state, MOSFETs, remaining capacity.
pub const CMD_MOSFET: u8 = 0x93;
/// Failure flags.
pub const CMD_FAILURES: u8 = 0x98;
/// The commands polled, in order.
pub const POLLED: [u8; 5] = [
    CMD_SOC,
    CMD_CELL_VOLTAGE_RANGE,
    CMD_TEMPERATURE_RANGE,
    CMD_MOSFET,
    CMD_FAILURES,
];

/// The request identifier: priority 0x18, command, BMS address, host address.
pub fn request_id(cmd: u8, bms: u8, host: u8) -> u32 {
    0x1800_0000 | (u32::from(cmd) << 16) | (u32::from(bms) << 8) | u32::from(host)
}

/// The reply identifier: priority 0x18, command, host address, BMS address.
pub fn reply_id(cmd: u8, bms: u8, host: u8) -> u32 {
    0x1800_0000 | (u32::from(cmd) << 16) | (u32::from(host) << 8) | u32::from(bms)
}

/// One decoded reply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DalyMessage {
    /// 0x90.
    Soc {
        /// Cumulative total voltage, V.
        voltage_v: f64,
        /// Current, A, as the wire has it: raw minus 30000, tenths.
        current_raw_a: f64,
        /// SOC, %.
        soc_pct: f64,
    },
    /// 0x91.
    CellVoltageRange {
        /// Highest cell, V.
        max_v: f64,
        /// Its cell number.
        max_cell: u8,
        /// Lowest cell, V.
        min_v: f64,
        /// Its cell number.
        min_cell: u8,
    },
    /// 0x92.
    TemperatureRange {
        /// Highest, °C.
        max_c: f64,
        /// Lowest, °C.
        min_c: f64,
    },
    /// 0x93.
    Mosfet {
        /// 0 stationary, 1 charging, 2 discharging.
        state: u8,
        /// Charge MOSFET on.
        charge: bool,
        /// Discharge MOSFET on.
        discharge: bool,
        /// Remaining capacity, Ah.
        remaining_ah: f64,
    },
    /// 0x98: the eight failure bytes.
    Failures([u8; 8]),
}

/// A Daly reply that could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DalyError {
    /// Replies carry eight bytes.
    #[error("Daly reply 0x{cmd:02X} has {len} bytes, not 8")]
    Length {
        /// The command.
        cmd: u8,
        /// Bytes present.
        len: usize,
    },
    /// A command chassisd does not poll.
    #[error("Daly command 0x{0:02X} is not decoded")]
    Command(u8),
}

/// Decodes the reply to `cmd`.
pub fn decode(cmd: u8, data: &[u8]) -> Result<DalyMessage, DalyError> {
    let d: [u8; 8] = data.try_into().map_err(|_| DalyError::Length {
        cmd,
        len: data.len(),
    })?;
    let u16_at = |i: usize| f64::from(u16::from_be_bytes([d[i], d[i + 1]]));
    Ok(match cmd {
        CMD_SOC => DalyMessage::Soc {
            voltage_v: u16_at(0) / 10.0,
            current_raw_a: (u16_at(4) - 30_000.0) / 10.0,
            soc_pct: u16_at(6) / 10.0,
        },
        CMD_CELL_VOLTAGE_RANGE => DalyMessage::CellVoltageRange {
            max_v: u16_at(0) / 1000.0,
            max_cell: d[2],
            min_v: f64::from(u16::from_be_bytes([d[3], d[4]])) / 1000.0,
            min_cell: d[5],
        },
        CMD_TEMPERATURE_RANGE => DalyMessage::TemperatureRange {
            max_c: f64::from(d[0]) - 40.0,
            min_c: f64::from(d[2]) - 40.0,
        },
        CMD_MOSFET => DalyMessage::Mosfet {
            state: d[0],
            charge: d[1] != 0,
            discharge: d[2] != 0,
            remaining_ah: f64::from(u32::from_be_bytes([d[4], d[5], d[6], d[7]])) / 1000.0,
        },
        CMD_FAILURES => DalyMessage::Failures(d),
        other => return Err(DalyError::Command(other)),
    })
}

/// The normalised alarm bits of the 0x98 failure bytes (Daly CAN protocol V1.0 table).
/// Level-2 alarms (odd bits of bytes 0–3) also set [`alarm::PROTECTION_TRIPPED`].
pub fn failure_alarms(b: [u8; 8]) -> u32 {
    use alarm::*;
    let pairs = |byte: u8, bits: [u32; 4]| -> u32 {
        (0..4)
            .filter(|i| byte & (0b11 << (2 * i)) != 0)
            .map(|i| bits[i])
            .fold(0, |a, x| a | x)
    };
    let mut a = pairs(
        b[0],
        [
            CELL_OVERVOLTAGE,
            CELL_UNDERVOLTAGE,
            PACK_OVERVOLTAGE,
            PACK_UNDERVOLTAGE,
        ],
    ) | pairs(
        b[1],
        [
            CHARGE_OVER_TEMPERATURE,
            CHARGE_UNDER_TEMPERATURE,
            DISCHARGE_OVER_TEMPERATURE,
            DISCHARGE_UNDER_TEMPERATURE,
        ],
    ) | pairs(
        b[2],
        [
            CHARGE_OVER_CURRENT,
            DISCHARGE_OVER_CURRENT,
            SOC_HIGH,
            SOC_LOW,
        ],
    ) | pairs(b[3] & 0x0F, [CELL_IMBALANCE, TEMPERATURE_IMBALANCE, 0, 0]);
    if b[4] != 0 {
        a |= MOSFET_FAULT;
    }
    if b[5] & 0x3F != 0 {
        a |= HARDWARE_FAULT;
    }
    if b[5] & 0xC0 != 0 {
        a |= COMMUNICATION_FAULT;
    }
    if b[6] & 0x03 != 0 {
        a |= HARDWARE_FAULT;
    }
    if b[6] & 0x04 != 0 {
        a |= SHORT_CIRCUIT | PROTECTION_TRIPPED;
    }
    if b[6] & 0x08 != 0 {
        a |= PACK_UNDERVOLTAGE | PROTECTION_TRIPPED;
    }
    if b[0..4].iter().any(|byte| byte & 0b1010_1010 != 0) {
        a |= PROTECTION_TRIPPED;
    }
    a
}

/// The reply frame a Daly BMS sends (for simulators and tests).
pub fn reply_frame(cmd: u8, bms: u8, host: u8, data: [u8; 8]) -> Frame {
    Frame::ext(reply_id(cmd, bms, host), data)
}

/// A polled Daly BMS.
#[derive(Debug, Clone)]
pub struct DalyBms {
    bms: u8,
    host: u8,
    /// +1 when a raw current above the 30000 offset means charging, -1 when it means
    /// discharging (firmware differs; see the profile).
    current_sign: f64,
    request_gap: Duration,
    next_request: Option<Timestamp>,
    next_command: usize,
    reading: BmsReading,
    malformed: u64,
}

impl DalyBms {
    /// A BMS at `bms` polled by `host`, `rounds_per_s` full rounds of [`POLLED`] a second.
    pub fn new(bms: u8, host: u8, current_sign: f64, rounds_per_s: f64) -> Self {
        let gap = 1.0 / (rounds_per_s.max(0.01) * POLLED.len() as f64);
        Self {
            bms,
            host,
            current_sign: current_sign.signum(),
            request_gap: Duration::from_secs_f64(gap),
            next_request: None,
            next_command: 0,
            reading: BmsReading::default(),
            malformed: 0,
        }
    }

    /// Sends the next request when due.
    pub fn poll(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if self.next_request.is_some_and(|at| t < at) {
            return;
        }
        let cmd = POLLED[self.next_command % POLLED.len()];
        self.next_command = (self.next_command + 1) % POLLED.len();
        out.push(Frame::ext(request_id(cmd, self.bms, self.host), [0u8; 8]));
        self.next_request = Some(t.saturating_add(self.request_gap));
    }

    /// Takes a frame; returns whether it was a reply from this BMS that updated the reading.
    pub fn on_frame(&mut self, t: Timestamp, frame: &Frame) -> bool {
        let id = frame.id();
        if !frame.is_extended()
            || id & 0xFF00_0000 != 0x1800_0000
            || (id >> 8) & 0xFF != u32::from(self.host)
            || id & 0xFF != u32::from(self.bms)
        {
            return false;
        }
        let cmd = ((id >> 16) & 0xFF) as u8;
        let message = match decode(cmd, frame.data()) {
            Ok(m) => m,
            Err(_) => {
                self.malformed += 1;
                return false;
            }
        };
        let r = &mut self.reading;
        match message {
            DalyMessage::Soc {
                voltage_v,
                current_raw_a,
                soc_pct,
            } => {
                r.voltage_v = Some(voltage_v);
                r.current_a = Some(current_raw_a * self.current_sign);
                r.soc_pct = Some(soc_pct);
            }
            DalyMessage::CellVoltageRange { max_v, min_v, .. } => {
                r.cell_voltage_range_v = Some((max_v, min_v));
            }
            DalyMessage::TemperatureRange { max_c, .. } => r.temperature_c = Some(max_c),
            DalyMessage::Mosfet {
                state,
                charge,
                discharge,
                remaining_ah,
            } => {
                r.charge_state = Some(match state {
                    1 => ChargeState::Charging,
                    2 => ChargeState::Discharging,
                    _ => ChargeState::Idle,
                });
                r.charge_mosfet = Some(charge);
                r.discharge_mosfet = Some(discharge);
                r.remaining_capacity_ah = Some(remaining_ah);
            }
            DalyMessage::Failures(bytes) => r.alarms = failure_alarms(bytes),
        }
        r.rx = Some(t);
        true
    }

    /// The reading so far.
    pub fn reading(&self) -> &BmsReading {
        &self.reading
    }

    /// Replies that failed to decode.
    pub fn malformed(&self) -> u64 {
        self.malformed
    }
}
