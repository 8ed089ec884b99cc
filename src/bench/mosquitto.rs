//! A mosquitto broker that a benchmark starts on a free local port, restarts on demand and
//! stops when dropped. It sets TCP_NODELAY, as a deployment should (see docs/development.md).

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::bench::error::{BenchError, invalid};

/// How long mosquitto may take to accept connections.
const READY_WITHIN: Duration = Duration::from_secs(5);

/// A mosquitto child process.
pub struct Mosquitto {
    child: Option<Child>,
    port: u16,
    conf: PathBuf,
}

impl Mosquitto {
    /// Why mosquitto cannot run here, if it cannot.
    pub fn missing() -> Option<String> {
        super::missing_program("mosquitto", "-h", "mosquitto")
    }

    /// Starts mosquitto on a free port with its configuration in `dir`, and waits until it
    /// accepts connections.
    pub fn start(dir: &Path) -> crate::bench::error::Result<Self> {
        let port = super::free_local_port()?;
        let conf = dir.join(format!("mosquitto-{port}.conf"));
        std::fs::write(
            &conf,
            format!(
                "listener {port} 127.0.0.1\nallow_anonymous true\nset_tcp_nodelay true\npersistence false\n"
            ),
        )
        .map_err(invalid(format!("writing {}", conf.display())))?;
        let mut broker = Self {
            child: None,
            port,
            conf,
        };
        broker.restart()?;
        Ok(broker)
    }

    /// Its port on 127.0.0.1.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// Its process id while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
    }

    /// Whether it is running.
    pub fn is_running(&self) -> bool {
        self.child.is_some()
    }

    /// Kills it (the clients see the connection drop).
    pub fn stop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Starts it again on the same port (stopping it first if it runs), and waits until
    /// it accepts connections.
    pub fn restart(&mut self) -> crate::bench::error::Result<()> {
        self.stop();
        let child = Command::new("mosquitto")
            .arg("-c")
            .arg(&self.conf)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(invalid("starting mosquitto"))?;
        self.child = Some(child);
        let deadline = Instant::now() + READY_WITHIN;
        while TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            let exited = self
                .child
                .as_mut()
                .and_then(|c| c.try_wait().ok().flatten());
            if let Some(status) = exited {
                self.child = None;
                return Err(BenchError::Failed(format!(
                    "mosquitto exited ({status}) instead of listening on {}",
                    self.port
                )));
            }
            if Instant::now() > deadline {
                self.stop();
                return Err(BenchError::Failed(format!(
                    "mosquitto did not listen on {} within {READY_WITHIN:?}",
                    self.port
                )));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        Ok(())
    }
}

impl Drop for Mosquitto {
    fn drop(&mut self) {
        self.stop();
        let _ = std::fs::remove_file(&self.conf);
    }
}
