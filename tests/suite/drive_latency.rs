//! A velocity command's way to the bus, in simulation time (deterministic, not a timing
//! test): the simulated vehicle in lockstep with the engine; each change of speed reaches the
//! left drive's RPDO within one control period, whatever the command's phase in the period,
//! and so does the watchdog's stop when commands cease.

use std::time::Duration;

use chassisd::devices::can::Received;
use chassisd::devices::gnss::FixQuality;
use chassisd::engine::EngineOutput;
use chassisd::record::{Payload, Record};
use chassisd::sim::lockstep::{Lockstep, PLANT_STEP, Sink};
use chassisd::sim::plant::{GnssCondition, LEFT_NODE, PlantConfig, SIM_BUS};
use chassisd::time::Timestamp;
use chassisd::vehicle::chassis::CONTROL_PERIOD;

const FIXED: GnssCondition = GnssCondition {
    quality: Some(FixQuality::RtkFixed),
    offset: (0.0, 0.0),
};

/// The target velocity of every RPDO chassisd sends to the left drive.
#[derive(Default)]
struct Rpdos(Vec<(Timestamp, i32)>);

impl Sink for Rpdos {
    fn record(&mut self, record: &Record) {
        let rpdo = 0x200 + u32::from(LEFT_NODE.get());
        if let Payload::CanTx(frame) = &record.payload
            && record.source == SIM_BUS
            && let Received::Data(f) = Received::from_socketcan(frame)
            && f.id() == rpdo
            && let Some(b) = f.data().get(2..6)
        {
            self.0
                .push((record.t, i32::from_le_bytes([b[0], b[1], b[2], b[3]])));
        }
    }
    fn output(&mut self, _: EngineOutput) {}
}

/// Holds `v` for `hold`, a command every 100 ms; returns when the first was sent.
fn hold(sim: &mut Lockstep, out: &mut Rpdos, v: f64, hold: Duration) -> Timestamp {
    let twist = format!(r#"{{"linear":{{"x":{v}}},"angular":{{"z":0.0}}}}"#);
    let sent = sim.time();
    let steps = (hold.as_secs_f64() / PLANT_STEP.as_secs_f64()).round() as u64;
    for k in 0..steps {
        if k % 100 == 0 {
            sim.command("cmd_vel", &twist, out);
        }
        sim.step(FIXED, out);
    }
    sent
}

#[test]
fn a_new_speed_reaches_the_drive_within_one_control_period() {
    let plant = PlantConfig::builtin().expect("built-in plant");
    let mut sim = Lockstep::new(plant, 3, Timestamp::from_micros(1_767_225_600_000_000))
        .expect("simulated vehicle");
    let mut out = Rpdos::default();
    // Boot, enable, and settle at 0.2 m/s.
    hold(&mut sim, &mut out, 0.0, Duration::from_secs(2));
    hold(&mut sim, &mut out, 0.2, Duration::from_millis(1500));
    let periods = CONTROL_PERIOD.as_millis() as u64;
    let mut worst = Duration::ZERO;
    for phase in 0..periods {
        // Move the next command `phase` ms into a control period.
        while (sim.time().as_micros() / 1000) % periods != phase {
            sim.step(FIXED, &mut out);
        }
        let v = if phase % 2 == 0 { 0.4 } else { 0.2 };
        let before = out.0.last().map(|(_, target)| *target);
        let sent = hold(&mut sim, &mut out, v, Duration::from_millis(1500));
        let (at, _) = *out
            .0
            .iter()
            .find(|(t, target)| *t >= sent && Some(*target) != before)
            .expect("the new speed reaches the drive");
        let latency = at.saturating_since(sent);
        worst = worst.max(latency);
        assert!(
            latency <= CONTROL_PERIOD,
            "phase {phase} ms: the new target left {latency:?} after the command"
        );
    }
    eprintln!("worst command-to-RPDO latency over every phase: {worst:?}");
}

/// The simulator's command timeout (src/sim/lockstep.rs).
const CMD_TIMEOUT: Duration = Duration::from_millis(500);

#[test]
fn a_lapsed_command_zeroes_the_target_from_the_first_stale_tick_whatever_its_phase() {
    let plant = PlantConfig::builtin().expect("built-in plant");
    let mut sim = Lockstep::new(plant, 5, Timestamp::from_micros(1_767_225_600_000_000))
        .expect("simulated vehicle");
    let mut out = Rpdos::default();
    hold(&mut sim, &mut out, 0.0, Duration::from_secs(2));
    // The drives' periodic refresh (20 ms) and the control period (10 ms) meet the command's
    // lapse at every phase over 40 ms: the last command comes `phase` ms after a second of
    // commands every 100 ms.
    for phase in 0..40 {
        hold(&mut sim, &mut out, 0.3, Duration::from_millis(1000));
        hold_silent(&mut sim, &mut out, Duration::from_millis(phase));
        let last = hold(&mut sim, &mut out, 0.3, Duration::from_millis(1));
        let from = out.0.len();
        hold_silent(&mut sim, &mut out, Duration::from_millis(800));
        let stale_from = last.saturating_add(CMD_TIMEOUT);
        let frames = &out.0[from..];
        assert!(
            frames.iter().any(|(t, v)| *t <= stale_from && *v != 0),
            "phase {phase} ms: the drive was driven until the lapse"
        );
        // A tick after the timeout sees the command stale: nothing it sends carries a target,
        // not even a refresh of the last one in the instant the target changes.
        for (t, target) in frames.iter().filter(|(t, _)| *t > stale_from) {
            assert_eq!(
                *target,
                0,
                "phase {phase} ms: target {target} at {:?} after the lapse",
                t.saturating_since(stale_from)
            );
        }
        let stopped = frames
            .iter()
            .find(|(t, _)| *t > stale_from)
            .expect("a frame after the lapse");
        assert!(
            stopped.0.saturating_since(stale_from) <= CONTROL_PERIOD,
            "phase {phase} ms: the stop left {:?} after the lapse",
            stopped.0.saturating_since(stale_from)
        );
    }
}

/// Steps for `span` with no command.
fn hold_silent(sim: &mut Lockstep, out: &mut Rpdos, span: Duration) {
    for _ in 0..(span.as_secs_f64() / PLANT_STEP.as_secs_f64()).round() as u64 {
        sim.step(FIXED, out);
    }
}
