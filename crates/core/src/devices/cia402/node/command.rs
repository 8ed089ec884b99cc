//! Commands out: the controlword and targets, by RPDO or by SDO write, when they change
//! and at least at the profile's command rate.

use std::time::Duration;

use super::{DriveNode, Tag};
use crate::devices::can::Frame;
use crate::devices::canopen::ObjectAddress;
use crate::devices::canopen::sdo::{SdoData, SdoRequest};
use crate::devices::cia402::profile::DriveProfile;
use crate::time::Timestamp;

pub(super) fn period(hz: f64) -> Duration {
    Duration::from_secs_f64(1.0 / hz.max(0.001))
}

/// Two i16 targets packed as the ZLAC8015D's 0x60FF:3 takes them: axis 1 low, axis 2 high.
pub(super) fn combine(targets: &[i32]) -> u32 {
    let lo = targets.first().copied().unwrap_or(0) as i16 as u16;
    let hi = targets.get(1).copied().unwrap_or(0) as i16 as u16;
    (u32::from(hi) << 16) | u32::from(lo)
}

pub(super) fn target_writes(profile: &DriveProfile, targets: &[i32]) -> Vec<SdoRequest> {
    match profile.objects.combined_target_velocity {
        Some(object) => vec![SdoRequest::Write(object, SdoData::u32(combine(targets)))],
        None => profile
            .objects
            .target_velocity
            .iter()
            .zip(targets)
            .map(|(o, v)| SdoRequest::Write(*o, SdoData::i32(*v)))
            .collect(),
    }
}

impl DriveNode {
    pub(super) fn send_sdo_commands(&mut self, t: Timestamp) {
        // One controlword write at a time; the next waits for the drive's answer.
        if self.sent_controlword != Some(self.controlword) && self.queued_controlword.is_none() {
            self.queued_controlword = Some(self.controlword);
            self.sdo.push(
                SdoRequest::Write(
                    self.profile.objects.controlword,
                    SdoData::u16(self.controlword),
                ),
                Tag::Controlword(self.controlword),
            );
        }
        let changed = self.sent_targets.as_deref() != Some(self.targets.as_slice());
        if (changed || t >= self.next_command) && self.sdo.backlog() <= 2 {
            self.next_command = t.saturating_add(period(self.profile.command.rate_hz));
            for request in target_writes(&self.profile, &self.targets) {
                self.sdo.push(request, Tag::Target);
            }
            self.sent_targets = Some(self.targets.clone());
        }
    }

    /// Sends the RPDOs when something changed or the command period elapsed.
    pub(super) fn send_rpdos(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        let changed = self.sent_controlword != Some(self.controlword)
            || self.sent_targets.as_deref() != Some(self.targets.as_slice());
        if !changed && t < self.next_command {
            return;
        }
        self.next_command = t.saturating_add(period(self.profile.command.rate_hz));
        for (cob, mapping) in &self.rpdos {
            let values: Vec<i64> = mapping
                .entries()
                .iter()
                .map(|e| self.value_of(e.object))
                .collect();
            if let Some(frame) = Frame::standard(*cob, &mapping.pack(&values)) {
                out.push(frame);
            }
        }
        self.sent_controlword = Some(self.controlword);
        self.sent_targets = Some(self.targets.clone());
    }

    /// The value chassisd writes to `object` in an RPDO.
    pub(super) fn value_of(&self, object: ObjectAddress) -> i64 {
        let objects = &self.profile.objects;
        if object == objects.controlword {
            return i64::from(self.controlword);
        }
        if Some(object) == objects.combined_target_velocity {
            return i64::from(combine(&self.targets));
        }
        objects
            .target_velocity
            .iter()
            .position(|o| *o == object)
            .and_then(|a| self.targets.get(a))
            .map_or(0, |v| i64::from(*v))
    }
}
