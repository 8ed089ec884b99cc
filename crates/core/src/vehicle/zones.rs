//! The zones as the core keeps them, and their two checks:
//! - at plan time, a motion whose way (the footprint's disc grown by the margin, swept
//!   along it) meets a zone is refused before it starts, with the zone and the place;
//! - at run time, every control tick, the footprint's disc grown by the position's σ is
//!   swept along the way the vehicle would cover if it braked now (from the speed the
//!   wheels measure, and from the speed it is about to be sent): a way into a zone stops it.
//!   At plan time the way is kept the larger of the margin and what the run-time check
//!   will take at the motion's speed (σ and the braking way), so a planned way does not trip
//!   it.

use std::sync::Arc;

use super::chassis::CommandRejected;
use crate::fusion::localizer::MapPlacement;
use crate::zones::local::{Conflict, LocalZones, ZoneOutline};
use crate::zones::{LonLat, Shape, ZoneKind, ZoneSet};

/// A shape in the map frame (m), as an edit gives it.
#[derive(Debug, Clone, PartialEq)]
pub enum MapShape {
    /// A polygon's corners (closed here when the last does not repeat the first).
    Polygon(Vec<(f64, f64)>),
    /// A circle: its centre and radius, m.
    Circle((f64, f64), f64),
    /// A line through these points (closed when the last repeats the first).
    Line(Vec<(f64, f64)>),
}

/// An edit of the zones at run time (ROS1 `/set_shape`, `/set_region`).
#[derive(Debug, Clone, PartialEq)]
pub enum ZoneEdit {
    /// Add a zone.
    Add {
        /// Its name.
        name: String,
        /// What it asks.
        kind: ZoneKind,
        /// Where, in the map frame.
        shape: MapShape,
    },
    /// Remove the zone of this id.
    Remove(u32),
}

/// A braking way is drawn in steps of at most this, m.
const WAY_STEP_M: f64 = 0.1;
/// Below this speed the vehicle is taken to stand (m/s): its way is its place.
const STANDING_MPS: f64 = 1e-3;
/// A way that ends this much nearer a zone it already stands too close to goes deeper, m.
const DEEPER_M: f64 = 1e-3;

/// The zones and the discs they are kept from.
#[derive(Debug, Clone)]
pub struct ZoneGuard {
    set: ZoneSet,
    /// The footprint's circumscribed radius, m.
    footprint_m: f64,
    /// The plan's margin beyond it, m.
    margin_m: f64,
    /// The zones in the map frame, and where that frame lay when they were placed.
    placed: Option<(MapPlacement, LocalZones)>,
    /// Their outlines, drawn from `placed` when a client first asks.
    outlines: Option<Arc<[ZoneOutline]>>,
}

/// The zone nearest the vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct NearestZone {
    /// Its name.
    pub name: String,
    /// What it asks.
    pub kind: ZoneKind,
    /// From the footprint's edge to the zone's, on the allowed side (negative: into it), m.
    pub clearance_m: f64,
}

impl ZoneGuard {
    /// `set`, kept from a footprint of circumscribed radius `footprint_m`, with `margin_m`
    /// more at plan time.
    pub fn new(set: ZoneSet, footprint_m: f64, margin_m: f64) -> Self {
        Self {
            set,
            footprint_m,
            margin_m,
            placed: None,
            outlines: None,
        }
    }

    /// The footprint's circumscribed radius, m.
    pub fn footprint_m(&self) -> f64 {
        self.footprint_m
    }

    /// The zones' outlines in the map frame as `placement` puts it: the same `Arc` until an
    /// edit or a move of the frame, so a client redraws them only then.
    pub fn outlines(&mut self, placement: MapPlacement) -> Arc<[ZoneOutline]> {
        self.local(placement);
        let placed = &self.placed;
        self.outlines
            .get_or_insert_with(|| {
                placed
                    .as_ref()
                    .map_or_else(Vec::new, |(_, zones)| zones.outlines())
                    .into()
            })
            .clone()
    }

    /// The zone nearest the footprint at `p` (map frame), if there are zones.
    pub fn nearest(&mut self, placement: MapPlacement, p: (f64, f64)) -> Option<NearestZone> {
        let footprint_m = self.footprint_m;
        self.local(placement)
            .nearest(p)
            .map(|(zone, clearance)| NearestZone {
                name: zone.name.clone(),
                kind: zone.kind,
                clearance_m: clearance - footprint_m,
            })
    }

    /// The zones.
    pub fn set(&self) -> &ZoneSet {
        &self.set
    }

    /// Applies `edit` (map coordinates placed on WGS84 by `placement`): the id of the zone
    /// added or removed. A zone that cannot be is refused with the reason, the set unchanged.
    pub fn edit(
        &mut self,
        placement: Option<MapPlacement>,
        edit: &ZoneEdit,
    ) -> Result<u32, CommandRejected> {
        let id = match edit {
            ZoneEdit::Remove(id) => {
                self.set
                    .remove(*id)
                    .ok_or_else(|| CommandRejected::ZoneEdit(format!("no zone has id {id}")))?;
                *id
            }
            ZoneEdit::Add { name, kind, shape } => {
                let placement = placement.ok_or_else(|| {
                    CommandRejected::ZoneEdit(
                        "a zone given in the map frame cannot be placed yet: there is no datum \
                         (localization.datum, SET_LNG_LAT, or the first valid fix sets it)"
                            .into(),
                    )
                })?;
                let at = |&(x, y): &(f64, f64)| -> LonLat {
                    let (lat, lon) = placement.geodetic(x, y);
                    [lon, lat]
                };
                let shape = match shape {
                    MapShape::Polygon(corners) => {
                        let mut ring: Vec<LonLat> = corners.iter().map(at).collect();
                        if let (Some(first), Some(last)) = (corners.first(), corners.last())
                            && first != last
                        {
                            ring.push(at(first));
                        }
                        Shape::Polygon(vec![ring])
                    }
                    MapShape::Circle(centre, radius_m) => Shape::Circle {
                        centre: at(centre),
                        radius_m: *radius_m,
                    },
                    MapShape::Line(points) => Shape::Line(points.iter().map(at).collect()),
                };
                self.set
                    .add(name, *kind, shape)
                    .map_err(|e| CommandRejected::ZoneEdit(e.to_string()))?
            }
        };
        self.placed = None;
        self.outlines = None;
        Ok(id)
    }

    /// The zones in the map frame as `placement` puts it (placed again when it moved).
    fn local(&mut self, placement: MapPlacement) -> &LocalZones {
        if self.placed.as_ref().is_some_and(|(p, _)| *p != placement) {
            self.placed = None;
            self.outlines = None;
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
    /// it first meets a zone, kept the larger of the margin and `run_time_m` (what the
    /// run-time check will take: the position's σ and the braking way at the motion's
    /// speed) beyond the footprint. Without a placement (no datum yet) nothing can be
    /// checked, so the way is refused.
    pub fn check_way(
        &mut self,
        placement: Option<MapPlacement>,
        points: &[(f64, f64)],
        run_time_m: f64,
    ) -> Result<(), CommandRejected> {
        let Some(placement) = placement else {
            return Err(CommandRejected::ZonesUnplaced);
        };
        let radius = self.footprint_m + self.margin_m.max(run_time_m);
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

/// How the vehicle brakes, for the run-time check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Braking {
    /// From a decision to the drives braking: the pose's age, a control period and the
    /// drives' response, s.
    pub reaction_s: f64,
    /// The deceleration the drives brake at, at least, m/s².
    pub decel_mps2: f64,
}

impl Braking {
    /// The distance covered braking from `speed` (m/s) to rest: the reaction's and the
    /// braking's, m.
    pub fn distance(&self, speed: f64) -> f64 {
        let speed = speed.abs();
        speed * self.reaction_s + speed * speed / (2.0 * self.decel_mps2)
    }

    /// The way a vehicle at `pose` (x, y, yaw in the map frame) covers braking from `v`
    /// (m/s) and `w` (rad/s) to rest: the arc of its curvature over the reaction's distance
    /// and the braking distance, as points every [`WAY_STEP_M`] or less.
    pub fn way(&self, pose: (f64, f64, f64), v: f64, w: f64) -> Vec<(f64, f64)> {
        let (x, y, yaw) = pose;
        let speed = v.abs();
        if !speed.is_finite() || speed < STANDING_MPS || !w.is_finite() {
            return vec![(x, y)];
        }
        let distance = self.distance(speed);
        let steps = (distance / WAY_STEP_M).ceil().clamp(1.0, 1000.0) as usize;
        let ds = distance / steps as f64;
        // Turning per metre travelled, and which way along the heading it travels.
        let (curvature, sign) = (w / speed, v.signum());
        let mut way = Vec::with_capacity(steps + 1);
        let (mut px, mut py, mut heading) = (x, y, yaw);
        way.push((px, py));
        // Each step's chord on the arc: along the step's middle heading.
        let turn = curvature * ds;
        let chord = if turn.abs() < 1e-9 {
            ds
        } else {
            2.0 * (turn / 2.0).sin() / curvature
        };
        for _ in 0..steps {
            let mid = heading + turn / 2.0;
            px += sign * chord * mid.cos();
            py += sign * chord * mid.sin();
            heading += turn;
            way.push((px, py));
        }
        way
    }
}

impl ZoneGuard {
    /// The run-time check: the footprint's disc grown by `sigma_m`, swept along each of
    /// `ways` (braking ways from where the vehicle stands, map frame). The first zone a way
    /// carries it into, if any. A vehicle that already stands too close to a zone (after a
    /// jump of its position, or a zone added under it) may move, but not nearer: a way that
    /// ends nearer to the zones than it starts is the conflict then.
    pub fn check_ahead(
        &mut self,
        placement: MapPlacement,
        ways: &[Vec<(f64, f64)>],
        sigma_m: f64,
    ) -> Option<Conflict> {
        let radius = self.footprint_m + sigma_m.max(0.0);
        let zones = self.local(placement);
        let start = *ways.first()?.first()?;
        match zones.disc_conflict(start, radius) {
            None => ways.iter().find_map(|w| zones.path_conflict(w, radius)),
            Some(here) => {
                let deeper = |end: &(f64, f64)| {
                    zones
                        .nearest(*end)
                        .is_some_and(|(_, clearance)| clearance < here.clearance_m - DEEPER_M)
                };
                ways.iter()
                    .filter_map(|w| w.last())
                    .any(deeper)
                    .then_some(here)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geodesy::{Enu, Geodetic};
    use crate::zones::{Shape, ZoneKind};
    use nalgebra::Vector3;

    const BRAKING: Braking = Braking {
        reaction_s: 0.1,
        decel_mps2: 1.0,
    };
    const FOOTPRINT_M: f64 = 0.5;

    /// A keep-out square 4..6 × -1..1 m in the map frame of a datum.
    fn pond() -> (ZoneGuard, MapPlacement) {
        let datum = Geodetic {
            lat_deg: 47.3977,
            lon_deg: 8.5456,
            h_m: 480.0,
        };
        let frame = Enu::new(datum);
        let at = |x: f64, y: f64| {
            let g = frame.to_geodetic(&Vector3::new(x, y, 0.0));
            [g.lon_deg, g.lat_deg]
        };
        let ring = [
            (4.0, -1.0),
            (6.0, -1.0),
            (6.0, 1.0),
            (4.0, 1.0),
            (4.0, -1.0),
        ];
        let mut set = ZoneSet::default();
        set.add(
            "pond",
            ZoneKind::KeepOut,
            Shape::Polygon(vec![ring.iter().map(|&(x, y)| at(x, y)).collect()]),
        )
        .expect("a valid zone");
        (
            ZoneGuard::new(set, FOOTPRINT_M, 0.1),
            MapPlacement::at_datum(datum),
        )
    }

    #[test]
    fn a_braking_way_is_the_reaction_and_the_braking_distance_along_the_arc() {
        // 1 m/s: 0.1 m reacting, 0.5 m braking.
        let way = BRAKING.way((0.0, 0.0, 0.0), 1.0, 0.0);
        let end = *way.last().expect("points");
        assert!((end.0 - 0.6).abs() < 1e-9 && end.1.abs() < 1e-9, "{end:?}");
        assert!(way.windows(2).all(|p| {
            let step = (p[1].0 - p[0].0).hypot(p[1].1 - p[0].1);
            step <= WAY_STEP_M + 1e-12
        }));
        // Backwards, facing north.
        let back = BRAKING.way((1.0, 1.0, std::f64::consts::FRAC_PI_2), -1.0, 0.0);
        let end = *back.last().expect("points");
        assert!(
            (end.0 - 1.0).abs() < 1e-9 && (end.1 - 0.4).abs() < 1e-9,
            "{end:?}"
        );
        // A quarter circle of radius 0.6 / (π/2): turning left ends up north-east.
        let w = std::f64::consts::FRAC_PI_2 / 0.6;
        let arc = BRAKING.way((0.0, 0.0, 0.0), 1.0, w);
        let end = *arc.last().expect("points");
        let r = 0.6 / std::f64::consts::FRAC_PI_2;
        assert!(
            (end.0 - r).abs() < 1e-9 && (end.1 - r).abs() < 1e-9,
            "{end:?}"
        );
        // Standing, turning on the spot, or a value that is not a number: the place only.
        for (v, w) in [
            (0.0, 0.0),
            (0.0, 1.0),
            (f64::NAN, 0.0),
            (1.0, f64::INFINITY),
        ] {
            assert_eq!(BRAKING.way((2.0, 3.0, 0.0), v, w), vec![(2.0, 3.0)]);
        }
    }

    #[test]
    fn the_braking_way_into_a_zone_is_a_conflict_and_one_short_of_it_is_not() {
        let (mut guard, placement) = pond();
        // The pond's west edge is at x = 4: the disc's edge at x + 0.5 + σ.
        let sigma = 0.05;
        let mut stop_at = |x: f64, v: f64| {
            let way = BRAKING.way((x, 0.0, 0.0), v, 0.0);
            guard.check_ahead(placement, &[way], sigma)
        };
        // At 1 m/s the way is 0.6 m: from x = 2.8 the disc reaches 3.4 + 0.55 = 3.95.
        assert_eq!(stop_at(2.8, 1.0), None);
        let c = stop_at(2.9, 1.0).expect("meets the pond");
        assert_eq!(c.name, "pond");
        assert!((c.at.0 - (4.0 - 0.55)).abs() < 0.02, "{c:?}");
        // Standing there, nothing is in the way.
        assert_eq!(stop_at(2.9, 0.0), None);
        // Driving away from it is never a conflict.
        let away = BRAKING.way((2.9, 0.0, std::f64::consts::PI), 1.0, 0.0);
        assert_eq!(guard.check_ahead(placement, &[away], sigma), None);
    }

    #[test]
    fn too_close_already_the_vehicle_may_back_away_but_not_go_deeper() {
        let (mut guard, placement) = pond();
        // 0.3 m from the pond's edge, within the 0.5 m disc.
        let pose = (3.7, 0.0, 0.0);
        let here = |v: f64, w: f64| BRAKING.way(pose, v, w);
        assert!(
            guard
                .check_ahead(placement, &[here(0.5, 0.0)], 0.0)
                .is_some()
        );
        assert_eq!(guard.check_ahead(placement, &[here(-0.5, 0.0)], 0.0), None);
        assert_eq!(guard.check_ahead(placement, &[here(0.0, 1.0)], 0.0), None);
        // Along the edge, southwards and a little away: allowed.
        let along = BRAKING.way((3.7, 0.0, -1.7), 0.5, 0.0);
        assert_eq!(guard.check_ahead(placement, &[along], 0.0), None);
        // Either way counts: backing away while the wheels still roll forward is deeper.
        let rolling = here(0.5, 0.0);
        assert!(
            guard
                .check_ahead(placement, &[here(-0.5, 0.0), rolling], 0.0)
                .is_some()
        );
    }
}
