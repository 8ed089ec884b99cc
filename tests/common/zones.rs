//! The zones file the zone tests share.

use std::path::{Path, PathBuf};

use chassisd::api::trajectory::MemoryStore;
use chassisd::config::zones::ZonesConfig;
use chassisd::geodesy::Enu;
use chassisd::sim::lockstep::{Lockstep, Sections};
use chassisd::sim::plant::PlantConfig;
use chassisd::vehicle::Localization;
use nalgebra::Vector3;

use super::lockstep::{START, SimRun};

/// The built-in mower in the [`yard`], its `[zones]` as `edit` leaves them, booted, nothing
/// run yet.
pub fn mower(name: &str, edit: impl FnOnce(&mut ZonesConfig)) -> SimRun {
    let plant = PlantConfig::builtin().expect("plant");
    let dir = super::tempdir(name);
    let file = yard(&plant, &dir);
    in_zones(plant, &file, 3, edit)
}

/// `plant` with noise `seed` among the zones of `file`, its `[zones]` as `edit` leaves them.
pub fn in_zones(
    plant: PlantConfig,
    file: &Path,
    seed: u64,
    edit: impl FnOnce(&mut ZonesConfig),
) -> SimRun {
    let mut zones = ZonesConfig::from_file(file, plant.geometry.footprint()).expect("zones");
    edit(&mut zones);
    let sections = Sections {
        zones: Some(zones),
        ..Sections::default()
    };
    let sim = Lockstep::with_sections(
        plant,
        seed,
        START,
        sections,
        Box::new(MemoryStore::default()),
    )
    .expect("sim");
    SimRun::on(sim)
}

/// [`mower`], standing until the GNSS gate opens (located, then the fix good for
/// `zones.resume_after_s`).
pub fn mower_in_the_yard(name: &str, edit: impl FnOnce(&mut ZonesConfig)) -> SimRun {
    let mut v = mower(name, edit);
    wait_for_the_gate(&mut v);
    v
}

/// Stands until the GNSS gate opens.
pub fn wait_for_the_gate(v: &mut SimRun) {
    assert!(
        v.run_until_event("GNSS gate open", 40.0),
        "the gate never opened"
    );
    assert_eq!(v.status().localization, Localization::Good);
}

/// A zone of a test's zones file, in the plant's datum frame (x east, y north, m).
#[derive(Debug, Clone)]
pub enum TestZone {
    /// A rectangle of `kind` (`boundary` or `keep_out`): x0, y0, x1, y1.
    Rect(&'static str, &'static str, [f64; 4]),
    /// A keep-out circle: its centre and radius.
    Circle(&'static str, (f64, f64), f64),
    /// A wall from one point to another.
    Wall(&'static str, (f64, f64), (f64, f64)),
}

/// A 40 × 20 m lawn round the start, a 2 × 2 m pond 4 m ahead, a fence 3 m behind and a
/// tree of 0.5 m to the north.
pub const YARD: [TestZone; 4] = [
    TestZone::Rect("boundary", "lawn", [-10.0, -10.0, 30.0, 10.0]),
    TestZone::Rect("keep_out", "pond", [4.0, -1.0, 6.0, 1.0]),
    TestZone::Wall("fence", (-3.0, -5.0), (-3.0, 5.0)),
    TestZone::Circle("tree", (0.0, 6.0), 0.5),
];

/// The [`YARD`]'s zones file in `dir`.
pub fn yard(plant: &PlantConfig, dir: &Path) -> PathBuf {
    write_zones(plant, dir, &YARD)
}

/// A zones file of `zones` in `dir`, placed about the plant's datum.
pub fn write_zones(plant: &PlantConfig, dir: &Path, zones: &[TestZone]) -> PathBuf {
    let frame = Enu::new(plant.datum());
    let at = |(x, y): (f64, f64)| {
        let g = frame.to_geodetic(&Vector3::new(x, y, 0.0));
        format!("[{}, {}]", g.lon_deg, g.lat_deg)
    };
    let feature = |kind: &str, name: &str, geometry: String, extra: String| {
        format!(
            r#"{{"type": "Feature", "properties": {{"kind": "{kind}", "name": "{name}"{extra}}}, "geometry": {geometry}}}"#
        )
    };
    let features: Vec<String> = zones
        .iter()
        .map(|z| match z {
            TestZone::Rect(kind, name, [x0, y0, x1, y1]) => {
                let ring = [(*x0, *y0), (*x1, *y0), (*x1, *y1), (*x0, *y1), (*x0, *y0)];
                let ring: Vec<String> = ring.into_iter().map(at).collect();
                let geometry = format!(
                    r#"{{"type": "Polygon", "coordinates": [[{}]]}}"#,
                    ring.join(", ")
                );
                feature(kind, name, geometry, String::new())
            }
            TestZone::Circle(name, centre, radius) => feature(
                "keep_out",
                name,
                format!(r#"{{"type": "Point", "coordinates": {}}}"#, at(*centre)),
                format!(r#", "radius_m": {radius}"#),
            ),
            TestZone::Wall(name, from, to) => feature(
                "wall",
                name,
                format!(
                    r#"{{"type": "LineString", "coordinates": [{}, {}]}}"#,
                    at(*from),
                    at(*to)
                ),
                String::new(),
            ),
        })
        .collect();
    let text = format!(
        r#"{{"type": "FeatureCollection", "features": [{}]}}"#,
        features.join(", ")
    );
    let path = dir.join("zones.geojson");
    std::fs::write(&path, text).expect("zones written");
    path
}
