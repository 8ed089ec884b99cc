//! Where the vehicle may go: boundaries it stays inside, keep-out zones (polygons and
//! circles) and virtual walls, read from GeoJSON (RFC 7946: longitude, latitude on WGS84, so
//! they survive a change of datum and open in any GIS tool), checked when they are read or
//! edited, and written back as GeoJSON. [`local`] places them in a map frame for the checks.

pub mod local;

use geo::{Coord, LineString, Polygon, Validation};
use geojson::feature::Id;
use geojson::{Feature, FeatureCollection, GeoJson, Geometry, GeometryValue, JsonObject};
use serde_json::{Value, json};

/// The most zones a set may hold.
pub const MAX_ZONES: usize = 1000;
/// The most positions one zone may have.
pub const MAX_POSITIONS: usize = 10_000;
/// The largest zones file, bytes.
pub const MAX_TEXT_BYTES: usize = 4 << 20;
/// The largest circle, m.
pub const MAX_RADIUS_M: f64 = 10_000.0;
/// The longest zone name, characters.
pub const MAX_NAME_CHARS: usize = 100;

/// What a zone asks of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZoneKind {
    /// A polygon the vehicle stays inside (with several, inside one of them).
    Boundary,
    /// A polygon or a circle the vehicle stays out of.
    KeepOut,
    /// A line the vehicle does not cross or touch.
    Wall,
}

impl ZoneKind {
    /// The kind's name in a zones file (`properties.kind`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Boundary => "boundary",
            Self::KeepOut => "keep_out",
            Self::Wall => "wall",
        }
    }

    fn of(name: &str) -> Option<Self> {
        [Self::Boundary, Self::KeepOut, Self::Wall]
            .into_iter()
            .find(|k| k.name() == name)
    }
}

/// A position: longitude, latitude, degrees (WGS84).
pub type LonLat = [f64; 2];

/// A zone's shape, on WGS84.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// A polygon: its exterior ring, then its holes; each ring closed (its first position
    /// repeated at its end).
    Polygon(Vec<Vec<LonLat>>),
    /// A disc around a centre.
    Circle {
        /// The centre.
        centre: LonLat,
        /// Its radius, m.
        radius_m: f64,
    },
    /// A polyline; closed when its last position repeats its first.
    Line(Vec<LonLat>),
}

/// One zone.
#[derive(Debug, Clone, PartialEq)]
pub struct Zone {
    /// Its number, unique in its set (a ROS `shapeId`).
    pub id: u32,
    /// Its name, for refusals and logs.
    pub name: String,
    /// What it asks.
    pub kind: ZoneKind,
    /// Where it is.
    pub shape: Shape,
}

/// A checked set of zones.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ZoneSet {
    zones: Vec<Zone>,
}

/// Why zones were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ZonesError {
    /// The text is not GeoJSON, or not a feature collection or a feature.
    #[error("not a GeoJSON feature collection: {0}")]
    NotGeoJson(String),
    /// The text is larger than a zones file may be.
    #[error("{bytes} bytes, more than the {MAX_TEXT_BYTES} a zones file may have")]
    TooLarge {
        /// Its size.
        bytes: usize,
    },
    /// An added zone would make the set's file larger than a zones file may be: written
    /// back, it would not load at the next start.
    #[error(
        "with it the zones file would be {bytes} bytes, more than the {MAX_TEXT_BYTES} a zones file may have; remove zones or simplify their shapes first"
    )]
    WouldOutgrowFile {
        /// The file's size with the zone.
        bytes: usize,
    },
    /// More zones than a set may hold.
    #[error("{count} zones, more than the {MAX_ZONES} a set may hold")]
    TooMany {
        /// How many there would be.
        count: usize,
    },
    /// One feature is wrong.
    #[error("feature {index}{}: {problem}; {fix}", name_part(name))]
    Feature {
        /// Its index in the collection, from 0.
        index: usize,
        /// Its name, when it has one.
        name: Option<String>,
        /// What is wrong.
        problem: String,
        /// How to put it right.
        fix: &'static str,
    },
}

impl ZonesError {
    /// What is wrong (where), and how to put it right, apart.
    pub fn problem_and_fix(&self) -> (String, &'static str) {
        match self {
            Self::Feature {
                index,
                name,
                problem,
                fix,
            } => (
                format!("feature {index}{}: {problem}", name_part(name)),
                fix,
            ),
            Self::NotGeoJson(_) => (
                self.to_string(),
                "write the zones as a GeoJSON FeatureCollection (RFC 7946)",
            ),
            Self::WouldOutgrowFile { .. } => (
                self.to_string(),
                "remove zones or simplify their shapes, then add it again",
            ),
            Self::TooLarge { .. } | Self::TooMany { .. } => (
                self.to_string(),
                "simplify the zones, or split the area among several files",
            ),
        }
    }
}

fn name_part(name: &Option<String>) -> String {
    name.as_ref()
        .map_or_else(String::new, |n| format!(" ({n:?})"))
}

/// A shape's problem and its fix.
type ShapeError = (String, &'static str);

const POSITION_FIX: &str =
    "positions are [longitude, latitude] in degrees on WGS84 (RFC 7946), longitude first";

impl ZoneSet {
    /// Reads and checks a zones file's text: a GeoJSON FeatureCollection (or one Feature)
    /// whose features carry `properties.kind` (`boundary`, `keep_out` or `wall`), optionally
    /// `properties.name`, and a circle's `properties.radius_m`; a feature's numeric `id` is
    /// its zone's id.
    pub fn from_geojson(text: &str) -> Result<Self, ZonesError> {
        if text.len() > MAX_TEXT_BYTES {
            return Err(ZonesError::TooLarge { bytes: text.len() });
        }
        let features = match text.parse::<GeoJson>() {
            Ok(GeoJson::FeatureCollection(c)) => c.features,
            Ok(GeoJson::Feature(f)) => vec![f],
            Ok(GeoJson::Geometry(_)) => {
                return Err(ZonesError::NotGeoJson(
                    "a bare geometry has no kind: put it in a Feature with properties.kind".into(),
                ));
            }
            Err(e) => return Err(ZonesError::NotGeoJson(e.to_string())),
        };
        if features.len() > MAX_ZONES {
            return Err(ZonesError::TooMany {
                count: features.len(),
            });
        }
        let mut parsed = Vec::with_capacity(features.len());
        for (index, feature) in features.iter().enumerate() {
            parsed.push(
                zone_of(feature).map_err(|(name, problem, fix)| ZonesError::Feature {
                    index,
                    name,
                    problem,
                    fix,
                })?,
            );
        }
        let mut set = Self::default();
        // Numbered features keep their ids; the others take the next free ones.
        for (index, (id, zone)) in parsed.iter().enumerate() {
            if let Some(id) = id {
                if set.zones.iter().any(|z| z.id == *id) {
                    return Err(ZonesError::Feature {
                        index,
                        name: Some(zone.name.clone()),
                        problem: format!("id {id} is taken by an earlier feature"),
                        fix: "give each feature its own id, or none",
                    });
                }
                set.zones.push(Zone {
                    id: *id,
                    ..zone.clone()
                });
            }
        }
        for (id, zone) in parsed {
            if id.is_none() {
                let id = set.next_id();
                set.zones.push(Zone { id, ..zone });
            }
        }
        set.zones.sort_by_key(|z| z.id);
        Ok(set)
    }

    /// The zones as a GeoJSON FeatureCollection, as [`ZoneSet::from_geojson`] reads it.
    pub fn to_geojson(&self) -> String {
        let collection = FeatureCollection {
            bbox: None,
            features: self.zones.iter().map(feature_of).collect(),
            foreign_members: None,
        };
        // A feature collection of numbers and strings always serialises.
        serde_json::to_string_pretty(&collection).unwrap_or_default()
    }

    /// The zones, by id.
    pub fn zones(&self) -> &[Zone] {
        &self.zones
    }

    /// Adds a zone after checking it; its id.
    pub fn add(&mut self, name: &str, kind: ZoneKind, shape: Shape) -> Result<u32, ZonesError> {
        let index = self.zones.len();
        if index >= MAX_ZONES {
            return Err(ZonesError::TooMany { count: index + 1 });
        }
        let refuse = |(problem, fix): ShapeError| ZonesError::Feature {
            index,
            name: Some(name.to_owned()),
            problem,
            fix,
        };
        check_name(name).map_err(refuse)?;
        check_shape(kind, &shape).map_err(refuse)?;
        let id = self.next_id();
        self.zones.push(Zone {
            id,
            name: name.to_owned(),
            kind,
            shape,
        });
        // The set is written back as the zones file, which must load at the next start.
        let bytes = self.to_geojson().len();
        if bytes > MAX_TEXT_BYTES {
            self.zones.pop();
            return Err(ZonesError::WouldOutgrowFile { bytes });
        }
        Ok(id)
    }

    /// Removes the zone `id`; it, if there was one.
    pub fn remove(&mut self, id: u32) -> Option<Zone> {
        let at = self.zones.iter().position(|z| z.id == id)?;
        Some(self.zones.remove(at))
    }

    /// Every position of every zone.
    pub fn positions(&self) -> impl Iterator<Item = LonLat> + '_ {
        self.zones.iter().flat_map(|z| match &z.shape {
            Shape::Polygon(rings) => rings.iter().flatten().copied().collect::<Vec<_>>(),
            Shape::Circle { centre, .. } => vec![*centre],
            Shape::Line(points) => points.clone(),
        })
    }

    fn next_id(&self) -> u32 {
        self.zones
            .iter()
            .map(|z| z.id.saturating_add(1))
            .max()
            .unwrap_or(1)
    }
}

type FeatureError = (Option<String>, String, &'static str);

/// A feature's zone and the id it asks for.
fn zone_of(feature: &Feature) -> Result<(Option<u32>, Zone), FeatureError> {
    let empty = JsonObject::new();
    let properties = feature.properties.as_ref().unwrap_or(&empty);
    let given_name = match properties.get("name") {
        None | Some(Value::Null) => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(_) => {
            return Err((
                None,
                "properties.name is not a string".into(),
                "name the zone with a string, or leave the name out",
            ));
        }
    };
    let fail = |(problem, fix): ShapeError| (given_name.clone(), problem, fix);
    let id = match &feature.id {
        None | Some(Id::String(_)) => None,
        Some(Id::Number(n)) => Some(
            n.as_u64()
                .and_then(|n| u32::try_from(n).ok())
                .filter(|n| *n > 0)
                .ok_or_else(|| {
                    fail((
                        format!("id {n} is not a whole number from 1 to {}", u32::MAX),
                        "number zones from 1, or leave the id out",
                    ))
                })?,
        ),
    };
    let kind_name = properties
        .get("kind")
        .and_then(Value::as_str)
        .ok_or_else(|| {
            fail((
                "has no properties.kind".into(),
                "give properties.kind: boundary, keep_out or wall",
            ))
        })?;
    let kind = ZoneKind::of(kind_name).ok_or_else(|| {
        fail((
            format!("kind {kind_name:?} is not a zone kind"),
            "use boundary, keep_out or wall",
        ))
    })?;
    let geometry = feature.geometry.as_ref().ok_or_else(|| {
        fail((
            "has no geometry".into(),
            "give a Polygon (boundary, keep_out), a Point with radius_m (keep_out) or a \
             LineString (wall)",
        ))
    })?;
    let shape = shape_of(kind, geometry, properties).map_err(fail)?;
    check_shape(kind, &shape).map_err(fail)?;
    let name = match given_name {
        Some(n) => n,
        None => match (&feature.id, id) {
            (Some(Id::String(s)), _) => s.clone(),
            (_, Some(id)) => format!("{} {id}", kind.name()),
            (_, None) => kind.name().to_owned(),
        },
    };
    check_name(&name).map_err(|e| (Some(name.clone()), e.0, e.1))?;
    Ok((
        id,
        Zone {
            id: id.unwrap_or(0),
            name,
            kind,
            shape,
        },
    ))
}

fn shape_of(
    kind: ZoneKind,
    geometry: &Geometry,
    properties: &JsonObject,
) -> Result<Shape, ShapeError> {
    let radius = properties.get("radius_m");
    match (&geometry.value, kind) {
        (GeometryValue::Polygon { coordinates }, ZoneKind::Boundary | ZoneKind::KeepOut) => {
            let rings = coordinates
                .iter()
                .map(|ring| ring.iter().map(|p| lon_lat(p.as_slice())).collect())
                .collect::<Result<Vec<Vec<LonLat>>, _>>()?;
            Ok(Shape::Polygon(rings))
        }
        (GeometryValue::Point { coordinates }, ZoneKind::KeepOut) => {
            let radius_m = radius.and_then(Value::as_f64).ok_or((
                "a circle has no properties.radius_m".to_owned(),
                "give the circle's radius in metres as properties.radius_m",
            ))?;
            Ok(Shape::Circle {
                centre: lon_lat(coordinates.as_slice())?,
                radius_m,
            })
        }
        (GeometryValue::LineString { coordinates }, ZoneKind::Wall) => Ok(Shape::Line(
            coordinates
                .iter()
                .map(|p| lon_lat(p.as_slice()))
                .collect::<Result<_, _>>()?,
        )),
        (value, kind) => Err((
            format!("a {} cannot be a {}", kind.name(), value.type_name()),
            "boundaries are Polygons, keep_out zones Polygons or Points with radius_m, \
             walls LineStrings (one feature per part)",
        )),
    }
}

fn lon_lat(p: &[f64]) -> Result<LonLat, ShapeError> {
    match *p {
        [lon, lat] | [lon, lat, _] if lon.is_finite() && lat.is_finite() => {
            if (-180.0..=180.0).contains(&lon) && (-90.0..=90.0).contains(&lat) {
                Ok([lon, lat])
            } else {
                Err((
                    format!("position [{lon}, {lat}] is off the globe"),
                    POSITION_FIX,
                ))
            }
        }
        _ => Err((
            format!("position {p:?} is not [longitude, latitude]"),
            POSITION_FIX,
        )),
    }
}

fn check_name(name: &str) -> Result<(), ShapeError> {
    if name.chars().count() > MAX_NAME_CHARS || name.chars().any(char::is_control) {
        return Err((
            format!("name is longer than {MAX_NAME_CHARS} characters or has control characters"),
            "use a short name of printable characters",
        ));
    }
    Ok(())
}

/// Checks a shape as its kind needs it.
fn check_shape(kind: ZoneKind, shape: &Shape) -> Result<(), ShapeError> {
    let positions = match shape {
        Shape::Polygon(rings) => rings.iter().map(Vec::len).sum(),
        Shape::Circle { .. } => 1,
        Shape::Line(points) => points.len(),
    };
    if positions > MAX_POSITIONS {
        return Err((
            format!("{positions} positions, more than the {MAX_POSITIONS} a zone may have"),
            "simplify the shape, or split it into several zones",
        ));
    }
    match (shape, kind) {
        (Shape::Polygon(rings), ZoneKind::Boundary | ZoneKind::KeepOut) => check_polygon(rings),
        (Shape::Circle { centre, radius_m }, ZoneKind::KeepOut) => {
            lon_lat(centre)?;
            if radius_m.is_finite() && *radius_m > 0.0 && *radius_m <= MAX_RADIUS_M {
                Ok(())
            } else {
                Err((
                    format!("radius {radius_m} m is not above 0 and up to {MAX_RADIUS_M} m"),
                    "give the circle's radius in metres",
                ))
            }
        }
        (Shape::Line(points), ZoneKind::Wall) => {
            for p in points {
                lon_lat(p)?;
            }
            if line_string(points).is_valid() && points.len() >= 2 {
                Ok(())
            } else {
                Err((
                    "a wall needs at least two distinct positions".into(),
                    "give the wall's ends (and the corners between them)",
                ))
            }
        }
        _ => Err((
            format!("a {} cannot have this shape", kind.name()),
            "boundaries are polygons, keep_out zones polygons or circles, walls lines",
        )),
    }
}

fn check_polygon(rings: &[Vec<LonLat>]) -> Result<(), ShapeError> {
    if rings.is_empty() {
        return Err((
            "a polygon has no ring".into(),
            "give the polygon's exterior ring",
        ));
    }
    for (i, ring) in rings.iter().enumerate() {
        for p in ring {
            lon_lat(p)?;
        }
        let which = if i == 0 {
            "the exterior ring".to_owned()
        } else {
            format!("hole {i}")
        };
        if ring.len() < 4 {
            return Err((
                format!(
                    "{which} has {} positions, fewer than a closed ring's 4",
                    ring.len()
                ),
                "a ring lists at least three corners and repeats the first at its end",
            ));
        }
        if ring.first() != ring.last() {
            return Err((
                format!("{which} is not closed"),
                "repeat the ring's first position at its end (RFC 7946 3.1.6)",
            ));
        }
    }
    let polygon = Polygon::new(
        line_string(&rings[0]),
        rings[1..].iter().map(|r| line_string(r)).collect(),
    );
    polygon.check_validation().map_err(|e| {
        (
            e.to_string(),
            "a ring may not cross or touch itself along a line, and holes lie inside the \
             exterior ring without crossing it: move the corners",
        )
    })
}

fn line_string(points: &[LonLat]) -> LineString<f64> {
    LineString::new(points.iter().map(|&[x, y]| Coord { x, y }).collect())
}

fn feature_of(zone: &Zone) -> Feature {
    let mut properties = JsonObject::new();
    properties.insert("name".into(), json!(zone.name));
    properties.insert("kind".into(), json!(zone.kind.name()));
    let position = |p: &LonLat| geojson::Position::from(*p);
    let value = match &zone.shape {
        Shape::Polygon(rings) => GeometryValue::Polygon {
            coordinates: rings
                .iter()
                .map(|r| r.iter().map(position).collect())
                .collect(),
        },
        Shape::Circle { centre, radius_m } => {
            properties.insert("radius_m".into(), json!(radius_m));
            GeometryValue::Point {
                coordinates: position(centre),
            }
        }
        Shape::Line(points) => GeometryValue::LineString {
            coordinates: points.iter().map(position).collect(),
        },
    };
    Feature {
        bbox: None,
        geometry: Some(Geometry {
            bbox: None,
            value,
            foreign_members: None,
        }),
        id: Some(Id::Number(zone.id.into())),
        properties: Some(properties),
        foreign_members: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const POND: &str = r#"{"type": "FeatureCollection", "features": [
        {"type": "Feature", "id": 7, "properties": {"kind": "boundary", "name": "lawn"},
         "geometry": {"type": "Polygon", "coordinates":
            [[[8.5450, 47.3970], [8.5470, 47.3970], [8.5470, 47.3985], [8.5450, 47.3985],
              [8.5450, 47.3970]]]}},
        {"type": "Feature", "properties": {"kind": "keep_out", "name": "pond"},
         "geometry": {"type": "Polygon", "coordinates":
            [[[8.5455, 47.3975], [8.5458, 47.3975], [8.5458, 47.3977], [8.5455, 47.3977],
              [8.5455, 47.3975]]]}},
        {"type": "Feature", "properties": {"kind": "keep_out", "name": "tree", "radius_m": 1.5},
         "geometry": {"type": "Point", "coordinates": [8.5462, 47.3980]}},
        {"type": "Feature", "properties": {"kind": "wall"},
         "geometry": {"type": "LineString", "coordinates": [[8.5465, 47.3972], [8.5465, 47.3982]]}}
    ]}"#;

    fn feature_error(text: &str) -> (usize, String) {
        match ZoneSet::from_geojson(text) {
            Err(ZonesError::Feature { index, .. }) => {
                (index, ZoneSet::from_geojson(text).unwrap_err().to_string())
            }
            other => panic!("{other:?}"),
        }
    }

    fn one(feature: &str) -> String {
        format!(r#"{{"type": "FeatureCollection", "features": [{POND_FIRST}, {feature}]}}"#)
    }

    const POND_FIRST: &str = r#"{"type": "Feature", "properties": {"kind": "keep_out", "radius_m": 1},
         "geometry": {"type": "Point", "coordinates": [8.5, 47.3]}, "id": 1}"#;

    #[test]
    fn a_zones_file_reads_with_its_kinds_names_and_ids() {
        let set = ZoneSet::from_geojson(POND).unwrap();
        let zones = set.zones();
        assert_eq!(zones.len(), 4);
        assert_eq!(
            zones
                .iter()
                .map(|z| (z.id, z.name.as_str(), z.kind))
                .collect::<Vec<_>>(),
            [
                (7, "lawn", ZoneKind::Boundary),
                (8, "pond", ZoneKind::KeepOut),
                (9, "tree", ZoneKind::KeepOut),
                (10, "wall", ZoneKind::Wall),
            ]
        );
        assert_eq!(
            zones[2].shape,
            Shape::Circle {
                centre: [8.5462, 47.3980],
                radius_m: 1.5
            }
        );
    }

    #[test]
    fn written_zones_read_back_the_same() {
        let set = ZoneSet::from_geojson(POND).unwrap();
        let again = ZoneSet::from_geojson(&set.to_geojson()).unwrap();
        assert_eq!(set, again);
    }

    #[test]
    fn edits_keep_ids_and_are_checked() {
        let mut set = ZoneSet::from_geojson(POND).unwrap();
        let id = set
            .add(
                "fence",
                ZoneKind::Wall,
                Shape::Line(vec![[8.546, 47.397], [8.547, 47.397]]),
            )
            .unwrap();
        assert_eq!(id, 11);
        assert!(set.remove(8).is_some_and(|z| z.name == "pond"));
        assert!(set.remove(8).is_none());
        let refused = set.add(
            "bow tie",
            ZoneKind::KeepOut,
            Shape::Polygon(vec![vec![
                [8.5450, 47.3970],
                [8.5460, 47.3980],
                [8.5460, 47.3970],
                [8.5450, 47.3980],
                [8.5450, 47.3970],
            ]]),
        );
        assert!(
            refused
                .unwrap_err()
                .to_string()
                .contains("self-intersection"),
        );
        assert_eq!(set.zones().len(), 4);
    }

    #[test]
    fn edits_never_make_a_file_that_would_not_load() {
        let mut set = ZoneSet::from_geojson(POND).unwrap();
        // Walls of 10,000 positions (some 400 KB of GeoJSON each) until the file is full.
        let wall: Vec<[f64; 2]> = (0..MAX_POSITIONS)
            .map(|i| {
                [
                    8.5 + i as f64 * 1e-7,
                    47.3 + (i % 2) as f64 * 1.234_567_8e-5,
                ]
            })
            .collect();
        let refused = (0..MAX_ZONES)
            .find_map(|n| {
                set.add(
                    &format!("wall {n}"),
                    ZoneKind::Wall,
                    Shape::Line(wall.clone()),
                )
                .err()
            })
            .expect("the file fills up before the zones do");
        assert!(
            matches!(refused, ZonesError::WouldOutgrowFile { bytes } if bytes > MAX_TEXT_BYTES),
            "{refused}"
        );
        assert!(refused.to_string().contains("remove zones"), "{refused}");
        let text = set.to_geojson();
        assert!(text.len() <= MAX_TEXT_BYTES);
        assert_eq!(ZoneSet::from_geojson(&text).unwrap(), set);
    }

    #[test]
    fn a_bad_feature_is_refused_with_its_index_and_the_fix() {
        let unclosed = one(
            r#"{"type": "Feature", "properties": {"kind": "keep_out", "name": "bed"},
            "geometry": {"type": "Polygon", "coordinates": [[[8.0, 47.0], [8.1, 47.0], [8.1, 47.1], [8.0, 47.1]]]}}"#,
        );
        let (index, message) = feature_error(&unclosed);
        assert_eq!(index, 1);
        assert!(
            message.contains("\"bed\"") && message.contains("not closed"),
            "{message}"
        );
        assert!(
            message.contains("repeat the ring's first position"),
            "{message}"
        );

        let crossing = one(r#"{"type": "Feature", "properties": {"kind": "boundary"},
            "geometry": {"type": "Polygon", "coordinates": [[[8.0, 47.0], [8.1, 47.1], [8.1, 47.0], [8.0, 47.1], [8.0, 47.0]]]}}"#);
        let (index, message) = feature_error(&crossing);
        assert_eq!(index, 1);
        assert!(message.contains("self-intersection"), "{message}");

        let unknown = one(r#"{"type": "Feature", "properties": {"kind": "lake"},
            "geometry": {"type": "Point", "coordinates": [8.0, 47.0]}}"#);
        let (_, message) = feature_error(&unknown);
        assert!(
            message.contains("\"lake\"") && message.contains("boundary, keep_out or wall"),
            "{message}"
        );

        for (feature, wanted) in [
            (
                r#"{"type": "Feature", "properties": {"kind": "keep_out"}, "geometry": {"type": "Point", "coordinates": [8.0, 47.0]}}"#,
                "radius_m",
            ),
            (
                r#"{"type": "Feature", "properties": {"kind": "keep_out", "radius_m": -1}, "geometry": {"type": "Point", "coordinates": [8.0, 47.0]}}"#,
                "radius -1",
            ),
            (
                r#"{"type": "Feature", "properties": {"kind": "keep_out", "radius_m": 1}, "geometry": {"type": "Point", "coordinates": [47.0, 200.0]}}"#,
                "off the globe",
            ),
            (
                r#"{"type": "Feature", "properties": {"kind": "wall"}, "geometry": {"type": "Polygon", "coordinates": [[[8.0, 47.0], [8.1, 47.0], [8.1, 47.1], [8.0, 47.0]]]}}"#,
                "a wall cannot be a Polygon",
            ),
            (
                r#"{"type": "Feature", "properties": {"kind": "wall"}, "geometry": {"type": "LineString", "coordinates": [[8.0, 47.0], [8.0, 47.0]]}}"#,
                "two distinct",
            ),
            (
                r#"{"type": "Feature", "properties": {"kind": "wall"}}"#,
                "no geometry",
            ),
            (
                r#"{"type": "Feature", "id": 1, "properties": {"kind": "wall"}, "geometry": {"type": "LineString", "coordinates": [[8.0, 47.0], [8.1, 47.0]]}}"#,
                "id 1 is taken",
            ),
            (
                r#"{"type": "Feature", "id": -3, "properties": {"kind": "wall"}, "geometry": {"type": "LineString", "coordinates": [[8.0, 47.0], [8.1, 47.0]]}}"#,
                "id -3",
            ),
        ] {
            let (index, message) = feature_error(&one(feature));
            assert_eq!(index, 1, "{message}");
            assert!(message.contains(wanted), "{wanted}: {message}");
        }
    }

    #[test]
    fn hostile_sizes_are_refused_before_they_are_read() {
        let huge = " ".repeat(MAX_TEXT_BYTES + 1);
        assert!(matches!(
            ZoneSet::from_geojson(&huge),
            Err(ZonesError::TooLarge { .. })
        ));
        let feature = r#"{"type": "Feature", "properties": {"kind": "wall"}, "geometry": {"type": "LineString", "coordinates": [[8.0, 47.0], [8.1, 47.0]]}}"#;
        let many = format!(
            r#"{{"type": "FeatureCollection", "features": [{}]}}"#,
            vec![feature; MAX_ZONES + 1].join(",")
        );
        assert!(matches!(
            ZoneSet::from_geojson(&many),
            Err(ZonesError::TooMany { .. })
        ));
        assert!(matches!(
            ZoneSet::from_geojson("{\"type\": \"Point\", \"coordinates\": [8, 47]}"),
            Err(ZonesError::NotGeoJson(_))
        ));
        assert!(matches!(
            ZoneSet::from_geojson("[1, 2"),
            Err(ZonesError::NotGeoJson(_))
        ));
    }
}
