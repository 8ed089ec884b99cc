//! The subcommands, one file each: its arguments (a `clap::Args` struct whose doc comment is
//! its `--help` text) and `execute`, which runs it and returns `Ok(false)` when it ran but its
//! verdict is negative (a probe failed). Errors are `anyhow` here and nowhere in the library:
//! this is where they become a message and an exit status. The benchmarks are a binary of
//! their own (`src/bin/chassisd-bench`); `chassisd bench` hands over to it.

pub mod bench;
pub mod calibrate;
pub mod can_sim;
pub mod check;
pub mod common;
pub mod export;
pub mod import;
pub mod ntrip;
pub mod record;
pub mod replay;
pub mod run;
pub mod sim;

use std::path::Path;

pub use common::{
    block_on, describe, find_scenario, load_calibration, load_plant, scenario_names, seconds_arg,
    sim_mqtt,
};

use chassisd::config::ntrip::NtripConfig;

/// Refuses a ROS1 node in a build without the `ros1` feature, saying how to get one.
pub fn ensure_ros1_built(wanted: bool) -> anyhow::Result<()> {
    anyhow::ensure!(
        !wanted || cfg!(feature = "ros1"),
        "this chassisd was built without the ros1 feature; build it with the default \
         features (cargo build --release) to join a ROS1 graph"
    );
    Ok(())
}

/// Checks a ROS 2 node's settings as it starts: a build with the `ros2` feature, an
/// interface that exists, a readable `ROS_DOMAIN_ID` (a configuration error otherwise: exit
/// 78, with the fix). `file` names where the settings came from.
pub fn ensure_ros2(
    ros2: Option<&chassisd::config::ros2::Ros2Config>,
    file: &std::path::Path,
) -> anyhow::Result<()> {
    let Some(ros2) = ros2 else {
        return Ok(());
    };
    #[cfg(feature = "ros2")]
    {
        chassisd::runtime::links::ros2::interface::resolve(ros2, file)?;
        Ok(())
    }
    #[cfg(not(feature = "ros2"))]
    {
        let _ = (ros2, file);
        anyhow::bail!(
            "this chassisd was built without the ros2 feature; build it with the default \
             features (cargo build --release) to join a ROS 2 domain"
        )
    }
}

/// `[ntrip]` with `--ntrip URL`'s caster (the rest of the section kept); a password in the
/// URL replaces a password file.
pub fn ntrip_override(configured: Option<NtripConfig>, url: &str) -> anyhow::Result<NtripConfig> {
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
