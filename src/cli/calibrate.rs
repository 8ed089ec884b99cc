//! `chassisd calibrate`: a fit on a recording, or a live collection (listening, or driving
//! the calibration pattern) followed by the fit.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;

use super::{block_on, seconds_arg};
use chassisd::calib::{self, Procedure, Settings, data::Dataset};
use chassisd::config::VehicleConfig;
use chassisd::config::calibration::{CalibrationFile, default_path};
use chassisd::record::segments::{Rotation, segment_dir};
use chassisd::runtime::modes::listen::{self, ListenOptions};
use chassisd::runtime::modes::live::{self, LiveOptions};
use chassisd::sim::scenario::{CalibrationPattern, Scenario};

/// Calibrate: `imu` (standing still: gyro bias, mounting roll and pitch), `odometry`
/// (wheel radii, track) or `gnss` (antenna position, dual-antenna heading offset), from a
/// recording (--from) or live on the vehicle (--config alone: collect, then fit).
/// Writes or updates the calibration file and prints a report.
#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).multiple(true).args(["from", "config"])))]
pub struct Args {
    /// What to calibrate.
    #[arg(value_enum)]
    procedure: CalibrateProcedure,
    /// The recording folder (`chassisd run --record`, `chassisd record` segment, or
    /// `chassisd sim --record`); without it, --config collects live.
    #[arg(long)]
    from: Option<PathBuf>,
    /// Vehicle configuration: with --from, used instead of the one stored with the
    /// recording; without, the vehicle to collect from live.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Calibration file to write or update (default calib/<vehicle>.toml under the
    /// current folder).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Standing still must last this long, s.
    #[arg(long, default_value = "20", value_parser = seconds_arg)]
    still: Duration,
    /// The report plot (SVG; default: beside the calibration file, named after it:
    /// <calibration file's stem>.<procedure>.svg).
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Live: collect this long, s (default: --still and 10 s for imu, 900 s otherwise;
    /// Ctrl-C ends the collection early and the fit follows).
    #[arg(long, value_parser = seconds_arg, conflicts_with = "from")]
    collect: Option<Duration>,
    /// Live: keep the collected recording in this new folder (default
    /// calib/recordings/<vehicle>-<procedure>-<unix time> beside the calibration file).
    #[arg(long, conflicts_with = "from")]
    record: Option<PathBuf>,
    /// Live, odometry or gnss: drive the calibration pattern (standing still, straight
    /// runs both ways, turns on the spot both ways, a figure eight) under every safety
    /// rule of `chassisd run`. Prints the plan and needs --yes to move.
    #[arg(long, requires = "config", conflicts_with_all = ["from", "collect"])]
    drive: bool,
    /// Confirms that the area is clear and the e-stop at hand: the vehicle moves.
    #[arg(long, requires = "drive")]
    yes: bool,
    /// --drive: speed of the runs, m/s (at most the configuration's max_speed_mps).
    #[arg(long, default_value_t = 0.3, requires = "drive")]
    speed: f64,
    /// --drive: length of each straight run, m.
    #[arg(long, default_value_t = 10.0, requires = "drive")]
    run_m: f64,
    /// --drive: pairs of runs, out and back.
    #[arg(long, default_value_t = 5, requires = "drive", value_parser = clap::value_parser!(u32).range(1..=20))]
    runs: u32,
}

/// The procedures of `chassisd calibrate`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CalibrateProcedure {
    /// Gyro bias and mounting roll and pitch, from standing still.
    Imu,
    /// Wheel radii and track, from straight runs and turns on the spot.
    Odometry,
    /// Antenna position and dual-antenna heading offset, from turns and runs.
    Gnss,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    // A live collection's recording holds the configuration as it was recorded
    // (CAN listen-only when only listening): the fit reads it from there.
    let (from, config) = match a.from {
        Some(from) => (from, a.config),
        None => {
            let path = a
                .config
                .as_deref()
                .context("--config or --from is needed")?;
            let vehicle = VehicleConfig::load(path)?;
            let live = LiveCalibration {
                procedure: a.procedure,
                record: a.record,
                out: a.out.clone(),
                still: a.still,
                collect: a.collect,
                drive: a.drive.then_some(DrivePlan {
                    yes: a.yes,
                    speed: a.speed,
                    run_m: a.run_m,
                    runs: a.runs,
                }),
            };
            match collect_live(&vehicle, live)? {
                Some(recording) => (recording, None),
                None => return Ok(false),
            }
        }
    };
    fit(
        a.procedure,
        &from,
        config.as_deref(),
        a.out,
        a.still,
        a.plot,
    )
}

/// `chassisd calibrate`: the procedure on a recording, its report on stdout, the file
/// written; a refusal is an error with the reason and the fix.
fn fit(
    procedure: CalibrateProcedure,
    from: &Path,
    config: Option<&Path>,
    out: Option<PathBuf>,
    still: Duration,
    plot: Option<PathBuf>,
) -> anyhow::Result<bool> {
    let procedure = match procedure {
        CalibrateProcedure::Imu => Procedure::Imu,
        CalibrateProcedure::Odometry => Procedure::Odometry,
        CalibrateProcedure::Gnss => Procedure::Gnss,
    };
    let config = config.map(VehicleConfig::load).transpose()?;
    let data = Dataset::from_recording(from, config, std::io::stderr().is_terminal())
        .with_context(|| format!("reading {}", from.display()))?;
    if data.truncated {
        eprintln!(
            "the recording is longer than {:.0} s; its first {:.0} s are used",
            calib::data::MAX_SPAN_S,
            calib::data::MAX_SPAN_S
        );
    }
    let out = out.unwrap_or_else(|| default_path(&data.vehicle.vehicle.name));
    let mut file = if out.exists() {
        CalibrationFile::load(&out)?
    } else {
        CalibrationFile::default()
    };
    let settings = Settings {
        min_still_s: still.as_secs_f64(),
    };
    let found = calib::run(procedure, &data, &settings, &mut file)
        .map_err(|r| anyhow::anyhow!("calibrate {}: {r}", procedure.name()))?;
    print!("{}", found.table());
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let text = format!(
        "# Calibration of {:?}, written by chassisd calibrate; each value replaces the\n\
         # configuration's (see calib/README.md).\n{}",
        data.vehicle.vehicle.name,
        file.to_toml()
    );
    // What is written must load: a value out of range (or not a number) is refused here,
    // not at the vehicle's next start.
    CalibrationFile::from_toml(&text, &out)
        .context("the result is not a valid calibration; nothing was written")?;
    std::fs::write(&out, text).with_context(|| format!("writing {}", out.display()))?;
    println!("written: {}", out.display());
    let plot = plot.unwrap_or_else(|| {
        out.with_file_name(format!(
            "{}.{}.svg",
            out.file_stem()
                .map_or("calibration".into(), |s| s.to_string_lossy()),
            procedure.name()
        ))
    });
    calib::plot::draw(procedure, &data, &found, &plot)?;
    println!("plot: {}", plot.display());
    Ok(true)
}

/// `chassisd calibrate --drive`'s pattern settings.
struct DrivePlan {
    yes: bool,
    speed: f64,
    run_m: f64,
    runs: u32,
}

/// A live calibration: collect (or drive) first, then fit.
struct LiveCalibration {
    procedure: CalibrateProcedure,
    record: Option<PathBuf>,
    out: Option<PathBuf>,
    still: Duration,
    collect: Option<Duration>,
    drive: Option<DrivePlan>,
}

/// Collects a recording live for `calibrate`: listening (someone else moves the vehicle, or
/// it stands still), or driving the pattern itself. Returns the recording folder, or `None`
/// when the plan was only shown (no --yes).
fn collect_live(vehicle: &VehicleConfig, live: LiveCalibration) -> anyhow::Result<Option<PathBuf>> {
    let name = &vehicle.vehicle.name;
    let procedure = match live.procedure {
        CalibrateProcedure::Imu => "imu",
        CalibrateProcedure::Odometry => "odometry",
        CalibrateProcedure::Gnss => "gnss",
    };
    let folder = live.record.unwrap_or_else(|| {
        let out = live.out.clone().unwrap_or_else(|| default_path(name));
        let unix = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        out.with_file_name("recordings")
            .join(format!("{name}-{procedure}-{unix}"))
    });
    if let Some(plan) = live.drive {
        anyhow::ensure!(
            live.procedure != CalibrateProcedure::Imu,
            "calibrate imu stands still: it needs no --drive"
        );
        anyhow::ensure!(
            !vehicle.drive.is_empty() && vehicle.chassis.is_some(),
            "--drive needs the drive train: a [chassis] and [[drive]]s in {name}'s configuration"
        );
        let chassis = vehicle.chassis.as_ref().context("[chassis]")?;
        anyhow::ensure!(
            plan.speed > 0.0 && plan.speed <= chassis.max_speed_mps,
            "--speed {} m/s: give a speed above 0 and at most chassis.max_speed_mps ({} m/s)",
            plan.speed,
            chassis.max_speed_mps
        );
        anyhow::ensure!(
            plan.run_m.is_finite() && (0.5..=100.0).contains(&plan.run_m),
            "--run-m {}: give 0.5 to 100 m",
            plan.run_m
        );
        let pattern = CalibrationPattern {
            still_s: live.still.as_secs_f64() + 10.0,
            speed: plan.speed,
            run_m: plan.run_m,
            run_pairs: plan.runs,
            turn_rate: chassis.max_yaw_rate_rps.min(0.5),
        };
        let scenario = Scenario::calibration_pattern(&pattern);
        let (along, across) = pattern.area_m();
        eprintln!(
            "calibration drive of {name}: {:.0} s standing still, {} pairs of {:.1} m runs at \
             {:.2} m/s joined by turns on the spot, turns on the spot both ways, a figure \
             eight of {:.1} m loops; about {:.0} s in all. It needs a clear, level area of \
             about {along:.0} m by {across:.0} m ahead of the vehicle, RTK fixed, and someone \
             at the e-stop. Every limit, watchdog and stop of `chassisd run` applies; a stop \
             abandons the pattern.",
            pattern.still_s,
            plan.runs,
            plan.run_m,
            plan.speed,
            pattern.eight_radius_m(),
            scenario.duration_s()
        );
        if !plan.yes {
            eprintln!("nothing moved: add --yes to drive it");
            return Ok(None);
        }
        let options = LiveOptions {
            config: vehicle.clone(),
            record: Some(folder.clone()),
            commands_stdin: false,
            pattern: Some(scenario),
        };
        block_on(2, live::run(options, std::io::sink()))?.context("calibration drive")?;
        return Ok(Some(folder));
    }
    let span = live.collect.unwrap_or(match live.procedure {
        CalibrateProcedure::Imu => live.still + Duration::from_secs(10),
        _ => Duration::from_secs(900),
    });
    eprintln!(
        "collecting for {:.0} s from {name}'s devices into {} (Ctrl-C ends it early){}",
        span.as_secs_f64(),
        folder.display(),
        match live.procedure {
            CalibrateProcedure::Imu => "; keep the vehicle still",
            _ => "; drive the pattern by hand (see docs/calibration.md)",
        }
    );
    let options = ListenOptions {
        config: vehicle.clone(),
        out: folder.clone(),
        rotation: Rotation {
            max_bytes: u64::MAX,
            max_span: Duration::MAX,
            keep: None,
        },
        duration: Some(span),
        progress: std::io::stderr().is_terminal(),
        mcap: false,
    };
    let summary = block_on(1, listen::run(options))??;
    eprintln!("{}", summary.line());
    Ok(Some(segment_dir(&folder, 1)))
}
