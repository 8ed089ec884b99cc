//! What the latched topics last carried, to tell when it changed: a latched topic goes out
//! when what it carries changes (and first at the first status), and the server keeps its
//! last message for the next subscriber.

use std::sync::Arc;

use serde_json::Value;

use super::{envelope, messages};
use crate::control::MotionId;
use crate::vehicle::VehicleStatus;
use crate::zones::local::ZoneOutline;

/// What the latched topics last carried (`None`: nothing sent yet).
#[derive(Debug, Default)]
pub struct Latches {
    /// The motion whose path `/plan` carried (`Some(None)`: no motion).
    plan: Option<Option<MotionId>>,
    /// The zones `/zones` carried, the same `Arc` until they change.
    zones: Option<Option<Arc<[ZoneOutline]>>>,
}

impl Latches {
    /// `/plan`'s message when the motion under way is another than the one it last carried.
    pub fn plan(&mut self, status: &VehicleStatus) -> Option<Value> {
        let plan = status.plan.as_ref().map(|p| p.id);
        if self.plan == Some(plan) {
            return None;
        }
        self.plan = Some(plan);
        let points = status.plan.as_ref().map_or(&[][..], |p| &p.points[..]);
        Some(messages::path(status.time, points))
    }

    /// `/zones`' message when the zones were drawn again (an edit, even one that leaves them
    /// looking the same) or went or came.
    pub fn zones(&mut self, status: &VehicleStatus) -> Option<Value> {
        let zones = status.envelope.as_ref().and_then(|e| e.zones.clone());
        let same = |last: &Option<Arc<[ZoneOutline]>>| match (last, &zones) {
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            (a, b) => a.is_none() && b.is_none(),
        };
        if self.zones.as_ref().is_some_and(same) {
            return None;
        }
        let outlines = zones.as_deref().unwrap_or(&[]);
        let msg = envelope::zones(status.time, outlines);
        self.zones = Some(zones);
        Some(msg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latched_topics_go_out_first_and_then_only_when_they_change() {
        use crate::vehicle::envelope::EnvelopeStatus;
        let mut latches = Latches::default();
        let mut status = VehicleStatus::default();
        assert!(latches.plan(&status).is_some());
        assert!(latches.zones(&status).is_some());
        assert!(latches.plan(&status).is_none());
        assert!(latches.zones(&status).is_none());
        let outlines: Arc<[ZoneOutline]> = Vec::new().into();
        status.envelope = Some(EnvelopeStatus {
            gate_closed: None,
            zones: Some(outlines.clone()),
            nearest: None,
            footprint_m: 0.5,
            sigma_m: None,
            braking_m: 0.0,
        });
        assert!(latches.plan(&status).is_none());
        assert!(latches.zones(&status).is_some());
        // A status carrying the same zones (a clone of the Arc) sends nothing.
        assert!(latches.zones(&status.clone()).is_none());
        // Zones drawn again (an edit) go out, even when they look the same.
        if let Some(e) = &mut status.envelope {
            e.zones = Some(Vec::new().into());
        }
        assert!(latches.zones(&status).is_some());
    }
}
