//! The broker nodes a fleet runs on: independent mosquitto brokers, a RabbitMQ cluster the
//! bench starts, or brokers the user names.

use std::process::Command;

use crate::bench::error::{BenchError, Result, invalid};
use crate::bench::mosquitto::Mosquitto;
use crate::bench::rabbitmq::RabbitCluster;

/// The broker nodes a fleet runs on.
pub trait Nodes: Send {
    /// How many.
    fn count(&self) -> usize;
    /// Node `i`'s address for MQTT clients.
    fn address(&self, i: usize) -> (String, u16);
    /// Whether the nodes form one cluster (a message published on one reaches subscribers
    /// on all) rather than independent brokers.
    fn clustered(&self) -> bool;
    /// Kills node `i` (its clients see their connections drop).
    fn stop(&mut self, i: usize) -> Result<()>;
    /// Starts node `i` again.
    fn start(&mut self, i: usize) -> Result<()>;
    /// The CPU time node `i`'s processes have used, s, where it can be read.
    fn cpu_seconds(&self, i: usize) -> Option<f64>;
}

/// Independent mosquitto brokers on loopback.
pub struct MosquittoNodes {
    nodes: Vec<Mosquitto>,
}

impl MosquittoNodes {
    /// Starts `count` brokers, their files in `dir`.
    pub fn start(count: usize, dir: &std::path::Path) -> Result<Self> {
        let nodes = (0..count)
            .map(|_| Mosquitto::start(dir))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { nodes })
    }
}

impl Nodes for MosquittoNodes {
    fn count(&self) -> usize {
        self.nodes.len()
    }
    fn address(&self, i: usize) -> (String, u16) {
        ("127.0.0.1".into(), self.nodes[i].port())
    }
    fn clustered(&self) -> bool {
        false
    }
    fn stop(&mut self, i: usize) -> Result<()> {
        self.nodes[i].stop();
        Ok(())
    }
    fn start(&mut self, i: usize) -> Result<()> {
        self.nodes[i].restart()
    }
    fn cpu_seconds(&self, i: usize) -> Option<f64> {
        crate::runtime::host::process_cpu_seconds(self.nodes[i].pid()?)
    }
}

/// A RabbitMQ cluster on loopback, with its MQTT plugin.
pub struct RabbitNodes {
    cluster: RabbitCluster,
}

impl RabbitNodes {
    /// Starts a cluster of `count` nodes, its files in `dir`.
    pub fn start(count: usize, dir: &std::path::Path) -> Result<Self> {
        Ok(Self {
            cluster: RabbitCluster::start(count, dir)?,
        })
    }
}

impl Nodes for RabbitNodes {
    fn count(&self) -> usize {
        self.cluster.count()
    }
    fn address(&self, i: usize) -> (String, u16) {
        ("127.0.0.1".into(), self.cluster.mqtt_port(i))
    }
    fn clustered(&self) -> bool {
        true
    }
    fn stop(&mut self, i: usize) -> Result<()> {
        self.cluster.stop(i);
        Ok(())
    }
    fn start(&mut self, i: usize) -> Result<()> {
        self.cluster.restart(i)
    }
    fn cpu_seconds(&self, i: usize) -> Option<f64> {
        crate::runtime::host::process_cpu_seconds(self.cluster.vm_pid(i)?)
    }
}

/// Brokers the user names (`host:port`), stopped and started by commands the user gives.
pub struct NamedNodes {
    addresses: Vec<(String, u16)>,
    clustered: bool,
    /// The shell commands that stop and start a node: `$CHASSISD_NODE` is its
    /// `host:port`, `$CHASSISD_NODE_INDEX` its place in the list.
    stop_start: Option<(String, String)>,
}

impl NamedNodes {
    /// `brokers` as `host:port`; `stop_start` the commands that kill a node and start it.
    pub fn new(
        brokers: &[String],
        clustered: bool,
        stop_start: Option<(String, String)>,
    ) -> Result<Self> {
        let addresses = brokers
            .iter()
            .map(|b| {
                crate::config::mqtt::link::parse_broker(b)
                    .map(|a| (a.host, a.port))
                    .map_err(|e| BenchError::Failed(format!("--broker {b}: {e}")))
            })
            .collect::<Result<Vec<_>>>()?;
        if addresses.is_empty() {
            return Err(BenchError::Failed("--broker names no broker".into()));
        }
        Ok(Self {
            addresses,
            clustered,
            stop_start,
        })
    }

    fn run(&self, i: usize, command: &str) -> Result<()> {
        let (host, port) = &self.addresses[i];
        let status = Command::new("sh")
            .args(["-c", command])
            .env("CHASSISD_NODE", format!("{host}:{port}"))
            .env("CHASSISD_NODE_INDEX", i.to_string())
            .status()
            .map_err(invalid(format!("running `{command}`")))?;
        if status.success() {
            return Ok(());
        }
        Err(BenchError::Failed(format!(
            "`{command}` for node {i}: {status}"
        )))
    }
}

impl Nodes for NamedNodes {
    fn count(&self) -> usize {
        self.addresses.len()
    }
    fn address(&self, i: usize) -> (String, u16) {
        self.addresses[i].clone()
    }
    fn clustered(&self) -> bool {
        self.clustered
    }
    fn stop(&mut self, i: usize) -> Result<()> {
        match &self.stop_start {
            Some((stop, _)) => self.run(i, stop),
            None => Err(BenchError::Failed(
                "no command to stop a named broker was given".into(),
            )),
        }
    }
    fn start(&mut self, i: usize) -> Result<()> {
        match &self.stop_start {
            Some((_, start)) => self.run(i, start),
            None => Ok(()),
        }
    }
    fn cpu_seconds(&self, _i: usize) -> Option<f64> {
        None
    }
}
