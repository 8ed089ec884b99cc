//! The ROS1 node's own process (`chassisd ros1-child`, started by chassisd, never by hand).
//! Everything a ROS peer reaches runs here: roslibrust's listeners, its TCPROS connections
//! and its XML-RPC server. roslibrust trusts the lengths a peer announces and holds what it
//! is sent, and a peer may open connections without end; in here that costs this process
//! at most its limits ([`MEMORY_LIMIT`], [`DESCRIPTOR_LIMIT`]), at a lower scheduling
//! priority than the control loop's. Past a limit the process ends, and chassisd starts a
//! new one, which registers again.
//!
//! Settings arrive as one JSON line on standard input; [`super::pipe`] says what follows
//! each way. Standard input's end means chassisd is gone, and so is this process.

use std::io::BufRead;
use std::time::{Duration, Instant};

use tokio::sync::mpsc;

use super::graph::{self, Registration, Requests};
use super::pipe::{FromNode, MAX_LINE, NodeSettings, ToNode};
use crate::runtime::child_process;
use crate::runtime::error::{RuntimeError, invalid, io};
use crate::runtime::links::child_pipes::{read_from_parent, write_to_parent};
use crate::runtime::outage_log::{OutageLog, Say};

/// The process's address space: roslibrust and its runtime need some 100 MB of it; a
/// peer's announced length beyond what is left fails its allocation and ends the process.
pub const MEMORY_LIMIT: u64 = 384 << 20;
/// Descriptors the process may open: a few dozen for the node's listeners and the master,
/// the rest for peers' connections, each a socket.
pub const DESCRIPTOR_LIMIT: u64 = 256;
/// Descriptors left that count as run out.
const DESCRIPTORS_SPARE: usize = 8;
/// How often the descriptors are counted.
const DESCRIPTORS_EVERY: Duration = Duration::from_millis(500);
/// Counts in a row at the limit before the process ends.
const DESCRIPTORS_STRIKES: u32 = 3;
/// Exit status when peers' connections took every descriptor.
pub const EXIT_DESCRIPTORS: i32 = 76;
/// The process's niceness: under load, the control loop's process runs first.
const NICENESS: libc::c_int = 5;
/// The runtime's worker threads: roslibrust's node actor, its listeners and connections.
const WORKER_THREADS: usize = 2;
/// Threads for service calls waiting on the vehicle's answer (each waits at most 2 s).
const BLOCKING_THREADS: usize = 16;
/// Requests waiting to go up before more are refused as a full queue.
const UP_QUEUE: usize = 256;
/// The longest wait between connection attempts.
const RETRY_MAX: Duration = Duration::from_secs(5);
/// The longest settings line read.
const MAX_SETTINGS: u64 = 64 << 10;

/// The process's whole life; returns only on error (its end is an exit).
pub fn main() -> Result<(), RuntimeError> {
    // A panic in roslibrust (it panics on some peers' resets) may leave a topic without its
    // listener: end the process, so chassisd starts a whole one.
    crate::runtime::child_process::end_on_panic("ROS1 node");
    let mut line = String::new();
    std::io::Read::take(std::io::stdin().lock(), MAX_SETTINGS)
        .read_line(&mut line)
        .map_err(io("reading the ROS1 node's settings"))?;
    let settings: NodeSettings = serde_json::from_str(&line)
        .map_err(invalid("the ROS1 node's settings are not valid JSON"))?;
    confine()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(WORKER_THREADS)
        .thread_name("ros1-node")
        .enable_all()
        .max_blocking_threads(BLOCKING_THREADS)
        .build()
        .map_err(io("the ROS1 node's runtime"))?;
    runtime.block_on(run(settings));
    Ok(())
}

/// Lowers the process's limits and priority for good.
fn confine() -> Result<(), RuntimeError> {
    child_process::limit(libc::RLIMIT_AS, MEMORY_LIMIT)
        .map_err(io("limiting the ROS1 node's memory"))?;
    child_process::limit(libc::RLIMIT_NOFILE, DESCRIPTOR_LIMIT)
        .map_err(io("limiting the ROS1 node's descriptors"))?;
    // SAFETY: setpriority on this process only; a failure leaves the priority as it was.
    if unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, NICENESS) } != 0 {
        tracing::debug!("ROS1 node: its priority could not be lowered");
    }
    Ok(())
}

/// Ends the process when peers' connections hold every descriptor: roslibrust then retries
/// its accept at once, without end, and logs each failure, a spin that would hold a core for
/// as long as the peers hold their connections. A new process starts without them.
async fn end_when_descriptors_run_out() {
    let mut strikes = 0;
    let mut every = tokio::time::interval(DESCRIPTORS_EVERY);
    loop {
        every.tick().await;
        // Counting needs a descriptor of its own: failing to open one is running out.
        let open = std::fs::read_dir("/proc/self/fd").map_or(usize::MAX, Iterator::count);
        if open.saturating_add(DESCRIPTORS_SPARE) < DESCRIPTOR_LIMIT as usize {
            strikes = 0;
            continue;
        }
        strikes += 1;
        if strikes >= DESCRIPTORS_STRIKES {
            crate::runtime::stderr::line(format!(
                "chassisd ROS1 node: peers' connections hold all {DESCRIPTOR_LIMIT} descriptors; the node's process ends and chassisd restarts it"
            ));
            std::process::exit(EXIT_DESCRIPTORS);
        }
    }
}

async fn run(settings: NodeSettings) {
    let (up_tx, up_rx) = mpsc::channel(UP_QUEUE);
    let (to_node_tx, mut to_node) = mpsc::channel(UP_QUEUE);
    tokio::spawn(write_to_parent(up_rx));
    tokio::spawn(end_when_descriptors_run_out());
    tokio::spawn(read_from_parent::<ToNode>(
        to_node_tx,
        MAX_LINE,
        "ROS1 node",
    ));
    let rate = (
        settings.config.command_rate_hz,
        settings.config.command_burst,
    );
    let requests = Requests::new(up_tx.clone(), rate);
    let mut outage = OutageLog::default();
    let mut outage_start: Option<Instant> = None;
    let mut retry = Duration::from_millis(250);
    let mut said_where = false;
    let mut watch = tokio::time::interval(graph::WATCH_EVERY);
    watch.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let master_uri = settings.config.master_uri.clone();
    loop {
        // Connect and register everything; meanwhile what chassisd says is taken (answers
        // reach their callers; messages wait for the registration, which brings the
        // latched ones again).
        let building = graph::build(&settings, &requests);
        tokio::pin!(building);
        let built = loop {
            tokio::select! {
                built = &mut building => break built,
                Some(message) = to_node.recv() => take(message, None, &requests).await,
            }
        };
        let graph = match built {
            Ok(graph) => graph,
            Err(e) => {
                let start = *outage_start.get_or_insert_with(Instant::now);
                match outage.failed(start.elapsed()) {
                    Say::First => {
                        tracing::warn!(master = %master_uri, error = %e, "ROS master unreachable; retrying")
                    }
                    Say::Still(attempts) => {
                        tracing::warn!(master = %master_uri, attempts, error = %e, "ROS master still unreachable")
                    }
                    Say::Quiet => tracing::debug!(error = %e, "ROS master unreachable"),
                }
                let pause = tokio::time::sleep(retry);
                tokio::pin!(pause);
                loop {
                    tokio::select! {
                        () = &mut pause => break,
                        Some(message) = to_node.recv() => take(message, None, &requests).await,
                    }
                }
                retry = (retry * 2).min(RETRY_MAX);
                continue;
            }
        };
        let uri = graph.node.get_client_uri().await.unwrap_or_default();
        graph::keep_to_advertised(&master_uri, &uri, &mut said_where).await;
        tracing::info!(
            master = %master_uri,
            node = %settings.config.node_name,
            %uri,
            "ROS1 node registered"
        );
        outage = OutageLog::default();
        outage_start = None;
        retry = Duration::from_millis(250);
        if up_tx.send(FromNode::Registered).await.is_err() {
            return;
        }
        let master = roslibrust::ros1::MasterClient::new(
            master_uri.as_str(),
            uri.as_str(),
            format!("{}_watch", settings.config.node_name),
        )
        .await
        .ok();
        let mut master_away = false;
        loop {
            tokio::select! {
                Some(message) = to_node.recv() => take(message, Some(&graph), &requests).await,
                _ = watch.tick() => {
                    match graph::still_registered(master.as_ref(), &master_uri, &settings.config.node_name, &uri).await {
                        Registration::Known => {
                            if master_away {
                                tracing::info!("ROS master back; the node is still registered");
                                master_away = false;
                            }
                        }
                        Registration::MasterAway => {
                            if !master_away {
                                tracing::warn!(master = %master_uri, "ROS master unreachable; publishing goes on to connected subscribers");
                                master_away = true;
                            }
                        }
                        Registration::Forgotten => {
                            tracing::warn!(master = %master_uri, "the ROS master does not know the node (restarted?): registering again");
                            break;
                        }
                    }
                }
            }
        }
        drop(graph);
    }
}

/// Acts on one of chassisd's messages: publishes (when registered), gives an answer to its
/// caller.
async fn take(message: ToNode, graph: Option<&graph::Graph>, requests: &Requests) {
    match message {
        ToNode::Publish { messages } => {
            if let Some(graph) = graph {
                graph.publish(messages).await;
            }
        }
        ToNode::Answer { call, result } => requests.answer(call, result),
    }
}
