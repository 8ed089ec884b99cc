//! The simulated CAN devices of a vehicle configuration, for `chassisd can-sim` and the
//! simulated plant: one trait, [`SimCanDevice`], and a registry, [`KINDS`], that follows the
//! engine's own ([`crate::engine::drivetrain::KINDS`]): every kind of device chassisd
//! drives has its simulated counterpart here, built from the same configuration, in the
//! same order. The plant couples them to its physics through the trait (the drives' motor
//! speeds, the battery's current, the cutter's state), never by knowing their types.

use serde_json::{Value, json};

use super::bms::{Battery, SimDaly, SimDbcBms};
use super::cia402_drive::{MotorModel, SimDrive};
use super::cutter_switch::SimCutterSwitch;
use super::estop::{Button, SimEStop};
use crate::config::VehicleConfig;
use crate::config::chassis::CanBusConfig;
use crate::config::mission::Cutter;
use crate::devices::bms::BmsProfile;
use crate::devices::can::Frame;
use crate::devices::canopen::NodeId;
use crate::time::Timestamp;

/// What the devices of one interface share within a step: the drives' load, which the
/// battery's current follows.
#[derive(Debug, Clone, Copy, Default)]
pub struct BusLoad {
    /// The motors' speeds summed, r/min.
    pub rpm: f64,
    /// The pack's current when a plant's physics decides it (the vehicle on its charger, the
    /// blade turning), A, positive while charging; else it follows `rpm`.
    pub current_a: Option<f64>,
}

/// What a configuration does not say about simulated hardware.
#[derive(Debug, Clone, Copy, Default)]
pub struct Hardware {
    /// The drives' motors.
    pub motor: MotorModel,
}

/// A fault or a state a test injects into one simulated device, by its name.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Injection {
    /// A drive's heartbeat stops or resumes.
    Heartbeat(bool),
    /// A drive raises an EMCY `code` on `axis` (0-based) and ignores the first `refused`
    /// reset edges.
    Fault {
        /// Axis, from 0.
        axis: usize,
        /// EMCY code.
        code: u16,
        /// Reset edges ignored.
        refused: u32,
    },
    /// A drive's TPDOs stop or resume while its heartbeat goes on.
    Tpdo(bool),
    /// An e-stop module's button, or its silence.
    EStop(Button),
}

/// What a device says in a report.
#[derive(Debug, Clone, PartialEq)]
pub enum Report {
    /// A drive's state.
    Drive(Value),
    /// The battery's state.
    Battery(Value),
    /// The cutter switch's relay.
    Cutter(Value),
    /// Nothing to say.
    Nothing,
}

/// One simulated device on a CAN interface.
pub trait SimCanDevice: Send + std::fmt::Debug {
    /// Its configuration name (`[[drive]]` and `[[estop]]` names; `bms` for the battery).
    fn name(&self) -> &str;
    /// A frame heard at `t`; answers go to `out`.
    fn on_frame(&mut self, _t: Timestamp, _frame: &Frame, _out: &mut Vec<Frame>) {}
    /// Runs on to `t` under the interface's `load`; frames due go to `out`.
    fn step(&mut self, t: Timestamp, load: &mut BusLoad, out: &mut Vec<Frame>);
    /// Takes an injection meant for it; frames it causes go to `out`.
    fn inject(&mut self, _injection: Injection, _out: &mut Vec<Frame>) {}
    /// Its state, for `report`.
    fn report(&self) -> Report {
        Report::Nothing
    }
    /// The drive, when it is one: the plant turns its wheels and blade by its motors.
    fn drive(&self) -> Option<&SimDrive> {
        None
    }
    /// The drive, when it is one, to back-drive.
    fn drive_mut(&mut self) -> Option<&mut SimDrive> {
        None
    }
    /// The battery, when it is a BMS.
    fn battery(&self) -> Option<Battery> {
        None
    }
    /// Whether the relay is closed, when it is a cutter switch.
    fn cutter_on(&self) -> Option<bool> {
        None
    }
}

/// The simulated devices a kind puts on an interface, or why they cannot be built.
pub type Built = Result<Vec<Box<dyn SimCanDevice>>, String>;

/// How the devices of one kind are simulated.
pub struct SimKind {
    /// The engine's kind it stands for (`DeviceKind::name`).
    pub simulates: &'static str,
    /// The simulated devices the configuration puts on an interface, or why they cannot be.
    pub build: fn(&VehicleConfig, &CanBusConfig, &Hardware) -> Built,
}

/// Every simulated kind, in the engine's order (the order frames are offered and sent).
pub const KINDS: &[SimKind] = &[
    SimKind {
        simulates: "cutter switch frame",
        build: cutter_switch,
    },
    SimKind {
        simulates: "CiA 402 drive",
        build: drives,
    },
    SimKind {
        simulates: "BMS",
        build: bms,
    },
    SimKind {
        simulates: "e-stop input",
        build: estops,
    },
];

/// The engine's kinds that have no simulated device: chassisd's own frames.
pub const NOT_SIMULATED: &[&str] = &["CANopen master heartbeat and SYNC"];

/// The simulated devices of `bus`, every kind in order.
pub fn build(config: &VehicleConfig, bus: &CanBusConfig, hardware: &Hardware) -> Built {
    let mut devices = Vec::new();
    for kind in KINDS {
        devices.extend((kind.build)(config, bus, hardware)?);
    }
    Ok(devices)
}

#[derive(Debug)]
struct CutterSwitch(SimCutterSwitch);

fn cutter_switch(config: &VehicleConfig, bus: &CanBusConfig, _: &Hardware) -> Built {
    Ok(match config.cutter.as_ref().and_then(|c| c.cutter().ok()) {
        Some(Cutter::Frame {
            bus: name,
            on,
            off,
            repeat,
        }) if name == bus.interface => vec![Box::new(CutterSwitch(SimCutterSwitch::new(
            on, off, repeat,
        )))],
        _ => Vec::new(),
    })
}

impl SimCanDevice for CutterSwitch {
    fn name(&self) -> &str {
        "cutter"
    }

    fn on_frame(&mut self, t: Timestamp, frame: &Frame, _out: &mut Vec<Frame>) {
        self.0.on_frame(t, frame);
    }

    fn step(&mut self, t: Timestamp, _load: &mut BusLoad, _out: &mut Vec<Frame>) {
        self.0.step(t);
    }

    fn report(&self) -> Report {
        Report::Cutter(json!({"on": self.0.on()}))
    }

    fn cutter_on(&self) -> Option<bool> {
        Some(self.0.on())
    }
}

#[derive(Debug)]
struct Drive {
    name: String,
    drive: SimDrive,
}

fn drives(config: &VehicleConfig, bus: &CanBusConfig, hardware: &Hardware) -> Built {
    let mut out: Vec<Box<dyn SimCanDevice>> = Vec::new();
    for d in config.drive.iter().filter(|d| d.bus == bus.interface) {
        let profile = d.profile.get().ok_or("drive profile not loaded")?.clone();
        let node = NodeId::new(d.node).ok_or("node id out of range")?;
        out.push(Box::new(Drive {
            name: d.name.clone(),
            drive: SimDrive::new(node, profile, hardware.motor),
        }));
    }
    Ok(out)
}

impl SimCanDevice for Drive {
    fn name(&self) -> &str {
        &self.name
    }

    fn on_frame(&mut self, t: Timestamp, frame: &Frame, out: &mut Vec<Frame>) {
        self.drive.on_frame(t, frame, out);
    }

    fn step(&mut self, t: Timestamp, load: &mut BusLoad, out: &mut Vec<Frame>) {
        self.drive.step(t, out);
        load.rpm += self.drive.motor_rpm().iter().map(|r| r.abs()).sum::<f64>();
    }

    fn inject(&mut self, injection: Injection, out: &mut Vec<Frame>) {
        match injection {
            Injection::Heartbeat(on) => self.drive.set_heartbeat(on),
            Injection::Fault {
                axis,
                code,
                refused,
            } => {
                self.drive.refuse_resets(refused);
                self.drive.inject_fault(axis, code, out);
            }
            Injection::Tpdo(on) => self.drive.set_tpdos(on),
            Injection::EStop(_) => {}
        }
    }

    fn drive(&self) -> Option<&SimDrive> {
        Some(&self.drive)
    }

    fn drive_mut(&mut self) -> Option<&mut SimDrive> {
        Some(&mut self.drive)
    }

    fn report(&self) -> Report {
        let d = &self.drive;
        Report::Drive(json!({
            "name": self.name,
            "node": d.node().get(),
            "nmt": format!("{:?}", d.nmt_state()),
            "axes": d.report(),
            "master_losses": d.master_losses(),
            "reset_edges": d.reset_edges(),
        }))
    }
}

#[derive(Debug)]
enum Pack {
    Daly(SimDaly),
    Dbc(SimDbcBms),
}

/// The battery and its BMS.
#[derive(Debug)]
struct Bms {
    pack: Pack,
    last: Option<Timestamp>,
}

fn bms(config: &VehicleConfig, bus: &CanBusConfig, _: &Hardware) -> Built {
    let Some(b) = config.bms.as_ref().filter(|b| b.bus == bus.interface) else {
        return Ok(Vec::new());
    };
    let pack = match b.profile.get().ok_or("BMS profile not loaded")? {
        BmsProfile::Daly(p) => Pack::Daly(SimDaly::new(p, b.address)),
        BmsProfile::Dbc(p) => {
            Pack::Dbc(SimDbcBms::new(p).ok_or("the BMS profile's DBC does not parse")?)
        }
    };
    Ok(vec![Box::new(Bms { pack, last: None })])
}

impl SimCanDevice for Bms {
    fn name(&self) -> &str {
        "bms"
    }

    fn on_frame(&mut self, _t: Timestamp, frame: &Frame, out: &mut Vec<Frame>) {
        if let Pack::Daly(daly) = &mut self.pack {
            daly.on_frame(frame, out);
        }
    }

    fn step(&mut self, t: Timestamp, load: &mut BusLoad, out: &mut Vec<Frame>) {
        let dt = self
            .last
            .map_or_else(Default::default, |l| t.saturating_since(l));
        self.last = Some(t);
        let battery = match &mut self.pack {
            Pack::Daly(d) => &mut d.battery,
            Pack::Dbc(d) => &mut d.battery,
        };
        battery.current_a = load.current_a.unwrap_or(-(1.5 + 0.004 * load.rpm));
        battery.step(dt);
        if let Pack::Dbc(dbc) = &mut self.pack {
            dbc.step(t, out);
        }
    }

    fn report(&self) -> Report {
        let b = self.battery().unwrap_or_default();
        Report::Battery(json!({"voltage": b.voltage_v, "current": b.current_a, "soc": b.soc_pct}))
    }

    fn battery(&self) -> Option<Battery> {
        Some(match &self.pack {
            Pack::Daly(d) => d.battery,
            Pack::Dbc(d) => d.battery,
        })
    }
}

#[derive(Debug)]
struct EStop {
    name: String,
    module: SimEStop,
}

fn estops(config: &VehicleConfig, bus: &CanBusConfig, _: &Hardware) -> Built {
    let mut out: Vec<Box<dyn SimCanDevice>> = Vec::new();
    for e in config.estop.iter().filter(|e| e.bus == bus.interface) {
        let profile = e.profile.get().ok_or("e-stop profile not loaded")?.clone();
        out.push(Box::new(EStop {
            name: e.name.clone(),
            module: SimEStop::new(profile),
        }));
    }
    Ok(out)
}

impl SimCanDevice for EStop {
    fn name(&self) -> &str {
        &self.name
    }

    fn step(&mut self, t: Timestamp, _load: &mut BusLoad, out: &mut Vec<Frame>) {
        self.module.step(t, out);
    }

    fn inject(&mut self, injection: Injection, _out: &mut Vec<Frame>) {
        if let Injection::EStop(button) = injection {
            self.module.set(button);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_the_engine_drives_is_simulated_in_its_order() {
        let engine: Vec<&str> = crate::engine::drivetrain::KINDS
            .iter()
            .map(|k| k.name)
            .filter(|name| !NOT_SIMULATED.contains(name))
            .collect();
        let simulated: Vec<&str> = KINDS.iter().map(|k| k.simulates).collect();
        assert_eq!(engine, simulated);
        for name in NOT_SIMULATED {
            assert!(
                crate::engine::drivetrain::KINDS
                    .iter()
                    .any(|k| k.name == *name),
                "{name} is not one of the engine's kinds"
            );
        }
    }

    #[test]
    fn a_configuration_becomes_its_simulated_devices() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("devices");
        let text = "[[can]]\ninterface = \"can0\"\n\
                    [[estop]]\nname = \"body\"\nprofile = \"estop-canopen-di.toml\"\nbus = \"can0\"\n";
        let config = VehicleConfig::from_toml(text, &dir.join("test.toml")).unwrap();
        let mut devices = build(&config, &config.can[0], &Hardware::default()).unwrap();
        assert_eq!(
            devices.iter().map(|d| d.name()).collect::<Vec<_>>(),
            ["body"]
        );
        let mut out = Vec::new();
        let t = Timestamp::from_nanos(1_000_000);
        devices[0].step(t, &mut BusLoad::default(), &mut out);
        assert_eq!(out.len(), 1, "a released button's status frame");
        devices[0].inject(Injection::EStop(Button::Silent), &mut out);
        out.clear();
        devices[0].step(t, &mut BusLoad::default(), &mut out);
        assert!(out.is_empty(), "a silent module sends nothing");
    }
}
