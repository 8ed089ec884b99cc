//! The zones' safety property (docs/safety.md, Zones): no sequence of commands (manual jogs
//! at any speed and turn, jogs steered at a zone, re-arms, goals, straight moves, turns and
//! path tasks) ever puts
//! the vehicle's true footprint into a keep-out zone or across a wall while the fix is RTK
//! fixed (the position's σ within the gate), on both shipped plants and random zones near
//! the start. The footprint is the plant's true outline at its true pose, checked every
//! plant step. Proptest keeps failing cases in `tests/zones_properties.proptest-regressions`.

use crate::common;

use std::path::{Path, PathBuf};

use chassisd::sim::lockstep::PLANT_STEP;
use chassisd::sim::plant::PlantConfig;
use common::lockstep::{FIXED, SimRun};
use common::zones::{TestZone, in_zones, write_zones};
use geo::{Coord, Intersects, Line, Polygon};
use proptest::prelude::*;

/// One thing the operator or a client does, then lets run.
#[derive(Debug, Clone)]
enum Act {
    /// Manual velocity commands (m/s, rad/s) every 0.1 s for a while, s.
    Jog(f64, f64, f64),
    /// Manual velocity commands (m/s) every 0.1 s for a while (s), steered at a zone's
    /// middle (the first zone, or the second): a driver heading for the pond.
    Toward(f64, f64, bool),
    /// A zero command and a reset: the deliberate act that re-arms.
    Rearm,
    /// A goal (x, y, m), then a while, s.
    Goal(f64, f64, f64),
    /// A straight move (cm, negative backwards), then a while, s.
    Straight(i32, f64),
    /// A turn on the spot (degrees, negative clockwise), then a while, s.
    Turn(i32, f64),
    /// A path task through these points, then a while, s.
    Path(Vec<(f64, f64)>, f64),
}

fn act() -> impl Strategy<Value = Act> {
    let point = || (-4.0f64..9.0, -4.0f64..4.0);
    prop_oneof![
        4 => (-1.5f64..1.5, -1.5f64..1.5, 0.2f64..4.0).prop_map(|(v, w, s)| Act::Jog(v, w, s)),
        3 => (0.2f64..1.5, 1.0f64..8.0, any::<bool>()).prop_map(|(v, s, z)| Act::Toward(v, s, z)),
        3 => Just(Act::Rearm),
        2 => (point(), 1.0f64..10.0).prop_map(|((x, y), s)| Act::Goal(x, y, s)),
        1 => (-600i32..600, 1.0f64..8.0).prop_map(|(d, s)| Act::Straight(d, s)),
        1 => (-180i32..180, 1.0f64..4.0).prop_map(|(a, s)| Act::Turn(a, s)),
        1 => (prop::collection::vec(point(), 1..4), 2.0f64..12.0)
            .prop_map(|(p, s)| Act::Path(p, s)),
    ]
}

/// A keep-out rectangle and a wall near the start, clear of where the vehicle stands.
fn zones() -> impl Strategy<Value = Vec<TestZone>> {
    let rect = (1.5f64..7.0, -3.0f64..3.0, 0.2f64..1.5, 0.2f64..1.5).prop_map(|(x, y, hx, hy)| {
        TestZone::Rect("keep_out", "pond", [x - hx, y - hy, x + hx, y + hy])
    });
    let wall = ((-6.0f64..6.0, -6.0f64..6.0), (-6.0f64..6.0, -6.0f64..6.0))
        .prop_map(|(a, b)| TestZone::Wall("fence", a, b));
    (rect, wall)
        .prop_filter("clear of the start", |(r, w)| {
            let (TestZone::Rect(_, _, [x0, y0, x1, y1]), TestZone::Wall(_, a, b)) = (r, w) else {
                return false;
            };
            // The origin's distance from the rectangle, and from the wall.
            let rect = x0.max(-x1).max(0.0).hypot(y0.max(-y1).max(0.0));
            rect > 1.2 && segment_distance(*a, *b) > 1.2 && (b.0 - a.0).hypot(b.1 - a.1) > 0.5
        })
        .prop_map(|(r, w)| vec![r, w])
}

/// A zone's middle, m.
fn middle(zone: &TestZone) -> (f64, f64) {
    match *zone {
        TestZone::Rect(_, _, [x0, y0, x1, y1]) => ((x0 + x1) / 2.0, (y0 + y1) / 2.0),
        TestZone::Circle(_, centre, _) => centre,
        TestZone::Wall(_, a, b) => ((a.0 + b.0) / 2.0, (a.1 + b.1) / 2.0),
    }
}

/// The origin's distance from the segment a–b, m.
fn segment_distance(a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let t = (-(a.0 * dx + a.1 * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
    (a.0 + t * dx).hypot(a.1 + t * dy)
}

fn plant_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("devices")
        .join(name)
}

/// The true outline at the true pose.
fn footprint(v: &SimRun, plant: &PlantConfig) -> Polygon<f64> {
    let t = v.sim.vehicle().truth();
    plant.geometry.footprint().outline_at(t.x, t.y, t.yaw)
}

/// A zone as the footprint must never meet it.
enum Solid {
    Rect(geo::Rect<f64>),
    Wall(Line<f64>),
}

impl Solid {
    /// A keep-out rectangle or a wall, named.
    fn of(zone: &TestZone) -> Option<(&'static str, Self)> {
        match *zone {
            TestZone::Rect(_, name, [x0, y0, x1, y1]) => Some((
                name,
                Self::Rect(geo::Rect::new(
                    Coord { x: x0, y: y0 },
                    Coord { x: x1, y: y1 },
                )),
            )),
            TestZone::Wall(name, a, b) => Some((
                name,
                Self::Wall(Line::new(
                    Coord { x: a.0, y: a.1 },
                    Coord { x: b.0, y: b.1 },
                )),
            )),
            TestZone::Circle(..) => None,
        }
    }

    fn meets(&self, outline: &Polygon<f64>) -> bool {
        match self {
            Self::Rect(r) => outline.intersects(r),
            Self::Wall(l) => outline.intersects(l),
        }
    }
}

/// Runs `acts` among `zones`; the first time the footprint meets one, if ever.
fn breach(plant_name: &str, seed: u64, zones: &[TestZone], acts: &[Act]) -> Option<String> {
    let plant = PlantConfig::load(&plant_file(plant_name)).expect("plant");
    let dir = common::tempdir("zones-properties");
    let file = write_zones(&plant, &dir, zones);
    let mut v = in_zones(plant.clone(), &file, seed, |_| {});
    // Half a metre forward and back gives a vehicle without a heading standing (the
    // delivery robot) one; then the gate opens. Should a zone stop the warm-up, the acts
    // still run: manual driving is not gated.
    v.run(3.0);
    for speed in [0.5, -0.5] {
        let command = format!(r#"{{"linear": {{"x": {speed}}}, "angular": {{"z": 0}}}}"#);
        for _ in 0..12 {
            let _ = v.send("cmd_vel", &command);
            v.run(0.1);
        }
    }
    let _ = v.send("cmd_vel", r#"{"linear": {"x": 0}, "angular": {"z": 0}}"#);
    v.run_until_event("GNSS gate open", 30.0);
    let _ = std::fs::remove_dir_all(&dir);
    let solids: Vec<(&str, Solid)> = zones.iter().filter_map(Solid::of).collect();
    let run = |v: &mut SimRun, seconds: f64| -> Option<String> {
        for _ in 0..(seconds / PLANT_STEP.as_secs_f64()).round() as u64 {
            v.sim.step(FIXED, &mut v.sink);
            let outline = footprint(v, &plant);
            if let Some((name, _)) = solids.iter().find(|(_, solid)| solid.meets(&outline)) {
                let t = v.sim.vehicle().truth();
                return Some(format!(
                    "into {name} at ({:.3}, {:.3}, yaw {:.2}) at {:.2} m/s",
                    t.x, t.y, t.yaw, t.v
                ));
            }
        }
        None
    };
    for act in acts {
        let (request, seconds) = match act {
            Act::Jog(speed, turn, seconds) => {
                let command =
                    format!(r#"{{"linear": {{"x": {speed}}}, "angular": {{"z": {turn}}}}}"#);
                for _ in 0..(seconds * 10.0).round() as usize {
                    let _ = v.send("cmd_vel", &command);
                    if let Some(b) = run(&mut v, 0.1) {
                        return Some(b);
                    }
                }
                continue;
            }
            Act::Toward(speed, seconds, second) => {
                let (x, y) = middle(&zones[usize::from(*second).min(zones.len() - 1)]);
                for _ in 0..(seconds * 10.0).round() as usize {
                    let t = v.sim.vehicle().truth();
                    let error = (y - t.y).atan2(x - t.x) - t.yaw;
                    let turn = (2.0 * error.sin().atan2(error.cos())).clamp(-1.5, 1.5);
                    let command =
                        format!(r#"{{"linear": {{"x": {speed}}}, "angular": {{"z": {turn}}}}}"#);
                    let _ = v.send("cmd_vel", &command);
                    if let Some(b) = run(&mut v, 0.1) {
                        return Some(b);
                    }
                }
                continue;
            }
            Act::Rearm => {
                let _ = v.send("cmd_vel", r#"{"linear": {"x": 0}, "angular": {"z": 0}}"#);
                let _ = v.send("reset", "{}");
                (None, 0.2)
            }
            Act::Goal(x, y, s) => (
                Some(("goal", format!(r#"{{"x": {x}, "y": {y}, "yaw": 0}}"#))),
                *s,
            ),
            Act::Straight(cm, s) => {
                let cmd = if *cm >= 0 { "1" } else { "2" };
                let request = format!(r#"{{"cmd": "{cmd}", "distance": {}}}"#, cm.abs());
                (Some(("set_navi_cmd", request)), *s)
            }
            Act::Turn(deg, s) => {
                let cmd = if *deg >= 0 { "3" } else { "4" };
                let request = format!(r#"{{"cmd": "{cmd}", "distance": {}}}"#, deg.abs());
                (Some(("set_navi_cmd", request)), *s)
            }
            Act::Path(points, s) => {
                let flat: Vec<String> = points
                    .iter()
                    .flat_map(|(x, y)| [x.to_string(), y.to_string()])
                    .collect();
                let request = format!(r#"{{"path": [{}], "speed": 0.8}}"#, flat.join(", "));
                (Some(("follow_path", request)), *s)
            }
        };
        if let Some((topic, payload)) = request {
            let _ = v.send(topic, &payload);
        }
        if let Some(b) = run(&mut v, seconds) {
            return Some(b);
        }
    }
    None
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn no_command_sequence_puts_the_footprint_into_a_zone(
        plant in prop_oneof![Just("plant.mower.toml"), Just("plant.delivery.toml")],
        seed in 0u64..1000,
        zones in zones(),
        acts in prop::collection::vec(act(), 1..12),
    ) {
        let breach = breach(plant, seed, &zones, &acts);
        prop_assert!(breach.is_none(), "{plant}: {}; zones {zones:?}", breach.unwrap_or_default());
    }
}
