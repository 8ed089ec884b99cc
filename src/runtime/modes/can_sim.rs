//! `chassisd can-sim`: the CAN devices of a vehicle configuration, simulated on real
//! SocketCAN interfaces (vcan in tests). Every `[[drive]]` becomes a simulated CiA 402 node
//! and the `[bms]` a simulated pack, speaking the same protocols chassisd expects.
//!
//! Standard input takes commands that inject faults, one per line:
//! `heartbeat DRIVE off|on`, `fault DRIVE AXIS CODE [REFUSED]` (CODE an EMCY code such as
//! 0x2310; the drive ignores the first REFUSED reset edges), `tpdo DRIVE off|on` (TPDOs stop
//! while the heartbeat goes on), `estop NAME pressed|released|silent` (an `[[estop]]` input's
//! module: its button, or silence), `report` (one JSON line on standard output with every node's
//! state).
//!
//! While an interface is down the drives on it keep running (their motors turn, their
//! watchdogs count) with nothing to hear: a cut cable, as the drives see it.

use crate::runtime::links::input_lines::{InputLine, InputLines, MAX_LINE_BYTES};
use std::time::Duration;

use crate::runtime::error::{RuntimeError, io};
use serde_json::json;
use socketcan::tokio::CanSocket;
use socketcan::{CanAnyFrame, CanFrame};
use tokio::sync::mpsc;

use crate::config::VehicleConfig;
use crate::devices::bms::BmsProfile;
use crate::devices::can::{Frame, Received};
use crate::devices::canopen::NodeId;
use crate::runtime::clock::RecordClock;
use crate::runtime::drivers::can::{interface_up, open};
use crate::sim::bms::{Battery, SimDaly, SimDbcBms};
use crate::sim::cia402_drive::{MotorModel, SimDrive};
use crate::sim::estop::{Button, SimEStop};

/// Simulation step.
const STEP: Duration = Duration::from_millis(5);

/// The devices on one interface.
struct SimBus {
    name: String,
    drives: Vec<(String, SimDrive)>,
    daly: Option<SimDaly>,
    dbc: Option<SimDbcBms>,
    estops: Vec<(String, SimEStop)>,
}

#[derive(Debug, Clone)]
enum SimCommand {
    Heartbeat(String, bool),
    Fault(String, usize, u16, u32),
    Tpdo(String, bool),
    EStop(String, Button),
    Report,
}

/// Runs until standard input closes or SIGTERM.
pub async fn run(config: VehicleConfig) -> crate::runtime::error::Result<()> {
    let clock = RecordClock::start();
    let mut senders = Vec::new();
    let mut tasks = Vec::new();
    for bus in &config.can {
        let mut sim = SimBus {
            name: bus.interface.clone(),
            drives: Vec::new(),
            daly: None,
            dbc: None,
            estops: Vec::new(),
        };
        for e in config.estop.iter().filter(|e| e.bus == bus.interface) {
            let profile = e
                .profile
                .get()
                .ok_or_else(|| RuntimeError::Failed("e-stop profile not loaded".into()))?
                .clone();
            sim.estops.push((e.name.clone(), SimEStop::new(profile)));
        }
        for d in config.drive.iter().filter(|d| d.bus == bus.interface) {
            let profile = d
                .profile
                .get()
                .ok_or_else(|| RuntimeError::Failed("drive profile not loaded".into()))?
                .clone();
            let node = NodeId::new(d.node)
                .ok_or_else(|| RuntimeError::Failed("node id out of range".into()))?;
            sim.drives.push((
                d.name.clone(),
                SimDrive::new(node, profile, MotorModel::default()),
            ));
        }
        if let Some(b) = config.bms.as_ref().filter(|b| b.bus == bus.interface) {
            match b
                .profile
                .get()
                .ok_or_else(|| RuntimeError::Failed("BMS profile not loaded".into()))?
            {
                BmsProfile::Daly(p) => sim.daly = Some(SimDaly::new(p, b.address)),
                BmsProfile::Dbc(p) => {
                    sim.dbc = Some(SimDbcBms::new(p).ok_or_else(|| {
                        RuntimeError::Failed("the BMS profile's DBC does not parse".into())
                    })?)
                }
            }
        }
        let (tx, rx) = mpsc::channel(64);
        senders.push(tx);
        tasks.push(tokio::spawn(serve_bus(sim, clock, rx)));
    }
    if tasks.is_empty() {
        return Err(RuntimeError::Failed(
            "the configuration has no [[can]] interface to simulate".into(),
        ));
    }
    let mut lines = InputLines::new(
        tokio::io::BufReader::new(tokio::io::stdin()),
        MAX_LINE_BYTES,
    );
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .map_err(io("cannot install the SIGTERM handler"))?;
    // One SIGINT stream for the whole loop: a `ctrl_c()` made afresh each turn misses a
    // signal that arrives between two turns.
    let mut sigint = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::interrupt())
        .map_err(io("cannot install the SIGINT handler"))?;
    loop {
        tokio::select! {
            line = lines.next() => {
                let line = match line {
                    Ok(Some(InputLine::Text(line))) => line,
                    Ok(Some(refused)) => {
                        eprintln!("can-sim: line refused: {refused:?}");
                        continue;
                    }
                    _ => break,
                };
                match parse(&line) {
                    Ok(Some(cmd)) => {
                        for tx in &senders {
                            let _ = tx.send(cmd.clone()).await;
                        }
                    }
                    Ok(None) => {}
                    Err(e) => eprintln!("can-sim: {e}"),
                }
            }
            _ = sigterm.recv() => break,
            _ = sigint.recv() => break,
        }
    }
    Ok(())
}

fn parse(line: &str) -> Result<Option<SimCommand>, String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    Ok(Some(match words.as_slice() {
        [] => return Ok(None),
        ["heartbeat", name, "on"] => SimCommand::Heartbeat((*name).to_owned(), true),
        ["heartbeat", name, "off"] => SimCommand::Heartbeat((*name).to_owned(), false),
        ["fault", name, axis, code, refused @ ..] if refused.len() <= 1 => {
            let axis: usize = axis.parse().map_err(|_| format!("axis {axis:?}"))?;
            let code = u16::from_str_radix(code.trim_start_matches("0x"), 16)
                .map_err(|_| format!("EMCY code {code:?}"))?;
            let refused = match refused.first() {
                Some(n) => n.parse().map_err(|_| format!("refused edges {n:?}"))?,
                None => 0,
            };
            SimCommand::Fault((*name).to_owned(), axis.saturating_sub(1), code, refused)
        }
        ["tpdo", name, "on"] => SimCommand::Tpdo((*name).to_owned(), true),
        ["tpdo", name, "off"] => SimCommand::Tpdo((*name).to_owned(), false),
        ["estop", name, state] => SimCommand::EStop(
            (*name).to_owned(),
            match *state {
                "pressed" => Button::Pressed,
                "released" => Button::Released,
                "silent" => Button::Silent,
                _ => {
                    return Err(format!(
                        "e-stop state {state:?}: pressed, released or silent"
                    ));
                }
            },
        ),
        ["report"] => SimCommand::Report,
        _ => return Err(format!("unknown command {line:?}")),
    }))
}

async fn serve_bus(mut sim: SimBus, clock: RecordClock, mut commands: mpsc::Receiver<SimCommand>) {
    loop {
        match open(&sim.name) {
            Ok(socket) => {
                if let Err(e) = exchange(&mut sim, &socket, clock, &mut commands).await {
                    eprintln!("can-sim: {}: {e}", sim.name);
                }
            }
            Err(_) => {
                // The bus is gone; the drives are not: they run on and hear nothing.
                let until = tokio::time::Instant::now() + Duration::from_millis(100);
                while tokio::time::Instant::now() < until {
                    tokio::select! {
                        () = tokio::time::sleep(STEP) => {
                            let t = clock.now();
                            let mut lost = Vec::new();
                            for (_, d) in &mut sim.drives {
                                d.step(t, &mut lost);
                            }
                        }
                        cmd = commands.recv() => match cmd {
                            Some(cmd) => apply(&mut sim, cmd, &mut Vec::new()),
                            None => return,
                        },
                    }
                }
            }
        }
        if commands.is_closed() {
            return;
        }
    }
}

async fn exchange(
    sim: &mut SimBus,
    socket: &CanSocket,
    clock: RecordClock,
    commands: &mut mpsc::Receiver<SimCommand>,
) -> Result<(), String> {
    let mut step = tokio::time::interval(STEP);
    step.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut check = tokio::time::interval(Duration::from_millis(200));
    let mut last = clock.now();
    loop {
        let mut out = Vec::new();
        tokio::select! {
            _ = step.tick() => {
                let t = clock.now();
                let mut load_rpm = 0.0;
                for (_, d) in &mut sim.drives {
                    d.step(t, &mut out);
                    load_rpm += d.report().iter().map(|a| a.rpm.abs()).sum::<f64>();
                }
                let dt = t.saturating_since(last);
                last = t;
                let draw = -(1.5 + 0.004 * load_rpm);
                for battery in batteries(sim) {
                    battery.current_a = draw;
                    battery.step(dt);
                }
                if let Some(dbc) = &mut sim.dbc {
                    dbc.step(t, &mut out);
                }
                for (_, e) in &mut sim.estops {
                    e.step(t, &mut out);
                }
            }
            read = socket.read_frame() => {
                let frame = read.map_err(|e| e.to_string())?;
                let t = clock.now();
                if let Received::Data(f) = Received::from_socketcan(&CanAnyFrame::from(frame)) {
                    for (_, d) in &mut sim.drives {
                        d.on_frame(t, &f, &mut out);
                    }
                    if let Some(daly) = &mut sim.daly {
                        daly.on_frame(&f, &mut out);
                    }
                }
            }
            cmd = commands.recv() => match cmd {
                Some(cmd) => apply(sim, cmd, &mut out),
                None => return Ok(()),
            },
            _ = check.tick() => {
                if !interface_up(&sim.name).unwrap_or(false) {
                    return Err("interface down".into());
                }
            }
        }
        for f in out {
            let frame: CanFrame = f.to_socketcan();
            // A full buffer means nobody acknowledges; the frame is lost as on a real bus.
            let _ =
                tokio::time::timeout(Duration::from_millis(20), socket.write_frame(frame)).await;
        }
    }
}

fn batteries(sim: &mut SimBus) -> impl Iterator<Item = &mut Battery> {
    sim.daly
        .as_mut()
        .map(|d| &mut d.battery)
        .into_iter()
        .chain(sim.dbc.as_mut().map(|d| &mut d.battery))
}

fn apply(sim: &mut SimBus, cmd: SimCommand, out: &mut Vec<Frame>) {
    match cmd {
        SimCommand::Heartbeat(name, on) => {
            for (n, d) in &mut sim.drives {
                if *n == name {
                    d.set_heartbeat(on);
                }
            }
        }
        SimCommand::Fault(name, axis, code, refused) => {
            for (n, d) in &mut sim.drives {
                if *n == name {
                    d.refuse_resets(refused);
                    d.inject_fault(axis, code, out);
                }
            }
        }
        SimCommand::Tpdo(name, on) => {
            for (n, d) in &mut sim.drives {
                if *n == name {
                    d.set_tpdos(on);
                }
            }
        }
        SimCommand::EStop(name, button) => {
            for (n, e) in &mut sim.estops {
                if *n == name {
                    e.set(button);
                }
            }
        }
        SimCommand::Report => {
            let drives: Vec<_> = sim
                .drives
                .iter()
                .map(|(n, d)| {
                    json!({
                        "name": n,
                        "node": d.node().get(),
                        "nmt": format!("{:?}", d.nmt_state()),
                        "axes": d.report(),
                        "master_losses": d.master_losses(),
                        "reset_edges": d.reset_edges(),
                    })
                })
                .collect();
            let battery = batteries(sim)
                .next()
                .map(|b| json!({"voltage": b.voltage_v, "current": b.current_a, "soc": b.soc_pct}));
            println!(
                "{}",
                json!({"bus": sim.name, "drives": drives, "battery": battery})
            );
        }
    }
}
