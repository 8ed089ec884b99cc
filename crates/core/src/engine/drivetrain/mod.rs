//! The CAN side of the engine: each interface with its devices, built from the
//! configuration by the registry [`KINDS`] and driven through one trait,
//! [`device::CanDevice`]: frames in, frames out with the time, link state, timers, and what
//! each reports to the core.

pub mod bms;
pub mod cutter;
pub mod deadman;
pub mod device;
pub mod drive;
pub mod estop;

use crate::config::VehicleConfig;
use crate::config::chassis::CanBusConfig;
use crate::devices::can::{Frame, Received};
use crate::devices::cia402::node::DriveNode;
use crate::devices::cia402::state::Goal;
use crate::time::Timestamp;
use crate::vehicle::chassis::{ChassisFeedback, WheelCommand};
use crate::vehicle::safety::Power;
use device::{CanDevice, DriveCommand, Heard};

pub use bms::bms_device;

/// One kind of CAN device: its name and how an interface's devices of that kind are built.
pub struct DeviceKind {
    /// What it is, for the documentation and diagnostics.
    pub name: &'static str,
    /// The devices of this kind the configuration puts on an interface.
    pub build: fn(&VehicleConfig, &CanBusConfig) -> Vec<Box<dyn CanDevice>>,
}

/// Every kind of CAN device. An interface lists its devices in this order, which is the
/// order a received frame is offered to them and the order their frames leave in at a
/// tick. A new kind is its module and one line here.
pub const KINDS: &[DeviceKind] = &[
    DeviceKind {
        name: "cutter switch frame",
        build: cutter::build,
    },
    DeviceKind {
        name: "CANopen master heartbeat and SYNC",
        build: deadman::build,
    },
    DeviceKind {
        name: "CiA 402 drive",
        build: drive::build,
    },
    DeviceKind {
        name: "BMS",
        build: bms::build,
    },
    DeviceKind {
        name: "e-stop input",
        build: estop::build,
    },
];

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
    /// Device frames too short to read (an e-stop's status without its bit).
    pub estop_malformed: u64,
}

/// One CAN interface and its devices.
#[derive(Debug)]
pub struct Bus {
    name: String,
    listen_only: bool,
    link: BusLink,
    devices: Vec<Box<dyn CanDevice>>,
    stats: BusStats,
}

/// Every CAN interface of the vehicle.
#[derive(Debug, Default)]
pub struct Drivetrain {
    buses: Vec<Bus>,
    /// The cutter's state, when `[cutter]` configures one.
    cutter_on: Option<bool>,
}

impl Drivetrain {
    /// The interfaces and devices of `config` (profiles must be resolved).
    pub fn new(config: &VehicleConfig) -> Self {
        let buses = config
            .can
            .iter()
            .map(|c| Bus {
                name: c.interface.clone(),
                listen_only: c.listen_only,
                link: BusLink::Unknown,
                devices: KINDS.iter().flat_map(|k| (k.build)(config, c)).collect(),
                stats: BusStats::default(),
            })
            .collect();
        let cutter = config.cutter.as_ref().and_then(|c| c.cutter().ok());
        Self {
            buses,
            cutter_on: cutter.map(|_| false),
        }
    }

    /// Switches the cutter: a blade drive runs at its speed from the next command on, while
    /// the drives are enabled; a switch frame leaves now (into `tx`). False without a cutter.
    pub fn set_cutter(&mut self, t: Timestamp, on: bool, tx: &mut Vec<(String, Frame)>) -> bool {
        let Some(state) = &mut self.cutter_on else {
            return false;
        };
        *state = on;
        for bus in &mut self.buses {
            let mut out = Vec::new();
            for d in &mut bus.devices {
                d.switch_cutter(t, on, &mut out);
            }
            bus.emit(out, tx);
        }
        true
    }

    /// Whether the cutter is switched on.
    pub fn cutter_on(&self) -> bool {
        self.cutter_on == Some(true)
    }

    /// The interfaces' names.
    pub fn bus_names(&self) -> impl Iterator<Item = &str> {
        self.buses.iter().map(|b| b.name.as_str())
    }

    /// Whether there is no CAN device at all.
    pub fn is_empty(&self) -> bool {
        self.buses.iter().all(|b| b.devices.is_empty())
    }

    /// Whether any interface carries drives.
    pub fn has_drives(&self) -> bool {
        self.buses
            .iter()
            .any(|b| b.devices.iter().any(|d| d.is_drive()))
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
        let mut changed = false;
        for d in &mut bus.devices {
            match d.on_frame(t, frame, &mut out) {
                Heard::Nothing => {}
                Heard::Changed => changed = true,
                Heard::Malformed => bus.stats.estop_malformed += 1,
            }
        }
        bus.emit(out, tx);
        changed
    }

    /// An interface went up or down.
    pub fn link(&mut self, t: Timestamp, source: &str, up: bool, tx: &mut Vec<(String, Frame)>) {
        let Some(bus) = self.buses.iter_mut().find(|b| b.name == source) else {
            return;
        };
        bus.link = if up { BusLink::Up } else { BusLink::Down };
        let mut out = Vec::new();
        for d in &mut bus.devices {
            d.on_link(t, up, &mut out);
        }
        bus.emit(out, tx);
    }

    /// Runs every device's timers on interfaces not known to be down (drives start there).
    pub fn poll(&mut self, t: Timestamp, tx: &mut Vec<(String, Frame)>) {
        for bus in self.buses.iter_mut().filter(|b| b.link != BusLink::Down) {
            let mut out = Vec::new();
            for d in &mut bus.devices {
                d.poll(t, &mut out);
            }
            bus.emit(out, tx);
        }
    }

    /// Sends the wheel command just given to [`Self::command`] in the same control tick, and
    /// the periodic refreshes due (never before the tick's command).
    pub fn flush_commands(&mut self, t: Timestamp, tx: &mut Vec<(String, Frame)>) {
        for bus in self.buses.iter_mut().filter(|b| b.link != BusLink::Down) {
            let mut out = Vec::new();
            for d in &mut bus.devices {
                d.flush(t, &mut out);
            }
            bus.emit(out, tx);
        }
    }

    /// The drive train's feedback, in wheel terms.
    pub fn feedback(&mut self) -> ChassisFeedback {
        let mut fb = ChassisFeedback::default();
        for bus in &mut self.buses {
            if bus.link == BusLink::Down && bus.devices.iter().any(|d| d.is_drive()) {
                fb.bus_down = true;
            }
            for d in &mut bus.devices {
                d.report(&mut fb);
            }
        }
        fb
    }

    /// Applies the core's wheel command to every device.
    pub fn command(&mut self, t: Timestamp, command: &WheelCommand) {
        let command = DriveCommand {
            goal: match command.power {
                Power::Standby => Goal::Standby,
                Power::Enabled => Goal::Enabled,
                Power::QuickStop => Goal::QuickStop,
                Power::Disabled => Goal::Disabled,
            },
            left_rad_s: command.left_rad_s,
            right_rad_s: command.right_rad_s,
            reset_faults: command.reset_faults,
            cutter_on: self.cutter_on(),
        };
        for bus in &mut self.buses {
            for d in &mut bus.devices {
                d.command(t, &command);
            }
        }
    }

    /// The frames that stop every device (drives quick-stop with zero targets, the cutter's
    /// switch off), by interface, for a panic hook: computed ahead, sent without the engine.
    pub fn stop_frames(&self) -> Vec<(String, Frame)> {
        self.buses
            .iter()
            .filter(|b| !b.listen_only)
            .flat_map(|b| {
                b.devices
                    .iter()
                    .flat_map(move |d| d.stop_frames().into_iter().map(|f| (b.name.clone(), f)))
            })
            .collect()
    }

    /// The daemon is exiting: the cutter is switched off and every running drive
    /// quick-stops with zero targets now; the frames go to `tx`.
    pub fn shut_down(&mut self, tx: &mut Vec<(String, Frame)>) {
        if self.cutter_on() {
            // A switch frame's blade is switched off (the time only schedules repeats while
            // on); a blade drive quick-stops below.
            self.set_cutter(Timestamp::default(), false, tx);
        }
        for bus in self.buses.iter_mut().filter(|b| b.link != BusLink::Down) {
            let mut out = Vec::new();
            for d in &mut bus.devices {
                d.shut_down(&mut out);
            }
            bus.emit(out, tx);
        }
    }

    /// The BMS reading, if a BMS is configured.
    pub fn bms_reading(&self) -> Option<&crate::devices::bms::BmsReading> {
        self.buses
            .iter()
            .flat_map(|b| &b.devices)
            .find_map(|d| d.bms())
    }

    /// Counters per interface.
    pub fn stats(&self) -> impl Iterator<Item = (&str, &BusStats)> {
        self.buses.iter().map(|b| (b.name.as_str(), &b.stats))
    }

    /// Drive nodes, for diagnostics: (bus, name, node).
    pub fn nodes(&self) -> impl Iterator<Item = (&str, &str, &DriveNode)> {
        self.buses.iter().flat_map(|b| {
            b.devices
                .iter()
                .filter_map(move |d| d.node().map(|(name, node)| (b.name.as_str(), name, node)))
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
    use std::time::Duration;

    #[test]
    fn estop_frames_reach_the_feedback() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices");
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
        let devices = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../devices");
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
        let mut u = drive::Unwrap::default();
        assert_eq!(u.update(i32::MAX - 10), i64::from(i32::MAX - 10));
        assert_eq!(u.update(i32::MIN + 9), i64::from(i32::MAX) + 10);
        assert_eq!(u.update(i32::MAX - 10), i64::from(i32::MAX - 10));
    }
}
