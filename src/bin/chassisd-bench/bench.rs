//! The benchmarks that print figures, each ending with a JSON line.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;

use crate::common::{
    block_on, find_scenario, load_calibration, load_plant, scenario_names, seconds_arg, sim_mqtt,
};
use chassisd::bench::Broker;
use chassisd::bench::fusion;
use chassisd::bench::mosquitto::Mosquitto;
use chassisd::bench::mqtt::{BrokerRun, MqttBenchOptions, MqttComparison};
use chassisd::bench::soak::SoakOptions;
use chassisd::sim::plant::PlantConfig;
use chassisd::sim::scenario::Scenario;

/// Run a benchmark that prints figures.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    which: BenchCommand,
}

#[derive(clap::Subcommand)]
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
    /// Every real vehicle's recording of ../shared/data/ekf (the Husky, with and without a
    /// course; the comma2k19 car; the Jackal) turned into a chassisd recording and replayed
    /// through the whole core: one table of each figure beside its target and the naive dead
    /// reckoning's; the last line is a JSON object with every figure and "pass". Exits with
    /// status 1 when a target is missed.
    Real {
        /// The shared data's ekf/ folder.
        #[arg(long, default_value = "../shared/data/ekf")]
        data: PathBuf,
        /// Replays run on this many threads.
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
        jobs: u32,
        /// Write each vehicle's whole run as CSV into this folder (time, map pose, heading
        /// 1σ, the scored point and its truth), to plot.
        #[arg(long)]
        trace: Option<PathBuf>,
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
    /// The safety envelope on the simulated vehicle against its truth: randomised
    /// approaches towards keep-out zones and walls (manual and autonomous, with RTK-float
    /// jumps), the blade at every gate closing, a covering mission under clean RTK, and
    /// plans through zones. A table, then a JSON line with "pass"; exits with status 1 when
    /// a target is missed.
    Envelope {
        /// Plant file (default: the built-in devices/plant.mower.toml).
        #[arg(long)]
        plant: Option<PathBuf>,
        /// Noise seed (each approach draws its own from it).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Randomised approaches.
        #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u32).range(1..=100_000))]
        approaches: u32,
        /// The covering mission's length.
        #[arg(long, default_value = "30", value_parser = minutes_arg)]
        minutes: Duration,
        /// Plans through zones (and as many clear of them).
        #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..=10_000))]
        plans: u32,
    },
    /// Time `chassisd export --mcap` on the longest fixture and on a synthetic recording of
    /// the simulated vehicle (× real time, MB/s, peak memory); the last line is JSON with
    /// "pass". Exits with status 1 when a target is missed.
    Export {
        /// The folder of recordings whose longest is exported.
        #[arg(long, default_value = "fixtures")]
        fixtures: PathBuf,
        /// The synthetic recording's length, seconds.
        #[arg(long, default_value_t = 3600, value_parser = clap::value_parser!(u64).range(10..=86_400))]
        seconds: u64,
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
    /// down, hostile MQTT, HTTP and TCPROS clients): memory slope, base_status gaps, each
    /// fault's detection, recovery and stop.
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
        /// Leave the ROS1 node and its TCPROS attack out (by default the soak starts a
        /// rosmaster, Debian's ros-core, for them).
        #[arg(long)]
        without_ros1: bool,
    },
    /// Many simulated vehicles in this process (each its own engine, plant and platform
    /// link) on broker nodes, with an operator on each node: report periods, command round
    /// trips, and, after node 0 is killed, the connects per second that followed, the time
    /// until every vehicle was back and any command lost or answered twice. A table, then a
    /// JSON line with "pass"; exits with status 1 when a target is missed.
    Fleet {
        /// Plant file (default: the built-in devices/plant.mower.toml).
        #[arg(long)]
        plant: Option<PathBuf>,
        /// Vehicles.
        #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=10_000))]
        vehicles: u32,
        /// Broker nodes started on loopback: independent mosquitto brokers (default 2), or
        /// with --rabbitmq one RabbitMQ cluster (default and least 3).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=16), conflicts_with = "broker")]
        nodes: Option<u32>,
        /// The nodes are one RabbitMQ cluster with its MQTT plugin (Debian's
        /// rabbitmq-server), started by the bench on loopback, node 0 killed.
        #[arg(long, conflicts_with = "broker")]
        rabbitmq: bool,
        /// Run on these brokers instead (host:port, comma-separated), started by you.
        #[arg(long, value_delimiter = ',')]
        broker: Vec<String>,
        /// The brokers of --broker are one cluster (each command is sent once, through the
        /// last of them, which must not be the one stopped).
        #[arg(long, requires = "broker")]
        clustered: bool,
        /// With --broker, the shell command that kills node 0 (its host:port in
        /// $CHASSISD_NODE); without it no node is killed.
        #[arg(long, requires_all = ["broker", "start_cmd"])]
        stop_cmd: Option<String>,
        /// The QoS the vehicles subscribe to commands with (their links' command_qos):
        /// default 1, and 0 with --rabbitmq, as docs/fleet.md advises for such a cluster.
        #[arg(long, value_parser = clap::value_parser!(u8).range(0..=1))]
        command_qos: Option<u8>,
        /// With --stop-cmd, the shell command that starts node 0 again at the end.
        #[arg(long, requires = "stop_cmd")]
        start_cmd: Option<String>,
        /// Steady running before the kill and after every vehicle is back.
        #[arg(long, default_value = "20", value_parser = seconds_arg)]
        steady: Duration,
        /// Do not kill a node.
        #[arg(long)]
        no_kill: bool,
        /// The platform links' first back-off bound, s.
        #[arg(long, default_value_t = 2.0)]
        reconnect_min: f64,
        /// The platform links' largest back-off bound, s.
        #[arg(long, default_value_t = 30.0)]
        reconnect_max: f64,
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
    /// `/odom` to several subscribers, each a process of its own, through the native ROS 2
    /// node (DDS) and through the rosbridge WebSocket, on the simulated vehicle: latency
    /// from the pose's stamp (p50, p99, max), messages each got, and the CPU each route adds
    /// to chassisd over the same vehicle publishing to nobody. Runs in a network namespace
    /// of its own (unshare, iproute2). A table, then a JSON line with "pass"; exits with
    /// status 1 when a target is missed.
    #[cfg(feature = "ros2")]
    Ros2 {
        /// Plant file (default: the built-in devices/plant.mower.toml).
        #[arg(long)]
        plant: Option<PathBuf>,
        /// How long each route is measured.
        #[arg(long, default_value = "20", value_parser = seconds_arg)]
        seconds: Duration,
        /// Subscribers of each route.
        #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=16))]
        subscribers: u32,
        /// `/odom`'s rate, Hz (1 to 100).
        #[arg(long, default_value_t = 100.0, value_parser = odom_rate_arg)]
        rate: f64,
    },
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

pub fn execute(a: Args) -> anyhow::Result<bool> {
    match a.which {
        BenchCommand::Husky { data, plant } => {
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
        BenchCommand::Real { data, jobs, trace } => {
            let options = chassisd::bench::real::Options {
                workers: jobs as usize,
                trace,
            };
            let table = chassisd::bench::real::run(&data, &options)?;
            print!("{table}");
            let pass = table.pass();
            println!(
                "{}",
                serde_json::json!({ "figures": table.figures, "pass": pass })
            );
            Ok(pass)
        }
        BenchCommand::Fusion {
            plant,
            seed,
            runs,
            scenario,
            gnss_rate,
            antennas,
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
        BenchCommand::Control {
            plant,
            seed,
            calibration,
        } => {
            let mut plant = load_plant(plant)?;
            plant.calibration = load_calibration(calibration.as_deref())?;
            let report = chassisd::bench::control::run(&plant, seed)?;
            print!("{}", report.table());
            println!("{}", report.json());
            Ok(report.pass)
        }
        BenchCommand::Envelope {
            plant,
            seed,
            approaches,
            minutes,
            plans,
        } => {
            let plant = load_plant(plant)?;
            let options = chassisd::bench::envelope::EnvelopeOptions {
                approaches,
                coverage_s: minutes.as_secs_f64(),
                plans,
            };
            let report = chassisd::bench::envelope::run(&plant, seed, options)?;
            print!("{}", report.table());
            println!("{}", report.json());
            Ok(report.pass)
        }
        BenchCommand::Soak {
            plant,
            minutes,
            broker,
            without_ros1,
        } => bench_soak(plant, minutes, broker, !without_ros1),
        BenchCommand::Fleet {
            plant,
            vehicles,
            nodes,
            rabbitmq,
            broker,
            clustered,
            stop_cmd,
            start_cmd,
            command_qos,
            steady,
            no_kill,
            reconnect_min,
            reconnect_max,
        } => {
            use chassisd::bench::fleet::{MosquittoNodes, NamedNodes, Nodes, RabbitNodes};
            let dir = tempfile_dir("chassisd-bench-fleet")?;
            let kill = !no_kill && (broker.is_empty() || stop_cmd.is_some());
            let nodes: Box<dyn Nodes> = if !broker.is_empty() {
                let stop_start = stop_cmd.zip(start_cmd);
                Box::new(NamedNodes::new(&broker, clustered, stop_start)?)
            } else if rabbitmq {
                let count = nodes.unwrap_or(3);
                if count < 3 {
                    anyhow::bail!(
                        "--rabbitmq needs at least 3 nodes: before 3.12 RabbitMQ's MQTT plugin \
                         takes connections only while a majority of the nodes runs, so with 2 \
                         a killed node would leave no node taking vehicles"
                    );
                }
                if let Some(why) = chassisd::bench::rabbitmq::RabbitCluster::missing() {
                    anyhow::bail!(why);
                }
                Box::new(RabbitNodes::start(count as usize, &dir)?)
            } else {
                if let Some(why) = Mosquitto::missing() {
                    anyhow::bail!(why);
                }
                Box::new(MosquittoNodes::start(nodes.unwrap_or(2) as usize, &dir)?)
            };
            let options = chassisd::bench::fleet::FleetOptions {
                plant: load_plant(plant)?,
                vehicles: vehicles as usize,
                steady,
                kill,
                reconnect: (reconnect_min, reconnect_max),
                command_qos: command_qos.unwrap_or(if rabbitmq { 0 } else { 1 }),
            };
            let report = block_on(2, chassisd::bench::fleet::run(options, nodes))??;
            std::fs::remove_dir_all(&dir).ok();
            print!("{}", report.table());
            println!("{}", report.json());
            Ok(report.pass)
        }
        BenchCommand::Export { fixtures, seconds } => {
            let exe = daemon_binary()?;
            let report = chassisd::bench::export::run(
                &exe,
                &fixtures,
                std::time::Duration::from_secs(seconds),
            )?;
            print!("{}", report.table());
            println!("{}", report.json());
            Ok(report.pass)
        }
        BenchCommand::Replay {
            data,
            megabytes,
            runs,
        } => {
            let exe = daemon_binary()?;
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
        BenchCommand::Mqtt {
            plant,
            seconds,
            mqtt,
            broker,
        } => bench_mqtt(plant, seconds, mqtt.as_deref(), broker),
        #[cfg(feature = "ros2")]
        BenchCommand::Ros2 {
            plant,
            seconds,
            subscribers,
            rate,
        } => bench_ros2(plant, seconds, subscribers, rate),
    }
}

#[cfg(feature = "ros2")]
fn bench_ros2(
    plant: Option<PathBuf>,
    seconds: Duration,
    subscribers: u32,
    rate_hz: f64,
) -> anyhow::Result<bool> {
    use chassisd::bench::ros2;
    // DDS discovery multicasts: the run happens in a network namespace of its own.
    if let Some(status) = ros2::enter_private_network()? {
        anyhow::ensure!(
            status.code().is_some(),
            "the benchmark in its network namespace ended by {status}"
        );
        return Ok(status.success());
    }
    let options = ros2::Ros2BenchOptions {
        plant: load_plant(plant)?,
        window: seconds,
        subscribers,
        rate_hz,
    };
    let report = ros2::run(&options)?;
    print!("{}", report.table());
    println!("{}", report.json());
    Ok(report.pass)
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
    // At the plant's own speed: a car drives the laps at ten times a mower's.
    let scenarios: Vec<Scenario> = scenarios
        .iter()
        .map(|s| s.at_speed(plant.drive.scenario_speed))
        .collect();
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
        let options = MqttBenchOptions {
            plant: plant.clone(),
            duration: seconds,
            mqtt,
        };
        let report = block_on(2, chassisd::bench::mqtt::run(options))?;
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
    ros1: bool,
) -> anyhow::Result<bool> {
    let brokers = bench_brokers(choice);
    if brokers.contains(&Broker::Mosquitto)
        && let Some(why) = Mosquitto::missing()
    {
        anyhow::bail!(why);
    }
    if ros1 && !cfg!(feature = "ros1") {
        anyhow::bail!("this build has no ROS1 node (feature ros1): pass --without-ros1");
    }
    if ros1 && let Some(why) = chassisd::bench::rosmaster::Rosmaster::missing() {
        anyhow::bail!("{why}; or pass --without-ros1");
    }
    let options = SoakOptions {
        plant: load_plant(plant)?,
        mqtt: sim_mqtt(None)?,
        run_for: total / brokers.len() as u32,
        brokers,
        ros1,
    };
    let report = block_on(2, chassisd::bench::soak::run(options))??;
    for run in &report.runs {
        print!("{}", run.table());
    }
    println!("{}", report.json());
    Ok(report.pass)
}

/// A new folder of this run's own under the system's temporary folder.
fn tempfile_dir(name: &str) -> anyhow::Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(dir)
}

/// Parses a positive number of minutes (up to a week).
pub fn minutes_arg(s: &str) -> Result<Duration, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v <= 7.0 * 24.0 * 60.0 => Ok(Duration::from_secs_f64(v * 60.0)),
        _ => Err(format!(
            "{s:?}: give a positive number of minutes, at most a week"
        )),
    }
}

/// Parses an `/odom` rate: 1 to 100 Hz.
#[cfg(feature = "ros2")]
fn odom_rate_arg(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (1.0..=100.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: give a rate from 1 to 100 Hz")),
    }
}

/// Parses a receiver rate: 0.1 to 50 Hz.
pub fn gnss_rate_arg(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.1..=50.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: give a rate from 0.1 to 50 Hz")),
    }
}

/// The daemon's binary, `chassisd`, beside this one: the replay benchmark times its
/// `replay` as a user runs it.
fn daemon_binary() -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe().context("finding this program")?;
    let daemon = exe.with_file_name("chassisd");
    anyhow::ensure!(
        daemon.is_file(),
        "no chassisd beside {}: build both with `cargo build --release`",
        exe.display()
    );
    Ok(daemon)
}
