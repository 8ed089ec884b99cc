//! Benchmarks that print figures (`chassisd bench ...`), as opposed to the criterion
//! micro-benchmarks under `benches/`.

pub mod attacks;
pub mod control;
pub mod envelope;
pub mod error;
pub mod export;
pub mod fleet;
pub mod fusion;
pub mod gnss_fit;
pub mod husky;
pub mod mosquitto;
pub mod mqtt;
pub mod rabbitmq;
pub mod real;
pub mod replay;
#[cfg(feature = "ros1")]
pub mod ros1_attack;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod rosmaster;
pub mod soak;

use std::process::{Command, Stdio};

use crate::bench::error::invalid;

use crate::config::mqtt::MqttConfig;
use mosquitto::Mosquitto;

/// A broker a benchmark runs the simulated vehicle on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Broker {
    /// The embedded rumqttd, on a free port.
    Embedded,
    /// A mosquitto the benchmark starts on a free port (and may restart).
    Mosquitto,
}

impl Broker {
    /// Its name in tables and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::Embedded => "embedded",
            Self::Mosquitto => "mosquitto",
        }
    }

    /// Points `mqtt` at this broker on 127.0.0.1, starting mosquitto if it is the one; the
    /// embedded broker starts with the simulation.
    pub fn start(self, mqtt: &mut MqttConfig) -> crate::bench::error::Result<Option<Mosquitto>> {
        let mqtt = mqtt.first_mut();
        mqtt.host = "127.0.0.1".into();
        mqtt.embedded_broker = self == Self::Embedded;
        match self {
            Self::Embedded => {
                // A port of its own, so a broker already on 1883 is no obstacle.
                mqtt.port = free_local_port()?;
                Ok(None)
            }
            Self::Mosquitto => {
                let m = Mosquitto::start(&std::env::temp_dir())?;
                mqtt.port = m.port();
                Ok(Some(m))
            }
        }
    }
}

/// A TCP port on 127.0.0.1 that nobody listens on right now.
pub fn free_local_port() -> crate::bench::error::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map_err(invalid("no free local port"))?
        .port())
}

/// Why `program` cannot run here (run once with `arg`, output discarded), naming the
/// Debian `package` that has it; `None` when it runs.
pub fn missing_program(program: &str, arg: &str, package: &str) -> Option<String> {
    Command::new(program)
        .arg(arg)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .err()
        .map(|e| format!("{program}: {e} (Debian: {package})"))
}
