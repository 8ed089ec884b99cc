//! An in-process CAN bus for sans-IO tests: drive nodes and simulated devices exchange
//! frames in time steps of 1 ms, with chassisd's nodes polled every 10 ms.

use chassisd::devices::can::Frame;
use chassisd::devices::canopen::NodeId;
use chassisd::devices::canopen::nmt::{NmtState, heartbeat_frame};
use chassisd::devices::cia402::DriveProfile;
use chassisd::devices::cia402::node::{DriveNode, NodeSettings};
use chassisd::devices::cia402::state::Goal;
use chassisd::sim::cia402_drive::{MotorModel, SimDrive};
use chassisd::time::Timestamp;
use std::path::Path;
use std::time::Duration;

/// A shipped profile from `devices/`.
pub fn profile(name: &str) -> DriveProfile {
    profile_edited(name, |text| text)
}

/// A shipped profile from `devices/`, its text changed by `edit` first.
pub fn profile_edited(name: &str, edit: impl FnOnce(String) -> String) -> DriveProfile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("devices")
        .join(name);
    let text = edit(std::fs::read_to_string(&path).expect("profile file"));
    DriveProfile::from_toml(&text, &path).expect("valid profile")
}

/// Settings used by the tests.
pub fn settings(node: u8) -> NodeSettings {
    NodeSettings {
        node: NodeId::new(node).expect("node id"),
        heartbeat_producer_ms: 100,
        heartbeat_timeout: Duration::from_millis(350),
        sdo_timeout: Duration::from_millis(50),
        sdo_retries: 2,
        boot_timeout: Duration::from_millis(1000),
        enable_timeout: Duration::from_millis(1000),
        feedback_timeout: Duration::from_millis(250),
        reset_attempts: 3,
        reset_wait: Duration::from_millis(200),
        master_node: MASTER,
        master_timeout: Duration::from_millis(250),
        sync_period: Duration::from_millis(20),
    }
}

/// chassisd's node id in the rig, whose heartbeat the drive consumes.
pub const MASTER: NodeId = match NodeId::new(0x7F) {
    Some(n) => n,
    None => panic!("0x7F is a node id"),
};
/// chassisd's heartbeat period in the rig, ms.
pub const MASTER_HEARTBEAT_MS: u64 = 50;

/// Milliseconds as a timestamp.
pub fn ms(v: u64) -> Timestamp {
    Timestamp::from_micros(v * 1_000)
}

/// One chassisd node and one simulated drive on a bus.
pub struct Rig {
    pub node: DriveNode,
    pub sim: SimDrive,
    pub now_ms: u64,
    /// Every frame, with who sent it (true: chassisd).
    pub log: Vec<(u64, bool, Frame)>,
    pub link_up: bool,
    /// chassisd produces its heartbeat (as the drive train does); false: chassisd is gone.
    pub master_alive: bool,
    /// chassisd also produces SYNC with this period, ms (for drives that watch SYNC).
    pub sync_ms: Option<u64>,
}

impl Rig {
    pub fn new(profile_name: &str, node: u8) -> Rig {
        Rig::with_profile(profile(profile_name), node)
    }

    /// A rig around a drive with profile `p`.
    pub fn with_profile(p: DriveProfile, node: u8) -> Rig {
        Rig {
            node: DriveNode::new(settings(node), p.clone()),
            sim: SimDrive::new(NodeId::new(node).unwrap(), p, MotorModel::default()),
            now_ms: 0,
            log: Vec::new(),
            link_up: true,
            master_alive: true,
            sync_ms: None,
        }
    }

    /// Starts chassisd's node and runs for `duration_ms`, commanding `(enable, rpm)` at each
    /// control tick.
    pub fn start(&mut self) {
        let mut out = Vec::new();
        self.node.start(ms(self.now_ms), &mut out);
        self.deliver(Vec::new(), out);
    }

    pub fn run(&mut self, duration_ms: u64, enable: bool, rpm: &[f64]) {
        let goal = if enable { Goal::Enabled } else { Goal::Standby };
        self.run_towards(duration_ms, goal, rpm);
    }

    /// Runs for `duration_ms`, commanding `(goal, rpm)` at each control tick.
    pub fn run_towards(&mut self, duration_ms: u64, goal: Goal, rpm: &[f64]) {
        for _ in 0..duration_ms {
            self.now_ms += 1;
            let t = ms(self.now_ms);
            let mut from_sim = Vec::new();
            self.sim.step(t, &mut from_sim);
            let mut from_node = Vec::new();
            if !self.master_alive {
                self.deliver(from_sim, Vec::new());
                continue;
            }
            if self.now_ms.is_multiple_of(MASTER_HEARTBEAT_MS) {
                from_node.push(heartbeat_frame(MASTER, NmtState::Operational));
            }
            if self.sync_ms.is_some_and(|p| self.now_ms.is_multiple_of(p)) {
                from_node.push(Frame::std(0x080, []));
            }
            if self.now_ms.is_multiple_of(10) {
                self.node.command(t, goal, rpm);
                self.node.poll(t, &mut from_node);
            }
            self.deliver(from_sim, from_node);
        }
    }

    /// Delivers frames both ways until the bus is quiet (responses cause more frames).
    pub fn deliver(&mut self, mut from_sim: Vec<Frame>, mut from_node: Vec<Frame>) {
        let t = ms(self.now_ms);
        while !from_sim.is_empty() || !from_node.is_empty() {
            let (sim_frames, node_frames) = (
                std::mem::take(&mut from_sim),
                std::mem::take(&mut from_node),
            );
            for f in sim_frames {
                self.log.push((self.now_ms, false, f));
                if self.link_up {
                    self.node.on_frame(t, &f, &mut from_node);
                }
            }
            for f in node_frames {
                self.log.push((self.now_ms, true, f));
                if self.link_up {
                    self.sim.on_frame(t, &f, &mut from_sim);
                }
            }
        }
    }

    /// Frames chassisd's node sent (not its heartbeat or SYNC), as candump text.
    pub fn sent(&self) -> Vec<String> {
        let heartbeat = 0x700 + u32::from(MASTER.get());
        self.log
            .iter()
            .filter(|(_, mine, f)| *mine && f.id() != heartbeat && f.id() != 0x080)
            .map(|(_, _, f)| f.to_string())
            .collect()
    }
}
