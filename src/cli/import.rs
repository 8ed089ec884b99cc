//! `chassisd import`.

use std::path::PathBuf;

use anyhow::Context;

use chassisd::interchange::import::{self, ImportSettings};

/// Turn a ROS bag (ROS1, or ROS 2 in MCAP) holding a receiver's fixes
/// (sensor_msgs/NavSatFix), an IMU (sensor_msgs/Imu) and wheel odometry (nav_msgs/Odometry)
/// into a chassisd recording: the frames a real receiver, IMU and pair of CiA 402 drives
/// would have sent for the same motion, so `chassisd replay OUT` runs the vehicle's own data
/// through chassisd's fusion. A topic is found by its type when the bag holds one of it;
/// every choice is printed. See docs/foxglove.md.
#[derive(clap::Args)]
pub struct Args {
    /// The bag: a ROS1 .bag, a ROS 2 .mcap, or a rosbag2 folder holding one .mcap.
    bag: PathBuf,
    /// The new recording folder.
    #[arg(long)]
    out: PathBuf,
    /// A TOML file with the settings below (fix_topic, imu_topic, odometry_topic,
    /// velocity_topic, odometry_track_m, track_m, wheel_radius_m, antenna_m = [x, y],
    /// imu_rpy_deg = [roll, pitch, yaw], imu_rate_hz, gnss_latency_s); the command line's
    /// options take precedence.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// The receiver's sensor_msgs/NavSatFix topic.
    #[arg(long)]
    fix_topic: Option<String>,
    /// The sensor_msgs/Imu topic.
    #[arg(long)]
    imu_topic: Option<String>,
    /// The wheels' nav_msgs/Odometry topic.
    #[arg(long)]
    odometry_topic: Option<String>,
    /// The receiver's velocity (TwistWithCovarianceStamped or TwistStamped, x east, y north).
    #[arg(long)]
    velocity_topic: Option<String>,
    /// The track the odometry's yaw rate was computed over, m.
    #[arg(long)]
    odometry_track_m: Option<f64>,
    /// The track chassisd's configuration gets, m (the odometry's unless given).
    #[arg(long)]
    track_m: Option<f64>,
    /// The wheel radius, m.
    #[arg(long)]
    wheel_radius_m: Option<f64>,
    /// The GNSS antenna in base_link, X,Y (forward, left), m.
    #[arg(
        long,
        value_name = "X,Y",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    antenna_m: Option<Vec<f64>>,
    /// The IMU's orientation in base_link, ROLL,PITCH,YAW in degrees.
    #[arg(
        long,
        value_name = "R,P,Y",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    imu_rpy_deg: Option<Vec<f64>>,
    /// The IMU's rate, Hz (the bag's median interval unless given).
    #[arg(long)]
    imu_rate_hz: Option<f64>,
    /// The receiver's latency, s.
    #[arg(long)]
    gnss_latency_s: Option<f64>,
}

pub fn execute(a: Args) -> anyhow::Result<bool> {
    anyhow::ensure!(
        !a.out.exists(),
        "{} exists; import writes a new recording folder",
        a.out.display()
    );
    let from_file = match &a.config {
        Some(path) => ImportSettings::load(path)?,
        None => ImportSettings::default(),
    };
    let settings = from_file.overridden_by(ImportSettings {
        fix_topic: a.fix_topic,
        imu_topic: a.imu_topic,
        odometry_topic: a.odometry_topic,
        velocity_topic: a.velocity_topic,
        odometry_track_m: a.odometry_track_m,
        track_m: a.track_m,
        wheel_radius_m: a.wheel_radius_m,
        antenna_m: a.antenna_m.map(|v| numbers("--antenna-m", v)).transpose()?,
        imu_rpy_deg: a
            .imu_rpy_deg
            .map(|v| numbers("--imu-rpy-deg", v))
            .transpose()?,
        imu_rate_hz: a.imu_rate_hz,
        gnss_latency_s: a.gnss_latency_s,
    });
    let report = import::import(&a.bag, &a.out, &settings)
        .with_context(|| format!("import of {}", a.bag.display()))?;
    for choice in &report.choices {
        eprintln!("import: {choice}");
    }
    for (topic, (n, why)) in &report.undecoded {
        eprintln!("import: {topic}: {n} messages did not decode (the first: {why})");
    }
    eprintln!(
        "import: {} fixes written ({} without a fix left out), {:.1} s, into {}; replay it with \
         chassisd replay {}",
        report.fixes.0,
        report.fixes.1,
        report.span_s,
        a.out.display(),
        a.out.display()
    );
    Ok(true)
}

/// Exactly `N` numbers of an option.
fn numbers<const N: usize>(option: &str, values: Vec<f64>) -> anyhow::Result<[f64; N]> {
    <[f64; N]>::try_from(values).map_err(|v| {
        anyhow::anyhow!(
            "{option} takes {N} numbers separated by commas, not {}",
            v.len()
        )
    })
}
