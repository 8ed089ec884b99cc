//! Battery management systems on CAN: Daly (polled) and any broadcast BMS described by a
//! DBC file. Both produce the same [`BmsReading`].

pub mod daly;
pub mod dbc;
pub mod profile;

use std::time::Duration;

use crate::devices::can::Frame;
use crate::time::Timestamp;

pub use profile::BmsProfile;

/// Alarm bits of `bms.error`, normalised across BMS protocols.
pub mod alarm {
    /// A cell is over voltage.
    pub const CELL_OVERVOLTAGE: u32 = 1 << 0;
    /// A cell is under voltage.
    pub const CELL_UNDERVOLTAGE: u32 = 1 << 1;
    /// The pack is over voltage.
    pub const PACK_OVERVOLTAGE: u32 = 1 << 2;
    /// The pack is under voltage.
    pub const PACK_UNDERVOLTAGE: u32 = 1 << 3;
    /// Too hot to charge.
    pub const CHARGE_OVER_TEMPERATURE: u32 = 1 << 4;
    /// Too cold to charge.
    pub const CHARGE_UNDER_TEMPERATURE: u32 = 1 << 5;
    /// Too hot to discharge.
    pub const DISCHARGE_OVER_TEMPERATURE: u32 = 1 << 6;
    /// Too cold to discharge.
    pub const DISCHARGE_UNDER_TEMPERATURE: u32 = 1 << 7;
    /// Charge over-current.
    pub const CHARGE_OVER_CURRENT: u32 = 1 << 8;
    /// Discharge over-current.
    pub const DISCHARGE_OVER_CURRENT: u32 = 1 << 9;
    /// State of charge low.
    pub const SOC_LOW: u32 = 1 << 10;
    /// Cell voltages too far apart.
    pub const CELL_IMBALANCE: u32 = 1 << 11;
    /// Temperatures too far apart.
    pub const TEMPERATURE_IMBALANCE: u32 = 1 << 12;
    /// MOSFET over-temperature or failure.
    pub const MOSFET_FAULT: u32 = 1 << 13;
    /// BMS hardware fault (measurement chip, sensor, EEPROM, clock).
    pub const HARDWARE_FAULT: u32 = 1 << 14;
    /// Short circuit protection.
    pub const SHORT_CIRCUIT: u32 = 1 << 15;
    /// BMS internal communication fault.
    pub const COMMUNICATION_FAULT: u32 = 1 << 16;
    /// A protection level was reached: the BMS has cut (or will cut) charge or discharge.
    pub const PROTECTION_TRIPPED: u32 = 1 << 17;
    /// State of charge high.
    pub const SOC_HIGH: u32 = 1 << 18;

    /// Every bit with its configuration name, in bit order.
    pub const NAMES: [(&str, u32); 19] = [
        ("cell_overvoltage", CELL_OVERVOLTAGE),
        ("cell_undervoltage", CELL_UNDERVOLTAGE),
        ("pack_overvoltage", PACK_OVERVOLTAGE),
        ("pack_undervoltage", PACK_UNDERVOLTAGE),
        ("charge_over_temperature", CHARGE_OVER_TEMPERATURE),
        ("charge_under_temperature", CHARGE_UNDER_TEMPERATURE),
        ("discharge_over_temperature", DISCHARGE_OVER_TEMPERATURE),
        ("discharge_under_temperature", DISCHARGE_UNDER_TEMPERATURE),
        ("charge_over_current", CHARGE_OVER_CURRENT),
        ("discharge_over_current", DISCHARGE_OVER_CURRENT),
        ("soc_low", SOC_LOW),
        ("cell_imbalance", CELL_IMBALANCE),
        ("temperature_imbalance", TEMPERATURE_IMBALANCE),
        ("mosfet_fault", MOSFET_FAULT),
        ("hardware_fault", HARDWARE_FAULT),
        ("short_circuit", SHORT_CIRCUIT),
        ("communication_fault", COMMUNICATION_FAULT),
        ("protection_tripped", PROTECTION_TRIPPED),
        ("soc_high", SOC_HIGH),
    ];

    /// The bit of a configuration name.
    pub fn by_name(name: &str) -> Option<u32> {
        NAMES.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
    }
}

/// Bits of `bms.status`.
pub mod status {
    /// A reading younger than the stale timeout.
    pub const FRESH: u32 = 1 << 0;
    /// No reading within the stale timeout; the values are the last known.
    pub const STALE: u32 = 1 << 1;
    /// Charging.
    pub const CHARGING: u32 = 1 << 2;
    /// Discharging.
    pub const DISCHARGING: u32 = 1 << 3;
    /// Charge MOSFET on.
    pub const CHARGE_MOSFET: u32 = 1 << 4;
    /// Discharge MOSFET on.
    pub const DISCHARGE_MOSFET: u32 = 1 << 5;
    /// Nothing received since start.
    pub const NEVER_RECEIVED: u32 = 1 << 6;
}

impl BmsReading {
    /// The `bms.status` bits of this reading.
    pub fn status_bits(&self, stale: bool) -> u32 {
        let mut bits = if stale { status::STALE } else { status::FRESH };
        if self.rx.is_none() {
            bits |= status::NEVER_RECEIVED;
        }
        match self.charge_state {
            Some(ChargeState::Charging) => bits |= status::CHARGING,
            Some(ChargeState::Discharging) => bits |= status::DISCHARGING,
            _ => {}
        }
        if self.charge_mosfet == Some(true) {
            bits |= status::CHARGE_MOSFET;
        }
        if self.discharge_mosfet == Some(true) {
            bits |= status::DISCHARGE_MOSFET;
        }
        bits
    }
}

/// Whether the pack is charging.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ChargeState {
    /// Neither charging nor discharging.
    #[default]
    Idle,
    /// Charging.
    Charging,
    /// Discharging.
    Discharging,
}

/// What a BMS reported, in SI units. Fields a protocol lacks stay `None`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BmsReading {
    /// Pack voltage, V.
    pub voltage_v: Option<f64>,
    /// Pack current, A; positive while charging.
    pub current_a: Option<f64>,
    /// State of charge, %.
    pub soc_pct: Option<f64>,
    /// Highest temperature, °C.
    pub temperature_c: Option<f64>,
    /// Remaining capacity, Ah.
    pub remaining_capacity_ah: Option<f64>,
    /// Charge state, from the BMS when it says, else from the current's sign.
    pub charge_state: Option<ChargeState>,
    /// Charge MOSFET on.
    pub charge_mosfet: Option<bool>,
    /// Discharge MOSFET on.
    pub discharge_mosfet: Option<bool>,
    /// Highest and lowest cell voltage, V.
    pub cell_voltage_range_v: Option<(f64, f64)>,
    /// Alarm bits ([`alarm`]).
    pub alarms: u32,
    /// When the last valid message arrived.
    pub rx: Option<Timestamp>,
}

/// A BMS on a bus.
#[derive(Debug, Clone)]
pub enum BmsDevice {
    /// Daly, polled.
    Daly(daly::DalyBms),
    /// DBC-described, broadcast.
    Dbc(dbc::DbcBms),
}

impl BmsDevice {
    /// Sends what is due (Daly requests).
    pub fn poll(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        match self {
            Self::Daly(d) => d.poll(t, out),
            Self::Dbc(_) => {}
        }
    }

    /// Takes a frame; returns whether it updated the reading.
    pub fn on_frame(&mut self, t: Timestamp, frame: &Frame) -> bool {
        match self {
            Self::Daly(d) => d.on_frame(t, frame),
            Self::Dbc(d) => d.on_frame(t, frame),
        }
    }

    /// The reading so far.
    pub fn reading(&self) -> &BmsReading {
        match self {
            Self::Daly(d) => d.reading(),
            Self::Dbc(d) => d.reading(),
        }
    }

    /// Frames that failed to decode.
    pub fn malformed(&self) -> u64 {
        match self {
            Self::Daly(d) => d.malformed(),
            Self::Dbc(_) => 0,
        }
    }
}

/// Whether a reading is older than `stale_after` at `t` (or never arrived).
pub fn is_stale(reading: &BmsReading, t: Timestamp, stale_after: Duration) -> bool {
    reading
        .rx
        .is_none_or(|rx| t.saturating_since(rx) > stale_after)
}
