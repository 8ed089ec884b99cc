//! The `chassisd` command line.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Parser, Subcommand};

use chassisd::bench::Broker;
use chassisd::bench::fusion;
use chassisd::bench::mosquitto::Mosquitto;
use chassisd::config::VehicleConfig;
use chassisd::config::mqtt::{
    DeviceDialectConfig, MqttConfig, RootDialectConfig, RtkDialectConfig,
};
use chassisd::config::ros1::Ros1Config;
use chassisd::config::websocket::WebsocketConfig;
use chassisd::record::nmea_import::ImportOptions;
use chassisd::replay;
use chassisd::runtime::live::{self, LiveOptions};
use chassisd::runtime::sim::{self, SimOptions};
use chassisd::sim::plant::PlantConfig;
use chassisd::sim::scenario::Scenario;

#[derive(Parser)]
#[command(version, about = "Chassis daemon for RTK ground robots")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Replay a recording folder or a plain NMEA log; print one base_status JSON line per
    /// 100 ms of recorded time.
    Replay {
        /// Recording folder (with meta.toml) or NMEA text log.
        path: PathBuf,
        /// Vehicle configuration to use instead of the one stored with the recording.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Add `stamp`, the recorded time in seconds, to each line (for analysis; the lines
        /// then leave the protocol's schema).
        #[arg(long)]
        stamped: bool,
        /// In a plain NMEA log, a forward step of the clock longer than this (seconds)
        /// starts a new segment instead of ticking through the gap.
        #[arg(long, default_value = "10", value_parser = seconds_arg)]
        max_gap: Duration,
        /// Accept records that go back in time within a file, and regenerated transmissions
        /// that differ from the recorded ones (both are reported either way; without this
        /// the replay exits 1).
        #[arg(long)]
        lenient: bool,
        /// Write the RTCM corrections the replayed run relays to the receiver (whole valid
        /// frames, in order: what live mode wrote to the receiver's port) to FILE.
        #[arg(long, value_name = "FILE")]
        corrections_out: Option<PathBuf>,
    },
    /// Run live on the configured devices; print base_status JSON lines at 10 Hz.
    Run {
        /// Vehicle configuration (TOML).
        #[arg(long)]
        config: PathBuf,
        /// Record every raw chunk, frame and command into this new folder.
        #[arg(long)]
        record: Option<PathBuf>,
        /// Read commands from standard input, one `TOPIC JSON` per line
        /// (e.g. `cmd_vel {"linear":{"x":0.2},"angular":{"z":0}}`).
        #[arg(long)]
        commands_stdin: bool,
        /// Join the ROS1 graph of this master as a node (ros1-navigation-interface.txt),
        /// over the configuration's `[ros1]` master_uri.
        #[arg(long, value_name = "URI")]
        ros_master: Option<String>,
        /// Serve the rosbridge v2 WebSocket topics on ADDR (e.g. 127.0.0.1:9090), over the
        /// configuration's `[websocket]` bind.
        #[arg(long, value_name = "ADDR")]
        websocket: Option<String>,
        /// Fetch RTK corrections from this NTRIP caster
        /// (ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT), over the configuration's `[ntrip]`
        /// url.
        #[arg(long, value_name = "URL")]
        ntrip: Option<String>,
    },
    /// Record every raw frame of every device, and every command sent to the vehicle over
    /// MQTT, without driving anything (listen-only: no engine, nothing transmitted). Writes
    /// segments DIR/0001, DIR/0002, … (each a recording that replays on its own), rotated by
    /// size or time; the oldest beyond --keep are removed. Stops at SIGINT or SIGTERM.
    Record {
        /// Vehicle configuration (TOML).
        #[arg(long)]
        config: PathBuf,
        /// New folder for the segments.
        #[arg(long)]
        out: PathBuf,
        /// A segment ends once it holds this many megabytes (10^6 bytes).
        #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u64).range(1..))]
        segment_mb: u64,
        /// A segment ends once it spans this many seconds.
        #[arg(long, default_value = "3600", value_parser = seconds_arg)]
        segment_s: Duration,
        /// Keep at most this many segments, removing the oldest (0: keep all).
        #[arg(long, default_value_t = 48)]
        keep: usize,
        /// Stop after this many seconds.
        #[arg(long, value_parser = seconds_arg)]
        duration: Option<Duration>,
    },
    /// Run the simulated vehicle in real time through the live engine (no hardware): print
    /// base_status JSON lines at 10 Hz.
    Sim {
        /// Plant file (default: the built-in devices/plant.mower.toml).
        #[arg(long)]
        plant: Option<PathBuf>,
        /// Noise seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Record the session (every frame, command and transmission) into this new folder.
        #[arg(long)]
        record: Option<PathBuf>,
        /// Read commands from standard input, one `TOPIC JSON` per line.
        #[arg(long)]
        commands_stdin: bool,
        /// Drive a scripted scenario (also those of `chassisd bench fusion`) and stop at its
        /// end. Each starts with 5 s standing still and 10 s straight.
        #[arg(long, value_parser = scenario_names())]
        scenario: Option<String>,
        /// Stop after this many seconds.
        #[arg(long, value_parser = seconds_arg)]
        duration: Option<Duration>,
        /// Use the MQTT broker at HOST:PORT instead of starting one on 127.0.0.1:1883.
        #[arg(long, value_name = "HOST:PORT", conflicts_with = "no_mqtt")]
        mqtt: Option<String>,
        /// Port of the embedded broker on 127.0.0.1 (default 1883).
        #[arg(long, conflicts_with_all = ["mqtt", "no_mqtt"])]
        broker_port: Option<u16>,
        /// No MQTT at all.
        #[arg(long)]
        no_mqtt: bool,
        /// Keep the rtk dialect's trajectories in this folder (default: in memory).
        #[arg(long, conflicts_with = "no_mqtt")]
        trajectory_dir: Option<PathBuf>,
        /// Join the ROS1 graph of this master as a node (ros1-navigation-interface.txt),
        /// e.g. http://127.0.0.1:11311.
        #[arg(long, value_name = "URI")]
        ros_master: Option<String>,
        /// Serve the rosbridge v2 WebSocket topics (device-mqtt-api.md) on ADDR, e.g.
        /// 127.0.0.1:9090.
        #[arg(long, value_name = "ADDR", conflicts_with = "fast")]
        websocket: Option<String>,
        /// Run in lockstep as fast as the machine allows: no wall clock, no MQTT, no
        /// standard input. Needs --scenario or --duration; --record works as without it.
        #[arg(long, conflicts_with_all = ["mqtt", "broker_port", "commands_stdin", "trajectory_dir", "ros_master"])]
        fast: bool,
        /// A calibration file for the simulated vehicle's configuration (as `[vehicle]
        /// calibration` names one on a real vehicle).
        #[arg(long, value_name = "FILE")]
        calibration: Option<PathBuf>,
        /// Fetch RTK corrections from this NTRIP caster
        /// (ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT): the simulated receiver then holds
        /// RTK fixed only while they arrive.
        #[arg(long, value_name = "URL", conflicts_with = "fast")]
        ntrip: Option<String>,
    },
    /// Calibrate: `imu` (standing still: gyro bias, mounting roll and pitch), `odometry`
    /// (wheel radii, track) or `gnss` (antenna position, dual-antenna heading offset), from a
    /// recording (--from) or live on the vehicle (--config alone: collect, then fit).
    /// Writes or updates the calibration file and prints a report.
    Calibrate {
        /// What to calibrate.
        #[arg(value_enum)]
        procedure: CalibrateProcedure,
        /// The recording folder (`chassisd run --record`, `chassisd record` segment, or
        /// `chassisd sim --record`).
        #[arg(long, required_unless_present = "config")]
        from: Option<PathBuf>,
        /// Vehicle configuration: with --from, used instead of the one stored with the
        /// recording; without, the vehicle to collect from live.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Calibration file to write or update (default calib/<vehicle>.toml).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Standing still must last this long, s.
        #[arg(long, default_value = "20", value_parser = seconds_arg)]
        still: Duration,
        /// The report plot (SVG; default: beside the calibration file, named
        /// <vehicle>.<procedure>.svg).
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
    },
    /// Run a benchmark that prints figures.
    Bench {
        #[command(subcommand)]
        which: BenchCommand,
    },
    /// Check a vehicle configuration and probe each of its devices once: serial ports
    /// (valid sentences or frames), CAN interfaces (up), drives (an SDO read), the BMS and
    /// the broker. Prints a table with ok or the reason and the fix; exits 1 when a probe
    /// failed, 78 when the configuration is wrong.
    Check {
        /// Vehicle configuration (TOML).
        #[arg(long)]
        config: PathBuf,
    },
    /// Simulate the CAN devices of a vehicle configuration (drives, BMS) on its CAN
    /// interfaces, e.g. vcan0. Standard input takes fault injections; see the README.
    CanSim {
        /// Vehicle configuration whose [[can]], [[drive]] and [bms] are simulated.
        #[arg(long)]
        config: PathBuf,
    },
    /// Fetch RTK corrections from an NTRIP caster with chassisd's client and write the valid
    /// RTCM 3 frames, whole and in order, to a file or a serial port (a receiver); prints the
    /// frames per message number at the end as JSON. For trying a caster and a mountpoint.
    Ntrip(NtripArgs),
    /// The embedded broker's own process, started and watched by chassisd (settings on
    /// standard input); not for use by hand.
    #[command(name = "broker-child", hide = true)]
    BrokerChild,
}

#[derive(Subcommand)]
enum BenchCommand {
    /// The map filter on a real robot's recording (a Husky's SBAS fixes, wheels and gyro:
    /// ../shared/data/ekf/husky-test1): GNSS outages against the odom frame's dead
    /// reckoning, distance to the fixes, the parked pose and wild fixes; the last line is
    /// a JSON object with every figure.
    Husky {
        /// The recording's folder (gps.csv, odom.csv, imu.csv).
        #[arg(long, default_value = "../shared/data/ekf/husky-test1")]
        data: PathBuf,
        /// The plant whose simulated GNSS errors are compared with the data's (default: the
        /// built-in mower).
        #[arg(long)]
        plant: Option<PathBuf>,
    },
    /// Score the fusion filter on scripted drives of the simulated vehicle against its
    /// truth; the last line is a JSON object with every figure and "pass". Exits with
    /// status 1 when a target is missed.
    Fusion {
        /// Plant file (default: the built-in devices/plant.mower.toml).
        #[arg(long)]
        plant: Option<PathBuf>,
        /// Noise seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Monte Carlo runs of each scenario, each with its own noise; figures pool them
        /// (the outage drift is the RMS over runs, the jump figure the worst run's).
        #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..=1000))]
        runs: u32,
        /// Run only these scenarios (repeatable).
        #[arg(long, value_parser = scenario_names())]
        scenario: Vec<String>,
        /// The receiver's rate, Hz, instead of the plant's.
        #[arg(long, value_parser = gnss_rate_arg)]
        gnss_rate: Option<f64>,
        /// One antenna (heading from course over ground) or two (dual-antenna heading),
        /// instead of the plant's.
        #[arg(long, value_parser = clap::value_parser!(u8).range(1..=2))]
        antennas: Option<u8>,
    },
    /// Score closed-loop moves and the command watchdog on the simulated vehicle against
    /// its truth; the last line is a JSON object with every figure and "pass". Exits with
    /// status 1 when a target is missed.
    Control {
        /// Plant file (default: the built-in devices/plant.mower.toml).
        #[arg(long)]
        plant: Option<PathBuf>,
        /// Noise seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// A calibration file for the simulated vehicle's configuration.
        #[arg(long, value_name = "FILE")]
        calibration: Option<PathBuf>,
    },
    /// Time plain-log replay against gpsd's gpsdecode on real receiver logs repeated to a
    /// size (all concatenated, then each receiver alone), with peak memory; the last line
    /// is JSON with "pass". Exits with status 1 when a target is missed.
    Replay {
        /// Folder of receiver logs (*.log).
        #[arg(long, default_value = "../shared/data/gnss")]
        data: PathBuf,
        /// Size each input is repeated up to, MB.
        #[arg(long, default_value_t = 70, value_parser = clap::value_parser!(u64).range(1..=10_000))]
        megabytes: u64,
        /// Timed runs of each command (the fastest counts).
        #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
        runs: u32,
    },
    /// Run the simulated vehicle on its brokers for minutes while faults come round
    /// (command floods, broker restarts, GNSS outage, IMU stall, lost drive heartbeats, CAN
    /// down): memory slope, base_status gaps, each fault's detection, recovery and stop.
    /// The last line is JSON with "pass"; exits with status 1 when a target is missed.
    Soak {
        /// Plant file (default: the built-in devices/plant.mower.toml).
        #[arg(long)]
        plant: Option<PathBuf>,
        /// Total length, minutes, shared between the brokers.
        #[arg(long, default_value = "10", value_parser = minutes_arg)]
        minutes: Duration,
        /// The embedded broker, mosquitto, or each for half the time.
        #[arg(long, value_enum, default_value_t = BenchBroker::Both)]
        broker: BenchBroker,
    },
    /// Time the MQTT surface on the simulated vehicle: base_status period (median, p99,
    /// max jitter) and the DRIVE command's way to the CAN bus. The last line is JSON.
    Mqtt {
        /// Plant file (default: the built-in devices/plant.mower.toml).
        #[arg(long)]
        plant: Option<PathBuf>,
        /// How long to measure, s.
        #[arg(long, default_value = "60", value_parser = seconds_arg)]
        seconds: Duration,
        /// Use the MQTT broker at HOST:PORT instead of starting one.
        #[arg(long, value_name = "HOST:PORT", conflicts_with = "broker")]
        mqtt: Option<String>,
        /// The broker to start on a free port: the embedded one, mosquitto, or each in turn.
        #[arg(long, value_enum, default_value_t = BenchBroker::Both)]
        broker: BenchBroker,
    },
}

/// The procedures of `chassisd calibrate`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum CalibrateProcedure {
    /// Gyro bias and mounting roll and pitch, from standing still.
    Imu,
    /// Wheel radii and track, from straight runs and turns on the spot.
    Odometry,
    /// Antenna position and dual-antenna heading offset, from turns and runs.
    Gnss,
}

/// Brokers `chassisd bench mqtt` can start.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum BenchBroker {
    /// The embedded rumqttd.
    Embedded,
    /// mosquitto (with set_tcp_nodelay).
    Mosquitto,
    /// The embedded broker, then mosquitto.
    Both,
}

/// Exit status of a configuration error (sysexits' EX_CONFIG).
const EX_CONFIG: u8 = 78;

/// Log lines waiting for stderr before new ones are dropped.
const LOG_QUEUE: usize = 4096;

fn main() -> ExitCode {
    // Before any thread exists: see runtime::heap.
    chassisd::runtime::heap::tune_allocator();
    // Errors travel to network clients (a ROS1 service's refusal carries its text), so they
    // carry no backtrace unless asked for by RUST_LIB_BACKTRACE itself; RUST_BACKTRACE still
    // gives panics theirs.
    if std::env::var_os("RUST_LIB_BACKTRACE").is_none() {
        // SAFETY: no other thread exists yet to read the environment concurrently.
        unsafe { std::env::set_var("RUST_LIB_BACKTRACE", "0") };
    }
    // The guard writes what is queued when main returns.
    let (log_writer, _log_guard) = tracing_appender::non_blocking::NonBlockingBuilder::default()
        .lossy(true)
        .buffered_lines_limit(LOG_QUEUE)
        .thread_name("log-out")
        .finish(std::io::stderr());
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        tracing_subscriber::EnvFilter::new("info,rumqttd=off,roslibrust_ros1=warn")
    });
    let logs = tracing_subscriber::fmt()
        .with_writer(log_writer)
        .with_env_filter(filter);
    if chassisd::runtime::journal::to_journal() {
        logs.event_format(chassisd::runtime::journal::JournalFormat::default())
            .init();
    } else {
        logs.with_ansi(std::io::stderr().is_terminal()).init();
    }
    match run(Cli::parse()) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("chassisd: {e:#}");
            // A configuration error does not mend itself: 78 (EX_CONFIG) tells systemd not to
            // restart (the unit's RestartPreventExitStatus).
            if e.chain()
                .any(|c| c.downcast_ref::<chassisd::config::ConfigError>().is_some())
            {
                ExitCode::from(EX_CONFIG)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// Runs the command; `Ok(false)` when it ran but its verdict is negative (a benchmark missed
/// a target).
fn run(cli: Cli) -> anyhow::Result<bool> {
    match cli.command {
        Command::Bench {
            which: BenchCommand::Husky { data, plant },
        } => {
            use chassisd::bench::{gnss_fit, husky};
            let data = husky::HuskyData::load(&data)?;
            let plant = load_plant(plant)?;
            let fit = gnss_fit::fit(&data, &plant, 1);
            let report = husky::report(&data, Default::default());
            print!("{report}");
            print!("{fit}");
            println!(
                "{}",
                serde_json::json!({ "filter": report, "gnss_errors": fit })
            );
            Ok(true)
        }
        Command::Bench {
            which:
                BenchCommand::Fusion {
                    plant,
                    seed,
                    runs,
                    scenario,
                    gnss_rate,
                    antennas,
                },
        } => {
            let mut plant = load_plant(plant)?;
            if let Some(rate) = gnss_rate {
                plant.gnss.rate_hz = rate;
            }
            if let Some(n) = antennas {
                plant.gnss.dual_antenna = n == 2;
            }
            bench_fusion(plant, seed, runs, &scenario)
        }
        Command::Bench {
            which:
                BenchCommand::Control {
                    plant,
                    seed,
                    calibration,
                },
        } => {
            let mut plant = load_plant(plant)?;
            plant.calibration = load_calibration(calibration.as_deref())?;
            let report = chassisd::bench::control::run(&plant, seed)?;
            print!("{}", report.table());
            println!("{}", report.json());
            Ok(report.pass)
        }
        Command::Bench {
            which:
                BenchCommand::Soak {
                    plant,
                    minutes,
                    broker,
                },
        } => bench_soak(plant, minutes, broker),
        Command::Bench {
            which:
                BenchCommand::Replay {
                    data,
                    megabytes,
                    runs,
                },
        } => {
            let exe = std::env::current_exe().context("finding this program")?;
            let report = chassisd::bench::replay::run(
                &chassisd::bench::replay::ReplayBenchOptions {
                    data,
                    bytes: megabytes * 1_000_000,
                    runs,
                },
                &exe,
            )?;
            print!("{}", report.table());
            println!("{}", report.json());
            Ok(report.pass)
        }
        Command::Bench {
            which:
                BenchCommand::Mqtt {
                    plant,
                    seconds,
                    mqtt,
                    broker,
                },
        } => bench_mqtt(plant, seconds, mqtt.as_deref(), broker),
        Command::Replay {
            path,
            config,
            stamped,
            max_gap,
            lenient,
            corrections_out,
        } => {
            let options = replay::ReplayOptions {
                config: config.map(|p| VehicleConfig::load(&p)).transpose()?,
                stamped,
                import: ImportOptions { max_gap },
                corrections_out,
            };
            let stdout = std::io::stdout();
            let mut out = std::io::BufWriter::with_capacity(1 << 16, stdout.lock());
            let summary = replay::replay(&path, &options, &mut out)
                .with_context(|| format!("replay of {}", path.display()))?;
            out.flush()?;
            for skip in &summary.skipped_lines.0 {
                eprintln!("skipped {}:{}: {}", skip.file, skip.line, skip.reason);
            }
            for late in &summary.out_of_order.0 {
                eprintln!(
                    "out of time order {}:{}: {}",
                    late.file, late.line, late.reason
                );
            }
            for (name, protocol) in &summary.sources_without_decoder {
                eprintln!(
                    "source {name:?} is not decoded ({protocol}); its frames are counted only"
                );
            }
            if let Some(import) = &summary.import
                && !import.date_known
            {
                eprintln!("no RMC or ZDA date in the log; 1970-01-01 assumed");
            }
            for correction in &summary.span_corrections {
                eprintln!("meta.toml: {correction}");
            }
            eprintln!("{}", summary.one_line());
            let late = summary.out_of_order.1;
            if late > 0 && !lenient {
                eprintln!(
                    "{late} records go back in time within their file: the recording was \
                     edited or its clock stepped; exit status 1 (--lenient accepts them)"
                );
            }
            let differ = summary.engine.tx_mismatched;
            if differ > 0 && !lenient {
                eprintln!(
                    "{differ} transmissions differ from the recording's: this chassisd does \
                     not drive the vehicle as the recorded one did; exit status 1 (--lenient \
                     accepts them)"
                );
            }
            Ok((late == 0 && differ == 0) || lenient)
        }
        Command::Run {
            config,
            record,
            commands_stdin,
            ros_master,
            websocket,
            ntrip,
        } => {
            let mut vehicle = VehicleConfig::load(&config)?;
            vehicle.require_devices(&config)?;
            if let Some(url) = ntrip {
                vehicle.ntrip = Some(ntrip_override(vehicle.ntrip.take(), &url)?);
            }
            if let Some(bind) = websocket {
                let mut w = vehicle.websocket.take().unwrap_or_default();
                w.bind = bind;
                w.validate(Path::new("--websocket"))?;
                vehicle.websocket = Some(w);
            }
            if let Some(uri) = ros_master {
                let mut ros1 = vehicle.ros1.take().unwrap_or_default();
                ros1.master_uri = uri;
                ros1.validate(Path::new("--ros-master"))?;
                vehicle.ros1 = Some(ros1);
            }
            ensure_ros1_built(vehicle.ros1.is_some())?;
            let runtime = async_runtime(2)?;
            let result = runtime.block_on(live::run(
                LiveOptions {
                    config: vehicle,
                    record,
                    commands_stdin,
                    pattern: None,
                },
                std::io::stdout(),
            ));
            // A read of standard input may still be blocked in a runtime thread; do not wait
            // for it.
            runtime.shutdown_background();
            result.map(|()| true)
        }
        Command::Record {
            config,
            out,
            segment_mb,
            segment_s,
            keep,
            duration,
        } => {
            let vehicle = VehicleConfig::load(&config)?;
            let runtime = async_runtime(1)?;
            let result = runtime.block_on(chassisd::runtime::listen::run(
                chassisd::runtime::listen::ListenOptions {
                    config: vehicle,
                    out,
                    rotation: chassisd::record::segments::Rotation {
                        max_bytes: segment_mb.saturating_mul(1_000_000),
                        max_span: segment_s,
                        keep: (keep > 0).then_some(keep),
                    },
                    duration,
                    progress: std::io::stderr().is_terminal(),
                },
            ));
            runtime.shutdown_background();
            let summary = result?;
            eprintln!("{}", summary.line());
            Ok(summary.dropped == 0)
        }
        Command::Sim {
            plant,
            seed,
            record,
            commands_stdin,
            scenario,
            duration,
            mqtt,
            broker_port,
            no_mqtt,
            trajectory_dir,
            ros_master,
            websocket,
            fast,
            calibration,
            ntrip,
        } => {
            let mut plant = load_plant(plant)?;
            plant.calibration = load_calibration(calibration.as_deref())?;
            let scenario = scenario.map(|name| find_scenario(&name)).transpose()?;
            if fast {
                let summary = chassisd::runtime::sim_fast::run(
                    chassisd::runtime::sim_fast::FastOptions {
                        plant,
                        seed,
                        scenario,
                        duration,
                        record,
                    },
                    std::io::stdout().lock(),
                )?;
                eprintln!("{}", summary.line());
                return Ok(true);
            }
            let ros1 = ros_master.map(|uri| Ros1Config::with_master(&uri));
            if let Some(r) = &ros1 {
                r.validate(Path::new("--ros-master"))?;
            }
            let websocket = websocket.map(|bind| WebsocketConfig::with_bind(&bind));
            if let Some(w) = &websocket {
                w.validate(Path::new("--websocket"))?;
            }
            ensure_ros1_built(ros1.is_some())?;
            let mut mqtt = (!no_mqtt).then(|| sim_mqtt(mqtt.as_deref())).transpose()?;
            if let (Some(m), Some(port)) = (mqtt.as_mut(), broker_port) {
                m.port = port;
            }
            if let Some(rtk) = mqtt.as_mut().and_then(|m| m.rtk.as_mut()) {
                rtk.trajectory_dir = trajectory_dir.map(|d| d.to_string_lossy().into_owned());
            }
            // The ROS1 node's publishing gets a worker of its own beside the simulation.
            let runtime = async_runtime(if ros1.is_some() { 2 } else { 1 })?;
            let result = runtime.block_on(sim::run(
                SimOptions {
                    plant,
                    seed,
                    record,
                    commands_stdin,
                    scenario,
                    duration,
                    mqtt,
                    ros1,
                    websocket,
                    handle: None,
                    ntrip: ntrip.map(|url| ntrip_override(None, &url)).transpose()?,
                },
                std::io::stdout(),
            ));
            runtime.shutdown_background();
            result.map(|()| true)
        }
        Command::Calibrate {
            procedure,
            from,
            config,
            out,
            still,
            plot,
            collect,
            record,
            drive,
            yes,
            speed,
            run_m,
            runs,
        } => {
            // A live collection's recording holds the configuration as it was recorded
            // (CAN listen-only when only listening): the fit reads it from there.
            let (from, config) = match from {
                Some(from) => (from, config),
                None => {
                    let path = config.as_deref().context("--config or --from is needed")?;
                    let vehicle = VehicleConfig::load(path)?;
                    let live = LiveCalibration {
                        procedure,
                        record,
                        out: out.clone(),
                        still,
                        collect,
                        drive: drive.then_some(DrivePlan {
                            yes,
                            speed,
                            run_m,
                            runs,
                        }),
                    };
                    match collect_live(&vehicle, live)? {
                        Some(recording) => (recording, None),
                        None => return Ok(false),
                    }
                }
            };
            calibrate(procedure, &from, config.as_deref(), out, still, plot)
        }
        Command::Check { config } => {
            let vehicle = VehicleConfig::load(&config)?;
            println!("configuration {}: ok", config.display());
            let runtime = async_runtime(1)?;
            let probes = runtime.block_on(chassisd::runtime::check::run(&vehicle));
            runtime.shutdown_background();
            print!("{}", chassisd::runtime::check::table(&probes));
            Ok(probes.iter().all(|p| p.result.is_ok()))
        }
        Command::CanSim { config } => {
            let vehicle = VehicleConfig::load(&config)?;
            let runtime = async_runtime(1)?;
            let result = runtime.block_on(chassisd::runtime::can_sim::run(vehicle));
            runtime.shutdown_background();
            result.map(|()| true)
        }
        Command::BrokerChild => chassisd::runtime::broker::child::main().map(|()| true),
        Command::Ntrip(args) => ntrip_fetch(args),
    }
}

/// Refuses a ROS1 node in a build without the `ros1` feature, saying how to get one.
fn ensure_ros1_built(wanted: bool) -> anyhow::Result<()> {
    anyhow::ensure!(
        !wanted || cfg!(feature = "ros1"),
        "this chassisd was built without the ros1 feature; build it with the default \
         features (cargo build --release) to join a ROS1 graph"
    );
    Ok(())
}

/// The `{vehicleId}` of the simulated vehicle's root dialect.
const SIM_VEHICLE_ID: &str = "sim";
/// The `{serial_number}` of the simulated vehicle's device dialect.
const SIM_SERIAL_NUMBER: &str = "SIM0001";

/// The MQTT settings of `chassisd sim`: every dialect, on the broker at `external`, or on an
/// embedded one at 127.0.0.1:1883.
fn sim_mqtt(external: Option<&str>) -> anyhow::Result<MqttConfig> {
    let mut config = MqttConfig {
        embedded_broker: external.is_none(),
        rtk: Some(RtkDialectConfig::default()),
        root: Some(RootDialectConfig {
            vehicle_id: SIM_VEHICLE_ID.into(),
            heartbeat_timeout_s: 3.0,
            require_heartbeat: false,
            heartbeat_client_id: None,
        }),
        device: Some(DeviceDialectConfig {
            serial_number: SIM_SERIAL_NUMBER.into(),
            mapping_forward: None,
        }),
        ..MqttConfig::default()
    };
    if let Some(address) = external {
        let (host, port) = address
            .rsplit_once(':')
            .and_then(|(h, p)| Some((h, p.parse::<u16>().ok()?)))
            .with_context(|| format!("--mqtt {address:?}: expected HOST:PORT"))?;
        config.host = host.to_owned();
        config.port = port;
    }
    Ok(config)
}

/// `chassisd calibrate`: the procedure on a recording, its report on stdout, the file
/// written; a refusal is an error with the reason and the fix.
fn calibrate(
    procedure: CalibrateProcedure,
    from: &Path,
    config: Option<&Path>,
    out: Option<PathBuf>,
    still: Duration,
    plot: Option<PathBuf>,
) -> anyhow::Result<bool> {
    use chassisd::calib::{self, Procedure, Settings, data::Dataset};
    use chassisd::config::calibration::{CalibrationFile, default_path};

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
    use chassisd::config::calibration::default_path;
    use chassisd::record::segments::{Rotation, segment_dir};
    use chassisd::sim::scenario::CalibrationPattern;

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
        let scenario = chassisd::sim::scenario::Scenario::calibration_pattern(&pattern);
        let (along, across) = pattern.area_m();
        eprintln!(
            "calibration drive of {name}: {:.0} s standing still, {} pairs of {:.1} m runs at              {:.2} m/s joined by turns on the spot, turns on the spot both ways, a figure              eight of {:.1} m loops; about {:.0} s in all. It needs a clear, level area of              about {along:.0} m by {across:.0} m ahead of the vehicle, RTK fixed, and someone              at the e-stop. Every limit, watchdog and stop of `chassisd run` applies; a stop              abandons the pattern.",
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
        let runtime = async_runtime(2)?;
        let result = runtime.block_on(live::run(
            LiveOptions {
                config: vehicle.clone(),
                record: Some(folder.clone()),
                commands_stdin: false,
                pattern: Some(scenario),
            },
            std::io::sink(),
        ));
        runtime.shutdown_background();
        result.context("calibration drive")?;
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
            _ => "; drive the pattern by hand (see the README)",
        }
    );
    let runtime = async_runtime(1)?;
    let result = runtime.block_on(chassisd::runtime::listen::run(
        chassisd::runtime::listen::ListenOptions {
            config: vehicle.clone(),
            out: folder.clone(),
            rotation: Rotation {
                max_bytes: u64::MAX,
                max_span: Duration::MAX,
                keep: None,
            },
            duration: Some(span),
            progress: std::io::stderr().is_terminal(),
        },
    ));
    runtime.shutdown_background();
    let summary = result?;
    eprintln!("{}", summary.line());
    Ok(Some(segment_dir(&folder, 1)))
}

/// The calibration file at `path`, if one is given.
fn load_calibration(
    path: Option<&Path>,
) -> anyhow::Result<Option<chassisd::config::calibration::CalibrationFile>> {
    Ok(path
        .map(chassisd::config::calibration::CalibrationFile::load)
        .transpose()?)
}

fn load_plant(path: Option<PathBuf>) -> anyhow::Result<PlantConfig> {
    Ok(match path {
        Some(path) => PlantConfig::load(&path)?,
        None => PlantConfig::builtin()?,
    })
}

/// The scenarios' names, each with what it drives, for `--help` and argument checking.
fn scenario_names() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        Scenario::every()
            .into_iter()
            .map(|s| clap::builder::PossibleValue::new(s.name).help(s.about)),
    )
}

fn find_scenario(name: &str) -> anyhow::Result<Scenario> {
    Scenario::named(name).ok_or_else(|| {
        let names: Vec<&str> = Scenario::every().iter().map(|s| s.name).collect();
        anyhow::anyhow!("no scenario {name:?}; there are {}", names.join(", "))
    })
}

fn bench_fusion(
    plant: PlantConfig,
    seed: u64,
    runs: u32,
    names: &[String],
) -> anyhow::Result<bool> {
    let scenarios = if names.is_empty() {
        Scenario::all()
    } else {
        names
            .iter()
            .map(|n| find_scenario(n))
            .collect::<anyhow::Result<Vec<_>>>()?
    };
    let started = std::time::Instant::now();
    let report = fusion::run(&plant, &scenarios, seed, runs)?;
    let elapsed = started.elapsed();
    let simulated = fusion::simulated_time(&scenarios).as_secs_f64() * f64::from(runs);
    print!("{}", report.table());
    println!(
        "simulated {simulated:.0} s in {:.1} s of wall time ({:.0}x real time)",
        elapsed.as_secs_f64(),
        simulated / elapsed.as_secs_f64().max(1e-9),
    );
    println!("{}", report.json());
    Ok(report.pass)
}

/// The brokers `--broker` names, in the order they run.
fn bench_brokers(choice: BenchBroker) -> Vec<Broker> {
    match choice {
        BenchBroker::Embedded => vec![Broker::Embedded],
        BenchBroker::Mosquitto => vec![Broker::Mosquitto],
        BenchBroker::Both => vec![Broker::Embedded, Broker::Mosquitto],
    }
}

fn bench_mqtt(
    plant: Option<PathBuf>,
    seconds: Duration,
    external: Option<&str>,
    choice: BenchBroker,
) -> anyhow::Result<bool> {
    use chassisd::bench::mqtt::{BrokerRun, MqttBenchOptions, MqttComparison};

    let plant = load_plant(plant)?;
    // An outside broker (`--mqtt`) runs alone; else each broker asked for, mosquitto left
    // out with the reason when it is missing and both were asked for.
    let mut brokers: Vec<Option<Broker>> = Vec::new();
    let mut skipped = None;
    if external.is_some() {
        brokers.push(None);
    } else {
        for broker in bench_brokers(choice) {
            let missing = (broker == Broker::Mosquitto)
                .then(Mosquitto::missing)
                .flatten();
            match missing {
                Some(why) if choice == BenchBroker::Both => skipped = Some(why),
                Some(why) => anyhow::bail!(why),
                None => brokers.push(Some(broker)),
            }
        }
    }
    let mut runs = Vec::new();
    for broker in brokers {
        let mut mqtt = sim_mqtt(external)?;
        let mosquitto = broker.map(|b| b.start(&mut mqtt)).transpose()?.flatten();
        let name = broker.map_or("external", Broker::name);
        let runtime = async_runtime(2)?;
        let report = runtime.block_on(chassisd::bench::mqtt::run(MqttBenchOptions {
            plant: plant.clone(),
            duration: seconds,
            mqtt,
        }));
        runtime.shutdown_background();
        drop(mosquitto);
        let run = BrokerRun::new(name, report?);
        println!("broker: {name}");
        print!("{}", run.report.table());
        runs.push(run);
    }
    let comparison = MqttComparison::new(runs, skipped);
    if let Some(why) = &comparison.skipped {
        println!("mosquitto not compared: {why}");
    }
    println!("{}", comparison.json());
    Ok(comparison.pass)
}

fn bench_soak(
    plant: Option<PathBuf>,
    total: Duration,
    choice: BenchBroker,
) -> anyhow::Result<bool> {
    use chassisd::bench::soak::SoakOptions;

    let brokers = bench_brokers(choice);
    if brokers.contains(&Broker::Mosquitto)
        && let Some(why) = Mosquitto::missing()
    {
        anyhow::bail!(why);
    }
    let options = SoakOptions {
        plant: load_plant(plant)?,
        mqtt: sim_mqtt(None)?,
        run_for: total / brokers.len() as u32,
        brokers,
    };
    let runtime = async_runtime(2)?;
    let report = runtime.block_on(chassisd::bench::soak::run(options));
    runtime.shutdown_background();
    let report = report?;
    for run in &report.runs {
        print!("{}", run.table());
    }
    println!("{}", report.json());
    Ok(report.pass)
}

/// Parses a positive number of minutes (up to a week).
fn minutes_arg(s: &str) -> Result<Duration, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v <= 7.0 * 24.0 * 60.0 => Ok(Duration::from_secs_f64(v * 60.0)),
        _ => Err(format!(
            "{s:?}: give a positive number of minutes, at most a week"
        )),
    }
}

/// `[ntrip]` with `--ntrip URL`'s caster (the rest of the section kept); a password in the
/// URL replaces a password file.
fn ntrip_override(
    configured: Option<chassisd::config::ntrip::NtripConfig>,
    url: &str,
) -> anyhow::Result<chassisd::config::ntrip::NtripConfig> {
    use chassisd::config::ntrip::NtripConfig;
    let mut n = configured.unwrap_or_else(|| NtripConfig::with_url(url));
    n.url = url.to_owned();
    if n.parsed_url()
        .is_ok_and(|u| !u.password.expose().is_empty())
    {
        n.password_file = None;
    }
    n.validate(Path::new("--ntrip"))?;
    Ok(n)
}

/// `chassisd ntrip`'s arguments.
#[derive(clap::Args)]
struct NtripArgs {
    /// The caster: ntrip://USER:PASSWORD@HOST:PORT/MOUNTPOINT (ntrips:// for TLS).
    url: String,
    /// A file with the password (its first line), instead of one in the URL.
    #[arg(long)]
    password_file: Option<PathBuf>,
    /// With ntrips://: the caster's certificate authority (PEM), trusted besides the
    /// system's roots.
    #[arg(long, value_name = "FILE")]
    ca_file: Option<PathBuf>,
    /// NTRIP version to ask for (a 1.0 answer is taken either way).
    #[arg(long, default_value = "2", value_parser = ["1", "2"])]
    version: String,
    /// Send the position as GGA every this many seconds (0: never).
    #[arg(long, default_value = "10")]
    gga_interval: f64,
    /// The position for the GGA: latitude, longitude (degrees), height (m).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    position: Option<Vec<f64>>,
    /// Drop a connection with no valid frame for this long, s.
    #[arg(long, default_value = "10", value_parser = seconds_arg)]
    timeout: Duration,
    /// Write the frames to this file ...
    #[arg(long, conflicts_with = "port")]
    out: Option<PathBuf>,
    /// ... or to this serial port.
    #[arg(long)]
    port: Option<String>,
    /// The port's baud rate.
    #[arg(long, default_value = "115200")]
    baud: u32,
    /// Stop after this long, s (default: at Ctrl-C).
    #[arg(long, value_parser = seconds_arg)]
    duration: Option<Duration>,
}

fn ntrip_fetch(a: NtripArgs) -> anyhow::Result<bool> {
    use chassisd::devices::gnss::encode::GgaFix;
    use chassisd::ntrip::request::Version;
    use chassisd::ntrip::url::{NtripUrl, Password};
    use chassisd::runtime::ntrip::{NtripSpec, fetch};
    let mut url = NtripUrl::parse(&a.url)?;
    if let Some(file) = &a.password_file {
        let text = std::fs::read_to_string(file)
            .with_context(|| format!("cannot read the password file {}", file.display()))?;
        url.password = Password::new(text.lines().next().unwrap_or("").trim_end());
    }
    anyhow::ensure!(
        a.gga_interval == 0.0 || (1.0..=3600.0).contains(&a.gga_interval),
        "--gga-interval must be 0 (none) or 1 to 3600 s"
    );
    let position = match a.position.as_deref() {
        Some(&[lat, lon, h]) => {
            anyhow::ensure!(
                (-90.0..=90.0).contains(&lat) && (-180.0..=180.0).contains(&lon) && h.is_finite(),
                "--position: latitude -90 to 90, longitude -180 to 180, a finite height"
            );
            Some(GgaFix::fallback(lat, lon, h))
        }
        Some(_) => anyhow::bail!("--position takes latitude,longitude,height"),
        None => None,
    };
    let url_tls = url.tls;
    let spec = NtripSpec {
        url,
        version: if a.version == "1" {
            Version::V1
        } else {
            Version::V2
        },
        gga_interval: (a.gga_interval > 0.0).then(|| Duration::from_secs_f64(a.gga_interval)),
        timeout: a.timeout,
        tls: if url_tls {
            Some(
                chassisd::ntrip::tls::client_config(a.ca_file.as_deref())
                    .map_err(anyhow::Error::msg)?,
            )
        } else {
            None
        },
    };
    let runtime = async_runtime(1)?;
    let report = runtime.block_on(async {
        let out: Box<dyn tokio::io::AsyncWrite + Unpin + Send> = match (&a.out, &a.port) {
            (Some(path), _) => Box::new(
                tokio::fs::File::create(path)
                    .await
                    .with_context(|| format!("cannot create {}", path.display()))?,
            ),
            (None, Some(port)) => {
                use tokio_serial::SerialPortBuilderExt;
                Box::new(
                    tokio_serial::new(port, a.baud)
                        .open_native_async()
                        .with_context(|| format!("cannot open {port}"))?,
                )
            }
            (None, None) => Box::new(tokio::io::stdout()),
        };
        anyhow::Ok(fetch(spec, position, out, a.duration).await?)
    })?;
    runtime.shutdown_background();
    eprintln!(
        "ntrip: {} frames ({} bytes) written, {} invalid bytes dropped, {} connects, {} GGA sent{}",
        report.frames,
        report.bytes,
        report.invalid_bytes,
        report.attempts,
        report.ggas_sent,
        report
            .last_error
            .as_deref()
            .map(|e| format!("; last: {e}"))
            .unwrap_or_default()
    );
    eprintln!("{}", serde_json::to_string(&report)?);
    Ok(report.frames > 0)
}

/// A multi-threaded tokio runtime with `threads` workers, timers and I/O enabled.
fn async_runtime(threads: usize) -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(threads)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

/// The longest span a seconds argument may give: about 31 years.
const MAX_SECONDS_ARG: f64 = 1e9;

/// Parses a positive, finite number of seconds (up to [`MAX_SECONDS_ARG`]).
fn seconds_arg(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if !(v > 0.0 && v <= MAX_SECONDS_ARG) {
        return Err(format!(
            "{s:?}: give a positive number of seconds, at most {MAX_SECONDS_ARG:e}"
        ));
    }
    Ok(Duration::from_secs_f64(v))
}

/// Parses a receiver rate: 0.1 to 50 Hz.
fn gnss_rate_arg(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.1..=50.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: give a rate from 0.1 to 50 Hz")),
    }
}
