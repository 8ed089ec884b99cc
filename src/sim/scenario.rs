//! Scripted drives for the simulator: velocity commands over time, what the GNSS receiver
//! can do when (fix quality, outages, a jump), and disturbances of the IMU. Every scenario
//! starts with the same warm-up: standing still, then a straight run, so the filter has
//! converged before scoring begins.

use std::f64::consts::{FRAC_PI_2, PI};

use super::plant::GnssCondition;
use crate::devices::gnss::FixQuality;

/// Standing still at the start, s.
const STILL_S: f64 = 5.0;
/// Then straight at this speed, m/s, ...
const WARMUP_SPEED: f64 = 0.8;
/// ... for this long, s.
const WARMUP_RUN_S: f64 = 10.0;
/// Scoring starts here, s.
pub const WARMUP_S: f64 = STILL_S + WARMUP_RUN_S;
/// The calibration pattern stands still this long first, s.
pub const CALIBRATION_STILL_S: f64 = 30.0;

/// The shape of the calibration pattern.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationPattern {
    /// Standing still first, s.
    pub still_s: f64,
    /// Speed of the runs, m/s (the figure eight goes at four fifths of it).
    pub speed: f64,
    /// Length of each straight run, m.
    pub run_m: f64,
    /// Pairs of runs (out and back); also the spot turns each way and the eights, up to 2.
    pub run_pairs: u32,
    /// Yaw rate of the turns on the spot, rad/s.
    pub turn_rate: f64,
}

impl Default for CalibrationPattern {
    /// The simulator's: 30 s still, five pairs of 20 m runs at 0.5 m/s, turns at 0.5 rad/s.
    fn default() -> Self {
        Self {
            still_s: CALIBRATION_STILL_S,
            speed: 0.5,
            run_m: 20.0,
            run_pairs: 5,
            turn_rate: 0.5,
        }
    }
}

impl CalibrationPattern {
    /// The figure eight's radius: a tenth of a run, 0.5 to 2 m.
    pub fn eight_radius_m(&self) -> f64 {
        (self.run_m / 10.0).clamp(0.5, 2.0)
    }

    /// The ground it needs, m: along the runs, and across (the half turns' offset and the
    /// eight's loops side by side).
    pub fn area_m(&self) -> (f64, f64) {
        let r = self.eight_radius_m();
        (self.run_m.max(4.0 * r) + 1.0, 4.0 * r + 1.0)
    }
}

/// Drive for `duration_s` at forward speed `v` (m/s) and yaw rate `w` (rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leg {
    /// How long, s.
    pub duration_s: f64,
    /// Forward speed, m/s.
    pub v: f64,
    /// Yaw rate, rad/s.
    pub w: f64,
}

/// The receiver's fix quality from `from_s` on (`None`: no fix, an outage).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssSegment {
    /// Start, s since the scenario's start.
    pub from_s: f64,
    /// Fix quality.
    pub quality: Option<FixQuality>,
}

/// A GNSS position jump: every fix in the window is off by `offset` (east, north), m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jump {
    /// Start, s.
    pub from_s: f64,
    /// End, s.
    pub to_s: f64,
    /// East, north, m.
    pub offset: (f64, f64),
}

/// One scripted drive.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Name, as `chassisd bench fusion` prints it.
    pub name: &'static str,
    /// What it drives, in a few words (for `--help`).
    pub about: &'static str,
    /// Velocity commands, one after another.
    pub legs: Vec<Leg>,
    /// Fix quality over time, in time order; RTK fixed before the first.
    pub gnss: Vec<GnssSegment>,
    /// A jump of the GNSS position.
    pub jump: Option<Jump>,
    /// Gyro z bias drift, rad/s per second (temperature).
    pub gyro_bias_ramp: f64,
}

/// Which GNSS regime a moment falls in, for scoring.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Regime {
    /// RTK fixed.
    Fixed,
    /// RTK float, DGPS or a single-point fix.
    Degraded,
    /// No fix.
    Outage,
}

impl Scenario {
    fn new(name: &'static str, about: &'static str, body: Vec<Leg>) -> Self {
        let mut legs = vec![leg(STILL_S, 0.0, 0.0), leg(WARMUP_RUN_S, WARMUP_SPEED, 0.0)];
        legs.extend(body);
        legs.push(leg(2.0, 0.0, 0.0));
        Self {
            name,
            about,
            legs,
            gnss: Vec::new(),
            jump: None,
            gyro_bias_ramp: 0.0,
        }
    }

    /// Every scenario, in the order the benchmark runs them.
    pub fn all() -> Vec<Self> {
        let fixed = Some(FixQuality::RtkFixed);
        let float = Some(FixQuality::RtkFloat);
        let single = Some(FixQuality::Single);
        let dgps = Some(FixQuality::Dgps);
        let segments = |list: &[(f64, Option<FixQuality>)]| {
            list.iter()
                .map(|&(from_s, quality)| GnssSegment { from_s, quality })
                .collect()
        };
        vec![
            Self::new(
                "straight",
                "60 s straight at 1 m/s, a stop, 30 s at 0.5 m/s",
                {
                    let mut l = vec![leg(60.0, 1.0, 0.0), leg(5.0, 0.0, 0.0)];
                    l.push(leg(30.0, 0.5, 0.0));
                    l
                },
            ),
            Self::new(
                "turns",
                "squares with turns on the spot both ways, then a circle each way",
                turns(),
            ),
            Self::new(
                "loop-10min",
                "10 minutes of laps, RTK fixed",
                laps(600.0, 1.0),
            ),
            Self {
                gnss: segments(&[
                    (75.0, float),
                    (135.0, fixed),
                    (165.0, single),
                    (225.0, dgps),
                    (255.0, float),
                    (285.0, fixed),
                ]),
                ..Self::new(
                    "float",
                    "5 minutes of laps through RTK float, single, DGPS and back to fixed",
                    laps(300.0, 1.0),
                )
            },
            Self {
                gnss: segments(&[(75.0, None), (105.0, fixed)]),
                ..Self::new(
                    "outage-30s",
                    "laps with a 30 s GNSS outage",
                    laps(150.0, 1.0),
                )
            },
            Self {
                jump: Some(Jump {
                    from_s: 60.0,
                    to_s: 61.0,
                    offset: (3.0, 4.0),
                }),
                ..Self::new(
                    "jump-5m",
                    "laps; the GNSS position jumps 5 m for 1 s",
                    laps(120.0, 1.0),
                )
            },
            Self {
                gnss: segments(&[(100.0, float), (160.0, fixed)]),
                gyro_bias_ramp: 1e-4,
                ..Self::new(
                    "bias-drift",
                    "5 minutes of laps with a drifting gyro bias and a minute of RTK float",
                    laps(300.0, 1.0),
                )
            },
        ]
    }

    /// The scenario called `name`, of [`Scenario::every`].
    pub fn named(name: &str) -> Option<Self> {
        Self::every().into_iter().find(|s| s.name == name)
    }

    /// The fusion benchmark's scenarios and the calibration pattern: every scenario `chassisd
    /// sim` drives.
    pub fn every() -> Vec<Self> {
        let mut all = Self::all();
        all.push(Self::calibration());
        all
    }

    /// The pattern the calibration procedures need, driven slowly with RTK fixed: 30 s
    /// standing still (gyro bias, mounting), straight runs both ways joined by half turns
    /// (wheel radii against RTK distance), turns on the spot both ways (track, antenna), and
    /// a figure eight. The runs are commanded straight: a miscalibrated vehicle drives them
    /// as arcs, which the fits allow for. Ten runs of 20 m: the wheels' random slip averages
    /// out to a few hundredths of a per cent of each radius over some 400 s of driving.
    pub fn calibration() -> Self {
        Self::calibration_pattern(&CalibrationPattern::default())
    }

    /// The calibration pattern of `p`.
    pub fn calibration_pattern(p: &CalibrationPattern) -> Self {
        let (speed, turn_rate) = (p.speed, p.turn_rate);
        let pause = leg(2.0, 0.0, 0.0);
        let mut legs = vec![leg(p.still_s, 0.0, 0.0)];
        for _ in 0..p.run_pairs {
            for direction in [1.0, -1.0] {
                legs.push(leg(p.run_m / speed, speed, 0.0));
                legs.push(pause);
                legs.push(leg(PI / turn_rate, 0.0, direction * turn_rate));
                legs.push(pause);
            }
        }
        let turns = p.run_pairs.min(2);
        for direction in [1.0, -1.0] {
            for _ in 0..turns {
                legs.push(leg(2.0 * PI / turn_rate, 0.0, direction * turn_rate));
                legs.push(pause);
            }
        }
        let radius = p.eight_radius_m();
        // Four fifths of the runs' speed, unless that would turn faster than the spot turns.
        let v = (speed * 0.8).min(turn_rate * radius);
        for _ in 0..turns {
            legs.push(leg(2.0 * PI * radius / v, v, v / radius));
            legs.push(leg(2.0 * PI * radius / v, v, -v / radius));
        }
        legs.push(leg(10.0, 0.0, 0.0));
        Self {
            name: "calibration",
            about: "the calibration pattern: 30 s still, straight runs both ways, turns on the \
                    spot both ways, a figure eight",
            legs,
            gnss: Vec::new(),
            jump: None,
            gyro_bias_ramp: 0.0,
        }
    }

    /// The same drive at `speed` times its speeds (a faster vehicle): the turn rates stay,
    /// so its curves widen by that much. The warm-up and the timing keep theirs.
    pub fn at_speed(&self, speed: f64) -> Self {
        let speed = if speed.is_finite() && speed > 0.0 {
            speed
        } else {
            1.0
        };
        Self {
            legs: self
                .legs
                .iter()
                .map(|l| Leg {
                    v: l.v * speed,
                    ..*l
                })
                .collect(),
            ..self.clone()
        }
    }

    /// Total length, s.
    pub fn duration_s(&self) -> f64 {
        self.legs.iter().map(|l| l.duration_s).sum()
    }

    /// The commanded (v, w) at `s` seconds.
    pub fn command_at(&self, s: f64) -> (f64, f64) {
        let mut end = 0.0;
        for l in &self.legs {
            end += l.duration_s;
            if s < end {
                return (l.v, l.w);
            }
        }
        (0.0, 0.0)
    }

    /// What the receiver delivers at `s` seconds.
    pub fn gnss_at(&self, s: f64) -> GnssCondition {
        let quality = self
            .gnss
            .iter()
            .rev()
            .find(|g| g.from_s <= s)
            .map_or(Some(FixQuality::RtkFixed), |g| g.quality);
        let offset = self
            .jump
            .filter(|j| (j.from_s..j.to_s).contains(&s))
            .map_or((0.0, 0.0), |j| j.offset);
        GnssCondition { quality, offset }
    }

    /// The regime at `s` seconds.
    pub fn regime_at(&self, s: f64) -> Regime {
        match self.gnss_at(s).quality {
            None => Regime::Outage,
            Some(FixQuality::RtkFixed) => Regime::Fixed,
            Some(_) => Regime::Degraded,
        }
    }

    /// The end of the first outage, s.
    pub fn outage_end_s(&self) -> Option<f64> {
        let start = self.gnss.iter().position(|g| g.quality.is_none())?;
        self.gnss.get(start + 1).map(|g| g.from_s)
    }
}

fn leg(duration_s: f64, v: f64, w: f64) -> Leg {
    Leg { duration_s, v, w }
}

/// Stadium laps for `total_s` at `v`: 20 s straights joined by half circles of 3 m radius.
fn laps(total_s: f64, v: f64) -> Vec<Leg> {
    let radius = 3.0;
    let w = v / radius;
    let lap = [leg(20.0, v, 0.0), leg(PI / w, v, w)];
    let mut legs = Vec::new();
    let mut t = 0.0;
    for l in lap.iter().cycle() {
        let d = l.duration_s.min(total_s - t);
        if d <= 0.0 {
            break;
        }
        legs.push(leg(d, l.v, l.w));
        t += d;
    }
    legs
}

/// Squares with turns on the spot, left then right, then a circle each way.
fn turns() -> Vec<Leg> {
    let turn_rate = 0.6;
    let mut legs = Vec::new();
    for direction in [1.0, -1.0] {
        for _ in 0..4 {
            legs.push(leg(8.0, 0.8, 0.0));
            legs.push(leg(1.0, 0.0, 0.0));
            legs.push(leg(FRAC_PI_2 / turn_rate, 0.0, direction * turn_rate));
            legs.push(leg(1.0, 0.0, 0.0));
        }
    }
    let (v, radius) = (0.6, 2.0);
    legs.push(leg(2.0 * PI * radius / v, v, v / radius));
    legs.push(leg(2.0 * PI * radius / v, v, -v / radius));
    legs
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Whatever the settings `calibrate --drive` accepts, the pattern never asks for
        /// more speed or yaw rate than it was given, starts and ends standing still, and
        /// drives each run to its length.
        #[test]
        fn the_calibration_pattern_stays_within_its_limits(
            still_s in 1.0f64..60.0,
            speed in 0.05f64..2.0,
            run_m in 0.5f64..100.0,
            run_pairs in 1u32..=20,
            turn_rate in 0.1f64..1.5,
        ) {
            let p = CalibrationPattern { still_s, speed, run_m, run_pairs, turn_rate };
            let s = Scenario::calibration_pattern(&p);
            for leg in &s.legs {
                prop_assert!(leg.v.abs() <= speed + 1e-12, "{leg:?}");
                prop_assert!(leg.w.abs() <= turn_rate + 1e-12, "{leg:?}");
                prop_assert!(leg.duration_s > 0.0 && leg.duration_s.is_finite(), "{leg:?}");
            }
            prop_assert_eq!(s.command_at(0.0), (0.0, 0.0));
            prop_assert_eq!(s.command_at(s.duration_s() - 1e-6), (0.0, 0.0));
            let runs: Vec<f64> = s
                .legs
                .iter()
                .filter(|l| l.w == 0.0 && l.v > 0.0)
                .map(|l| l.v * l.duration_s)
                .collect();
            prop_assert_eq!(runs.len(), 2 * run_pairs as usize);
            for r in runs {
                prop_assert!((r - run_m).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn the_default_pattern_is_the_simulators_twelve_minutes() {
        let s = Scenario::calibration();
        // 30 s still, ten 20 m runs with their turns and pauses, four spot turns, two eights.
        assert!((s.duration_s() - 726.8).abs() < 0.1, "{}", s.duration_s());
    }

    #[test]
    fn the_outage_scenario_loses_the_fix_for_30_s() {
        let s = Scenario::named("outage-30s").expect("defined");
        assert_eq!(s.regime_at(74.9), Regime::Fixed);
        assert_eq!(s.regime_at(75.0), Regime::Outage);
        assert_eq!(s.regime_at(104.9), Regime::Outage);
        assert_eq!(s.regime_at(105.0), Regime::Fixed);
        assert_eq!(s.outage_end_s(), Some(105.0));
    }

    #[test]
    fn commands_follow_the_legs() {
        let s = Scenario::new("t", "test", vec![leg(10.0, 1.0, 0.5)]);
        assert_eq!(s.command_at(0.0), (0.0, 0.0));
        assert_eq!(s.command_at(STILL_S + 1.0), (WARMUP_SPEED, 0.0));
        assert_eq!(s.command_at(WARMUP_S + 5.0), (1.0, 0.5));
        assert_eq!(s.command_at(WARMUP_S + 10.5), (0.0, 0.0));
        assert_eq!(s.duration_s(), WARMUP_S + 12.0);
    }
}
