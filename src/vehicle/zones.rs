//! The zones as the core keeps them, and the plan-time check: a motion whose way (the
//! footprint's disc grown by the margin, swept along it) meets a zone is refused before it
//! starts, with the zone and the place.

use super::chassis::CommandRejected;
use crate::fusion::localizer::MapPlacement;
use crate::zones::ZoneSet;
use crate::zones::local::LocalZones;

/// The zones and the disc they are kept from.
#[derive(Debug, Clone)]
pub struct ZoneGuard {
    set: ZoneSet,
    radius_m: f64,
    /// The zones in the map frame, and where that frame lay when they were placed.
    placed: Option<(MapPlacement, LocalZones)>,
}

impl ZoneGuard {
    /// `set`, kept `radius_m` from (the footprint's circumscribed radius plus the margin).
    pub fn new(set: ZoneSet, radius_m: f64) -> Self {
        Self {
            set,
            radius_m,
            placed: None,
        }
    }

    /// The zones in the map frame as `placement` puts it (placed again when it moved).
    fn local(&mut self, placement: MapPlacement) -> &LocalZones {
        if self.placed.as_ref().is_some_and(|(p, _)| *p != placement) {
            self.placed = None;
        }
        let set = &self.set;
        let (_, local) = self.placed.get_or_insert_with(|| {
            (
                placement,
                LocalZones::new(set, |lat, lon| placement.place(lat, lon)),
            )
        });
        local
    }

    /// Refuses the way through `points` (map frame, from where the vehicle stands) where
    /// it first meets a zone. Without a placement (no datum yet) nothing can be checked, so
    /// the way is refused.
    pub fn check_way(
        &mut self,
        placement: Option<MapPlacement>,
        points: &[(f64, f64)],
    ) -> Result<(), CommandRejected> {
        let Some(placement) = placement else {
            return Err(CommandRejected::ZonesUnplaced);
        };
        let radius = self.radius_m;
        match self.local(placement).path_conflict(points, radius) {
            None => Ok(()),
            Some(c) => Err(CommandRejected::Zone {
                kind: c.kind.name(),
                name: c.name,
                x: c.at.0,
                y: c.at.1,
            }),
        }
    }
}
