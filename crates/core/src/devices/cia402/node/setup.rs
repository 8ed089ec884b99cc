//! The SDO set-up a node gets after boot-up, in order: heartbeat producer, the
//! loss-of-master watchdog, profile velocity mode, zero targets, PDO configuration, then the
//! profile's own writes.

use super::NodeSettings;
use super::command::target_writes;
use crate::devices::canopen::pdo::TpdoTrigger;
use crate::devices::canopen::sdo::{SdoData, SdoRequest};
use crate::devices::canopen::{rpdo_cob_id, tpdo_cob_id};
use crate::devices::cia402::profile::{
    ABORT_CONNECTION_OPTION, COMMUNICATION_CYCLE, CONSUMER_HEARTBEAT, DriveProfile, MasterLoss,
    Transport, ValueType,
};

/// Profile velocity mode.
const PROFILE_VELOCITY_MODE: i8 = 3;

/// The writes that make the drive stop by itself when chassisd is gone (the profile's
/// `[master_loss]`).
pub(super) fn master_loss_writes(
    settings: &NodeSettings,
    profile: &DriveProfile,
) -> Vec<SdoRequest> {
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
pub(super) fn setup_writes(settings: &NodeSettings, profile: &DriveProfile) -> Vec<SdoRequest> {
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
