//! A RabbitMQ cluster with its MQTT plugin that a benchmark starts on loopback, one node of
//! which it kills and starts again: the clustered broker of `bench fleet --rabbitmq`.
//!
//! Each node is Debian's `rabbitmq-server` run as the current user from its library folder
//! (the `/usr/sbin` wrapper would switch to the system's `rabbitmq` user and its files), with
//! its own configuration, data and ports, a cookie of this run's, and Erlang distribution
//! and epmd held to 127.0.0.1 on ports of their own: nothing of the system's broker is used,
//! and nothing listens beyond loopback.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::bench::error::{BenchError, Result, invalid};

/// Where Debian installs the server's own scripts.
const SCRIPTS: &str = "/usr/lib/rabbitmq/bin";
/// How long a node may take to boot and take MQTT connections (some 12 s here, alone).
const READY_WITHIN: Duration = Duration::from_secs(90);
/// Erlang distribution held to loopback, for the nodes and for `rabbitmqctl`.
const LOOPBACK_DIST: &str = "-kernel inet_dist_use_interface {127,0,0,1}";

/// One node's ports on 127.0.0.1.
#[derive(Debug, Clone, Copy)]
struct Ports {
    amqp: u16,
    mqtt: u16,
    dist: u16,
}

/// A cluster of `rabbitmq-server` nodes on loopback.
pub struct RabbitCluster {
    dir: PathBuf,
    epmd: Child,
    epmd_port: u16,
    ports: Vec<Ports>,
    nodes: Vec<Option<Child>>,
}

impl RabbitCluster {
    /// Why the cluster cannot run here, if it cannot.
    pub fn missing() -> Option<String> {
        let server = Path::new(SCRIPTS).join("rabbitmq-server");
        if !server.exists() {
            return Some(format!(
                "{} is missing (Debian: rabbitmq-server)",
                server.display()
            ));
        }
        super::missing_program("epmd", "-help", "erlang-base")
    }

    /// Starts `count` nodes with their files in a fresh folder `rabbitmq` of `dir`, joins
    /// them into one cluster, and waits until every node takes MQTT connections.
    pub fn start(count: usize, dir: &Path) -> Result<Self> {
        if count == 0 {
            return Err(BenchError::Failed("a cluster needs a node".into()));
        }
        // A folder left by an earlier run would hold another cluster's data and cookie.
        let dir = dir.join("rabbitmq");
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(invalid("clearing an old cluster's files"))?;
        }
        let home = dir.join("home");
        std::fs::create_dir_all(&home).map_err(invalid("creating the cluster's home"))?;
        write_cookie(&home.join(".erlang.cookie"))?;
        let ports = (0..count)
            .map(|_| {
                Ok(Ports {
                    amqp: super::free_local_port()?,
                    mqtt: super::free_local_port()?,
                    dist: super::free_local_port()?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        // Last: nothing after it can fail before the cluster owns it and stops it on drop.
        let epmd_port = super::free_local_port()?;
        let epmd = Command::new("epmd")
            .args(["-address", "127.0.0.1", "-port", &epmd_port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(invalid("starting epmd"))?;
        let mut cluster = Self {
            dir,
            epmd,
            epmd_port,
            ports,
            nodes: (0..count).map(|_| None).collect(),
        };
        for i in 0..count {
            cluster.write_node_files(i)?;
            cluster.spawn(i)?;
        }
        for i in 0..count {
            cluster.wait_ready(i)?;
        }
        for i in 1..count {
            let node = cluster.node_name(i);
            for args in [
                vec!["-n", &node, "stop_app"],
                vec!["-n", &node, "join_cluster", &cluster.node_name(0)],
                vec!["-n", &node, "start_app"],
            ] {
                cluster.ctl(&args)?;
            }
        }
        for i in 1..count {
            cluster.wait_ready(i)?;
        }
        Ok(cluster)
    }

    /// How many nodes.
    pub fn count(&self) -> usize {
        self.ports.len()
    }

    /// Node `i`'s MQTT port on 127.0.0.1.
    pub fn mqtt_port(&self, i: usize) -> u16 {
        self.ports[i].mqtt
    }

    /// Node `i`'s Erlang VM's process id while it runs (the server script's child, which
    /// writes it to the node's pid file).
    pub fn vm_pid(&self, i: usize) -> Option<u32> {
        self.nodes[i].as_ref()?;
        std::fs::read_to_string(self.node_dir(i).join("pid"))
            .ok()?
            .trim()
            .parse()
            .ok()
    }

    /// Kills node `i` and everything it started (its clients see their connections drop).
    pub fn stop(&mut self, i: usize) {
        if let Some(mut child) = self.nodes[i].take() {
            // The server script runs the Erlang VM as its child: the whole group goes.
            // SAFETY: a plain signal to the process group this node leads.
            unsafe { libc::kill(-(child.id() as libc::pid_t), libc::SIGKILL) };
            let _ = child.wait();
        }
    }

    /// Starts node `i` again (it rejoins the cluster from its data) and waits until it
    /// takes MQTT connections.
    pub fn restart(&mut self, i: usize) -> Result<()> {
        self.stop(i);
        self.spawn(i)?;
        self.wait_ready(i)
    }

    fn node_name(&self, i: usize) -> String {
        format!("rabbit{i}@localhost")
    }

    fn node_dir(&self, i: usize) -> PathBuf {
        self.dir.join(format!("node{i}"))
    }

    fn write_node_files(&self, i: usize) -> Result<()> {
        let dir = self.node_dir(i);
        std::fs::create_dir_all(&dir).map_err(invalid("creating a node's folder"))?;
        let p = self.ports[i];
        let conf = format!(
            "listeners.tcp.default = 127.0.0.1:{}\n\
             mqtt.listeners.tcp.default = 127.0.0.1:{}\n\
             mqtt.allow_anonymous = true\n\
             loopback_users = none\n\
             log.console = false\n",
            p.amqp, p.mqtt
        );
        std::fs::write(dir.join("rabbitmq.conf"), conf)
            .map_err(invalid("writing a node's configuration"))?;
        std::fs::write(dir.join("enabled_plugins"), "[rabbitmq_mqtt].\n")
            .map_err(invalid("writing a node's plugins"))
    }

    /// The environment every RabbitMQ program of this cluster runs in.
    fn environment(&self, cmd: &mut Command) {
        cmd.env("HOME", self.dir.join("home"))
            .env("RABBITMQ_CONF_ENV_FILE", "/dev/null")
            .env("ERL_EPMD_ADDRESS", "127.0.0.1")
            .env("ERL_EPMD_PORT", self.epmd_port.to_string())
            .env("RABBITMQ_CTL_ERL_ARGS", LOOPBACK_DIST);
    }

    fn spawn(&mut self, i: usize) -> Result<()> {
        let dir = self.node_dir(i);
        let p = self.ports[i];
        let mut cmd = Command::new(Path::new(SCRIPTS).join("rabbitmq-server"));
        self.environment(&mut cmd);
        cmd.env("RABBITMQ_NODENAME", self.node_name(i))
            .env("RABBITMQ_NODE_IP_ADDRESS", "127.0.0.1")
            .env("RABBITMQ_NODE_PORT", p.amqp.to_string())
            .env("RABBITMQ_DIST_PORT", p.dist.to_string())
            .env("RABBITMQ_CONFIG_FILE", dir.join("rabbitmq.conf"))
            .env("RABBITMQ_ENABLED_PLUGINS_FILE", dir.join("enabled_plugins"))
            .env("RABBITMQ_MNESIA_BASE", dir.join("mnesia"))
            .env("RABBITMQ_LOG_BASE", dir.join("log"))
            .env("RABBITMQ_PID_FILE", dir.join("pid"))
            .env("RABBITMQ_SERVER_ADDITIONAL_ERL_ARGS", LOOPBACK_DIST)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .process_group(0);
        let child = cmd.spawn().map_err(invalid("starting rabbitmq-server"))?;
        self.nodes[i] = Some(child);
        Ok(())
    }

    fn wait_ready(&mut self, i: usize) -> Result<()> {
        let deadline = Instant::now() + READY_WITHIN;
        let port = self.ports[i].mqtt;
        while !mqtt_accepts(port) {
            let exited = self.nodes[i]
                .as_mut()
                .and_then(|c| c.try_wait().ok().flatten());
            if let Some(status) = exited {
                self.nodes[i] = None;
                return Err(BenchError::Failed(format!(
                    "rabbitmq node {i} exited ({status}) before taking MQTT connections; \
                     its log is in {}",
                    self.node_dir(i).join("log").display()
                )));
            }
            if Instant::now() > deadline {
                return Err(BenchError::Failed(format!(
                    "rabbitmq node {i} took no MQTT connection on {port} within {READY_WITHIN:?}"
                )));
            }
            std::thread::sleep(Duration::from_millis(250));
        }
        Ok(())
    }

    /// Runs `rabbitmqctl` with `args` against this cluster.
    fn ctl(&self, args: &[&str]) -> Result<()> {
        let mut cmd = Command::new(Path::new(SCRIPTS).join("rabbitmqctl"));
        self.environment(&mut cmd);
        let out = cmd
            .args(args)
            .stdin(Stdio::null())
            .output()
            .map_err(invalid("running rabbitmqctl"))?;
        if out.status.success() {
            return Ok(());
        }
        Err(BenchError::Failed(format!(
            "rabbitmqctl {}: {}{}",
            args.join(" "),
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )))
    }
}

impl Drop for RabbitCluster {
    fn drop(&mut self) {
        for i in 0..self.nodes.len() {
            self.stop(i);
        }
        let _ = self.epmd.kill();
        let _ = self.epmd.wait();
    }
}

/// A cookie only this run knows, readable by its owner alone (Erlang refuses any other).
fn write_cookie(path: &Path) -> Result<()> {
    use std::os::unix::fs::OpenOptionsExt;
    let cookie = format!(
        "{:016X}{:016X}",
        crate::secret::unguessable(),
        crate::secret::unguessable()
    );
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o400)
        .open(path)
        .and_then(|mut f| f.write_all(cookie.as_bytes()))
        .map_err(invalid("writing the cluster's cookie"))
}

/// Whether an MQTT 3.1.1 broker on 127.0.0.1:`port` accepts a clean session now (a node
/// listens before its plugin can register clients, and refuses them without a majority).
fn mqtt_accepts(port: u16) -> bool {
    const ID: &[u8] = b"chassisd-bench-probe";
    let mut connect = vec![0x10, 12 + ID.len() as u8];
    connect.extend_from_slice(&[0, 4, b'M', b'Q', b'T', b'T', 4, 0x02, 0, 10]);
    connect.extend_from_slice(&[0, ID.len() as u8]);
    connect.extend_from_slice(ID);
    let Ok(mut stream) = TcpStream::connect_timeout(
        &std::net::SocketAddr::from(([127, 0, 0, 1], port)),
        Duration::from_secs(2),
    ) else {
        return false;
    };
    let _ = stream.set_read_timeout(Some(Duration::from_secs(5)));
    let mut ack = [0u8; 4];
    let accepted = stream.write_all(&connect).is_ok()
        && stream.read_exact(&mut ack).is_ok()
        && ack == [0x20, 0x02, 0x00, 0x00];
    // DISCONNECT, so the probe leaves no session behind.
    let _ = stream.write_all(&[0xe0, 0x00]);
    accepted
}
