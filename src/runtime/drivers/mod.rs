//! Starts the device drivers a vehicle configuration names (the GNSS receiver, the IMU, each
//! CAN interface), for `chassisd run` and for `chassisd record` alike.

pub mod can;
pub mod serial;
pub mod serial_open;
pub mod serial_tx;
pub mod ublox;

use std::collections::BTreeMap;
use std::time::Duration;

use tokio::sync::mpsc;

use crate::config::VehicleConfig;
use crate::engine::{CORRECTIONS_PORT, Decoder};
use crate::record::{Record, SourceMeta};
use crate::runtime::clock::RecordClock;
use can::{CanSpec, CanTx};
use serial::SerialSpec;
use serial_tx::SerialTx;

/// Source name of the GNSS receiver.
pub use crate::engine::GNSS_SOURCE;
/// Source name of the IMU.
pub const IMU_SOURCE: &str = crate::sources::IMU;

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
    /// The write queue of each serial port written to (the receiver's corrections).
    pub serial_tx: BTreeMap<String, SerialTx>,
}

/// What the drivers are for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Driving the vehicle: ports may be written (corrections to the receiver).
    Drive,
    /// Listening only: nothing is written anywhere.
    Listen,
}

/// Spawns one driver per device of `config`; records (and link events) go to `tx`.
pub fn start(
    config: &VehicleConfig,
    clock: RecordClock,
    tx: &mpsc::Sender<Record>,
    mode: Mode,
) -> Devices {
    let mut devices = Devices {
        decoders: Vec::new(),
        sources: Vec::new(),
        can_tx: BTreeMap::new(),
        names: Vec::new(),
        serial_tx: BTreeMap::new(),
    };
    // Corrections go to the receiver's port, or to a port of their own.
    let corrections = config
        .ntrip
        .as_ref()
        .filter(|_| mode == Mode::Drive)
        .map(|n| {
            let port = if n.port.is_some() {
                CORRECTIONS_PORT
            } else {
                GNSS_SOURCE
            };
            let queue = SerialTx::new(
                n.queue_frames,
                "RTCM corrections dropped: the receiver's port is not taking them",
            );
            devices.serial_tx.insert(port.to_owned(), queue.clone());
            (n, queue)
        });
    if let Some((n, queue)) = &corrections
        && let Some(port) = &n.port
    {
        let spec = SerialSpec {
            source: CORRECTIONS_PORT.into(),
            port: port.clone(),
            baud: n.baud,
            reconnect_max: Duration::from_secs(30),
            writes: Some(queue.clone()),
            forward_reads: false,
        };
        let tx = tx.clone();
        tokio::spawn(crate::runtime::panics::restarting(
            "corrections port",
            move || serial::run(spec.clone(), clock, tx.clone()),
        ));
    }
    let serial_ports = [
        config.gnss.as_ref().map(|g| {
            let spec = SerialSpec {
                source: GNSS_SOURCE.into(),
                port: g.port.clone(),
                baud: g.baud,
                reconnect_max: g.reconnect_max(),
                writes: devices.serial_tx.get(GNSS_SOURCE).cloned(),
                forward_reads: true,
            };
            (spec, Decoder::Nmea)
        }),
        config.imu.as_ref().map(|i| {
            let spec = SerialSpec {
                source: IMU_SOURCE.into(),
                port: i.port.clone(),
                baud: i.baud,
                reconnect_max: Duration::from_secs_f64(i.reconnect_max_s),
                writes: None,
                forward_reads: true,
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
        tokio::spawn(crate::runtime::panics::restarting(
            "serial driver",
            move || serial::run(spec.clone(), clock, tx.clone()),
        ));
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
