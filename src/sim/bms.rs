//! Simulated BMS nodes: a Daly pack that answers polls, and a broadcast pack that sends the
//! messages of its DBC profile. Both report a simple battery model.

use std::time::Duration;

use can_dbc::{ByteOrder, Dbc, MessageId, Signal, ValueType};

use crate::devices::bms::daly::{
    CMD_CELL_VOLTAGE_RANGE, CMD_FAILURES, CMD_MOSFET, CMD_SOC, CMD_TEMPERATURE_RANGE, reply_frame,
};
use crate::devices::bms::profile::{CurrentAboveOffset, DalyProfile, DbcProfile};
use crate::devices::can::Frame;
use crate::time::Timestamp;

/// The simulated battery's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Battery {
    /// Pack voltage, V.
    pub voltage_v: f64,
    /// Current, A, positive while charging.
    pub current_a: f64,
    /// SOC, %.
    pub soc_pct: f64,
    /// Temperature, °C.
    pub temperature_c: f64,
    /// Capacity, Ah.
    pub capacity_ah: f64,
}

impl Default for Battery {
    fn default() -> Self {
        Self {
            voltage_v: 51.2,
            current_a: -3.0,
            soc_pct: 80.0,
            temperature_c: 27.0,
            capacity_ah: 30.0,
        }
    }
}

impl Battery {
    /// Discharges for `dt` at the present current.
    pub fn step(&mut self, dt: Duration) {
        let ah = self.current_a * dt.as_secs_f64() / 3600.0;
        self.soc_pct = (self.soc_pct + 100.0 * ah / self.capacity_ah).clamp(0.0, 100.0);
        // A 16-cell LiFePO4 pack: 2.9 V empty to 3.4 V full per cell.
        self.voltage_v = 16.0 * (2.9 + 0.5 * self.soc_pct / 100.0);
    }
}

/// A Daly pack answering polls.
#[derive(Debug, Clone)]
pub struct SimDaly {
    /// The battery.
    pub battery: Battery,
    bms: u8,
    host: u8,
    sign: f64,
}

impl SimDaly {
    /// A pack at `bms` for `profile`'s host and current direction.
    pub fn new(profile: &DalyProfile, bms: u8) -> Self {
        Self {
            battery: Battery::default(),
            bms,
            host: profile.host_address,
            sign: match profile.current_above_offset {
                CurrentAboveOffset::Charge => 1.0,
                CurrentAboveOffset::Discharge => -1.0,
            },
        }
    }

    /// Answers a request addressed to this pack.
    pub fn on_frame(&mut self, frame: &Frame, out: &mut Vec<Frame>) {
        let id = frame.id();
        if !frame.is_extended()
            || id & 0xFF00_0000 != 0x1800_0000
            || (id >> 8) & 0xFF != u32::from(self.bms)
            || id & 0xFF != u32::from(self.host)
        {
            return;
        }
        let cmd = ((id >> 16) & 0xFF) as u8;
        let b = &self.battery;
        let be16 = |v: f64| (v.round().clamp(0.0, 65535.0) as u16).to_be_bytes();
        let data = match cmd {
            CMD_SOC => {
                let v = be16(b.voltage_v * 10.0);
                let i = be16(30_000.0 + b.current_a * 10.0 * self.sign);
                let s = be16(b.soc_pct * 10.0);
                [v[0], v[1], v[0], v[1], i[0], i[1], s[0], s[1]]
            }
            CMD_CELL_VOLTAGE_RANGE => {
                let cell = b.voltage_v / 16.0 * 1000.0;
                let hi = be16(cell + 5.0);
                let lo = be16(cell - 5.0);
                [hi[0], hi[1], 1, lo[0], lo[1], 9, 0, 0]
            }
            CMD_TEMPERATURE_RANGE => {
                let t = (b.temperature_c + 40.0).round().clamp(0.0, 255.0) as u8;
                [t, 1, t.saturating_sub(2), 2, 0, 0, 0, 0]
            }
            CMD_MOSFET => {
                let state = if b.current_a > 0.05 {
                    1
                } else if b.current_a < -0.05 {
                    2
                } else {
                    0
                };
                let mah =
                    ((b.soc_pct / 100.0 * b.capacity_ah * 1000.0).round() as u32).to_be_bytes();
                [state, 1, 1, 7, mah[0], mah[1], mah[2], mah[3]]
            }
            CMD_FAILURES => [0; 8],
            _ => return,
        };
        out.push(reply_frame(cmd, self.bms, self.host, data));
    }
}

/// Writes `physical` into `signal`'s bits of `data` (the inverse of extraction).
pub fn encode_signal(signal: &Signal, physical: f64, data: &mut [u8]) {
    let raw = ((physical - signal.offset) / signal.factor).round();
    let size = signal.size.min(64) as u32;
    let bits: u64 = match signal.value_type {
        ValueType::Signed => (raw as i64) as u64,
        ValueType::Unsigned => raw.max(0.0) as u64,
    } & if size == 64 {
        u64::MAX
    } else {
        (1u64 << size) - 1
    };
    match signal.byte_order {
        ByteOrder::LittleEndian => {
            for i in 0..size {
                let pos = signal.start_bit as usize + i as usize;
                set_bit(data, pos, (bits >> i) & 1 == 1);
            }
        }
        ByteOrder::BigEndian => {
            let mut pos = signal.start_bit as usize;
            for i in (0..size).rev() {
                set_bit(data, pos, (bits >> i) & 1 == 1);
                pos = if pos.is_multiple_of(8) {
                    pos + 15
                } else {
                    pos - 1
                };
            }
        }
    }
}

fn set_bit(data: &mut [u8], pos: usize, on: bool) {
    if let Some(byte) = data.get_mut(pos / 8) {
        let mask = 1u8 << (pos % 8);
        if on {
            *byte |= mask;
        } else {
            *byte &= !mask;
        }
    }
}

/// One broadcast message: id, extended, length, and the signals it carries.
#[derive(Debug, Clone)]
struct Message {
    id: u32,
    extended: bool,
    len: usize,
    signals: Vec<(Signal, Field)>,
}

/// A pack broadcasting the messages its DBC profile maps, once a second.
#[derive(Debug, Clone)]
pub struct SimDbcBms {
    /// The battery.
    pub battery: Battery,
    messages: Vec<Message>,
    sign: f64,
    next: Timestamp,
}

#[derive(Debug, Clone, Copy)]
enum Field {
    Voltage,
    Current,
    Soc,
    Temperature,
    RemainingCapacity,
}

impl SimDbcBms {
    /// A pack for `profile`; `None` when its DBC does not parse.
    pub fn new(profile: &DbcProfile) -> Option<Self> {
        let dbc = Dbc::try_from(profile.dbc_text.as_str()).ok()?;
        let f = &profile.fields;
        let wanted = [
            (Some(&f.voltage), Field::Voltage),
            (Some(&f.current), Field::Current),
            (Some(&f.soc), Field::Soc),
            (f.temperature.as_ref(), Field::Temperature),
            (f.remaining_capacity.as_ref(), Field::RemainingCapacity),
        ];
        let mut messages: Vec<Message> = Vec::new();
        for (reference, field) in wanted {
            let Some((m, s)) = reference.and_then(|r| r.split_once('.')) else {
                continue;
            };
            let message = dbc.messages.iter().find(|x| x.name == m)?;
            let signal = message.signals.iter().find(|x| x.name == s)?.clone();
            let (id, ext) = match message.id {
                MessageId::Standard(id) => (u32::from(id), false),
                MessageId::Extended(id) => (id, true),
            };
            match messages
                .iter_mut()
                .find(|x| x.id == id && x.extended == ext)
            {
                Some(entry) => entry.signals.push((signal, field)),
                None => messages.push(Message {
                    id,
                    extended: ext,
                    len: message.size as usize,
                    signals: vec![(signal, field)],
                }),
            }
        }
        Some(Self {
            battery: Battery::default(),
            messages,
            sign: profile.current_sign,
            next: Timestamp::default(),
        })
    }

    /// Broadcasts the mapped messages when due.
    pub fn step(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if t < self.next {
            return;
        }
        self.next = t.saturating_add(Duration::from_secs(1));
        let b = self.battery;
        for m in &self.messages {
            let mut data = vec![0u8; m.len.min(8)];
            for (signal, field) in &m.signals {
                let value = match field {
                    Field::Voltage => b.voltage_v,
                    Field::Current => b.current_a * self.sign,
                    Field::Soc => b.soc_pct,
                    Field::Temperature => b.temperature_c,
                    Field::RemainingCapacity => b.soc_pct / 100.0 * b.capacity_ah,
                };
                encode_signal(signal, value, &mut data);
            }
            let frame = if m.extended {
                Frame::extended(m.id, &data)
            } else {
                Frame::standard(m.id, &data)
            };
            out.extend(frame);
        }
    }
}
