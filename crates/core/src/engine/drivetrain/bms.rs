//! The battery's BMS on its interface: polled (Daly) or listened to (DBC).

use super::device::{CanDevice, Heard};
use crate::config::VehicleConfig;
use crate::config::chassis::{BmsConfig, CanBusConfig};
use crate::devices::bms::daly::DalyBms;
use crate::devices::bms::dbc::DbcBms;
use crate::devices::bms::profile::CurrentAboveOffset;
use crate::devices::bms::{BmsDevice, BmsProfile, BmsReading};
use crate::devices::can::Frame;
use crate::time::Timestamp;

/// The BMS `config` describes, ready to poll and decode.
pub fn bms_device(config: &BmsConfig) -> Option<BmsDevice> {
    Some(match config.profile.get()? {
        BmsProfile::Daly(p) => BmsDevice::Daly(DalyBms::new(
            config.address,
            p.host_address,
            match p.current_above_offset {
                CurrentAboveOffset::Charge => 1.0,
                CurrentAboveOffset::Discharge => -1.0,
            },
            config.poll_hz,
        )),
        BmsProfile::Dbc(p) => BmsDevice::Dbc(DbcBms::new(p).ok()?),
    })
}

/// The `[bms]` of `bus`.
pub fn build(config: &VehicleConfig, bus: &CanBusConfig) -> Vec<Box<dyn CanDevice>> {
    config
        .bms
        .as_ref()
        .filter(|b| b.bus == bus.interface)
        .and_then(bms_device)
        .map(|b| Box::new(b) as Box<dyn CanDevice>)
        .into_iter()
        .collect()
}

impl CanDevice for BmsDevice {
    fn on_frame(&mut self, t: Timestamp, frame: &Frame, _out: &mut Vec<Frame>) -> Heard {
        if BmsDevice::on_frame(self, t, frame) {
            Heard::Changed
        } else {
            Heard::Nothing
        }
    }

    fn poll(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        BmsDevice::poll(self, t, out);
    }

    fn bms(&self) -> Option<&BmsReading> {
        Some(self.reading())
    }
}
