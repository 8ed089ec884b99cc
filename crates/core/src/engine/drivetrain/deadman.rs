//! What chassisd itself produces on an interface with drives, so that they notice when it is
//! gone: its heartbeat as the CANopen master, and SYNC when a drive watches SYNC.

use std::time::Duration;

use super::device::{CanDevice, Heard};
use crate::config::VehicleConfig;
use crate::config::chassis::CanBusConfig;
use crate::devices::can::Frame;
use crate::devices::canopen::NodeId;
use crate::devices::canopen::nmt::{NmtState, heartbeat_frame};
use crate::devices::cia402::profile::MasterLoss;
use crate::time::Timestamp;

/// The master's heartbeat and SYNC on one interface.
#[derive(Debug, Clone)]
pub struct Deadman {
    /// chassisd's heartbeat: node id, period, next due.
    heartbeat: (NodeId, Duration, Option<Timestamp>),
    /// SYNC period and next due, when a drive watches SYNC.
    sync: Option<(Duration, Option<Timestamp>)>,
}

/// The deadman of `bus`, when it carries drives and chassisd may send there.
pub fn build(config: &VehicleConfig, bus: &CanBusConfig) -> Vec<Box<dyn CanDevice>> {
    if bus.listen_only || super::drive::build(config, bus).is_empty() {
        return Vec::new();
    }
    let watches_sync = config.drive.iter().any(|d| {
        d.bus == bus.interface
            && matches!(
                d.profile.get().and_then(|p| p.master_loss),
                Some(MasterLoss::Sync { .. })
            )
    });
    NodeId::new(bus.master_node)
        .map(|node| {
            Box::new(Deadman {
                heartbeat: (node, Duration::from_millis(bus.master_heartbeat_ms), None),
                sync: watches_sync.then(|| (Duration::from_millis(bus.sync_ms), None)),
            }) as Box<dyn CanDevice>
        })
        .into_iter()
        .collect()
}

impl CanDevice for Deadman {
    fn on_frame(&mut self, _t: Timestamp, _frame: &Frame, _out: &mut Vec<Frame>) -> Heard {
        Heard::Nothing
    }

    fn poll(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        let (node, period, next) = &mut self.heartbeat;
        if next.is_none_or(|n| t >= n) {
            out.push(heartbeat_frame(*node, NmtState::Operational));
            *next = Some(t.saturating_add(*period));
        }
        if let Some((period, next)) = &mut self.sync
            && next.is_none_or(|n| t >= n)
        {
            out.push(Frame::std(0x080, []));
            *next = Some(t.saturating_add(*period));
        }
    }
}
