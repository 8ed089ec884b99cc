//! The CAN side of the engine: each interface with its drive nodes and BMS, the mapping of
//! drive axes to wheels, unit conversion between motor and wheel, and encoder unwrapping.

use std::f64::consts::TAU;

use crate::config::VehicleConfig;
use crate::config::chassis::{Wheel, WheelConfig};
use crate::config::mission::Cutter;
use crate::devices::bms::daly::DalyBms;
use crate::devices::bms::dbc::DbcBms;
use crate::devices::bms::profile::CurrentAboveOffset;
use crate::devices::bms::{BmsDevice, BmsProfile};
use crate::devices::can::{Frame, Received};
use crate::devices::canopen::NodeId;
use crate::devices::canopen::nmt::{NmtState, heartbeat_frame};
use crate::devices::cia402::node::{DriveFault, DriveNode, NodeSettings, Phase};
use crate::devices::cia402::profile::MasterLoss;
use crate::devices::cia402::state::Goal;
use crate::devices::estop::EStopSignal;
use crate::time::Timestamp;
use crate::vehicle::chassis::{ChassisFeedback, DriveSummary, WheelCommand, WheelFeedback};
use crate::vehicle::safety::Power;
use std::time::Duration;

/// Whether an interface is usable, as its driver last said.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusLink {
    /// No report yet (replays of plain candump logs): treated as up.
    Unknown,
    /// Up.
    Up,
    /// Down.
    Down,
}

/// Counters of one interface.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct BusStats {
    /// Data frames received.
    pub rx: u64,
    /// Frames chassisd queued for transmission.
    pub tx: u64,
    /// Frames not sent because the interface is listen-only.
    pub suppressed: u64,
    /// Error frames received.
    pub error_frames: u64,
    /// The last error frame, decoded.
    pub last_error: Option<String>,
    /// Remote and CAN FD frames, which no device uses.
    pub ignored: u64,
    /// E-stop status frames too short to hold their bit.
    pub estop_malformed: u64,
}

/// Unwraps a 32-bit encoder count into a continuous one.
#[derive(Debug, Clone, Copy, Default)]
struct Unwrap {
    last: Option<i32>,
    total: i64,
}

impl Unwrap {
    fn update(&mut self, raw: i32) -> i64 {
        match self.last {
            None => self.total = i64::from(raw),
            Some(last) => self.total += i64::from(raw.wrapping_sub(last)),
        }
        self.last = Some(raw);
        self.total
    }
}

#[derive(Debug, Clone)]
struct Axis {
    wheel: Wheel,
    /// Motor revolutions per wheel revolution, signed by the wheel's direction.
    ratio: f64,
    unwrap: Unwrap,
}

#[derive(Debug, Clone)]
struct Drive {
    name: String,
    node: DriveNode,
    axes: Vec<Axis>,
    /// The blade drive's motor speed while the cutter is on, r/min (`None`: a wheel drive).
    blade_rpm: Option<f64>,
    started: bool,
}

/// The cutter's switch state, and for a switch frame when it is next repeated.
#[derive(Debug, Clone)]
struct CutterState {
    cutter: Cutter,
    on: bool,
    next_repeat: Option<Timestamp>,
}

/// What chassisd produces on a bus so that its drives notice when it is gone.
#[derive(Debug, Clone)]
struct Deadman {
    /// chassisd's heartbeat: node id, period, next due.
    heartbeat: (NodeId, Duration, Option<Timestamp>),
    /// SYNC period and next due, when a drive watches SYNC.
    sync: Option<(Duration, Option<Timestamp>)>,
}

impl Deadman {
    fn poll(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        let (node, period, next) = &mut self.heartbeat;
        if next.is_none_or(|n| t >= n) {
            out.push(heartbeat_frame(*node, NmtState::Operational));
            *next = Some(t.saturating_add(*period));
        }
        if let Some((period, next)) = &mut self.sync
            && next.is_none_or(|n| t >= n)
        {
            out.push(Frame::std(0x080, []));
            *next = Some(t.saturating_add(*period));
        }
    }
}

/// One CAN interface and its devices.
#[derive(Debug, Clone)]
pub struct Bus {
    name: String,
    listen_only: bool,
    link: BusLink,
    drives: Vec<Drive>,
    deadman: Option<Deadman>,
    bms: Option<BmsDevice>,
    estops: Vec<EStopSignal>,
    stats: BusStats,
}

/// Every CAN interface of the vehicle.
#[derive(Debug, Clone, Default)]
pub struct Drivetrain {
    buses: Vec<Bus>,
    cutter: Option<CutterState>,
}

/// The BMS `config` describes, ready to poll and decode.
pub fn bms_device(config: &crate::config::chassis::BmsConfig) -> Option<BmsDevice> {
    Some(match config.profile.get()? {
        BmsProfile::Daly(p) => BmsDevice::Daly(DalyBms::new(
            config.address,
            p.host_address,
            match p.current_above_offset {
                CurrentAboveOffset::Charge => 1.0,
                CurrentAboveOffset::Discharge => -1.0,
            },
            config.poll_hz,
        )),
        BmsProfile::Dbc(p) => BmsDevice::Dbc(DbcBms::new(p).ok()?),
    })
}

impl Drivetrain {
    /// The interfaces and devices of `config` (profiles must be resolved).
    pub fn new(config: &VehicleConfig) -> Self {
        let wheel_config = |w: Wheel| -> WheelConfig {
            let wheels = config
                .wheels
                .unwrap_or(crate::config::chassis::WheelsConfig {
                    left: WheelConfig {
                        direction: 1,
                        gear_ratio: 1.0,
                    },
                    right: WheelConfig {
                        direction: 1,
                        gear_ratio: 1.0,
                    },
                });
            match w {
                Wheel::Left => wheels.left,
                Wheel::Right => wheels.right,
            }
        };
        let cutter = config.cutter.as_ref().and_then(|c| c.cutter().ok());
        let blade_rpm = |name: &str| match &cutter {
            Some(Cutter::Drive { name: blade, rpm }) if blade == name => Some(*rpm),
            _ => None,
        };
        let buses = config
            .can
            .iter()
            .map(|c| {
                let drives: Vec<Drive> = config
                    .drive
                    .iter()
                    .filter(|d| d.bus == c.interface)
                    .filter_map(|d| {
                        let profile = d.profile.get()?.clone();
                        let settings = NodeSettings {
                            node: NodeId::new(d.node)?,
                            heartbeat_producer_ms: d.heartbeat_ms,
                            heartbeat_timeout: Duration::from_millis(d.heartbeat_timeout_ms),
                            sdo_timeout: Duration::from_millis(d.sdo_timeout_ms),
                            sdo_retries: d.sdo_retries,
                            boot_timeout: Duration::from_millis(d.boot_timeout_ms),
                            enable_timeout: Duration::from_millis(d.enable_timeout_ms),
                            feedback_timeout: d.feedback_timeout(&profile),
                            reset_attempts: d.reset_attempts,
                            reset_wait: Duration::from_millis(d.reset_wait_ms),
                            master_node: NodeId::new(c.master_node)?,
                            master_timeout: Duration::from_millis(d.master_timeout_ms),
                            sync_period: Duration::from_millis(c.sync_ms),
                        };
                        let mut node = DriveNode::new(settings, profile);
                        node.set_monitor(c.listen_only);
                        let axes = d
                            .wheels
                            .iter()
                            .map(|w| {
                                let wc = wheel_config(*w);
                                Axis {
                                    wheel: *w,
                                    ratio: wc.gear_ratio * f64::from(wc.direction),
                                    unwrap: Unwrap::default(),
                                }
                            })
                            .collect();
                        Some(Drive {
                            name: d.name.clone(),
                            node,
                            axes,
                            blade_rpm: blade_rpm(&d.name),
                            started: false,
                        })
                    })
                    .collect();
                let bms = config
                    .bms
                    .as_ref()
                    .filter(|b| b.bus == c.interface)
                    .and_then(bms_device);
                let watches_sync = config.drive.iter().any(|d| {
                    d.bus == c.interface
                        && matches!(
                            d.profile.get().and_then(|p| p.master_loss),
                            Some(MasterLoss::Sync { .. })
                        )
                });
                let deadman = NodeId::new(c.master_node)
                    .filter(|_| !drives.is_empty() && !c.listen_only)
                    .map(|node| Deadman {
                        heartbeat: (node, Duration::from_millis(c.master_heartbeat_ms), None),
                        sync: watches_sync.then(|| (Duration::from_millis(c.sync_ms), None)),
                    });
                let estops = config
                    .estop
                    .iter()
                    .filter(|e| e.bus == c.interface)
                    .filter_map(|e| {
                        Some(EStopSignal::new(e.name.clone(), e.profile.get()?.clone()))
                    })
                    .collect();
                Bus {
                    name: c.interface.clone(),
                    listen_only: c.listen_only,
                    link: BusLink::Unknown,
                    drives,
                    deadman,
                    bms,
                    estops,
                    stats: BusStats::default(),
                }
            })
            .collect();
        Self {
            buses,
            cutter: cutter.map(|cutter| CutterState {
                cutter,
                on: false,
                next_repeat: None,
            }),
        }
    }

    /// Switches the cutter: a blade drive runs at its speed from the next command on, while
    /// the drives are enabled; a switch frame leaves now (into `tx`). False without a cutter.
    pub fn set_cutter(&mut self, t: Timestamp, on: bool, tx: &mut Vec<(String, Frame)>) -> bool {
        let Some(state) = &mut self.cutter else {
            return false;
        };
        state.on = on;
        if let Cutter::Frame {
            bus,
            on: on_frame,
            off,
            repeat,
        } = &state.cutter
        {
            state.next_repeat = repeat.filter(|_| on).map(|r| t.saturating_add(r));
            let frame = if on { *on_frame } else { *off };
            if let Some(bus) = self.buses.iter_mut().find(|b| &b.name == bus) {
                bus.emit(vec![frame], tx);
            }
        }
        true
    }

    /// Whether the cutter is switched on.
    pub fn cutter_on(&self) -> bool {
        self.cutter.as_ref().is_some_and(|c| c.on)
    }

    /// A switch frame's repeat, when due.
    fn repeat_cutter(&mut self, t: Timestamp, tx: &mut Vec<(String, Frame)>) {
        let Some(state) = &mut self.cutter else {
            return;
        };
        let Cutter::Frame {
            bus,
            on,
            repeat: Some(repeat),
            ..
        } = &state.cutter
        else {
            return;
        };
        if !state.on || state.next_repeat.is_some_and(|next| t < next) {
            return;
        }
        state.next_repeat = Some(t.saturating_add(*repeat));
        if let Some(bus) = self
            .buses
            .iter_mut()
            .find(|b| &b.name == bus && b.link != BusLink::Down)
        {
            bus.emit(vec![*on], tx);
        }
    }

    /// The interfaces' names.
    pub fn bus_names(&self) -> impl Iterator<Item = &str> {
        self.buses.iter().map(|b| b.name.as_str())
    }

    /// Whether there is no CAN device at all.
    pub fn is_empty(&self) -> bool {
        self.buses
            .iter()
            .all(|b| b.drives.is_empty() && b.bms.is_none() && b.estops.is_empty())
    }

    /// Whether any interface carries drives.
    pub fn has_drives(&self) -> bool {
        self.buses.iter().any(|b| !b.drives.is_empty())
    }

    /// Whether any interface is listen-only.
    pub fn is_listen_only(&self, source: &str) -> bool {
        self.buses.iter().any(|b| b.name == source && b.listen_only)
    }

    /// Takes a frame from `source`. Frames for the bus go to `tx`; returns whether the BMS
    /// reading changed.
    pub fn on_frame(
        &mut self,
        t: Timestamp,
        source: &str,
        received: &Received,
        tx: &mut Vec<(String, Frame)>,
    ) -> bool {
        let Some(bus) = self.buses.iter_mut().find(|b| b.name == source) else {
            return false;
        };
        let frame = match received {
            Received::Data(f) => f,
            Received::Error(e) => {
                bus.stats.error_frames += 1;
                bus.stats.last_error = Some(e.to_string());
                return false;
            }
            Received::Remote | Received::Fd => {
                bus.stats.ignored += 1;
                return false;
            }
        };
        bus.stats.rx += 1;
        let mut out = Vec::new();
        for d in &mut bus.drives {
            d.node.on_frame(t, frame, &mut out);
        }
        let bms_changed = bus.bms.as_mut().is_some_and(|b| b.on_frame(t, frame));
        for e in &mut bus.estops {
            if e.on_frame(t, frame).is_err() {
                bus.stats.estop_malformed += 1;
            }
        }
        bus.emit(out, tx);
        bms_changed
    }

    /// An interface went up or down.
    pub fn link(&mut self, t: Timestamp, source: &str, up: bool, tx: &mut Vec<(String, Frame)>) {
        let Some(bus) = self.buses.iter_mut().find(|b| b.name == source) else {
            return;
        };
        bus.link = if up { BusLink::Up } else { BusLink::Down };
        let mut out = Vec::new();
        for d in &mut bus.drives {
            if up {
                if d.started && !bus.listen_only {
                    d.node.link_up(t, &mut out);
                }
            } else {
                d.node.link_down();
            }
        }
        bus.emit(out, tx);
    }

    /// Runs every device's timers; starts nodes on interfaces not known to be down.
    pub fn poll(&mut self, t: Timestamp, tx: &mut Vec<(String, Frame)>) {
        self.repeat_cutter(t, tx);
        for bus in &mut self.buses {
            if bus.link == BusLink::Down {
                continue;
            }
            let mut out = Vec::new();
            if let Some(deadman) = &mut bus.deadman {
                deadman.poll(t, &mut out);
            }
            for d in &mut bus.drives {
                if !d.started && !bus.listen_only {
                    d.started = true;
                    d.node.start(t, &mut out);
                }
                d.node.poll(t, &mut out);
            }
            if let Some(bms) = &mut bus.bms {
                bms.poll(t, &mut out);
            }
            bus.emit(out, tx);
        }
    }

    /// Sends the wheel command just given to [`Self::command`] in the same control tick.
    pub fn flush_commands(&mut self, t: Timestamp, tx: &mut Vec<(String, Frame)>) {
        for bus in &mut self.buses {
            if bus.link == BusLink::Down {
                continue;
            }
            let mut out = Vec::new();
            for d in &mut bus.drives {
                d.node.flush_command(t, &mut out);
            }
            bus.emit(out, tx);
        }
    }

    /// The drive train's feedback, in wheel terms.
    pub fn feedback(&mut self) -> ChassisFeedback {
        let mut fb = ChassisFeedback::default();
        for bus in &mut self.buses {
            if bus.link == BusLink::Down && !bus.drives.is_empty() {
                fb.bus_down = true;
            }
            // A bus that is down delivers nothing: its e-stops fall silent and count as pressed.
            fb.estops.extend(bus.estops.iter().map(EStopSignal::input));
            for d in &mut bus.drives {
                let units = d.node.profile().units;
                for (a, axis) in d.axes.iter_mut().enumerate() {
                    let Some(raw) = d.node.axes().get(a).copied() else {
                        continue;
                    };
                    let wheel = WheelFeedback {
                        velocity_rad_s: raw.velocity.map(|v| {
                            f64::from(v) / units.actual_velocity_per_rpm / 60.0 * TAU / axis.ratio
                        }),
                        angle_rad: raw.position.map(|p| {
                            axis.unwrap.update(p) as f64 / units.counts_per_rev * TAU / axis.ratio
                        }),
                        received: raw.rx,
                        velocity_received: raw.velocity_rx,
                    };
                    match axis.wheel {
                        Wheel::Left => fb.left = wheel,
                        Wheel::Right => fb.right = wheel,
                    }
                }
                let fault = d.node.fault();
                fb.drives.push(DriveSummary {
                    name: d.name.clone(),
                    ready: d.node.is_ready(),
                    running: d.node.phase() == Phase::Running,
                    enabled: d.node.is_enabled(),
                    fault: fault.map(|f| f.to_string()),
                    heartbeat_lost: fault == Some(DriveFault::HeartbeatLost),
                    resetting: d.node.is_resetting(),
                });
            }
        }
        fb
    }

    /// Applies the core's wheel command to every drive.
    pub fn command(&mut self, t: Timestamp, command: &WheelCommand) {
        let goal = match command.power {
            Power::Standby => Goal::Standby,
            Power::Enabled => Goal::Enabled,
            Power::QuickStop => Goal::QuickStop,
            Power::Disabled => Goal::Disabled,
        };
        let cutter_on = self.cutter_on();
        for bus in &mut self.buses {
            for d in &mut bus.drives {
                if command.reset_faults && d.node.fault().is_some() && !d.node.reset_fault(t) {
                    tracing::warn!(drive = %d.name, "fault cannot be reset yet");
                }
                if let Some(blade) = d.blade_rpm {
                    d.node
                        .command(t, goal, &[if cutter_on { blade } else { 0.0 }]);
                    continue;
                }
                let rpm: Vec<f64> = d
                    .axes
                    .iter()
                    .map(|axis| {
                        let wheel = match axis.wheel {
                            Wheel::Left => command.left_rad_s,
                            Wheel::Right => command.right_rad_s,
                        };
                        wheel / TAU * 60.0 * axis.ratio
                    })
                    .collect();
                d.node.command(t, goal, &rpm);
            }
        }
    }

    /// The frames that quick-stop every drive with zero targets, by interface (for a panic
    /// hook: computed ahead, sent without the engine).
    pub fn stop_frames(&self) -> Vec<(String, Frame)> {
        let mut frames: Vec<(String, Frame)> = self
            .buses
            .iter()
            .filter(|b| !b.listen_only)
            .flat_map(|b| {
                b.drives.iter().flat_map(move |d| {
                    d.node
                        .stop_frames()
                        .into_iter()
                        .map(|f| (b.name.clone(), f))
                })
            })
            .collect();
        if let Some((bus, off)) = self.cutter_off_frame()
            && !self.is_listen_only(bus)
        {
            frames.push((bus.to_owned(), off));
        }
        frames
    }

    /// A switch-frame cutter's bus and off frame.
    fn cutter_off_frame(&self) -> Option<(&str, Frame)> {
        match &self.cutter.as_ref()?.cutter {
            Cutter::Frame { bus, off, .. } => Some((bus, *off)),
            Cutter::Drive { .. } => None,
        }
    }

    /// The daemon is exiting: every running drive quick-stops with zero targets now; the
    /// frames go to `tx`.
    pub fn shut_down(&mut self, tx: &mut Vec<(String, Frame)>) {
        if self.cutter_on() {
            // A switch frame's blade is switched off (the time only schedules repeats while
            // on); a blade drive quick-stops below.
            self.set_cutter(Timestamp::default(), false, tx);
        }
        for bus in &mut self.buses {
            if bus.link == BusLink::Down {
                continue;
            }
            let mut out = Vec::new();
            for d in &mut bus.drives {
                d.node.shut_down(&mut out);
            }
            bus.emit(out, tx);
        }
    }

    /// The BMS reading, if a BMS is configured.
    pub fn bms_reading(&self) -> Option<&crate::devices::bms::BmsReading> {
        self.buses
            .iter()
            .find_map(|b| b.bms.as_ref())
            .map(BmsDevice::reading)
    }

    /// Counters per interface.
    pub fn stats(&self) -> impl Iterator<Item = (&str, &BusStats)> {
        self.buses.iter().map(|b| (b.name.as_str(), &b.stats))
    }

    /// Drive nodes, for diagnostics: (bus, name, node).
    pub fn nodes(&self) -> impl Iterator<Item = (&str, &str, &DriveNode)> {
        self.buses.iter().flat_map(|b| {
            b.drives
                .iter()
                .map(move |d| (b.name.as_str(), d.name.as_str(), &d.node))
        })
    }
}

impl Bus {
    fn emit(&mut self, out: Vec<Frame>, tx: &mut Vec<(String, Frame)>) {
        if self.listen_only {
            self.stats.suppressed += out.len() as u64;
            return;
        }
        self.stats.tx += out.len() as u64;
        tx.extend(out.into_iter().map(|f| (self.name.clone(), f)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estop_frames_reach_the_feedback() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("devices");
        let text = "[[can]]\ninterface = \"can0\"\n\
                    [[estop]]\nname = \"body\"\nprofile = \"estop-canopen-di.toml\"\nbus = \"can0\"\n";
        let config = VehicleConfig::from_toml(text, &dir.join("test.toml")).unwrap();
        let mut train = Drivetrain::new(&config);
        assert!(!train.is_empty());
        let mut tx = Vec::new();
        let t = Timestamp::from_nanos(1_000_000);
        let fb = train.feedback();
        assert_eq!(fb.estops.len(), 1);
        assert_eq!((fb.estops[0].pressed, fb.estops[0].heard), (None, None));
        // Input 1 high: the normally-closed loop is closed, released.
        train.on_frame(
            t,
            "can0",
            &Received::Data(Frame::std(0x18A, [0x01])),
            &mut tx,
        );
        let input = &train.feedback().estops[0];
        assert_eq!((input.pressed, input.heard), (Some(false), Some(t)));
        assert_eq!(input.timeout, Duration::from_millis(300));
        train.on_frame(
            t,
            "can0",
            &Received::Data(Frame::std(0x18A, [0x00])),
            &mut tx,
        );
        assert_eq!(train.feedback().estops[0].pressed, Some(true));
        train.on_frame(t, "can0", &Received::Data(Frame::std(0x18A, [])), &mut tx);
        assert_eq!(train.stats().next().unwrap().1.estop_malformed, 1);
        assert!(tx.is_empty(), "an e-stop input is only listened to");
    }

    /// A drive train with one generic drive whose profile watches `watch`; frames of the
    /// first 100 ms of polling.
    fn deadman_frames(watch: &str) -> Vec<Frame> {
        let devices = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("devices");
        let dir =
            std::env::temp_dir().join(format!("chassisd-deadman-{watch}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let profile = std::fs::read_to_string(devices.join("cia402-generic.toml"))
            .unwrap()
            .replace("watch = \"heartbeat\"", &format!("watch = \"{watch}\""));
        std::fs::write(dir.join("drive.toml"), profile).unwrap();
        let text = "[chassis]\nwheel_radius_m = 0.1\ntrack_m = 0.5\n\
                    [wheels.left]\ndirection = 1\n[wheels.right]\ndirection = -1\n\
                    [[can]]\ninterface = \"can0\"\nsync_ms = 20\n\
                    [[drive]]\nname = \"l\"\nprofile = \"drive.toml\"\nbus = \"can0\"\nnode = 1\nwheels = [\"left\"]\n\
                    [[drive]]\nname = \"r\"\nprofile = \"drive.toml\"\nbus = \"can0\"\nnode = 2\nwheels = [\"right\"]\n";
        let config = VehicleConfig::from_toml(text, &dir.join("vehicle.toml")).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        let mut train = Drivetrain::new(&config);
        let mut tx = Vec::new();
        for ms in (0..100).step_by(10) {
            train.poll(Timestamp::from_micros(ms * 1000), &mut tx);
        }
        tx.into_iter().map(|(_, f)| f).collect()
    }

    #[test]
    fn sync_is_produced_only_for_drives_that_watch_it() {
        let count = |frames: &[Frame], id: u32| frames.iter().filter(|f| f.id() == id).count();
        let sync = deadman_frames("sync");
        // Every 20 ms over 100 ms, and chassisd's heartbeat (node 0x7F) every 50 ms.
        assert_eq!(count(&sync, 0x080), 5);
        assert_eq!(count(&sync, 0x77F), 2);
        let heartbeat = deadman_frames("heartbeat");
        assert_eq!(count(&heartbeat, 0x080), 0);
        assert_eq!(count(&heartbeat, 0x77F), 2);
    }

    #[test]
    fn a_switch_frame_cutter_is_sent_repeated_while_on_and_switched_off_to_stop() {
        let text = "[[can]]\ninterface = \"can0\"\n\
                    [cutter]\nbus = \"can0\"\ncan_id = 0x6A0\non = [1]\noff = [0]\nrepeat_ms = 100\n";
        let config = VehicleConfig::from_toml(text, std::path::Path::new("test.toml")).unwrap();
        let mut train = Drivetrain::new(&config);
        let ms = |ms: u64| Timestamp::from_micros(ms * 1000);
        let sent = |tx: &mut Vec<(String, Frame)>| -> Vec<Vec<u8>> {
            tx.drain(..)
                .inspect(|(bus, f)| assert_eq!((bus.as_str(), f.id()), ("can0", 0x6A0)))
                .map(|(_, f)| f.data().to_vec())
                .collect()
        };
        let mut tx = Vec::new();
        train.poll(ms(0), &mut tx);
        assert!(sent(&mut tx).is_empty(), "off: nothing is sent");
        assert!(train.set_cutter(ms(10), true, &mut tx));
        assert_eq!(sent(&mut tx), [vec![1]]);
        train.poll(ms(60), &mut tx);
        assert!(sent(&mut tx).is_empty());
        train.poll(ms(110), &mut tx);
        train.poll(ms(150), &mut tx);
        train.poll(ms(210), &mut tx);
        assert_eq!(sent(&mut tx), [vec![1], vec![1]], "every 100 ms while on");
        assert!(train.set_cutter(ms(220), false, &mut tx));
        assert_eq!(sent(&mut tx), [vec![0]]);
        train.poll(ms(500), &mut tx);
        assert!(sent(&mut tx).is_empty(), "no repeats once off");
        // The panic hook's frames and the exit switch it off.
        assert!(train.stop_frames().iter().any(|(_, f)| f.data() == [0]));
        train.set_cutter(ms(600), true, &mut tx);
        tx.clear();
        train.shut_down(&mut tx);
        assert_eq!(sent(&mut tx), [vec![0]]);
        assert!(!train.cutter_on());
        // Without a cutter there is nothing to switch.
        let mut bare = Drivetrain::new(
            &VehicleConfig::from_toml("[[can]]\ninterface = \"can0\"\n", std::path::Path::new("t"))
                .unwrap(),
        );
        assert!(!bare.set_cutter(ms(0), true, &mut tx));
    }

    #[test]
    fn unwraps_encoder_roll_over() {
        let mut u = Unwrap::default();
        assert_eq!(u.update(i32::MAX - 10), i64::from(i32::MAX - 10));
        assert_eq!(u.update(i32::MIN + 9), i64::from(i32::MAX) + 10);
        assert_eq!(u.update(i32::MAX - 10), i64::from(i32::MAX - 10));
    }
}
