//! `chassisd bench control`: closed-loop moves and the command watchdog on the simulated
//! vehicle, through the whole path (local command channel, engine, core, CAN frames to the
//! simulated drives), scored against the simulator's truth.
//!
//! The vehicle first stands still (the drives boot, the gyro bias is learnt), then drives
//! straight so the fusion finds its heading, then stops. Each move then starts from rest
//! where the last ended. A move's duration is compared with the time-optimal profile under
//! the configured limits (`[motion]`, by default the chassis limits).

use std::f64::consts::{FRAC_PI_2, PI};

use serde::Serialize;

use crate::config::ConfigError;
use crate::config::motion::MotionSettings;
use crate::control::moves::HeadingSource;
use crate::control::profile::Profile;
use crate::control::{MotionResult, MoveKind, Outcome};
use crate::devices::gnss::FixQuality;
use crate::engine::EngineOutput;
use crate::fusion::planar::wrap;
use crate::record::Record;
use crate::sim::lockstep::{Lockstep, PLANT_STEP, Sink};
use crate::sim::plant::{GnssCondition, PlantConfig, Truth};
use crate::time::Timestamp;
use crate::vehicle::status::VehicleStatus;

/// Sessions start here (2026-01-01T00:00:00Z).
const START: Timestamp = Timestamp::from_micros(1_767_225_600_000_000);
/// Standing still at the start, s.
const STILL_S: f64 = 5.0;
/// Then straight at this speed (m/s) for this long (s), so the heading is known and 20 m of
/// RTK prove the wheels' scale (random slip takes more than 10 m: `fusion::wheel_scale`).
const WARMUP: (f64, f64) = (0.8, 25.0);
/// Rest after each move before the truth is read (a move that ends still moving shows it).
const SETTLE_S: f64 = 1.0;
/// Watchdog trials, each with its last command at another phase of the control period.
const WATCHDOG_TRIALS: u32 = 10;
/// Speed of the watchdog trials, m/s.
const WATCHDOG_SPEED: f64 = 1.0;
/// The wheels count as stopped below this, m/s (a first-order drive only approaches zero).
const STOPPED_MPS: f64 = 0.01;

/// The targets.
pub mod target {
    /// Distance moves against truth, less the random wheel slip that no odometry sees (the
    /// plant's truth keeps its sum): at most this, m ...
    pub const DISTANCE_ABS_M: f64 = 0.005;
    /// ... plus this share of the distance.
    pub const DISTANCE_REL: f64 = 0.005;
    /// Distance moves in the frame they closed on, m.
    pub const DISTANCE_FRAME_M: f64 = 0.002;
    /// Turns against truth, degrees.
    pub const TURN_DEG: f64 = 0.3;
    /// A move's duration over the time-optimal profile's, at most.
    pub const DURATION_RATIO: f64 = 1.15;
    /// A goal 10 m away: position against truth, m ...
    pub const GOAL_M: f64 = 0.05;
    /// ... and heading, degrees.
    pub const GOAL_DEG: f64 = 2.0;
    /// The closed path: cross-track RMS against truth, m ...
    pub const PATH_RMS_M: f64 = 0.03;
    /// ... and its largest, m.
    pub const PATH_MAX_M: f64 = 0.10;
}

/// The closed path: a stadium of this length (m) with half circles of this radius (m),
/// driven at this speed (m/s), its points this far apart (m), as a recorded trajectory has
/// them.
const PATH: (f64, f64, f64, f64) = (50.0, 2.0, 0.5, 0.1);
/// Truth is compared with the path every this many plant steps.
const PATH_SCORE_EVERY: u64 = 10;

/// The closed path's figures.
#[derive(Debug, Clone, Serialize)]
pub struct PathFigures {
    /// How it ended.
    pub outcome: String,
    /// Its length, m.
    pub length_m: f64,
    /// Cross-track RMS against truth, m.
    pub truth_rms_m: f64,
    /// Largest cross-track error against truth, m.
    pub truth_max_m: f64,
    /// Cross-track RMS the follower measured in the map frame, m.
    pub frame_rms_m: f64,
    /// Where it ended from the last point against truth, m.
    pub end_error_m: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// Driving it at the speed and curve limits, s.
    pub planned_s: f64,
    /// Within the targets.
    pub pass: bool,
}

/// The goal: this far (m) from where the moves ended, this far off the heading (rad), to
/// end this far (rad) turned from the line to it.
const GOAL: (f64, f64, f64) = (10.0, 0.5, 1.2);

/// The goal's figures.
#[derive(Debug, Clone, Serialize)]
pub struct GoalFigures {
    /// How it ended.
    pub outcome: String,
    /// Distance from the goal against truth after it settled, m.
    pub truth_error_m: f64,
    /// Heading off the goal's against truth, degrees.
    pub truth_heading_deg: f64,
    /// Distance left in the map frame at its end, m.
    pub frame_error_m: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// Face, drive and turn under the configured limits, s.
    pub planned_s: f64,
    /// Within the targets.
    pub pass: bool,
}

/// One move's figures.
#[derive(Debug, Clone, Serialize)]
pub struct MoveFigures {
    /// What it was.
    pub name: String,
    /// A turn (figures in degrees) rather than a distance (metres).
    pub turn: bool,
    /// How it ended.
    pub outcome: String,
    /// Error against truth after it settled: m for distances, degrees for turns.
    pub truth_error: f64,
    /// How far the random wheel slip alone moved the vehicle along the move, which no
    /// odometry sees, m (NaN for turns).
    pub unseen_slip_m: f64,
    /// The error against truth less that slip: what the controller and the learnt wheel
    /// scale answer for, scored against the target (the truth error for turns).
    pub scored_error: f64,
    /// The target for it.
    pub truth_target: f64,
    /// Error in the frame it closed on at its end: m or degrees.
    pub frame_error: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// The time-optimal profile under the configured limits, s.
    pub optimal_s: f64,
    /// The wheel scale the move's distance was corrected by (odometry per true distance).
    pub wheel_scale: f64,
    /// A distance's odometry per true distance over the move itself, as the plant's slip
    /// made it (NaN for turns).
    pub slip_scale: f64,
    /// Met every target.
    pub pass: bool,
}

/// The watchdog's figures.
#[derive(Debug, Clone, Serialize)]
pub struct WatchdogFigures {
    /// Time from the last command to the wheels at rest, worst trial, s.
    pub worst_stop_s: f64,
    /// cmd_timeout + one control period + the deceleration time at the configured limit.
    pub bound_s: f64,
    /// Every trial within the bound.
    pub pass: bool,
}

/// The whole report.
#[derive(Debug, Clone, Serialize)]
pub struct ControlReport {
    /// The plant's name.
    pub plant: String,
    /// Noise seed.
    pub seed: u64,
    /// The drives' response time learnt by the controller, s.
    pub response_time_s: f64,
    /// Every move.
    pub moves: Vec<MoveFigures>,
    /// A goal 10 m away.
    pub goal: GoalFigures,
    /// The closed path.
    pub path: PathFigures,
    /// The command watchdog.
    pub watchdog: WatchdogFigures,
    /// Parts of the issue's benchmark not measured yet, named.
    pub not_measured: Vec<&'static str>,
    /// Every target met.
    pub pass: bool,
}

#[derive(Default)]
struct Collector {
    results: Vec<MotionResult>,
    refused: Vec<String>,
    last_status: Option<Box<VehicleStatus>>,
}

impl Sink for Collector {
    fn record(&mut self, _record: &Record) {}

    fn output(&mut self, output: EngineOutput) {
        match output {
            EngineOutput::MotionEnded(r) => self.results.push(r),
            EngineOutput::Status(s) => self.last_status = Some(s),
            EngineOutput::CommandResult {
                result: Err(e),
                topic,
                ..
            } => self.refused.push(format!("{topic}: {e}")),
            _ => {}
        }
    }
}

const FIXED: GnssCondition = GnssCondition {
    quality: Some(FixQuality::RtkFixed),
    offset: (0.0, 0.0),
};

/// The simulated vehicle under test.
struct Bench {
    sim: Lockstep,
    sink: Collector,
}

impl Bench {
    fn run_for(&mut self, seconds: f64) {
        let steps = (seconds / PLANT_STEP.as_secs_f64()).round() as u64;
        for _ in 0..steps {
            self.sim.step(FIXED, &mut self.sink);
        }
    }

    /// Velocity commands every 100 ms for `seconds`.
    fn drive(&mut self, v: f64, w: f64, seconds: f64) {
        let twist = format!(r#"{{"linear":{{"x":{v}}},"angular":{{"z":{w}}}}}"#);
        for _ in 0..(seconds * 10.0).round() as u64 {
            self.sim.command("cmd_vel", &twist, &mut self.sink);
            self.run_for(0.1);
        }
    }

    fn truth(&self) -> Truth {
        self.sim.vehicle().truth()
    }

    /// The pose the moves close on, from the last status: `odom` x, y, yaw and the map yaw.
    fn frame_pose(&self) -> Option<FramePose> {
        let s = self.sink.last_status.as_ref()?;
        let odom = s.odom?;
        Some(FramePose {
            x: odom.x,
            y: odom.y,
            odom_yaw: odom.yaw,
            map_yaw: s.pose.yaw,
        })
    }

    /// Sends `topic` `request` on the local channel and steps until the motion it starts
    /// ends (at most `limit_s`), calling `watch` with each step's number; its result.
    fn until_result(
        &mut self,
        topic: &str,
        request: &str,
        limit_s: f64,
        mut watch: impl FnMut(&Self, u64),
    ) -> Option<MotionResult> {
        self.sink.results.clear();
        self.sim.command(topic, request, &mut self.sink);
        for step in 0..(limit_s / PLANT_STEP.as_secs_f64()) as u64 {
            self.sim.step(FIXED, &mut self.sink);
            if !self.sink.results.is_empty() {
                break;
            }
            watch(self, step);
        }
        self.sink.results.pop()
    }

    /// What a case without a result reports.
    fn no_result(&self) -> String {
        format!(
            "no result (refused: {})",
            self.sink.refused.last().map_or("no", String::as_str)
        )
    }

    /// One move through the local channel; its result once it ended and settled, with the
    /// truth and the frame's pose before and after.
    fn do_move(&mut self, request: &str) -> Option<MoveRun> {
        // A status tick, so the frame's pose is current.
        self.run_for(0.1);
        let before = (self.truth(), self.frame_pose()?);
        let result = self.until_result("set_navi_cmd", request, 60.0, |_, _| {})?;
        self.run_for(SETTLE_S);
        Some(MoveRun {
            result,
            before,
            after: (self.truth(), self.frame_pose()?),
        })
    }
}

/// The pose a move closes on.
#[derive(Debug, Clone, Copy)]
struct FramePose {
    x: f64,
    y: f64,
    odom_yaw: f64,
    map_yaw: f64,
}

/// One move's result, and the truth and frame pose before it and after it settled.
struct MoveRun {
    result: MotionResult,
    before: (Truth, FramePose),
    after: (Truth, FramePose),
}

/// Runs every move and the watchdog trials on `plant`.
pub fn run(plant: &PlantConfig, seed: u64) -> Result<ControlReport, ConfigError> {
    let sim = Lockstep::new(plant.clone(), seed, START)?;
    let Some(chassis) = sim.config().chassis else {
        return Err(ConfigError::invalid(
            std::path::Path::new("<simulated vehicle>"),
            "chassis",
            "is missing".to_owned(),
            "the simulated vehicle needs a drive train",
        ));
    };
    let settings: MotionSettings = sim.config().motion.unwrap_or_default().settings(&chassis);
    let mut bench = Bench {
        sim,
        sink: Collector::default(),
    };
    bench.run_for(STILL_S);
    bench.drive(WARMUP.0, 0.0, WARMUP.1);
    bench.drive(0.0, 0.0, 2.0);

    let cases = [
        MoveKind::Straight { distance_m: 0.1 },
        MoveKind::Straight { distance_m: 1.0 },
        MoveKind::Straight { distance_m: 5.0 },
        MoveKind::Straight { distance_m: -0.1 },
        MoveKind::Straight { distance_m: -1.0 },
        MoveKind::Straight { distance_m: -5.0 },
        MoveKind::Turn {
            angle_rad: FRAC_PI_2,
        },
        MoveKind::Turn {
            angle_rad: -FRAC_PI_2,
        },
        MoveKind::Turn { angle_rad: PI },
        MoveKind::Turn { angle_rad: -PI },
    ];
    let mut moves = Vec::new();
    for kind in cases {
        let figures = match bench.do_move(&navi_cmd(kind)) {
            Some(run) => score(kind, &run, &settings),
            None => MoveFigures {
                name: kind.to_string(),
                turn: matches!(kind, MoveKind::Turn { .. }),
                outcome: bench.no_result(),
                truth_error: f64::NAN,
                unseen_slip_m: f64::NAN,
                scored_error: f64::NAN,
                truth_target: f64::NAN,
                frame_error: f64::NAN,
                duration_s: f64::NAN,
                optimal_s: f64::NAN,
                wheel_scale: f64::NAN,
                slip_scale: f64::NAN,
                pass: false,
            },
        };
        moves.push(figures);
    }
    let response_time_s = bench.sim.engine().response_time().unwrap_or(f64::NAN);
    let goal = goal(&mut bench);
    let path = closed_path(&mut bench);
    let watchdog = watchdog(&mut bench, &chassis);
    let pass = moves.iter().all(|m| m.pass) && goal.pass && path.pass && watchdog.pass;
    Ok(ControlReport {
        plant: plant.name.clone(),
        seed,
        response_time_s,
        moves,
        goal,
        path,
        watchdog,
        not_measured: Vec::new(),
        pass,
    })
}

/// Scores a move after it settled: against truth, and in the frame it closed on.
/// The `set_navi_cmd` request of a move: cm or whole degrees, as the service takes them.
fn navi_cmd(kind: MoveKind) -> String {
    let (cmd, amount) = match kind {
        MoveKind::Straight { distance_m } if distance_m < 0.0 => (2, -distance_m * 100.0),
        MoveKind::Straight { distance_m } => (1, distance_m * 100.0),
        MoveKind::Turn { angle_rad } if angle_rad < 0.0 => (4, -angle_rad.to_degrees()),
        MoveKind::Turn { angle_rad } => (3, angle_rad.to_degrees()),
    };
    format!(r#"{{"cmd":"{cmd}","distance":{}}}"#, amount.round())
}

fn score(kind: MoveKind, run: &MoveRun, settings: &MotionSettings) -> MoveFigures {
    let result = &run.result;
    let ((before, frame_before), (after, frame_after)) = (run.before, run.after);
    let (mut slip_scale, mut unseen_slip_m) = (f64::NAN, f64::NAN);
    let (truth_error, scored_error, truth_target, frame_error, frame_target, optimal_s) = match kind
    {
        MoveKind::Straight { distance_m } => {
            let (s, c) = before.yaw.sin_cos();
            let along = (after.x - before.x) * c + (after.y - before.y) * s;
            let (s, c) = frame_before.odom_yaw.sin_cos();
            let frame_along = ((frame_after.x - frame_before.x) * c
                + (frame_after.y - frame_before.y) * s)
                / result.wheel_scale;
            slip_scale = frame_along * result.wheel_scale / along;
            unseen_slip_m = after.unseen_slip_m - before.unseen_slip_m;
            (
                (along - distance_m).abs(),
                (along - unseen_slip_m - distance_m).abs(),
                target::DISTANCE_ABS_M + target::DISTANCE_REL * distance_m.abs(),
                (frame_along - distance_m).abs(),
                target::DISTANCE_FRAME_M,
                Profile::plan(distance_m, settings.linear).duration(),
            )
        }
        MoveKind::Turn { angle_rad } => {
            let turned = wrap(after.yaw - before.yaw);
            let frame_turned = match result.heading {
                HeadingSource::Map => wrap(frame_after.map_yaw - frame_before.map_yaw),
                HeadingSource::Odom => wrap(frame_after.odom_yaw - frame_before.odom_yaw),
            };
            let truth_error = wrap(turned - angle_rad).abs().to_degrees();
            (
                truth_error,
                truth_error,
                target::TURN_DEG,
                wrap(frame_turned - angle_rad).abs().to_degrees(),
                target::TURN_DEG,
                Profile::plan(angle_rad, settings.angular).duration(),
            )
        }
    };
    let pass = result.outcome == Outcome::Succeeded
        && scored_error <= truth_target
        && frame_error <= frame_target
        && result.duration_s <= target::DURATION_RATIO * optimal_s;
    MoveFigures {
        name: kind.to_string(),
        turn: matches!(kind, MoveKind::Turn { .. }),
        outcome: result.outcome.to_string(),
        truth_error,
        unseen_slip_m,
        scored_error,
        truth_target,
        frame_error,
        duration_s: result.duration_s,
        optimal_s,
        wheel_scale: result.wheel_scale,
        slip_scale,
        pass,
    }
}

/// A goal `GOAL` away from where the vehicle stands (through the local channel, in the map
/// frame it publishes), scored against truth after it settled.
fn goal(bench: &mut Bench) -> GoalFigures {
    bench.run_for(0.1);
    let failed = |outcome: String| GoalFigures {
        outcome,
        truth_error_m: f64::NAN,
        truth_heading_deg: f64::NAN,
        frame_error_m: f64::NAN,
        duration_s: f64::NAN,
        planned_s: f64::NAN,
        pass: false,
    };
    let Some(s) = bench.sink.last_status.as_ref() else {
        return failed("no status".into());
    };
    let (x, y, yaw) = (s.pose.x, s.pose.y, s.pose.yaw);
    let (distance, off, turn) = GOAL;
    let bearing = yaw + off;
    let (gx, gy, gyaw) = (
        x + distance * bearing.cos(),
        y + distance * bearing.sin(),
        wrap(bearing + turn),
    );
    let request = format!(r#"{{"x":{gx},"y":{gy},"yaw":{gyaw}}}"#);
    let Some(result) = bench.until_result("goal", &request, 120.0, |_, _| {}) else {
        return failed(bench.no_result());
    };
    bench.run_for(SETTLE_S);
    let truth = bench.truth();
    let truth_error_m = (truth.x - gx).hypot(truth.y - gy);
    let truth_heading_deg = wrap(truth.yaw - gyaw).abs().to_degrees();
    GoalFigures {
        outcome: result.outcome.to_string(),
        truth_error_m,
        truth_heading_deg,
        frame_error_m: result.error,
        duration_s: result.duration_s,
        planned_s: result.planned_s,
        pass: result.outcome == Outcome::Succeeded
            && truth_error_m <= target::GOAL_M
            && truth_heading_deg <= target::GOAL_DEG,
    }
}

/// The stadium of [`PATH`] starting where the vehicle stands, ahead of it, turning left:
/// points of the map frame.
fn stadium(x: f64, y: f64, yaw: f64) -> Vec<(f64, f64)> {
    let (length, radius, _, spacing) = PATH;
    let straight = (length - 2.0 * PI * radius) / 2.0;
    let mut local = Vec::new();
    let n = (straight / spacing).round() as usize;
    let arc = (PI * radius / spacing).round() as usize;
    for i in 0..n {
        local.push((straight * i as f64 / n as f64, 0.0));
    }
    for i in 0..arc {
        let a = -FRAC_PI_2 + PI * i as f64 / arc as f64;
        local.push((straight + radius * a.cos(), radius + radius * a.sin()));
    }
    for i in 0..n {
        local.push((straight - straight * i as f64 / n as f64, 2.0 * radius));
    }
    for i in 0..=arc {
        let a = FRAC_PI_2 + PI * i as f64 / arc as f64;
        local.push((radius * a.cos(), radius + radius * a.sin()));
    }
    let (s, c) = yaw.sin_cos();
    local
        .into_iter()
        .map(|(lx, ly)| (x + lx * c - ly * s, y + lx * s + ly * c))
        .collect()
}

/// Follows the closed path of [`PATH`] from where the vehicle stands (through the local
/// channel, in the map frame it publishes), scoring the truth's distance from it.
fn closed_path(bench: &mut Bench) -> PathFigures {
    bench.run_for(0.1);
    let failed = |outcome: String| PathFigures {
        outcome,
        length_m: f64::NAN,
        truth_rms_m: f64::NAN,
        truth_max_m: f64::NAN,
        frame_rms_m: f64::NAN,
        end_error_m: f64::NAN,
        duration_s: f64::NAN,
        planned_s: f64::NAN,
        pass: false,
    };
    let Some(s) = bench.sink.last_status.as_ref() else {
        return failed("no status".into());
    };
    let path = stadium(s.pose.x, s.pose.y, s.pose.yaw);
    let flat: Vec<String> = path
        .iter()
        .flat_map(|(x, y)| [format!("{x:.4}"), format!("{y:.4}")])
        .collect();
    let request = format!(r#"{{"path":[{}],"speed":{}}}"#, flat.join(","), PATH.2);
    let (mut sum_sq, mut count, mut max) = (0.0, 0u64, 0.0_f64);
    let scored = bench.until_result("follow_path", &request, 600.0, |bench, step| {
        if step % PATH_SCORE_EVERY == 0 {
            let truth = bench.truth();
            let off = crate::control::track::distance_to_polyline(&path, truth.x, truth.y);
            sum_sq += off * off;
            count += 1;
            max = max.max(off);
        }
    });
    let Some(result) = scored else {
        return failed(bench.no_result());
    };
    bench.run_for(SETTLE_S);
    let truth = bench.truth();
    let end = path[path.len() - 1];
    let truth_rms_m = (sum_sq / count.max(1) as f64).sqrt();
    let length_m = match result.kind {
        crate::control::MotionKind::Path { length_m, .. } => length_m,
        _ => f64::NAN,
    };
    PathFigures {
        outcome: result.outcome.to_string(),
        length_m,
        truth_rms_m,
        truth_max_m: max,
        frame_rms_m: result.cross_track.map_or(f64::NAN, |c| c.rms_m),
        end_error_m: (truth.x - end.0).hypot(truth.y - end.1),
        duration_s: result.duration_s,
        planned_s: result.planned_s,
        pass: result.outcome == Outcome::Succeeded
            && truth_rms_m <= target::PATH_RMS_M
            && max <= target::PATH_MAX_M,
    }
}

/// Drives at full speed, stops commanding, and times the stop; each trial's last command
/// falls at another millisecond of the control period.
fn watchdog(bench: &mut Bench, chassis: &crate::config::chassis::ChassisConfig) -> WatchdogFigures {
    let bound_s = chassis.cmd_timeout_s
        + crate::vehicle::chassis::CONTROL_PERIOD.as_secs_f64()
        + WATCHDOG_SPEED / chassis.max_decel_mps2;
    let mut worst: f64 = 0.0;
    for trial in 0..WATCHDOG_TRIALS {
        // Re-arm (a move's end leaves the vehicle armed; a zero command is harmless).
        bench.drive(0.0, 0.0, 0.3);
        bench.run_for(0.001 * f64::from(trial));
        bench.drive(WATCHDOG_SPEED, 0.0, 2.0);
        // `drive` ran 100 ms past its last command.
        let mut since_last = 0.1;
        let step = PLANT_STEP.as_secs_f64();
        while bench.truth().v.abs() >= STOPPED_MPS && since_last < 10.0 {
            bench.sim.step(FIXED, &mut bench.sink);
            since_last += step;
        }
        worst = worst.max(since_last);
        bench.run_for(0.5);
    }
    WatchdogFigures {
        worst_stop_s: worst,
        bound_s,
        pass: worst <= bound_s,
    }
}

impl ControlReport {
    /// The table.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "control benchmark: plant {}, seed {}, drive response learnt {:.3} s",
            self.plant, self.seed, self.response_time_s
        );
        let _ = writeln!(
            out,
            "{:<18} {:<10} {:>12} {:>12} {:>12} {:>10} {:>12} {:>8} {:>8} {:>6} {:>6}",
            "move",
            "outcome",
            "truth err",
            "unseen slip",
            "less slip",
            "target",
            "frame err",
            "took s",
            "opt s",
            "ratio",
            ""
        );
        for m in &self.moves {
            let (unit, scale) = if m.turn { ("°", 1.0) } else { (" mm", 1000.0) };
            let slip = if m.turn {
                format!("{:>12}", "-")
            } else {
                format!("{:>9.2} mm", m.unseen_slip_m * 1000.0)
            };
            let _ = writeln!(
                out,
                "{:<18} {:<10} {:>9.2}{unit:<3} {slip} {:>9.2}{unit:<3} {:>7.2}{unit:<3} {:>9.2}{unit:<3} {:>8.2} {:>8.2} {:>6.3} {:>6}",
                m.name,
                m.outcome.split(':').next().unwrap_or(""),
                m.truth_error * scale,
                m.scored_error * scale,
                m.truth_target * scale,
                m.frame_error * scale,
                m.duration_s,
                m.optimal_s,
                m.duration_s / m.optimal_s,
                if m.pass { "ok" } else { "MISSED" },
            );
        }
        let g = &self.goal;
        let _ = writeln!(
            out,
            "goal {:.0} m away: {}, {:.1} mm and {:.2}° from it against truth (targets {:.0} mm, {:.1}°), {:.1} mm in the map frame, {:.2} s (face, drive, turn at the limits {:.2} s): {}",
            GOAL.0,
            g.outcome,
            g.truth_error_m * 1000.0,
            g.truth_heading_deg,
            target::GOAL_M * 1000.0,
            target::GOAL_DEG,
            g.frame_error_m * 1000.0,
            g.duration_s,
            g.planned_s,
            if g.pass { "ok" } else { "MISSED" }
        );
        let p = &self.path;
        let _ = writeln!(
            out,
            "closed path {:.1} m, {:.0} m curves at {} m/s: {}, cross-track against truth RMS {:.1} mm, max {:.1} mm (targets {:.0} mm, {:.0} mm), RMS {:.1} mm in the map frame, ended {:.1} mm from its end, {:.2} s (at the limits {:.2} s): {}",
            p.length_m,
            PATH.1,
            PATH.2,
            p.outcome,
            p.truth_rms_m * 1000.0,
            p.truth_max_m * 1000.0,
            target::PATH_RMS_M * 1000.0,
            target::PATH_MAX_M * 1000.0,
            p.frame_rms_m * 1000.0,
            p.end_error_m * 1000.0,
            p.duration_s,
            p.planned_s,
            if p.pass { "ok" } else { "MISSED" }
        );
        let _ = writeln!(
            out,
            "watchdog: wheels at rest {:.3} s after the last command at worst of {WATCHDOG_TRIALS} (bound {:.3} s): {}",
            self.watchdog.worst_stop_s,
            self.watchdog.bound_s,
            if self.watchdog.pass { "ok" } else { "MISSED" }
        );
        for n in &self.not_measured {
            let _ = writeln!(out, "not measured: {n}");
        }
        out
    }

    /// The one-line JSON summary.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|e| format!(r#"{{"error":"{e}"}}"#))
    }
}
