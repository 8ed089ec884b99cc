//! The simulator's fault hooks that `chassisd bench soak` uses, through the whole engine:
//! the CAN interface down, lost drive heartbeats and a stalled IMU are each seen in the
//! status, stop a moving vehicle within the watchdog's bound where they must, and clear by
//! themselves once the fault ends; motion then needs the deliberate re-arm. Each runs on
//! both shipped plants.

use crate::common;

use chassisd::sim::lockstep::{Lockstep, PLANT_STEP};
use chassisd::sim::plant::PlantConfig;
use chassisd::vehicle::chassis::{CONTROL_PERIOD, status_bits};
use common::lockstep::{FIXED, START, SimRun as Vehicle};

/// The speed the vehicle runs at when a fault strikes, m/s.
const SPEED: f64 = 0.4;

fn twist(v: f64) -> String {
    format!(r#"{{"linear":{{"x":{v}}},"angular":{{"z":0.0}}}}"#)
}

fn bits(v: &Vehicle) -> u32 {
    v.status().chassis.as_ref().map_or(0, |c| c.status_bits)
}

/// Commands `speed` every 100 ms for `seconds` (refusals are the point of some tests).
fn drive(v: &mut Vehicle, speed: f64, seconds: f64) {
    for _ in 0..(seconds * 10.0).round() as u32 {
        let _ = v.send("cmd_vel", &twist(speed));
        v.run(0.1);
    }
}

/// Steps until the true speed is below 1 cm/s while commands keep coming; the time taken.
fn time_to_stop(v: &mut Vehicle, within: f64) -> Option<f64> {
    let steps = (within / PLANT_STEP.as_secs_f64()).round() as u64;
    for step in 0..steps {
        if v.speed().abs() < 0.01 {
            return Some(step as f64 * PLANT_STEP.as_secs_f64());
        }
        // The sender goes on commanding every 100 ms: the fault alone must stop it.
        if step.is_multiple_of(100) {
            let _ = v.send("cmd_vel", &twist(SPEED));
        }
        v.sim.step(FIXED, &mut v.sink);
    }
    None
}

/// cmd_timeout + one control period + the deceleration time from [`SPEED`], from the
/// chassisd configuration of the simulated vehicle.
fn stop_bound(v: &Vehicle) -> f64 {
    let chassis = v.sim.config().chassis.as_ref().expect("a chassis");
    chassis.cmd_timeout_s + CONTROL_PERIOD.as_secs_f64() + SPEED / chassis.max_decel_mps2
}

/// Steps (commanding zero, the re-arm) until `healthy` holds; the time taken.
fn time_to_recover(
    v: &mut Vehicle,
    within: f64,
    healthy: impl Fn(&Vehicle) -> bool,
) -> Option<f64> {
    let mut t = 0.0;
    while t < within {
        let _ = v.send("cmd_vel", &twist(0.0));
        v.run(0.1);
        t += 0.1;
        if healthy(v) {
            return Some(t);
        }
    }
    None
}

fn enabled_without(flag: u32) -> impl Fn(&Vehicle) -> bool {
    move |v| bits(v) & flag == 0 && bits(v) & status_bits::ENABLED != 0
}

/// The shipped plant files: every test runs on each.
const PLANTS: [&str; 2] = ["plant.mower.toml", "plant.delivery.toml"];

/// The vehicle of `plant` with noise `seed`, booted (3 s standing).
fn booted(plant: &str, seed: u64) -> Vehicle {
    let plant = PlantConfig::load(&common::repo().join("devices").join(plant)).expect("plant");
    let mut v = Vehicle::on(Lockstep::new(plant, seed, START).expect("sim"));
    v.run(3.0);
    v
}

/// On every plant: drives at [`SPEED`], sets the fault with `fault(true)`: the vehicle
/// stops within the bound and `flag` shows; clears it with `fault(false)`: the flag
/// clears and the drives are enabled again, and after the zero command motion works again.
fn stops_and_recovers(seed: u64, flag: u32, fault: impl Fn(&mut Vehicle, bool)) {
    for plant in PLANTS {
        let mut v = booted(plant, seed);
        drive(&mut v, SPEED, 2.0);
        assert!(v.speed() > 0.3, "{plant}: under way: {}", v.speed());
        fault(&mut v, true);
        let stop = time_to_stop(&mut v, 3.0).expect("stopped");
        let bound = stop_bound(&v);
        println!("{plant}: stopped in {stop:.3} s (bound {bound:.3} s)");
        assert!(stop <= bound, "{plant}: {stop} s > {bound} s");
        assert_ne!(bits(&v) & flag, 0, "{plant}: {:b}", bits(&v));
        fault(&mut v, false);
        let back = time_to_recover(&mut v, 20.0, enabled_without(flag));
        assert!(back.is_some(), "{plant}: not recovered: {:b}", bits(&v));
        println!("{plant}: recovered {back:?} s after the fault cleared");
        drive(&mut v, SPEED, 2.0);
        assert!(
            v.speed() > 0.3,
            "{plant}: drives again after the re-arm: {}",
            v.speed()
        );
    }
}

#[test]
fn a_can_interface_down_stops_the_vehicle_and_recovers_when_back() {
    stops_and_recovers(1, status_bits::BUS_DOWN, |v, down| {
        v.sim.set_bus_up(!down, &mut v.sink)
    });
}

#[test]
fn lost_drive_heartbeats_stop_the_vehicle_and_recover_when_back() {
    stops_and_recovers(2, status_bits::HEARTBEAT_LOST, |v, lost| {
        v.sim.vehicle_mut().set_drive_heartbeats(!lost)
    });
}

#[test]
fn a_stalled_imu_is_reported_and_clears_when_it_sends_again() {
    for plant in PLANTS {
        let mut v = booted(plant, 3);
        v.run(1.0);
        assert!(v.status().imu_ok, "{plant}: IMU healthy at the start");
        v.sim.vehicle_mut().set_imu_stalled(true);
        v.run(2.0);
        assert!(!v.status().imu_ok, "{plant}: a silent IMU is reported");
        v.sim.vehicle_mut().set_imu_stalled(false);
        v.run(0.5);
        assert!(v.status().imu_ok, "{plant}: and clears once it sends again");
    }
}
