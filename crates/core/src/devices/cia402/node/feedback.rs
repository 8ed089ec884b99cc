//! Feedback in: statusword, velocity and position from TPDOs, from SDO poll answers, or (in
//! listen-only mode) from another master's SDO traffic.

use super::fault::DriveFault;
use super::{DriveNode, Tag};
use crate::devices::can::Frame;
use crate::devices::canopen::ObjectAddress;
use crate::devices::canopen::sdo::{SdoData, SdoRequest};
use crate::devices::cia402::profile::Transport;
use crate::devices::cia402::state::DriveState;
use crate::time::Timestamp;

impl DriveNode {
    /// Takes an object value from an SDO answer: a poll's, or (listen-only mode) one to
    /// another master.
    pub(super) fn observe(&mut self, t: Timestamp, addr: ObjectAddress, data: SdoData) {
        let value = if addr == self.profile.objects.statusword {
            i64::from(data.as_u32())
        } else {
            i64::from(data.as_i32())
        };
        self.take(t, addr, value);
    }

    /// Takes one feedback object's value: a statusword (of one axis, or two packed in 32
    /// bits), an actual velocity or an actual position.
    fn take(&mut self, t: Timestamp, object: ObjectAddress, value: i64) {
        let objects = &self.profile.objects;
        if object == objects.statusword {
            if objects.statusword_bits == 32 {
                self.set_statusword(0, (value & 0xFFFF) as u16, t);
                self.set_statusword(1, ((value >> 16) & 0xFFFF) as u16, t);
            } else {
                self.set_statusword(0, value as u16, t);
            }
            return;
        }
        for (a, axis) in self.axes.iter_mut().enumerate() {
            if objects.actual_velocity.get(a) == Some(&object) {
                axis.velocity = Some(value as i32);
                axis.rx = Some(t);
                axis.velocity_rx = Some(t);
            }
            if objects.actual_position.get(a) == Some(&object) {
                axis.position = Some(value as i32);
                axis.rx = Some(t);
            }
        }
    }

    pub(super) fn set_statusword(&mut self, axis: usize, sw: u16, t: Timestamp) {
        if let Some(a) = self.axes.get_mut(axis) {
            a.statusword = Some(sw);
            a.rx = Some(t);
        }
        if DriveState::from_statusword(sw).is_fault() {
            self.raise(DriveFault::Drive {
                axis,
                statusword: sw,
            });
        }
    }

    pub(super) fn on_tpdo(&mut self, t: Timestamp, frame: &Frame) {
        let Some((_, mapping)) = self.tpdos.iter().find(|(cob, _)| *cob == frame.id()) else {
            return;
        };
        let Some(values) = mapping.unpack(frame.data()) else {
            self.stats.short_tpdos += 1;
            return;
        };
        self.stats.tpdos += 1;
        for (object, value) in values {
            self.take(t, object, value);
        }
    }

    pub(super) fn request_feedback(&mut self) {
        if self.profile.feedback.mode != Transport::Sdo {
            return;
        }
        let objects = &self.profile.objects;
        self.sdo
            .push(SdoRequest::Read(objects.statusword), Tag::Feedback);
        for object in objects
            .actual_velocity
            .iter()
            .chain(&objects.actual_position)
        {
            self.sdo.push(SdoRequest::Read(*object), Tag::Feedback);
        }
    }
}
