//! A rosmaster that the soak starts on a free local port for the ROS1 node (and its
//! attacker) to meet at, killed when dropped.

use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::bench::error::{BenchError, invalid};

/// How long rosmaster (Python) may take to accept connections.
const READY_WITHIN: Duration = Duration::from_secs(20);

/// A rosmaster child process.
pub struct Rosmaster {
    child: Child,
    port: u16,
}

impl Rosmaster {
    /// Why rosmaster cannot run here, if it cannot.
    pub fn missing() -> Option<String> {
        super::missing_program("rosmaster", "--help", "ros-core")
    }

    /// Starts it on a free port of 127.0.0.1 and waits until it accepts connections.
    pub fn start() -> crate::bench::error::Result<Self> {
        let port = super::free_local_port()?;
        let child = Command::new("rosmaster")
            .args(["--core", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(invalid("starting rosmaster"))?;
        let mut master = Self { child, port };
        let deadline = Instant::now() + READY_WITHIN;
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            if let Ok(Some(status)) = master.child.try_wait() {
                return Err(BenchError::Failed(format!(
                    "rosmaster exited ({status}) instead of listening on {port}"
                )));
            }
            if Instant::now() > deadline {
                master.stop();
                return Err(BenchError::Failed(format!(
                    "rosmaster did not listen on {port} within {READY_WITHIN:?}"
                )));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        Ok(master)
    }

    /// Its URI, as `ROS_MASTER_URI` gives it.
    pub fn uri(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Rosmaster {
    fn drop(&mut self) {
        self.stop();
    }
}
