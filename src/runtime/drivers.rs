//! Starts the device drivers a vehicle configuration names (the GNSS receiver, the IMU, each
//! CAN interface), for `chassisd run` and for `chassisd record` alike.

use std::collections::BTreeMap;
use std::time::Duration;

use tokio::sync::mpsc;

use super::can::{self, CanSpec, CanTx};
use super::clock::RecordClock;
use super::serial::{self, SerialSpec};
use crate::config::VehicleConfig;
use crate::engine::Decoder;
use crate::record::{Record, SourceMeta};

/// Source name of the GNSS receiver.
pub const GNSS_SOURCE: &str = "gnss";
/// Source name of the IMU.
pub const IMU_SOURCE: &str = "imu";

/// The running drivers of a configuration's devices.
pub struct Devices {
    /// Each serial source and the decoder its bytes need.
    pub decoders: Vec<(String, Decoder)>,
    /// Each source as a recording lists it.
    pub sources: Vec<SourceMeta>,
    /// The transmit queue of each CAN interface (never used by a listen-only recorder).
    pub can_tx: BTreeMap<String, CanTx>,
    /// The name of every device, which reports its link state under that name.
    pub names: Vec<String>,
}

/// Spawns one driver per device of `config`; records (and link events) go to `tx`.
pub fn start(config: &VehicleConfig, clock: RecordClock, tx: &mpsc::Sender<Record>) -> Devices {
    let mut devices = Devices {
        decoders: Vec::new(),
        sources: Vec::new(),
        can_tx: BTreeMap::new(),
        names: Vec::new(),
    };
    let serial_ports = [
        config.gnss.as_ref().map(|g| {
            let spec = SerialSpec {
                source: GNSS_SOURCE.into(),
                port: g.port.clone(),
                baud: g.baud,
                reconnect_max: g.reconnect_max(),
            };
            (spec, Decoder::Nmea)
        }),
        config.imu.as_ref().map(|i| {
            let spec = SerialSpec {
                source: IMU_SOURCE.into(),
                port: i.port.clone(),
                baud: i.baud,
                reconnect_max: Duration::from_secs_f64(i.reconnect_max_s),
            };
            (spec, Decoder::Imu(i.protocol))
        }),
    ];
    for (spec, decoder) in serial_ports.into_iter().flatten() {
        devices.decoders.push((spec.source.clone(), decoder));
        devices
            .sources
            .push(SourceMeta::serial(&spec.source, decoder.protocol()));
        devices.names.push(spec.source.clone());
        let tx = tx.clone();
        tokio::spawn(super::panics::restarting("serial driver", move || {
            serial::run(spec.clone(), clock, tx.clone())
        }));
    }
    for bus in &config.can {
        devices.sources.push(SourceMeta::can(&bus.interface));
        devices.names.push(bus.interface.clone());
        let spec = CanSpec {
            interface: bus.interface.clone(),
            reconnect_max: Duration::from_secs_f64(bus.reconnect_max_s),
        };
        devices.can_tx.insert(
            bus.interface.clone(),
            can::spawn(spec, clock, tx.clone(), bus.tx_queue),
        );
    }
    devices
}
