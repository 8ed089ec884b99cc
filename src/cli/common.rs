//! What both binaries' subcommands share (`chassisd` and `chassisd-bench`): the async
//! runtime, error messages, the simulated vehicle's MQTT settings, plants, scenarios and
//! seconds arguments.

use std::future::Future;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;

use chassisd::config::calibration::CalibrationFile;
use chassisd::config::mqtt::{
    DeviceDialectConfig, MqttConfig, MqttLinkConfig, RootDialectConfig, RtkDialectConfig,
};
use chassisd::sim::plant::PlantConfig;
use chassisd::sim::scenario::Scenario;

/// Runs `task` to its end on a multi-threaded tokio runtime of `threads` workers (timers and
/// I/O enabled), then shuts the runtime down without waiting: a read of standard input may
/// still be blocked in one of its threads. Every async subcommand goes through here.
pub fn block_on<T>(threads: usize, task: impl Future<Output = T>) -> anyhow::Result<T> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(threads)
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    let result = runtime.block_on(task);
    runtime.shutdown_background();
    Ok(result)
}

/// An error and its causes joined by ": ", as `{:#}` shows them, leaving out a cause whose
/// words its wrapper already said (a library error that only carries another, such as
/// `RuntimeError::Config`, keeps it as its source so the exit status can find it).
pub fn describe(error: &anyhow::Error) -> String {
    let mut said: Vec<String> = Vec::new();
    for cause in error.chain() {
        let text = cause.to_string();
        if said.last() != Some(&text) {
            said.push(text);
        }
    }
    said.join(": ")
}

/// The `{vehicleId}` of the simulated vehicle's root dialect.
const SIM_VEHICLE_ID: &str = "sim";
/// The `{serial_number}` of the simulated vehicle's device dialect.
const SIM_SERIAL_NUMBER: &str = "SIM0001";

/// The MQTT settings of the simulated vehicle (`sim`, `bench mqtt`, `bench soak`): every
/// dialect, on the broker at `external`, or on an embedded one at 127.0.0.1:1883.
pub fn sim_mqtt(external: Option<&str>) -> anyhow::Result<MqttConfig> {
    let mut config = MqttConfig {
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
        ..MqttConfig::one(MqttLinkConfig {
            embedded_broker: external.is_none(),
            ..MqttLinkConfig::default()
        })
    };
    if let Some(address) = external {
        let (host, port) = address
            .rsplit_once(':')
            .and_then(|(h, p)| Some((h, p.parse::<u16>().ok()?)))
            .with_context(|| format!("--mqtt {address:?}: expected HOST:PORT"))?;
        config.first_mut().host = host.to_owned();
        config.first_mut().port = port;
    }
    Ok(config)
}

/// The calibration file at `path`, if one is given.
pub fn load_calibration(path: Option<&Path>) -> anyhow::Result<Option<CalibrationFile>> {
    Ok(path.map(CalibrationFile::load).transpose()?)
}

/// The plant at `path`, or the built-in one.
pub fn load_plant(path: Option<PathBuf>) -> anyhow::Result<PlantConfig> {
    Ok(match path {
        Some(path) => PlantConfig::load(&path)?,
        None => PlantConfig::builtin()?,
    })
}

/// The scenarios' names, each with what it drives, for `--help` and argument checking.
pub fn scenario_names() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        Scenario::every()
            .into_iter()
            .map(|s| clap::builder::PossibleValue::new(s.name).help(s.about)),
    )
}

/// The scenario called `name`.
pub fn find_scenario(name: &str) -> anyhow::Result<Scenario> {
    Scenario::named(name).ok_or_else(|| {
        let names: Vec<&str> = Scenario::every().iter().map(|s| s.name).collect();
        anyhow::anyhow!("no scenario {name:?}; there are {}", names.join(", "))
    })
}

/// The longest span a seconds argument may give: about 31 years.
const MAX_SECONDS_ARG: f64 = 1e9;

/// Parses a positive, finite number of seconds (up to [`MAX_SECONDS_ARG`]).
pub fn seconds_arg(s: &str) -> Result<Duration, String> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use chassisd::config::ConfigError;
    use chassisd::runtime::error::RuntimeError;

    #[test]
    fn a_wrapped_configuration_error_is_said_once_and_still_found() {
        let config = ConfigError::invalid(Path::new("v.toml"), "gnss.baud", "0", "use 9600");
        let said = config.to_string();
        let e = anyhow::Error::from(RuntimeError::from(config)).context("starting the vehicle");
        assert_eq!(describe(&e), format!("starting the vehicle: {said}"));
        // main's exit status 78 looks for it among the causes.
        assert!(e.chain().any(|c| c.downcast_ref::<ConfigError>().is_some()));
    }
}
