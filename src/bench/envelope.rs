//! `chassisd bench envelope`: the safety envelope on the simulated vehicle, through the
//! whole path (local command channel, engine, core, CAN frames to the simulated drives),
//! scored against the simulator's truth:
//! - **approaches**: randomised approaches towards a keep-out rectangle, a keep-out circle
//!   or a wall 3.5–6.5 m away, at 0.3–1.0 m/s, manual (jogs steered at the zone) or
//!   autonomous (a path task ending where the plan's margin allows, or a mission with the
//!   blade on), half of them with a 1–3 m RTK-float jump of the fix for 1–5 s on the way:
//!   the true outline must never meet the zone;
//! - **the blade**: from the first fix that fails the GNSS gate to the blade off, at most
//!   one control period, at every gate closing with the blade on;
//! - **coverage**: a covering mission inside a boundary whose lanes end where the plan's
//!   margin allows, under clean RTK fixed for 30 minutes: no pause of the gate and no stop
//!   at a zone;
//! - **plans**: random goals, path tasks, missions and straight moves through a zone are
//!   all refused, and as many clear of every zone all start.
//!
//! Each approach starts a fresh vehicle: it stands, jogs half a metre forward and back (a
//! vehicle without a heading standing gets one), and waits for the gate to open.

use std::f64::consts::PI;

use geo::{Coord, Distance, Euclidean, Intersects, Line, LineString, Point, Polygon};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::api::trajectory::MemoryStore;
use crate::config::zones::ZonesConfig;
use crate::config::{ConfigError, VehicleConfig};
use crate::control::mission::MissionEvent;
use crate::control::{MotionResult, Outcome};
use crate::devices::gnss::FixQuality;
use crate::engine::{EngineOutput, GNSS_SOURCE};
use crate::fusion::localizer::MapPlacement;
use crate::geodesy::Enu;
use crate::record::{Payload, Record};
use crate::sim::lockstep::{Lockstep, PLANT_STEP, Sections, Sink};
use crate::sim::plant::{GnssCondition, PlantConfig};
use crate::time::Timestamp;
use crate::vehicle::chassis::CONTROL_PERIOD;
use crate::vehicle::status::VehicleStatus;
use crate::vehicle::{CoreConfig, Event};
use crate::zones::local::LocalZones;
use crate::zones::{LonLat, Shape, ZoneKind, ZoneSet};

/// Sessions start here (2026-01-01T00:00:00Z).
const START: Timestamp = Timestamp::from_micros(1_767_225_600_000_000);
/// RTK fixed, no offset.
const FIXED: GnssCondition = GnssCondition {
    quality: Some(FixQuality::RtkFixed),
    offset: (0.0, 0.0),
};
/// The longest wait for the gate to open after the warm-up, s.
const GATE_WAIT_S: f64 = 90.0;
/// Coverage lanes are this far apart, m.
const LANE_SPACING_M: f64 = 0.5;
/// Coverage lanes: this many (even, so the last ends where the first began), this long, m.
const LANES: (usize, f64) = (14, 16.0);
/// The missions' speed (`[mission] speed_mps`'s default), m/s.
const MISSION_SPEED: f64 = 0.5;
/// Plans and coverage lanes keep this much more than the plan's margin, m.
const SLACK_M: f64 = 0.03;

/// How much to run.
#[derive(Debug, Clone, Copy)]
pub struct EnvelopeOptions {
    /// Randomised approaches.
    pub approaches: u32,
    /// The covering mission's length, s.
    pub coverage_s: f64,
    /// Plans through zones (and as many clear of them).
    pub plans: u32,
}

impl Default for EnvelopeOptions {
    fn default() -> Self {
        Self {
            approaches: 1000,
            coverage_s: 1800.0,
            plans: 200,
        }
    }
}

/// The approaches' figures.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ApproachFigures {
    /// Approaches run.
    pub runs: u32,
    /// Manual ones.
    pub manual: u32,
    /// Autonomous ones (path tasks and missions).
    pub autonomous: u32,
    /// With a float jump on the way.
    pub with_jumps: u32,
    /// Runs whose gate never opened after the warm-up (not scored).
    pub not_started: u32,
    /// Runs in which the true outline met the zone.
    pub incursions: u32,
    /// The least clearance of the true outline from the zone over all runs, m.
    pub min_clearance_m: f64,
    /// Manual runs stopped by the zone check.
    pub manual_stops: u32,
    /// Where manual runs came to rest from the zone: the median, m.
    pub manual_rest_median_m: f64,
    /// Autonomous runs without a jump stopped by the zone check (a planned way must not
    /// trip it).
    pub false_stops: u32,
    /// The worst approach, described.
    pub worst: String,
}

/// The blade's figures.
#[derive(Debug, Clone, Default, Serialize)]
pub struct BladeFigures {
    /// Gate closings with the blade on.
    pub closings: u32,
    /// The longest from the first failing fix to the blade off, ms.
    pub worst_ms: f64,
    /// The limit: one control period, ms.
    pub limit_ms: f64,
}

/// The covering mission's figures.
#[derive(Debug, Clone, Default, Serialize)]
pub struct CoverageFigures {
    /// Time covered, s.
    pub seconds: f64,
    /// Distance driven, m.
    pub distance_m: f64,
    /// Missions completed (it starts again until the time is up).
    pub missions: u32,
    /// Gate closings.
    pub pauses: u32,
    /// Stops at a zone.
    pub zone_stops: u32,
    /// Missions that did not succeed, and why.
    pub failures: Vec<String>,
}

/// The plans' figures.
#[derive(Debug, Clone, Default, Serialize)]
pub struct PlanFigures {
    /// Plans whose way crosses a zone.
    pub through: u32,
    /// Of them refused.
    pub refused: u32,
    /// Plans clear of every zone by more than the plan's margin.
    pub clear: u32,
    /// Of them started.
    pub started: u32,
    /// The first plan judged wrongly, described.
    pub first_wrong: String,
}

/// The whole report.
#[derive(Debug, Clone, Serialize)]
pub struct EnvelopeReport {
    /// The plant's name.
    pub plant: String,
    /// Noise seed.
    pub seed: u64,
    /// Randomised approaches.
    pub approaches: ApproachFigures,
    /// The blade at gate closings.
    pub blade: BladeFigures,
    /// The covering mission.
    pub coverage: CoverageFigures,
    /// Plans through zones and clear of them.
    pub plans: PlanFigures,
    /// Every target met.
    pub pass: bool,
}

/// What the engine put out, with the times it came at.
#[derive(Default)]
struct Collector {
    now: Timestamp,
    events: Vec<(Timestamp, Event)>,
    answers: Vec<Result<(), String>>,
    results: Vec<MotionResult>,
    status: Option<Box<VehicleStatus>>,
    /// How missions ended.
    missions_ended: Vec<Outcome>,
    /// The first fix the engine saw that was not RTK fixed, once watching.
    first_unfixed: Option<Timestamp>,
}

impl Sink for Collector {
    fn record(&mut self, record: &Record) {
        if self.first_unfixed.is_some() || record.source != GNSS_SOURCE {
            return;
        }
        if let Payload::Serial(bytes) = &record.payload
            && unfixed_gga(bytes)
        {
            self.first_unfixed = Some(record.t);
        }
    }

    fn output(&mut self, output: EngineOutput) {
        match output {
            EngineOutput::Event(e) => self.events.push((self.now, e)),
            EngineOutput::CommandResult { result, .. } => self.answers.push(result),
            EngineOutput::MotionEnded(r) => self.results.push(r),
            EngineOutput::Status(s) => self.status = Some(s),
            EngineOutput::Mission {
                event: MissionEvent::Ended(outcome),
                ..
            } => self.missions_ended.push(outcome),
            _ => {}
        }
    }
}

/// Whether `bytes` hold a GGA sentence whose quality is not RTK fixed (4).
fn unfixed_gga(bytes: &[u8]) -> bool {
    String::from_utf8_lossy(bytes)
        .lines()
        .filter(|l| l.get(3..6) == Some("GGA"))
        .any(|l| l.split(',').nth(6).is_some_and(|q| q != "4"))
}

/// A vehicle and what it put out.
struct Run {
    sim: Lockstep,
    sink: Collector,
}

impl Run {
    fn new(plant: &PlantConfig, seed: u64, set: ZoneSet) -> Result<Self, ConfigError> {
        let zones = ZonesConfig::of_set(set, plant.geometry.footprint());
        let sections = Sections {
            zones: Some(zones),
            ..Sections::default()
        };
        let sim = Lockstep::with_sections(
            plant.clone(),
            seed,
            START,
            sections,
            Box::new(MemoryStore::default()),
        )?;
        Ok(Self {
            sim,
            sink: Collector::default(),
        })
    }

    fn step(&mut self, gnss: GnssCondition) {
        self.sim.step(gnss, &mut self.sink);
        self.sink.now = self.sim.time();
    }

    fn run(&mut self, seconds: f64) {
        for _ in 0..steps(seconds) {
            self.step(FIXED);
        }
    }

    fn send(&mut self, topic: &str, payload: &str) -> Result<(), String> {
        self.sink.answers.clear();
        self.sim.command(topic, payload, &mut self.sink);
        self.sink
            .answers
            .pop()
            .unwrap_or_else(|| Err("no answer".into()))
    }

    fn jog(&mut self, v: f64, w: f64) -> Result<(), String> {
        self.send(
            "cmd_vel",
            &format!(r#"{{"linear": {{"x": {v}}}, "angular": {{"z": {w}}}}}"#),
        )
    }

    /// Stands, jogs half a metre forward and back, and waits for the gate; whether it
    /// opened.
    fn warm_up(&mut self) -> bool {
        self.run(3.0);
        for v in [0.5, -0.5] {
            for _ in 0..12 {
                let _ = self.jog(v, 0.0);
                self.run(0.1);
            }
        }
        let _ = self.jog(0.0, 0.0);
        for _ in 0..steps(GATE_WAIT_S) {
            self.step(FIXED);
            if self.event(|e| *e == Event::GateOpened).is_some() {
                return true;
            }
        }
        false
    }

    /// When the first event `is` took came.
    fn event(&self, is: impl Fn(&Event) -> bool) -> Option<Timestamp> {
        self.sink
            .events
            .iter()
            .find(|(_, e)| is(e))
            .map(|(t, _)| *t)
    }

    /// The map pose (x, y, yaw) the status shows.
    fn pose(&self) -> (f64, f64, f64) {
        self.sink
            .status
            .as_ref()
            .map_or((0.0, 0.0, 0.0), |s| (s.pose.x, s.pose.y, s.pose.yaw))
    }
}

fn steps(seconds: f64) -> u64 {
    (seconds / PLANT_STEP.as_secs_f64()).round() as u64
}

/// A zone as the truth sees it, in the datum's frame (m).
#[derive(Debug, Clone)]
enum Solid {
    Polygon(Polygon<f64>),
    Circle(Coord<f64>, f64),
    Wall(Line<f64>),
}

impl Solid {
    /// The least distance of `outline` from it, m (0 when they meet).
    fn clearance(&self, outline: &Polygon<f64>) -> f64 {
        match self {
            Self::Polygon(p) if p.intersects(outline) => 0.0,
            Self::Polygon(p) => Euclidean.distance(p, outline),
            Self::Circle(c, r) => (Euclidean.distance(&Point(*c), outline) - r).max(0.0),
            Self::Wall(l) if l.intersects(outline) => 0.0,
            Self::Wall(l) => Euclidean.distance(l, outline),
        }
    }

    /// The least distance of the segment a–b from it, m (0 when they meet).
    fn segment_clearance(&self, a: (f64, f64), b: (f64, f64)) -> f64 {
        let segment = Line::new(Coord { x: a.0, y: a.1 }, Coord { x: b.0, y: b.1 });
        match self {
            Self::Polygon(p) if p.intersects(&segment) => 0.0,
            Self::Polygon(p) => Euclidean.distance(&segment, p),
            Self::Circle(c, r) => (Euclidean.distance(&segment, &Point(*c)) - r).max(0.0),
            Self::Wall(l) if l.intersects(&segment) => 0.0,
            Self::Wall(l) => Euclidean.distance(&segment, l),
        }
    }
}

/// Zones built in the datum's frame, for the core (WGS84) and for the truth.
struct Zones {
    frame: Enu,
    set: ZoneSet,
    solids: Vec<(String, Solid)>,
    boundary: Option<Polygon<f64>>,
}

impl Zones {
    fn new(plant: &PlantConfig) -> Self {
        Self {
            frame: Enu::new(plant.datum()),
            set: ZoneSet::default(),
            solids: Vec::new(),
            boundary: None,
        }
    }

    fn lon_lat(&self, (x, y): (f64, f64)) -> LonLat {
        let g = self.frame.to_geodetic(&Vector3::new(x, y, 0.0));
        [g.lon_deg, g.lat_deg]
    }

    fn polygon(&mut self, name: &str, kind: ZoneKind, corners: &[(f64, f64)]) {
        let mut ring: Vec<LonLat> = corners.iter().map(|&p| self.lon_lat(p)).collect();
        ring.push(ring[0]);
        // The corners are chosen, so a refusal is this program's fault.
        if self.set.add(name, kind, Shape::Polygon(vec![ring])).is_ok() {
            let polygon = Polygon::new(
                LineString::from(
                    corners
                        .iter()
                        .map(|&(x, y)| Coord { x, y })
                        .collect::<Vec<_>>(),
                ),
                Vec::new(),
            );
            match kind {
                ZoneKind::Boundary => self.boundary = Some(polygon),
                _ => self.solids.push((name.into(), Solid::Polygon(polygon))),
            }
        }
    }

    fn circle(&mut self, name: &str, centre: (f64, f64), radius_m: f64) {
        let shape = Shape::Circle {
            centre: self.lon_lat(centre),
            radius_m,
        };
        if self.set.add(name, ZoneKind::KeepOut, shape).is_ok() {
            let c = Coord {
                x: centre.0,
                y: centre.1,
            };
            self.solids.push((name.into(), Solid::Circle(c, radius_m)));
        }
    }

    fn wall(&mut self, name: &str, a: (f64, f64), b: (f64, f64)) {
        let shape = Shape::Line(vec![self.lon_lat(a), self.lon_lat(b)]);
        if self.set.add(name, ZoneKind::Wall, shape).is_ok() {
            let line = Line::new(Coord { x: a.0, y: a.1 }, Coord { x: b.0, y: b.1 });
            self.solids.push((name.into(), Solid::Wall(line)));
        }
    }

    /// The least clearance of the true outline from any zone (and from the boundary's
    /// edge, inside), m; 0 when it meets one.
    fn clearance(&self, outline: &Polygon<f64>) -> (f64, String) {
        let mut least = (f64::INFINITY, String::new());
        for (name, solid) in &self.solids {
            let c = solid.clearance(outline);
            if c < least.0 {
                least = (c, name.clone());
            }
        }
        if let Some(b) = &self.boundary {
            let inside = outline
                .exterior()
                .points()
                .all(|p| geo::Contains::contains(b, &p));
            let c = if inside {
                Euclidean.distance(b.exterior(), outline.exterior())
            } else {
                0.0
            };
            if c < least.0 {
                least = (c, "boundary".into());
            }
        }
        least
    }
}

/// The plant's true outline.
fn outline(sim: &Lockstep, plant: &PlantConfig) -> Polygon<f64> {
    let t = sim.vehicle().truth();
    plant.geometry.footprint().outline_at(t.x, t.y, t.yaw)
}

/// Whether the plant has a blade.
fn has_cutter(plant: &PlantConfig) -> bool {
    plant
        .yard
        .as_ref()
        .is_some_and(|y| y.cutter_can_id.is_some() || y.blade_node.is_some())
}

/// The mission's steps around `steps`: the blade on first and off last, with a blade.
fn with_blade(plant: &PlantConfig, steps: &str) -> String {
    if has_cutter(plant) {
        format!(
            r#"[{{"action": "OPEN_CUTTER", "parameters": {{}}}}, {steps},
                {{"action": "CLOSE_CUTTER", "parameters": {{}}}}]"#
        )
    } else {
        format!("[{steps}]")
    }
}

/// The plan-time radius at `speed` (m/s), as the core keeps it, with room to spare: the
/// footprint's circumscribed radius and the larger of the margin and the gate's most σ plus
/// the braking way (the reaction taken as two control periods, twice the drives' lag and
/// 50 ms more), m.
fn plan_radius(plant: &PlantConfig, config: &VehicleConfig, speed: f64) -> f64 {
    let zones = ZonesConfig::of_set(ZoneSet::default(), plant.geometry.footprint());
    let decel = config.chassis.map_or(1.0, |c| c.max_decel_mps2);
    let reaction = 2.0 * CONTROL_PERIOD.as_secs_f64() + 2.0 * plant.motors.time_constant_s + 0.05;
    let braking = speed * reaction + speed * speed / (2.0 * decel);
    zones.footprint.radius_m() + zones.margin_m.max(zones.max_sigma_m + braking)
}

/// The speed goals and straight moves cruise at on `config`, m/s.
fn cruise_mps(config: &VehicleConfig) -> f64 {
    CoreConfig::from_vehicle(config)
        .motion
        .map_or(0.0, |m| m.linear.speed)
}

/// Runs the benchmark on `plant` with noise `seed`.
pub fn run(
    plant: &PlantConfig,
    seed: u64,
    options: EnvelopeOptions,
) -> Result<EnvelopeReport, ConfigError> {
    let mut approaches = ApproachFigures {
        min_clearance_m: f64::INFINITY,
        ..ApproachFigures::default()
    };
    let mut blade = BladeFigures {
        limit_ms: CONTROL_PERIOD.as_secs_f64() * 1000.0,
        ..BladeFigures::default()
    };
    let mut rests = Vec::new();
    for i in 0..options.approaches {
        approach(
            plant,
            seed.wrapping_mul(1_000_003).wrapping_add(u64::from(i)),
            &mut approaches,
            &mut blade,
            &mut rests,
        )?;
    }
    rests.sort_by(f64::total_cmp);
    approaches.manual_rest_median_m = rests.get(rests.len() / 2).copied().unwrap_or(f64::NAN);
    let coverage = coverage(plant, seed, options.coverage_s)?;
    let plans = plans(plant, seed, options.plans)?;
    let pass = approaches.incursions == 0
        && approaches.false_stops == 0
        && approaches.not_started * 20 <= approaches.runs
        && blade.worst_ms <= blade.limit_ms
        && coverage.pauses == 0
        && coverage.zone_stops == 0
        && coverage.failures.is_empty()
        && plans.refused == plans.through
        && plans.started == plans.clear;
    Ok(EnvelopeReport {
        plant: plant.name.clone(),
        seed,
        approaches,
        blade,
        coverage,
        plans,
        pass,
    })
}

/// How an approach drives at its zone.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Drive {
    /// Jogs steered at the zone's middle.
    Manual,
    /// A path task to where the plan's margin allows.
    Path,
    /// A mission with the blade on, to the same place.
    Mission,
}

/// One randomised approach.
fn approach(
    plant: &PlantConfig,
    seed: u64,
    figures: &mut ApproachFigures,
    blade: &mut BladeFigures,
    rests: &mut Vec<f64>,
) -> Result<(), ConfigError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut zones = Zones::new(plant);
    let direction = rng.random_range(-PI..PI);
    let distance = rng.random_range(3.5..6.5);
    let (ux, uy) = (direction.cos(), direction.sin());
    let middle = (distance * ux, distance * uy);
    let kind = rng.random_range(0..3);
    match kind {
        0 => {
            let (a, b) = (rng.random_range(0.3..1.5), rng.random_range(0.3..1.5));
            let corner = |s: f64, t: f64| {
                (
                    middle.0 + s * a * ux - t * b * uy,
                    middle.1 + s * a * uy + t * b * ux,
                )
            };
            let corners = [
                corner(-1.0, -1.0),
                corner(1.0, -1.0),
                corner(1.0, 1.0),
                corner(-1.0, 1.0),
            ];
            zones.polygon("pond", ZoneKind::KeepOut, &corners);
        }
        1 => zones.circle("tree", middle, rng.random_range(0.3..1.5)),
        _ => {
            let half = rng.random_range(1.0..3.0);
            let a = (middle.0 - half * uy, middle.1 + half * ux);
            let b = (middle.0 + half * uy, middle.1 - half * ux);
            zones.wall("fence", a, b);
        }
    }
    let drive = match rng.random_range(0..4) {
        0 | 1 => Drive::Manual,
        2 => Drive::Path,
        _ => Drive::Mission,
    };
    let speed = match drive {
        Drive::Mission => MISSION_SPEED,
        _ => rng.random_range(0.3..1.0),
    };
    let jump = rng.random_bool(0.5).then(|| {
        let size = rng.random_range(1.0..3.0);
        let angle = rng.random_range(-PI..PI);
        (
            rng.random_range(0.3..0.8),
            rng.random_range(1.0..5.0),
            (size * angle.cos(), size * angle.sin()),
        )
    });

    figures.runs += 1;
    let mut run = Run::new(plant, seed, zones.set.clone())?;
    if !run.warm_up() {
        figures.not_started += 1;
        return Ok(());
    }
    match drive {
        Drive::Manual => figures.manual += 1,
        Drive::Path | Drive::Mission => figures.autonomous += 1,
    }
    if jump.is_some() {
        figures.with_jumps += 1;
    }
    let start = run.pose();
    let travel_s = distance / speed;
    if drive != Drive::Manual {
        // Where the plan's disc first meets the zone, less a little: the path's end.
        let placement = MapPlacement::at_datum(plant.datum());
        let local = LocalZones::new(&zones.set, |lat, lon| placement.place(lat, lon));
        let far = (start.0 + 2.0 * distance * ux, start.1 + 2.0 * distance * uy);
        let radius = plan_radius(plant, run.sim.config(), speed) + SLACK_M;
        let Some(meet) = local.path_conflict(&[(start.0, start.1), far], radius) else {
            return Ok(());
        };
        let end = (meet.at.0 - 0.02 * ux, meet.at.1 - 0.02 * uy);
        let path = format!("[{}, {}, {}, {}]", start.0, start.1, end.0, end.1);
        let answer = match drive {
            Drive::Path => run.send(
                "follow_path",
                &format!(r#"{{"path": {path}, "speed": {speed}}}"#),
            ),
            _ => run.send(
                "mission",
                &with_blade(
                    plant,
                    &format!(
                        r#"{{"action": "MOVE_TO_POSITION", "parameters": {{"path": {path}}}}}"#
                    ),
                ),
            ),
        };
        if answer.is_err() {
            // Too close to start (the turn on the spot already meets it): not an approach.
            figures.runs -= 1;
            figures.autonomous -= 1;
            if jump.is_some() {
                figures.with_jumps -= 1;
            }
            return Ok(());
        }
    }
    let began = run.sim.time();
    let length_s = travel_s + 8.0;
    let mut least = f64::INFINITY;
    run.sink.first_unfixed = None;
    let mut watching = false;
    for k in 0..steps(length_s) {
        let s = k as f64 * PLANT_STEP.as_secs_f64();
        let gnss = match jump {
            Some((at, lasting, offset)) if s >= at * travel_s && s < at * travel_s + lasting => {
                GnssCondition {
                    quality: Some(FixQuality::RtkFloat),
                    offset,
                }
            }
            _ => FIXED,
        };
        if gnss != FIXED && !watching {
            watching = true;
            run.sink.first_unfixed = None;
        }
        if drive == Drive::Manual && k % 100 == 0 {
            let t = run.sim.vehicle().truth();
            let error = (middle.1 - t.y).atan2(middle.0 - t.x) - t.yaw;
            let turn = (2.0 * error.sin().atan2(error.cos())).clamp(-1.0, 1.0);
            let _ = run.jog(speed, turn);
        }
        run.step(gnss);
        if k % 10 == 0 {
            let (c, _) = zones.clearance(&outline(&run.sim, plant));
            least = least.min(c);
        }
    }
    if !watching {
        run.sink.first_unfixed = None;
    }
    let stopped_at_zone = run
        .sink
        .events
        .iter()
        .any(|(t, e)| *t >= began && is_zone_stop(e));
    if least <= 0.0 {
        figures.incursions += 1;
    }
    if least < figures.min_clearance_m {
        figures.min_clearance_m = least;
        let jumped = jump.map_or("no jump".to_owned(), |(at, lasting, (dx, dy))| {
            format!(
                "a {:.1} m float jump at {:.1} s for {lasting:.1} s",
                dx.hypot(dy),
                at * travel_s
            )
        });
        figures.worst = format!(
            "seed {seed}: {drive:?} at {speed:.2} m/s towards the {} {distance:.1} m away, \
             {jumped}: {least:.3} m",
            zones.solids.first().map_or("", |(n, _)| n.as_str())
        );
    }
    match drive {
        Drive::Manual if stopped_at_zone => {
            figures.manual_stops += 1;
            rests.push(least);
        }
        Drive::Path | Drive::Mission if jump.is_none() && stopped_at_zone => {
            figures.false_stops += 1;
        }
        _ => {}
    }
    // The blade at the gate's closing, when it was on.
    if drive == Drive::Mission
        && let (Some(bad), Some(closed)) = (
            run.sink.first_unfixed,
            run.event(|e| matches!(e, Event::GateClosed(_))),
        )
        && closed >= began
    {
        let off = run
            .sink
            .events
            .iter()
            .find(|(t, e)| {
                *t >= closed
                    && *e
                        == Event::Cutter {
                            on: false,
                            configured: true,
                        }
            })
            .map(|(t, _)| *t);
        if let Some(off) = off {
            blade.closings += 1;
            let ms = off.saturating_since(bad).as_secs_f64() * 1000.0;
            blade.worst_ms = blade.worst_ms.max(ms);
        }
    }
    Ok(())
}

/// The covering mission under clean RTK fixed, started again until `seconds` are up.
fn coverage(plant: &PlantConfig, seed: u64, seconds: f64) -> Result<CoverageFigures, ConfigError> {
    let mut zones = Zones::new(plant);
    let config = crate::sim::lockstep::vehicle_config(plant)?;
    let clearance = plan_radius(plant, &config, MISSION_SPEED) + SLACK_M;
    let (count, length) = LANES;
    let width = (count - 1) as f64 * LANE_SPACING_M;
    // The lanes run east and west between x = 0 and their length, stacked north from y = 0,
    // and the way back runs south along x = 0; the boundary keeps the plan's clearance round
    // them, and a flower bed sits the same clearance beyond the lanes' east ends.
    let (x0, y0, x1, y1) = (
        -clearance,
        -clearance,
        length + clearance,
        width + clearance,
    );
    zones.polygon(
        "lawn",
        ZoneKind::Boundary,
        &[
            (x0 - 0.01, y0),
            (x1 + 2.0, y0),
            (x1 + 2.0, y1),
            (x0 - 0.01, y1),
        ],
    );
    zones.polygon(
        "bed",
        ZoneKind::KeepOut,
        &[
            (x1, y0 + 1.0),
            (x1 + 1.5, y0 + 1.0),
            (x1 + 1.5, y1 - 1.0),
            (x1, y1 - 1.0),
        ],
    );
    let mut path = Vec::new();
    for lane in 0..count {
        let y = lane as f64 * LANE_SPACING_M;
        let (a, b) = if lane % 2 == 0 {
            (0.0, length)
        } else {
            (length, 0.0)
        };
        path.extend([a, y, b, y]);
    }
    // Back along the lanes' west ends to the start, so the mission can start again there.
    path.extend([0.0, 0.0]);
    let path: Vec<String> = path.iter().map(f64::to_string).collect();
    let mission = with_blade(
        plant,
        &format!(
            r#"{{"action": "COVERAGE", "parameters": {{"path": [{}]}}}}"#,
            path.join(", ")
        ),
    );
    let mut figures = CoverageFigures::default();
    // Clean RTK fixed: the receiver's float episodes off (its steps and wild fixes kept).
    let mut clean = plant.clone();
    clean.gnss.faults.float_per_hour = 0.0;
    let mut run = Run::new(&clean, seed, zones.set)?;
    if !run.warm_up() {
        figures.failures.push("the gate never opened".into());
        return Ok(figures);
    }
    let began = run.sim.time();
    let mut last = run.sim.vehicle().truth();
    let mut elapsed = 0.0;
    while elapsed < seconds {
        if let Err(e) = run.send("mission", &mission) {
            figures.failures.push(e);
            break;
        }
        loop {
            run.step(FIXED);
            let t = run.sim.vehicle().truth();
            figures.distance_m += (t.x - last.x).hypot(t.y - last.y);
            last = t;
            elapsed = run.sim.time().saturating_since(began).as_secs_f64();
            if let Some(outcome) = run.sink.missions_ended.pop() {
                match outcome {
                    Outcome::Succeeded => figures.missions += 1,
                    other => figures.failures.push(other.to_string()),
                }
                break;
            }
            if elapsed >= seconds {
                break;
            }
        }
        if !figures.failures.is_empty() {
            break;
        }
    }
    figures.seconds = elapsed;
    figures.pauses = count_events(&run, |e| matches!(e, Event::GateClosed(_)));
    figures.zone_stops = count_events(&run, is_zone_stop);
    Ok(figures)
}

fn count_events(run: &Run, is: impl Fn(&Event) -> bool) -> u32 {
    run.sink.events.iter().filter(|(_, e)| is(e)).count() as u32
}

/// The zones' guard stopping the vehicle before a boundary.
fn is_zone_stop(event: &Event) -> bool {
    matches!(event, Event::Zone(text) if text.starts_with("stopping: the"))
}

/// Random plans through the yard's zones, and as many clear of them.
fn plans(plant: &PlantConfig, seed: u64, count: u32) -> Result<PlanFigures, ConfigError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_f1a5);
    let mut zones = Zones::new(plant);
    zones.polygon(
        "lawn",
        ZoneKind::Boundary,
        &[(-15.0, -12.0), (25.0, -12.0), (25.0, 12.0), (-15.0, 12.0)],
    );
    zones.polygon(
        "pond",
        ZoneKind::KeepOut,
        &[(5.0, -1.5), (8.0, -1.5), (8.0, 1.5), (5.0, 1.5)],
    );
    zones.circle("tree", (-4.0, 5.0), 1.0);
    zones.wall("fence", (-6.0, -8.0), (6.0, -5.0));
    zones.polygon(
        "bed",
        ZoneKind::KeepOut,
        &[(10.0, 4.0), (14.0, 5.0), (12.0, 8.0)],
    );
    let solids = zones.solids.clone();
    let boundary = zones.boundary.clone();
    let config = crate::sim::lockstep::vehicle_config(plant)?;
    let cruise = cruise_mps(&config);
    let mut figures = PlanFigures::default();
    let mut run = Run::new(plant, seed, zones.set)?;
    if !run.warm_up() {
        figures.first_wrong = "the gate never opened".into();
        figures.through = count;
        return Ok(figures);
    }
    let mut attempts = 0;
    while (figures.through < count || figures.clear < count) && attempts < count * 50 {
        attempts += 1;
        let (x, y, yaw) = run.pose();
        let kind = rng.random_range(0..4);
        let end = if kind == 3 {
            // A straight move along the heading.
            let d = rng.random_range(1.0..15.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            (x + d * yaw.cos(), y + d * yaw.sin())
        } else {
            (rng.random_range(-14.0..24.0), rng.random_range(-11.0..11.0))
        };
        let way_clearance = solids
            .iter()
            .map(|(_, s)| s.segment_clearance((x, y), end))
            .fold(f64::INFINITY, f64::min);
        let inside = |radius: f64| {
            boundary.as_ref().is_none_or(|b| {
                let e = Line::new(Coord { x, y }, Coord { x: end.0, y: end.1 });
                geo::Contains::contains(b, &e)
                    && Euclidean.distance(&e, b.exterior()) > radius + 0.1
            })
        };
        let speed = if matches!(kind, 0 | 3) {
            cruise
        } else {
            MISSION_SPEED
        };
        let radius = plan_radius(plant, &config, speed);
        let through = way_clearance == 0.0;
        let clear = way_clearance > radius + 0.1 && inside(radius);
        if (through && figures.through >= count) || (clear && figures.clear >= count) {
            continue;
        }
        if !through && !clear {
            continue;
        }
        let (topic, request) = match kind {
            0 => (
                "goal",
                format!(r#"{{"x": {}, "y": {}, "yaw": 0}}"#, end.0, end.1),
            ),
            1 => (
                "follow_path",
                format!(
                    r#"{{"path": [{x}, {y}, {}, {}], "speed": {MISSION_SPEED}}}"#,
                    end.0, end.1
                ),
            ),
            2 => (
                "mission",
                format!(
                    r#"[{{"action": "COVERAGE", "parameters": {{"path": [{x}, {y}, {}, {}]}}}}]"#,
                    end.0, end.1
                ),
            ),
            _ => {
                let d = (end.0 - x).hypot(end.1 - y);
                let forward = (end.0 - x) * yaw.cos() + (end.1 - y) * yaw.sin() > 0.0;
                (
                    "set_navi_cmd",
                    format!(
                        r#"{{"cmd": "{}", "distance": {}}}"#,
                        if forward { 1 } else { 2 },
                        (d * 100.0).round()
                    ),
                )
            }
        };
        let answer = run.send(topic, &request);
        let judged_right = if through {
            figures.through += 1;
            let ok = answer.as_ref().is_err_and(|e| e.contains("zone"));
            figures.refused += u32::from(ok);
            ok
        } else {
            figures.clear += 1;
            let ok = answer.is_ok();
            figures.started += u32::from(ok);
            ok
        };
        if !judged_right && figures.first_wrong.is_empty() {
            figures.first_wrong = format!("{topic} {request} from ({x:.2}, {y:.2}): {answer:?}");
        }
        if answer.is_ok() {
            // Stop it where it stands and let it settle.
            let _ = run.send("set_navi_cmd", r#"{"cmd": "5"}"#);
            run.run(0.5);
        }
    }
    Ok(figures)
}

impl EnvelopeReport {
    /// The figures as a table.
    pub fn table(&self) -> String {
        let a = &self.approaches;
        let b = &self.blade;
        let c = &self.coverage;
        let p = &self.plans;
        let mut out = format!("bench envelope: plant {}, seed {}\n", self.plant, self.seed);
        out += &format!(
            "approaches           {} ({} manual, {} autonomous, {} with a float jump; {} not started)\n",
            a.runs, a.manual, a.autonomous, a.with_jumps, a.not_started
        );
        out += &format!(
            "  incursions         {} (target 0); least clearance {:.3} m\n",
            a.incursions, a.min_clearance_m
        );
        out += &format!(
            "  manual stops       {} at rest {:.3} m from the zone (median)\n",
            a.manual_stops, a.manual_rest_median_m
        );
        out += &format!("  false stops        {} (target 0)\n", a.false_stops);
        out += &format!("  worst              {}\n", a.worst);
        out += &format!(
            "blade at the gate    {} closings, worst {:.1} ms from the first failing fix to off (limit {:.0} ms)\n",
            b.closings, b.worst_ms, b.limit_ms
        );
        out += &format!(
            "coverage             {:.0} s, {:.0} m, {} missions: {} pauses, {} zone stops (targets 0){}\n",
            c.seconds,
            c.distance_m,
            c.missions,
            c.pauses,
            c.zone_stops,
            if c.failures.is_empty() {
                String::new()
            } else {
                format!("; failed: {}", c.failures.join("; "))
            }
        );
        out += &format!(
            "plans                {}/{} through a zone refused, {}/{} clear of them started{}\n",
            p.refused,
            p.through,
            p.started,
            p.clear,
            if p.first_wrong.is_empty() {
                String::new()
            } else {
                format!("; first wrong: {}", p.first_wrong)
            }
        );
        out += &format!("pass                 {}\n", self.pass);
        out
    }

    /// The figures as one JSON line.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|e| format!(r#"{{"error": "{e}"}}"#))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_gga_below_fixed_counts_as_unfixed() {
        let fixed =
            b"$GNGGA,120000.00,4723.862,N,00832.736,E,4,12,0.6,480.0,M,47.0,M,1.0,0001*5C\r\n";
        let float =
            b"$GNGGA,120000.00,4723.862,N,00832.736,E,5,12,0.6,480.0,M,47.0,M,1.0,0001*5B\r\n";
        assert!(!unfixed_gga(fixed));
        assert!(unfixed_gga(float));
        assert!(!unfixed_gga(b"$GNRMC,120000.00,A,4723.862,N\r\n"));
    }
}
