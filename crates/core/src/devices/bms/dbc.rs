//! A broadcast BMS described by a DBC file: the profile maps DBC signals to the reading's
//! fields and alarm bits. Signal extraction handles Intel and Motorola byte order and signed
//! values.

use can_dbc::{ByteOrder, Dbc, MessageId, Signal, ValueType};
use serde::{Deserialize, Serialize};

use super::{BmsReading, ChargeState, alarm};
use crate::devices::can::Frame;
use crate::time::Timestamp;

/// `kind = "dbc"`
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DbcProfile {
    /// Human-readable name.
    pub name: String,
    /// DBC file, relative to the profile. Read into `dbc_text` on load.
    #[serde(default, skip_serializing)]
    pub dbc: Option<String>,
    /// The DBC's text (written inline in effective configurations).
    #[serde(default)]
    pub dbc_text: String,
    /// +1 when the DBC's current is positive while charging, -1 when while discharging.
    #[serde(default = "default_sign")]
    pub current_sign: f64,
    /// Signals for the reading's fields, `"message.signal"`.
    pub fields: DbcFields,
    /// Signals that raise alarm bits while non-zero.
    #[serde(default)]
    pub alarm: Vec<DbcAlarm>,
}

fn default_sign() -> f64 {
    1.0
}

/// `[fields]` of a DBC profile.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DbcFields {
    /// Pack voltage, V.
    pub voltage: String,
    /// Current, A.
    pub current: String,
    /// SOC, %.
    pub soc: String,
    /// Temperature, °C.
    #[serde(default)]
    pub temperature: Option<String>,
    /// Remaining capacity, Ah.
    #[serde(default)]
    pub remaining_capacity: Option<String>,
}

/// `[[alarm]]` of a DBC profile.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DbcAlarm {
    /// The signal, `"message.signal"`.
    pub signal: String,
    /// The alarm bit's name (see the `bms.error` table in docs/protocols/mqtt.md).
    pub bit: String,
    /// Whether the BMS has tripped a protection when this is set.
    #[serde(default)]
    pub protection: bool,
}

/// The raw bits of a signal, or `None` when the frame is too short.
pub fn raw_bits(signal: &Signal, data: &[u8]) -> Option<u64> {
    let size = u32::try_from(signal.size)
        .ok()
        .filter(|s| (1..=64).contains(s))?;
    let start = usize::try_from(signal.start_bit).ok()?;
    match signal.byte_order {
        ByteOrder::LittleEndian => {
            let end = start.checked_add(size as usize)?;
            if end > data.len() * 8 {
                return None;
            }
            let mut bytes = [0u8; 8];
            let n = data.len().min(8);
            bytes[..n].copy_from_slice(&data[..n]);
            let all = u64::from_le_bytes(bytes);
            let shifted = all >> start;
            Some(if size == 64 {
                shifted
            } else {
                shifted & ((1u64 << size) - 1)
            })
        }
        ByteOrder::BigEndian => {
            // DBC numbers Motorola bits from the most significant one, walking down a byte
            // and on to the next byte's bit 7.
            let mut pos = start;
            let mut value = 0u64;
            for _ in 0..size {
                let byte = *data.get(pos / 8)?;
                let bit = pos % 8;
                value = (value << 1) | u64::from((byte >> bit) & 1);
                pos = if bit == 0 { pos + 15 } else { pos - 1 };
            }
            Some(value)
        }
    }
}

/// A signal's physical value: raw (sign-extended when signed) × factor + offset.
pub fn physical(signal: &Signal, data: &[u8]) -> Option<f64> {
    let raw = raw_bits(signal, data)?;
    let size = signal.size as u32;
    let value = match signal.value_type {
        ValueType::Signed if size < 64 => {
            let shift = 64 - size;
            (((raw << shift) as i64) >> shift) as f64
        }
        ValueType::Signed => raw as i64 as f64,
        ValueType::Unsigned => raw as f64,
    };
    Some(value * signal.factor + signal.offset)
}

/// What a mapped signal feeds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    /// Pack voltage, V.
    Voltage,
    /// Current, A (times the profile's sign).
    Current,
    /// SOC, %.
    Soc,
    /// Temperature, °C.
    Temperature,
    /// Remaining capacity, Ah.
    RemainingCapacity,
    /// An alarm bit set while the signal is non-zero.
    Alarm(u32),
}

#[derive(Debug, Clone)]
struct Mapped {
    id: u32,
    extended: bool,
    signal: Signal,
    target: Target,
    active: bool,
}

/// A DBC-described BMS.
#[derive(Debug, Clone)]
pub struct DbcBms {
    mapped: Vec<Mapped>,
    current_sign: f64,
    reading: BmsReading,
}

/// A profile whose DBC or mapping does not fit together.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DbcMapError {
    /// The DBC text did not parse.
    #[error("DBC does not parse: {0}")]
    Parse(String),
    /// A `message.signal` reference names nothing in the DBC.
    #[error("{0:?} is not a message.signal in the DBC")]
    Missing(String),
}

impl DbcBms {
    /// Resolves a profile against its DBC.
    pub fn new(profile: &DbcProfile) -> Result<Self, DbcMapError> {
        let dbc = Dbc::try_from(profile.dbc_text.as_str())
            .map_err(|e| DbcMapError::Parse(format!("{e:?}")))?;
        let mut mapped = Vec::new();
        let fields = &profile.fields;
        let mut add = |reference: &str, target: Target| -> Result<(), DbcMapError> {
            let (message_name, signal_name) = reference
                .split_once('.')
                .ok_or_else(|| DbcMapError::Missing(reference.to_owned()))?;
            let message = dbc
                .messages
                .iter()
                .find(|m| m.name == message_name)
                .ok_or_else(|| DbcMapError::Missing(reference.to_owned()))?;
            let signal = message
                .signals
                .iter()
                .find(|s| s.name == signal_name)
                .ok_or_else(|| DbcMapError::Missing(reference.to_owned()))?;
            let (id, extended) = match message.id {
                MessageId::Standard(id) => (u32::from(id), false),
                MessageId::Extended(id) => (id, true),
            };
            mapped.push(Mapped {
                id,
                extended,
                signal: signal.clone(),
                target,
                active: false,
            });
            Ok(())
        };
        for (reference, target) in [
            (Some(&fields.voltage), Target::Voltage),
            (Some(&fields.current), Target::Current),
            (Some(&fields.soc), Target::Soc),
            (fields.temperature.as_ref(), Target::Temperature),
            (
                fields.remaining_capacity.as_ref(),
                Target::RemainingCapacity,
            ),
        ] {
            if let Some(r) = reference {
                add(r, target)?;
            }
        }
        for a in &profile.alarm {
            let mut bit = alarm::by_name(&a.bit).unwrap_or(0);
            if a.protection {
                bit |= alarm::PROTECTION_TRIPPED;
            }
            add(&a.signal, Target::Alarm(bit))?;
        }
        Ok(Self {
            mapped,
            current_sign: profile.current_sign.signum(),
            reading: BmsReading::default(),
        })
    }

    /// Takes a frame; returns whether a mapped message updated the reading.
    pub fn on_frame(&mut self, t: Timestamp, frame: &Frame) -> bool {
        let mut hit = false;
        for m in &mut self.mapped {
            if m.id != frame.id() || m.extended != frame.is_extended() {
                continue;
            }
            let Some(value) = physical(&m.signal, frame.data()) else {
                continue;
            };
            hit = true;
            let r = &mut self.reading;
            match m.target {
                Target::Voltage => r.voltage_v = Some(value),
                Target::Current => {
                    let current = value * self.current_sign;
                    r.current_a = Some(current);
                    r.charge_state = Some(if current > 0.05 {
                        ChargeState::Charging
                    } else if current < -0.05 {
                        ChargeState::Discharging
                    } else {
                        ChargeState::Idle
                    });
                }
                Target::Soc => r.soc_pct = Some(value),
                Target::Temperature => r.temperature_c = Some(value),
                Target::RemainingCapacity => r.remaining_capacity_ah = Some(value),
                Target::Alarm(_) => m.active = value != 0.0,
            }
        }
        if hit {
            self.reading.alarms = self
                .mapped
                .iter()
                .filter(|m| m.active)
                .filter_map(|m| match m.target {
                    Target::Alarm(bits) => Some(bits),
                    _ => None,
                })
                .fold(0, |a, b| a | b);
            self.reading.rx = Some(t);
        }
        hit
    }

    /// The reading so far.
    pub fn reading(&self) -> &BmsReading {
        &self.reading
    }
}
