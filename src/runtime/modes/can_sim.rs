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
use crate::devices::can::{Frame, Received};
use crate::runtime::clock::RecordClock;
use crate::runtime::drivers::can::{interface_up, open};
use crate::sim::can_devices::{self, BusLoad, Hardware, Injection, Report, SimCanDevice};
use crate::sim::estop::Button;

/// Simulation step.
const STEP: Duration = Duration::from_millis(5);

/// The devices on one interface, built by `sim::can_devices`' registry.
struct SimBus {
    name: String,
    devices: Vec<Box<dyn SimCanDevice>>,
}

#[derive(Debug, Clone)]
enum SimCommand {
    /// An injection for the device of this name.
    Inject(String, Injection),
    Report,
}

/// Runs until standard input closes or SIGTERM.
pub async fn run(config: VehicleConfig) -> crate::runtime::error::Result<()> {
    let clock = RecordClock::start();
    let mut senders = Vec::new();
    let mut tasks = Vec::new();
    for bus in &config.can {
        let sim = SimBus {
            name: bus.interface.clone(),
            devices: can_devices::build(&config, bus, &Hardware::default())
                .map_err(RuntimeError::Failed)?,
        };
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
                    Ok(Some(InputLine::NotUtf8(number))) => {
                        eprintln!("can-sim: line {number} refused: not UTF-8");
                        continue;
                    }
                    Ok(Some(InputLine::TooLong(number, bytes))) => {
                        eprintln!("can-sim: line {number} refused: {bytes} bytes, over the limit");
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
        ["heartbeat", name, "on"] => inject(name, Injection::Heartbeat(true)),
        ["heartbeat", name, "off"] => inject(name, Injection::Heartbeat(false)),
        ["fault", name, axis, code, refused @ ..] if refused.len() <= 1 => {
            let axis: usize = axis.parse().map_err(|_| format!("axis {axis:?}"))?;
            let code = u16::from_str_radix(code.trim_start_matches("0x"), 16)
                .map_err(|_| format!("EMCY code {code:?}"))?;
            let refused = match refused.first() {
                Some(n) => n.parse().map_err(|_| format!("refused edges {n:?}"))?,
                None => 0,
            };
            inject(
                name,
                Injection::Fault {
                    axis: axis.saturating_sub(1),
                    code,
                    refused,
                },
            )
        }
        ["tpdo", name, "on"] => inject(name, Injection::Tpdo(true)),
        ["tpdo", name, "off"] => inject(name, Injection::Tpdo(false)),
        ["estop", name, state] => inject(
            name,
            Injection::EStop(match *state {
                "pressed" => Button::Pressed,
                "released" => Button::Released,
                "silent" => Button::Silent,
                _ => {
                    return Err(format!(
                        "e-stop state {state:?}: pressed, released or silent"
                    ));
                }
            }),
        ),
        ["report"] => SimCommand::Report,
        _ => return Err(format!("unknown command {line:?}")),
    }))
}

fn inject(name: &str, injection: Injection) -> SimCommand {
    SimCommand::Inject(name.to_owned(), injection)
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
                            let mut load = BusLoad::default();
                            for d in &mut sim.devices {
                                d.step(t, &mut load, &mut lost);
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
    loop {
        let mut out = Vec::new();
        tokio::select! {
            _ = step.tick() => {
                let t = clock.now();
                let mut load = BusLoad::default();
                for d in &mut sim.devices {
                    d.step(t, &mut load, &mut out);
                }
            }
            read = socket.read_frame() => {
                let frame = read.map_err(|e| e.to_string())?;
                let t = clock.now();
                if let Received::Data(f) = Received::from_socketcan(&CanAnyFrame::from(frame)) {
                    for d in &mut sim.devices {
                        d.on_frame(t, &f, &mut out);
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

fn apply(sim: &mut SimBus, cmd: SimCommand, out: &mut Vec<Frame>) {
    match cmd {
        SimCommand::Inject(name, injection) => {
            for d in sim.devices.iter_mut().filter(|d| d.name() == name) {
                d.inject(injection, out);
            }
        }
        SimCommand::Report => {
            let reports: Vec<Report> = sim.devices.iter().map(|d| d.report()).collect();
            let drives: Vec<&serde_json::Value> = reports
                .iter()
                .filter_map(|r| match r {
                    Report::Drive(v) => Some(v),
                    _ => None,
                })
                .collect();
            let battery = reports.iter().find_map(|r| match r {
                Report::Battery(v) => Some(v),
                _ => None,
            });
            let cutter = reports.iter().find_map(|r| match r {
                Report::Cutter(v) => Some(v),
                _ => None,
            });
            println!(
                "{}",
                json!({"bus": sim.name, "drives": drives, "battery": battery, "cutter": cutter})
            );
        }
    }
}
