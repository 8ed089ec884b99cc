//! Zones placed in a map frame (x, y, m: a datum's ENU frame, moved and turned as the map
//! frame is) and the questions the checks ask of them: how far a disc (the vehicle's
//! footprint grown by a margin) stands from each zone, and where a path swept by that disc
//! first meets one. Each zone keeps its bounding box, so a zone far from the disc or the
//! segment costs four comparisons, not a walk round its edges.

use geo::{
    BoundingRect, Contains, Coord, Distance, Euclidean, Line, LineString, Point, Polygon, Rect,
};

use super::{LonLat, Shape, ZoneKind, ZoneSet};

/// One zone in the map frame.
#[derive(Debug, Clone)]
pub struct LocalZone {
    /// Its id in its set.
    pub id: u32,
    /// Its name.
    pub name: String,
    /// What it asks.
    pub kind: ZoneKind,
    shape: LocalShape,
    /// The shape's bounding box (`None` only for an empty one).
    bounds: Option<Rect<f64>>,
}

#[derive(Debug, Clone)]
enum LocalShape {
    Polygon(Polygon<f64>),
    Circle { centre: Coord<f64>, radius_m: f64 },
    Line(LineString<f64>),
}

/// Where a disc or a path meets a zone.
#[derive(Debug, Clone, PartialEq)]
pub struct Conflict {
    /// The zone's id.
    pub id: u32,
    /// The zone's name.
    pub name: String,
    /// Its kind.
    pub kind: ZoneKind,
    /// The disc's centre where it first comes within its radius (east, north, m).
    pub at: (f64, f64),
    /// The disc's clearance there: its centre's distance from the zone's edge on the
    /// allowed side (negative on the wrong side), m.
    pub clearance_m: f64,
}

/// A zone as drawn in the map frame: its lines (a polygon's rings and a circle's, closed by
/// repeating their first point; a wall's points as they are).
#[derive(Debug, Clone, PartialEq)]
pub struct ZoneOutline {
    /// Its id in its set.
    pub id: u32,
    /// Its name.
    pub name: String,
    /// What it asks.
    pub kind: ZoneKind,
    /// Its lines (east, north, m).
    pub lines: Vec<Vec<(f64, f64)>>,
}

/// A set of zones in one map frame.
#[derive(Debug, Clone, Default)]
pub struct LocalZones {
    zones: Vec<LocalZone>,
}

/// A circle is drawn as this many chords: within 0.3 % of its radius.
const CIRCLE_CHORDS: usize = 48;

/// How finely a path's conflict is placed, m.
const PLACE_STEP_M: f64 = 0.01;
/// The most halvings of one segment (a 10,000 km segment still reaches 1 cm).
const MAX_HALVINGS: u32 = 40;

impl LocalZones {
    /// `set` in the frame where `place` puts a position (latitude, longitude in degrees).
    pub fn new(set: &ZoneSet, place: impl Fn(f64, f64) -> (f64, f64)) -> Self {
        let local = |p: &LonLat| {
            let (x, y) = place(p[1], p[0]);
            Coord { x, y }
        };
        let line = |points: &[LonLat]| LineString::new(points.iter().map(local).collect());
        let zones = set
            .zones()
            .iter()
            .map(|z| {
                let shape = match &z.shape {
                    Shape::Polygon(rings) => LocalShape::Polygon(Polygon::new(
                        rings
                            .first()
                            .map_or_else(|| LineString::new(Vec::new()), |r| line(r)),
                        rings.iter().skip(1).map(|r| line(r)).collect(),
                    )),
                    Shape::Circle { centre, radius_m } => LocalShape::Circle {
                        centre: local(centre),
                        radius_m: *radius_m,
                    },
                    Shape::Line(points) => LocalShape::Line(line(points)),
                };
                LocalZone {
                    id: z.id,
                    name: z.name.clone(),
                    kind: z.kind,
                    bounds: shape.bounds(),
                    shape,
                }
            })
            .collect();
        Self { zones }
    }

    /// Every zone's outline, for a client to draw.
    pub fn outlines(&self) -> Vec<ZoneOutline> {
        let points = |l: &LineString<f64>| l.coords().map(|c| (c.x, c.y)).collect();
        self.zones
            .iter()
            .map(|z| ZoneOutline {
                id: z.id,
                name: z.name.clone(),
                kind: z.kind,
                lines: match &z.shape {
                    LocalShape::Polygon(p) => std::iter::once(p.exterior())
                        .chain(p.interiors())
                        .map(points)
                        .collect(),
                    LocalShape::Circle { centre, radius_m } => vec![
                        (0..=CIRCLE_CHORDS)
                            .map(|i| {
                                let a = std::f64::consts::TAU * i as f64 / CIRCLE_CHORDS as f64;
                                (centre.x + radius_m * a.cos(), centre.y + radius_m * a.sin())
                            })
                            .collect(),
                    ],
                    LocalShape::Line(l) => vec![points(l)],
                },
            })
            .collect()
    }

    /// The disc of `radius` m at `p` against every zone: the first it meets (the one with
    /// the least clearance), if any. With boundaries, the disc must lie inside one of them.
    pub fn disc_conflict(&self, p: (f64, f64), radius: f64) -> Option<Conflict> {
        let c = Coord { x: p.0, y: p.1 };
        let mut worst: Option<Conflict> = None;
        let mut consider = |zone: &LocalZone, clearance: f64| {
            if clearance < radius && worst.as_ref().is_none_or(|w| clearance < w.clearance_m) {
                worst = Some(conflict(zone, p, clearance));
            }
        };
        // A zone whose box lies beyond the radius cannot be within it.
        let near = |z: &&LocalZone| z.kind != ZoneKind::Boundary && z.near(c, c, radius);
        for zone in self.zones.iter().filter(near) {
            consider(zone, zone.clearance(c));
        }
        if let Some((zone, clearance)) = self.best_boundary(c) {
            consider(zone, clearance);
        }
        worst
    }

    /// The least clearance of `p` from any zone, and that zone (none without zones).
    pub fn nearest(&self, p: (f64, f64)) -> Option<(&LocalZone, f64)> {
        let c = Coord { x: p.0, y: p.1 };
        self.zones
            .iter()
            .filter(|z| z.kind != ZoneKind::Boundary)
            .map(|z| (z, z.clearance(c)))
            .chain(self.best_boundary(c))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The path through `points` swept by a disc of `radius` m: where it first meets a zone.
    /// Each segment is halved down to 1 cm towards the first part that meets one, each part
    /// checked exactly, so a wall thinner than any step is still found.
    pub fn path_conflict(&self, points: &[(f64, f64)], radius: f64) -> Option<Conflict> {
        if let [only] = points {
            return self.disc_conflict(*only, radius);
        }
        points
            .windows(2)
            .find_map(|pair| self.first_on_segment(pair[0], pair[1], radius, 0))
    }

    fn first_on_segment(
        &self,
        a: (f64, f64),
        b: (f64, f64),
        radius: f64,
        depth: u32,
    ) -> Option<Conflict> {
        let segment = Line::new(Coord { x: a.0, y: a.1 }, Coord { x: b.0, y: b.1 });
        let zone = self.segment_meets(&segment, radius)?;
        let mid = ((a.0 + b.0) / 2.0, (a.1 + b.1) / 2.0);
        if (b.0 - a.0).hypot(b.1 - a.1) <= PLACE_STEP_M || depth >= MAX_HALVINGS {
            return self
                .disc_conflict(a, radius)
                .or_else(|| self.disc_conflict(b, radius))
                .or_else(|| {
                    let clearance = zone.clearance(Coord { x: mid.0, y: mid.1 });
                    Some(conflict(zone, mid, clearance))
                });
        }
        self.first_on_segment(a, mid, radius, depth + 1)
            .or_else(|| self.first_on_segment(mid, b, radius, depth + 1))
    }

    /// A zone a disc swept along `segment` meets, if any (exact).
    fn segment_meets(&self, segment: &Line<f64>, radius: f64) -> Option<&LocalZone> {
        let obstacle = self
            .zones
            .iter()
            .filter(|z| z.kind != ZoneKind::Boundary)
            .filter(|z| z.near(segment.start, segment.end, radius))
            .find(|z| z.segment_distance(segment) < radius);
        if obstacle.is_some() {
            return obstacle;
        }
        // Inside one boundary for the whole segment: its start inside, and no ring of it
        // within the radius.
        let mut boundaries = self
            .zones
            .iter()
            .filter(|z| z.kind == ZoneKind::Boundary)
            .peekable();
        boundaries.peek()?;
        let inside_one = boundaries.any(|z| match &z.shape {
            LocalShape::Polygon(p) => {
                p.contains(&segment.start)
                    && std::iter::once(p.exterior())
                        .chain(p.interiors())
                        .all(|ring| Euclidean.distance(segment, ring) >= radius)
            }
            _ => false,
        });
        if inside_one {
            None
        } else {
            self.best_boundary(segment.start).map(|(z, _)| z)
        }
    }

    /// The boundary the point is deepest inside, and its clearance (negative outside all).
    fn best_boundary(&self, c: Coord<f64>) -> Option<(&LocalZone, f64)> {
        self.zones
            .iter()
            .filter(|z| z.kind == ZoneKind::Boundary)
            .map(|z| (z, z.clearance(c)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }
}

impl LocalShape {
    /// The bounding box (a circle's square).
    fn bounds(&self) -> Option<Rect<f64>> {
        match self {
            Self::Polygon(p) => p.bounding_rect(),
            Self::Circle { centre, radius_m } => Some(Rect::new(
                Coord {
                    x: centre.x - radius_m,
                    y: centre.y - radius_m,
                },
                Coord {
                    x: centre.x + radius_m,
                    y: centre.y + radius_m,
                },
            )),
            Self::Line(l) => l.bounding_rect(),
        }
    }
}

impl LocalZone {
    /// Whether the box round `a` and `b`, grown by `radius`, meets this zone's box: when it
    /// does not, nothing between them comes within `radius` of the zone.
    fn near(&self, a: Coord<f64>, b: Coord<f64>, radius: f64) -> bool {
        self.bounds.is_none_or(|r| {
            a.x.min(b.x) - radius <= r.max().x
                && a.x.max(b.x) + radius >= r.min().x
                && a.y.min(b.y) - radius <= r.max().y
                && a.y.max(b.y) + radius >= r.min().y
        })
    }

    /// The signed distance of `c` from this zone's edge, positive on the side the vehicle
    /// may be (outside a keep-out zone or a wall's line, inside a boundary), m.
    fn clearance(&self, c: Coord<f64>) -> f64 {
        let point = Point(c);
        match &self.shape {
            LocalShape::Polygon(polygon) => {
                let edge = std::iter::once(polygon.exterior())
                    .chain(polygon.interiors())
                    .map(|ring| Euclidean.distance(&point, ring))
                    .fold(f64::INFINITY, f64::min);
                // A boundary is kept inside, a keep-out zone outside.
                let allowed = polygon.contains(&c) == (self.kind == ZoneKind::Boundary);
                if allowed { edge } else { -edge }
            }
            LocalShape::Circle { centre, radius_m } => {
                (c.x - centre.x).hypot(c.y - centre.y) - radius_m
            }
            LocalShape::Line(line) => Euclidean.distance(&point, line),
        }
    }

    /// The distance from a segment to a keep-out zone or a wall (0 when it enters one).
    fn segment_distance(&self, segment: &Line<f64>) -> f64 {
        match &self.shape {
            LocalShape::Polygon(polygon) => Euclidean.distance(segment, polygon),
            LocalShape::Circle { centre, radius_m } => {
                Euclidean.distance(segment, *centre) - radius_m
            }
            LocalShape::Line(line) => Euclidean.distance(segment, line),
        }
    }
}

fn conflict(zone: &LocalZone, at: (f64, f64), clearance_m: f64) -> Conflict {
    Conflict {
        id: zone.id,
        name: zone.name.clone(),
        kind: zone.kind,
        at,
        clearance_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geodesy::{Enu, Geodetic};
    use nalgebra::Vector3;

    fn frame() -> Enu {
        Enu::new(Geodetic {
            lat_deg: 47.3977,
            lon_deg: 8.5456,
            h_m: 480.0,
        })
    }

    fn lon_lat(frame: &Enu, x: f64, y: f64) -> LonLat {
        let g = frame.to_geodetic(&Vector3::new(x, y, 0.0));
        [g.lon_deg, g.lat_deg]
    }

    fn rect(frame: &Enu, [x0, y0, x1, y1]: [f64; 4]) -> Shape {
        let ring = [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)];
        Shape::Polygon(vec![
            ring.iter().map(|&(x, y)| lon_lat(frame, x, y)).collect(),
        ])
    }

    /// A 40 × 30 m lawn with a 4 × 4 m pond at (10, 10), a tree of 1 m at (-10, 5) and a
    /// wall from (5, -10) to (5, 0).
    fn yard() -> LocalZones {
        let f = frame();
        let mut set = ZoneSet::default();
        set.add(
            "lawn",
            ZoneKind::Boundary,
            rect(&f, [-20.0, -15.0, 20.0, 15.0]),
        )
        .unwrap();
        set.add("pond", ZoneKind::KeepOut, rect(&f, [8.0, 8.0, 12.0, 12.0]))
            .unwrap();
        set.add(
            "tree",
            ZoneKind::KeepOut,
            Shape::Circle {
                centre: lon_lat(&f, -10.0, 5.0),
                radius_m: 1.0,
            },
        )
        .unwrap();
        set.add(
            "fence",
            ZoneKind::Wall,
            Shape::Line(vec![lon_lat(&f, 5.0, -10.0), lon_lat(&f, 5.0, 0.0)]),
        )
        .unwrap();
        in_frame(&set, &f)
    }

    fn in_frame(set: &ZoneSet, f: &Enu) -> LocalZones {
        LocalZones::new(set, |lat_deg, lon_deg| {
            let p = f.to_enu(&Geodetic {
                lat_deg,
                lon_deg,
                h_m: f.datum().h_m,
            });
            (p.x, p.y)
        })
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-3
    }

    #[test]
    fn outlines_close_rings_and_circles_and_keep_walls_open() {
        let outlines = yard().outlines();
        let names: Vec<_> = outlines.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["lawn", "pond", "tree", "fence"]);
        let pond = &outlines[1].lines;
        assert_eq!(pond.len(), 1);
        assert_eq!(pond[0].len(), 5);
        assert!(close(pond[0][0].0, pond[0][4].0) && close(pond[0][0].1, pond[0][4].1));
        assert!(
            close(pond[0][0].0, 8.0) && close(pond[0][0].1, 8.0),
            "{pond:?}"
        );
        let tree = &outlines[2].lines[0];
        assert_eq!(tree.len(), CIRCLE_CHORDS + 1);
        assert!(
            tree.iter()
                .all(|&(x, y)| close((x + 10.0).hypot(y - 5.0), 1.0)),
            "{tree:?}"
        );
        let fence = &outlines[3].lines[0];
        assert_eq!(fence.len(), 2);
        assert!(
            close(fence[1].0, 5.0) && close(fence[1].1, 0.0),
            "{fence:?}"
        );
    }

    #[test]
    fn a_disc_meets_the_zone_it_comes_within_its_radius_of() {
        let zones = yard();
        assert_eq!(zones.disc_conflict((0.0, 5.0), 0.5), None, "in the open");
        let c = zones
            .disc_conflict((7.6, 10.0), 0.5)
            .expect("0.4 m from the pond");
        assert_eq!(c.name, "pond");
        assert!(close(c.clearance_m, 0.4), "{c:?}");
        let inside = zones.disc_conflict((10.0, 10.0), 0.5).expect("in the pond");
        assert!(close(inside.clearance_m, -2.0), "{inside:?}");
        let tree = zones.disc_conflict((-10.0, 6.3), 0.5).expect("the tree");
        assert_eq!(tree.name, "tree");
        assert!(close(tree.clearance_m, 0.3), "{tree:?}");
        let fence = zones.disc_conflict((5.2, -5.0), 0.5).expect("the fence");
        assert_eq!((fence.name.as_str(), fence.kind), ("fence", ZoneKind::Wall));
        let edge = zones
            .disc_conflict((19.7, 0.0), 0.5)
            .expect("the lawn's edge");
        assert_eq!(
            (edge.name.as_str(), edge.kind),
            ("lawn", ZoneKind::Boundary)
        );
        assert!(close(edge.clearance_m, 0.3), "{edge:?}");
        let out = zones.disc_conflict((25.0, 0.0), 0.5).expect("off the lawn");
        assert!(close(out.clearance_m, -5.0), "{out:?}");
        let (nearest, clearance) = zones.nearest((0.0, 5.0)).unwrap();
        assert_eq!(nearest.name, "fence");
        assert!(close(clearance, 50f64.sqrt()), "{clearance}");
    }

    #[test]
    fn a_path_meets_the_first_zone_on_its_way_where_it_does() {
        let zones = yard();
        // Straight through the pond from the west: met 0.5 m before its west edge.
        let c = zones
            .path_conflict(&[(0.0, 10.0), (18.0, 10.0)], 0.5)
            .expect("through the pond");
        assert_eq!(c.name, "pond");
        assert!((c.at.0 - 7.5).abs() <= 0.011 && c.at.1 == 10.0, "{c:?}");
        // Round it, and clear of everything.
        let round = [(0.0, 5.0), (15.0, 5.0), (15.0, 14.0)];
        assert_eq!(zones.path_conflict(&round, 0.5), None);
        // The last leg grazes the lawn's north edge.
        assert!(
            zones
                .path_conflict(&[(15.0, 5.0), (15.0, 14.8)], 0.5)
                .is_some_and(|c| c.name == "lawn")
        );
        // One long leg across the fence, met however thin the disc.
        let across = zones
            .path_conflict(&[(0.5, -5.0), (10_000.5, -5.0)], 0.001)
            .expect("across the fence");
        assert_eq!(across.name, "fence");
        assert!((across.at.0 - 5.0).abs() < 0.011, "{across:?}");
    }

    #[test]
    fn without_boundaries_only_the_keep_out_zones_and_walls_count() {
        let f = frame();
        let mut set = ZoneSet::default();
        set.add("pond", ZoneKind::KeepOut, rect(&f, [8.0, 8.0, 12.0, 12.0]))
            .unwrap();
        let zones = in_frame(&set, &f);
        assert_eq!(zones.disc_conflict((1000.0, 1000.0), 1.0), None);
        assert_eq!(
            zones.path_conflict(&[(-500.0, 0.0), (500.0, 0.0)], 1.0),
            None
        );
    }
}
