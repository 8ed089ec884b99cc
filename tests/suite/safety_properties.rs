//! The safety rules of docs/safety.md, as properties of the drive-train arbiter and its
//! supervisor (`vehicle::chassis`, `vehicle::safety`) over random sequences of commands, faults,
//! e-stops, resets and silences. Proptest keeps failing cases in
//! `tests/safety_properties.proptest-regressions` (persistence on) and replays them first.

use std::time::Duration;

use chassisd::config::chassis::{ChassisConfig, WheelRadius};
use chassisd::time::Timestamp;
use chassisd::vehicle::chassis::{
    Chassis, ChassisFeedback, DriveSummary, MAX_LEAD_S, WheelCommand, status_bits,
};
use chassisd::vehicle::safety::{ControlLinkConfig, EStopInput, Power, SafetyConfig, State};
use proptest::prelude::*;

/// The engine's control period.
const PERIOD_MS: u64 = 10;

/// A typical configuration, for the worked example.
fn chassis_config() -> ChassisConfig {
    ChassisConfig {
        wheel_radius_m: WheelRadius::both(0.1),
        track_m: 0.5,
        max_speed_mps: 1.0,
        max_yaw_rate_rps: 1.5,
        max_accel_mps2: 0.5,
        max_decel_mps2: 1.0,
        max_yaw_accel_rps2: 2.0,
        cmd_timeout_s: 0.3,
        enable_on_start: true,
        quick_stop_s: 0.2,
        reset_timeout_s: 1.0,
    }
}

/// Legal configurations: geometry, ramps, command timeout and quick-stop time across the
/// ranges the configuration accepts (the command timeout from 50 ms, a few periods, to 2 s).
fn config_sweep() -> impl Strategy<Value = ChassisConfig> {
    (
        (0.05f64..0.5, 0.97f64..1.03, 0.2f64..1.5),
        (0.1f64..3.0, 1.0f64..2.0, 0.5f64..5.0),
        (5u64..=200, 0u64..=100),
    )
        .prop_map(
            |(
                (radius, right_factor, track),
                (accel, decel_factor, yaw_accel),
                (timeout, quick),
            )| ChassisConfig {
                // Calibrated wheels differ by a few per cent.
                wheel_radius_m: WheelRadius {
                    left: radius,
                    right: radius * right_factor,
                },
                track_m: track,
                max_accel_mps2: accel,
                max_decel_mps2: accel * decel_factor,
                max_yaw_accel_rps2: yaw_accel,
                cmd_timeout_s: timeout as f64 / 100.0,
                quick_stop_s: quick as f64 / 100.0,
                ..chassis_config()
            },
        )
}

/// A chassis with `config`, enabled on start, optionally with a control link required from
/// start.
fn chassis(config: ChassisConfig, control_link: bool) -> Chassis {
    Chassis::new(
        config,
        SafetyConfig {
            cmd_timeout: config.cmd_timeout(),
            quick_stop: config.quick_stop(),
            reset_timeout: config.reset_timeout(),
            control_link: control_link.then_some(ControlLinkConfig {
                timeout: Duration::from_millis(500),
                required_from_start: true,
            }),
            enable_on_start: true,
        },
    )
}

/// What happens between two control ticks.
#[derive(Debug, Clone)]
enum Event {
    /// A velocity command (m/s, rad/s); zero is the deliberate act.
    Velocity(f64, f64),
    /// A closed-loop move's velocity (m/s, rad/s): never a deliberate act, and its command
    /// may lead the drives' modelled speed.
    Move(f64, f64),
    /// The explicit reset.
    Reset,
    /// The operator's stop.
    OperatorStop,
    /// The software e-stop engaged or released.
    SoftwareEStop(bool),
    /// The drive raises a fault; `sticky` faults survive resets.
    Fault { sticky: bool },
    /// The sticky fault condition goes away (a later reset can clear it).
    FaultCondition(bool),
    /// The CAN interface goes down or up.
    Bus(bool),
    /// The e-stop input reports pressed or released.
    EStopInput(bool),
    /// The e-stop input goes silent (its frames stop) or speaks again.
    EStopSilent(bool),
    /// A control-link heartbeat.
    Heartbeat,
    /// Nothing for this many ticks.
    Wait(u8),
}

fn event() -> impl Strategy<Value = Event> {
    let speed = prop_oneof![
        3 => Just(0.0),
        5 => -1.5f64..1.5,
    ];
    prop_oneof![
        20 => (speed.clone(), speed.clone()).prop_map(|(v, w)| Event::Velocity(v, w)),
        10 => (speed.clone(), speed).prop_map(|(v, w)| Event::Move(v, w)),
        2 => Just(Event::Reset),
        1 => Just(Event::OperatorStop),
        1 => any::<bool>().prop_map(Event::SoftwareEStop),
        2 => any::<bool>().prop_map(|sticky| Event::Fault { sticky }),
        1 => any::<bool>().prop_map(Event::FaultCondition),
        1 => any::<bool>().prop_map(Event::Bus),
        1 => any::<bool>().prop_map(Event::EStopInput),
        1 => any::<bool>().prop_map(Event::EStopSilent),
        6 => Just(Event::Heartbeat),
        12 => (1u8..60).prop_map(Event::Wait),
    ]
}

/// The drive and bus the chassis sees, as a small model: faults latch in the drive until a
/// reset clears them, unless their condition is still there.
#[derive(Debug, Default)]
struct Plant {
    fault: bool,
    condition: bool,
    bus_down: bool,
    estop_pressed: bool,
    estop_silent: bool,
    estop_heard: Option<Timestamp>,
}

impl Plant {
    fn feedback(&mut self, t: Timestamp, wheels: Option<&WheelCommand>) -> ChassisFeedback {
        if !self.estop_silent {
            self.estop_heard = Some(t);
        }
        let speed = wheels.map(|w| (w.left_rad_s, w.right_rad_s));
        ChassisFeedback {
            left: chassisd::vehicle::chassis::WheelFeedback {
                velocity_rad_s: speed.map(|s| s.0),
                angle_rad: None,
                received: None,
                velocity_received: None,
            },
            right: chassisd::vehicle::chassis::WheelFeedback {
                velocity_rad_s: speed.map(|s| s.1),
                angle_rad: None,
                received: None,
                velocity_received: None,
            },
            drives: vec![DriveSummary {
                name: "drive".into(),
                ready: !self.fault && !self.bus_down,
                running: !self.bus_down,
                enabled: !self.fault,
                fault: self.fault.then(|| "over-current".to_owned()),
                heartbeat_lost: false,
                resetting: false,
            }],
            bus_down: self.bus_down,
            estops: vec![EStopInput {
                name: "front".into(),
                pressed: Some(self.estop_pressed),
                heard: self.estop_heard,
                timeout: Duration::from_millis(100),
            }],
        }
    }
}

fn ms(v: u64) -> Timestamp {
    Timestamp::from_micros(v * 1000)
}

/// Speed (m/s) and yaw rate (rad/s) of a wheel command on `c`.
fn body(w: &WheelCommand, c: &ChassisConfig) -> (f64, f64) {
    let (l, r) = (
        w.left_rad_s * c.wheel_radius_m.left,
        w.right_rad_s * c.wheel_radius_m.right,
    );
    ((l + r) / 2.0, (r - l) / c.track_m)
}

fn is_latched(state: &State) -> bool {
    matches!(state, State::Latched { .. } | State::Resetting { .. })
}

/// Runs `events` on `config`, checking every rule at every tick.
fn check(events: &[Event], config: ChassisConfig, control_link: bool) -> Result<(), TestCaseError> {
    let mut chassis = chassis(config, control_link);
    let mut plant = Plant {
        estop_heard: Some(ms(0)),
        ..Plant::default()
    };
    let mut now = 0u64;
    // The last command the chassis took: time and whether it asked for motion.
    let mut accepted: Option<(u64, bool)> = None;
    // Since the last latch: was there a deliberate act (accepted zero command or reset)?
    let mut deliberate_since_latch = false;
    let mut was_latched = false;
    let mut last = WheelCommand {
        power: Power::Enabled,
        reset_faults: false,
        left_rad_s: 0.0,
        right_rad_s: 0.0,
    };
    // The command in force came from a move; the modelled drive speed the last tick.
    let mut autonomous = false;
    let mut last_reference = (0.0, 0.0);
    chassis.feedback(plant.feedback(ms(now), None));
    for event in events {
        let t = ms(now);
        let ticks = match event {
            Event::Velocity(v, w) => {
                if chassis.command(t, *v, *w).is_ok() {
                    let zero = *v == 0.0 && *w == 0.0;
                    accepted = Some((now, !zero));
                    deliberate_since_latch |= zero;
                    autonomous = false;
                }
                1
            }
            Event::Move(v, w) => {
                if chassis.autonomous(t, *v, *w).is_ok() {
                    accepted = Some((now, *v != 0.0 || *w != 0.0));
                    autonomous = true;
                }
                1
            }
            Event::Reset => {
                if chassis.reset(t).is_ok() {
                    deliberate_since_latch = true;
                }
                1
            }
            Event::OperatorStop => {
                chassis.operator_stop(t);
                1
            }
            Event::SoftwareEStop(on) => {
                chassis.software_estop(t, *on);
                1
            }
            Event::Fault { sticky } => {
                plant.fault = true;
                plant.condition = *sticky;
                1
            }
            Event::FaultCondition(on) => {
                plant.condition = *on;
                1
            }
            Event::Bus(down) => {
                plant.bus_down = *down;
                1
            }
            Event::EStopInput(pressed) => {
                plant.estop_pressed = *pressed;
                1
            }
            Event::EStopSilent(silent) => {
                plant.estop_silent = *silent;
                1
            }
            Event::Heartbeat => {
                chassis.control_heartbeat(t);
                1
            }
            Event::Wait(n) => u64::from(*n),
        };
        for _ in 0..ticks {
            now += PERIOD_MS;
            let t = ms(now);
            chassis.feedback(plant.feedback(t, Some(&last)));
            let before = chassis.safety().state().clone();
            let cmd = chassis.tick(t);
            let state = chassis.safety().state().clone();
            let status = chassis.status(t);
            let moving = cmd.left_rad_s != 0.0 || cmd.right_rad_s != 0.0;

            // 1. No non-zero wheel target after cmd_timeout + one period without a fresh
            //    command.
            let fresh = accepted.is_some_and(|(at, _)| {
                Duration::from_millis(now - at)
                    <= config.cmd_timeout() + Duration::from_millis(PERIOD_MS)
            });
            prop_assert!(
                !moving || fresh,
                "moving at {now} ms with the last command at {accepted:?}"
            );

            // 2. Ramps are never exceeded; only a stop drops to zero at once. A manual
            //    command ramps itself; a move's command stays within its lead of a modelled
            //    drive speed that ramps within the limits.
            let (v0, w0) = body(&last, &config);
            let (v1, w1) = body(&cmd, &config);
            let dt = PERIOD_MS as f64 / 1000.0;
            let stop = v1 == 0.0 && w1 == 0.0;
            let ramped = |from: (f64, f64), to: (f64, f64)| -> Result<(), TestCaseError> {
                let slowing = to.0.abs() < from.0.abs() || to.0 * from.0 < 0.0;
                let limit = if slowing {
                    config.max_decel_mps2
                } else {
                    config.max_accel_mps2
                };
                prop_assert!(
                    (to.0 - from.0).abs() <= limit * dt + 1e-9,
                    "speed jumped {} → {} at {now} ms",
                    from.0,
                    to.0
                );
                prop_assert!(
                    (to.1 - from.1).abs() <= config.max_yaw_accel_rps2 * dt + 1e-9,
                    "yaw rate jumped {} → {} at {now} ms",
                    from.1,
                    to.1
                );
                Ok(())
            };
            let lead_v = MAX_LEAD_S * config.max_accel_mps2.max(config.max_decel_mps2);
            let lead_w = MAX_LEAD_S * config.max_yaw_accel_rps2;
            let reference = chassis.reference();
            if !stop && autonomous {
                ramped(last_reference, reference)?;
                prop_assert!(
                    (v1 - reference.0).abs() <= lead_v + 1e-9
                        && (w1 - reference.1).abs() <= lead_w + 1e-9,
                    "a move's command ({v1}, {w1}) beyond its lead of the drives' \
                     modelled speed {reference:?} at {now} ms"
                );
            } else if !stop {
                ramped((v0, w0), (v1, w1))?;
            }
            last_reference = reference;

            // 3. A latch means zero targets, a quick stop, then disabled drives.
            if let State::Latched { since, .. } = &state {
                prop_assert!(!moving, "moving while latched at {now} ms");
                prop_assert!(
                    matches!(cmd.power, Power::QuickStop | Power::Disabled),
                    "{:?} while latched",
                    cmd.power
                );
                if t.saturating_since(*since) >= config.quick_stop() {
                    prop_assert_eq!(cmd.power, Power::Disabled);
                }
            }
            if matches!(state, State::Resetting { .. }) {
                prop_assert!(!moving);
                prop_assert_eq!(cmd.power, Power::Disabled);
            }

            // 4. A non-zero stream never re-arms: leaving a latch takes a deliberate act.
            if is_latched(&state) && !is_latched(&before) {
                deliberate_since_latch = false;
            }
            if was_latched && !is_latched(&state) {
                prop_assert!(
                    deliberate_since_latch,
                    "re-armed at {now} ms without a zero command or a reset"
                );
            }
            was_latched = is_latched(&state);

            // 5. Every stop has a reason. (A ramp may pass through zero on its way to the
            //    other direction: that is no stop.)
            let asked = accepted.is_some_and(|(_, motion)| motion);
            let (lead_v, lead_w) = if autonomous {
                (lead_v, lead_w)
            } else {
                (0.0, 0.0)
            };
            let ramp_through_zero = (v0 != 0.0 || w0 != 0.0)
                && v0.abs() <= config.max_decel_mps2 * dt + lead_v + 1e-9
                && w0.abs() <= config.max_yaw_accel_rps2 * dt + lead_w + 1e-9;
            if asked && !moving && !ramp_through_zero {
                prop_assert!(
                    status.stop_reason.is_some()
                        || status.status_bits & status_bits::COMMAND_TIMEOUT != 0,
                    "stopped without a reason at {now} ms: {status:?}"
                );
            }
            if is_latched(&state) {
                prop_assert!(status.stop_reason.is_some());
                prop_assert!(status.status_bits & status_bits::AWAITING_COMMAND != 0);
            }

            // The drive model: a reset clears a fault whose condition has gone.
            if cmd.reset_faults && !plant.condition {
                plant.fault = false;
            }
            last = cmd;
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn safety_rules_hold(
        config in config_sweep(),
        events in prop::collection::vec(event(), 1..120),
    ) {
        check(&events, config, false)?;
    }

    #[test]
    fn safety_rules_hold_with_a_required_control_link(
        config in config_sweep(),
        events in prop::collection::vec(event(), 1..120),
    ) {
        check(&events, config, true)?;
    }
}

/// The finding of the review, as an example: after a fault, a joystick stream that never
/// pauses does not move the vehicle until it sends zero.
#[test]
fn a_continuous_stream_after_a_fault_does_not_move_until_zero() {
    let mut events = vec![Event::Velocity(0.5, 0.0), Event::Wait(10)];
    events.push(Event::Fault { sticky: false });
    for _ in 0..100 {
        events.push(Event::Velocity(0.5, 0.0));
    }
    let config = chassis_config();
    check(&events, config, false).expect("rules hold");
    let mut chassis = chassis(config, false);
    let mut plant = Plant {
        estop_heard: Some(ms(0)),
        ..Plant::default()
    };
    let mut now = 0;
    let mut step = |chassis: &mut Chassis, plant: &mut Plant, vx: f64| {
        now += PERIOD_MS;
        let _ = chassis.command(ms(now), vx, 0.0);
        chassis.feedback(plant.feedback(ms(now), None));
        let cmd = chassis.tick(ms(now));
        if cmd.reset_faults {
            plant.fault = false;
        }
        body(&cmd, &config).0
    };
    for _ in 0..50 {
        step(&mut chassis, &mut plant, 0.5);
    }
    plant.fault = true;
    for _ in 0..300 {
        assert_eq!(step(&mut chassis, &mut plant, 0.5), 0.0);
    }
    assert_eq!(step(&mut chassis, &mut plant, 0.0), 0.0);
    let mut v = 0.0;
    for _ in 0..20 {
        v = step(&mut chassis, &mut plant, 0.5);
    }
    assert!(v > 0.05, "moves again after the zero command: {v}");
}

/// A move's command passes through zero on its way from one turn direction to the other:
/// no stop, so no reason is owed (a case the properties once shrank to).
#[test]
fn a_move_reversing_its_turn_passes_through_zero() {
    let config = ChassisConfig {
        wheel_radius_m: WheelRadius::both(0.05),
        track_m: 0.2,
        max_accel_mps2: 2.108,
        max_decel_mps2: 2.108,
        max_yaw_accel_rps2: 0.5,
        cmd_timeout_s: 0.05,
        ..chassis_config()
    };
    let events = [
        Event::Move(0.82, 0.0),
        Event::Wait(5),
        Event::Velocity(0.0, 0.40),
        Event::FaultCondition(false),
        Event::Move(0.0, -0.26),
    ];
    check(&events, config, false).expect("rules hold");
}

/// Starting backwards from rest is acceleration, whatever the deceleration limit allows.
#[test]
fn a_move_from_rest_backwards_accelerates_within_the_limit() {
    let config = ChassisConfig {
        max_accel_mps2: 0.1,
        max_decel_mps2: 0.12,
        ..chassis_config()
    };
    check(&[Event::Move(-1.4, 0.0), Event::Wait(3)], config, false).expect("rules hold");
}
