//! A velocity command's way to the bus, in simulation time (deterministic, not a timing
//! test): the simulated vehicle in lockstep with the engine; each change of speed reaches the
//! left drive's RPDO within one control period, whatever the command's phase in the period.

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
