//! The zones file the zone tests share.

use std::path::{Path, PathBuf};

use chassisd::fusion::geodesy::Enu;
use chassisd::sim::plant::PlantConfig;
use nalgebra::Vector3;

/// A 40 × 20 m lawn round the start, a 2 × 2 m pond 4 m ahead, a fence 3 m behind and a
/// tree of 0.5 m to the north, in the plant's datum frame (x east, y north, m).
pub fn yard(plant: &PlantConfig, dir: &Path) -> PathBuf {
    let frame = Enu::new(plant.datum());
    let at = |x: f64, y: f64| {
        let g = frame.to_geodetic(&Vector3::new(x, y, 0.0));
        format!("[{}, {}]", g.lon_deg, g.lat_deg)
    };
    let rect = |x0: f64, y0: f64, x1: f64, y1: f64| {
        format!(
            "[[{}, {}, {}, {}, {}]]",
            at(x0, y0),
            at(x1, y0),
            at(x1, y1),
            at(x0, y1),
            at(x0, y0)
        )
    };
    let feature = |kind: &str, name: &str, geometry: String, extra: &str| {
        format!(
            r#"{{"type": "Feature", "properties": {{"kind": "{kind}", "name": "{name}"{extra}}}, "geometry": {geometry}}}"#
        )
    };
    let text = format!(
        r#"{{"type": "FeatureCollection", "features": [{}, {}, {}, {}]}}"#,
        feature(
            "boundary",
            "lawn",
            format!(
                r#"{{"type": "Polygon", "coordinates": {}}}"#,
                rect(-10.0, -10.0, 30.0, 10.0)
            ),
            ""
        ),
        feature(
            "keep_out",
            "pond",
            format!(
                r#"{{"type": "Polygon", "coordinates": {}}}"#,
                rect(4.0, -1.0, 6.0, 1.0)
            ),
            ""
        ),
        feature(
            "wall",
            "fence",
            format!(
                r#"{{"type": "LineString", "coordinates": [{}, {}]}}"#,
                at(-3.0, -5.0),
                at(-3.0, 5.0)
            ),
            ""
        ),
        feature(
            "keep_out",
            "tree",
            format!(r#"{{"type": "Point", "coordinates": {}}}"#, at(0.0, 6.0)),
            r#", "radius_m": 0.5"#
        ),
    );
    let path = dir.join("zones.geojson");
    std::fs::write(&path, text).expect("zones written");
    path
}
