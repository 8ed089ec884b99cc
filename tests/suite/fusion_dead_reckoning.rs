//! What may change the dead reckoning (docs/fusion.md, "What may change the dead reckoning"):
//! whatever a single, DGPS/SBAS or RTK-float receiver reports (fixes with steps, wander and
//! wild ones; courses late, smoothed, noisy when slow, from the antenna's motion in turns or
//! garbage; dual-antenna headings of those epochs), the odom frame's yaw is the gyro's
//! integral less the bias its standstills teach: exactly what it is without any GNSS. Only
//! an RTK-fixed epoch's heading may correct it, which the last test shows the harness sees.
//!
//! The simulated vehicle is back-driven through random motions (standstills, reversing,
//! turns) with a biased gyro, once without GNSS and once with a hostile receiver's
//! sentences, and the odom frame's yaw is compared at every control tick.

use chassisd::bench::real::recording::Epoch;
use chassisd::devices::gnss::FixQuality;
use chassisd::devices::gnss::encode::sentence;
use chassisd::engine::EngineOutput;
use chassisd::geodesy::{Enu, Geodetic};
use chassisd::record::{Payload, Record};
use chassisd::sim::lockstep::{GNSS_SOURCE, Lockstep, PLANT_STEP, Sink};
use chassisd::sim::plant::{ForcedMotion, GnssCondition, PlantConfig};
use chassisd::time::Timestamp;
use proptest::prelude::*;

/// Sessions start here (2026-01-01T00:00:00Z).
const START: Timestamp = Timestamp::from_micros(1_767_225_600_000_000);
/// The drives boot, standing, before the motion starts, s.
const BOOT_S: f64 = 3.0;

/// The odom frame's yaw at every control tick, and how many ticks had a map pose.
#[derive(Default)]
struct OdomYaw(Vec<(Timestamp, f64)>, usize);

impl Sink for OdomYaw {
    fn record(&mut self, _: &Record) {}

    fn output(&mut self, output: EngineOutput) {
        if let EngineOutput::Poses(t, r) = output
            && let Some(o) = r.odom
        {
            self.0.push((t, o.yaw));
            self.1 += usize::from(r.map.is_some());
        }
    }
}

/// One leg of the motion: seconds, speed (m/s), yaw rate (rad/s).
type Leg = (f64, f64, f64);

/// What the receiver does wrong.
#[derive(Debug, Clone)]
struct Receiver {
    rate_hz: f64,
    /// Qualities it cycles through, epoch by epoch in runs of 20.
    qualities: Vec<FixQuality>,
    /// Its latency, s (the configuration says none).
    latency_s: f64,
    /// White position noise, m.
    white_m: f64,
    /// A step of the position's error every this many epochs, m.
    step: (u32, f64),
    /// A fix hundreds of metres off every this many epochs.
    wild_every: u32,
    /// How late its course is beyond its latency, s, and its smoothing's weight (0: none).
    course_lag_s: f64,
    course_smoothing: f64,
    /// Course noise as velocity noise, m/s.
    course_noise_mps: f64,
    /// A course of garbage every this many epochs.
    garbage_every: u32,
    /// A dual-antenna heading with this offset (degrees), or none.
    heading_offset_deg: Option<f64>,
}

fn receiver() -> impl Strategy<Value = Receiver> {
    let quality = prop_oneof![
        Just(FixQuality::Single),
        Just(FixQuality::Dgps),
        Just(FixQuality::RtkFloat),
    ];
    (
        prop_oneof![Just(1.0), Just(5.0), Just(10.0)],
        proptest::collection::vec(quality, 1..4),
        0.0f64..0.3,
        0.01f64..2.0,
        (10u32..40, 0.5f64..5.0),
        10u32..200,
        (0.0f64..0.5, 0.0f64..0.9),
        0.01f64..0.5,
        3u32..100,
        proptest::option::of(-10.0f64..10.0),
    )
        .prop_map(
            |(
                rate_hz,
                qualities,
                latency_s,
                white_m,
                step,
                wild_every,
                (course_lag_s, course_smoothing),
                course_noise_mps,
                garbage_every,
                heading_offset_deg,
            )| Receiver {
                rate_hz,
                qualities,
                latency_s,
                white_m,
                step,
                wild_every,
                course_lag_s,
                course_smoothing,
                course_noise_mps,
                garbage_every,
                heading_offset_deg,
            },
        )
}

fn legs() -> impl Strategy<Value = Vec<Leg>> {
    let leg = prop_oneof![
        (1.0f64..4.0).prop_map(|s| (s, 0.0, 0.0)),
        (4.0f64..10.0, 0.3f64..3.0, -0.5f64..0.5),
        (1.0f64..4.0, -0.8f64..-0.2, -0.3f64..0.3),
        (1.0f64..4.0, 0.0f64..0.01, -0.8f64..0.8),
    ];
    proptest::collection::vec(leg, 8..14)
}

/// A deterministic noise source for the receiver (the plant has its own).
struct Noise(u64);

impl Noise {
    fn normal(&mut self) -> f64 {
        (0..12)
            .map(|_| {
                self.0 = self
                    .0
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                (self.0 >> 11) as f64 / (1u64 << 53) as f64
            })
            .sum::<f64>()
            - 6.0
    }
}

/// Runs the motion on the built-in mower (gyro bias `bias`), with the receiver's sentences
/// when given; the odom frame's yaw at every control tick.
fn run(legs: &[Leg], bias: f64, receiver: Option<&Receiver>, seed: u64) -> OdomYaw {
    let mut plant = PlantConfig::builtin().expect("plant");
    plant.gnss.dual_antenna = false;
    let frame = Enu::new(Geodetic {
        lat_deg: plant.datum[0],
        lon_deg: plant.datum[1],
        h_m: plant.datum[2],
    });
    let antenna = plant.geometry.antenna;
    let mut sim = Lockstep::new(plant, 1, START).expect("lockstep");
    sim.engine_mut().emit_poses();
    let mut sink = OdomYaw::default();
    let no_fix = GnssCondition {
        quality: None,
        offset: (0.0, 0.0),
    };
    let step = PLANT_STEP.as_secs_f64();
    let total: f64 = BOOT_S + legs.iter().map(|l| l.0).sum::<f64>();
    let mut noise = Noise(seed);
    // The receiver's state: its slow error, its epoch count, its smoothed course, and the
    // antenna's past velocities for a late course.
    let (mut slow, mut epoch, mut smoothed) = ((0.0, 0.0), 0u32, None::<f64>);
    let mut history: Vec<(f64, (f64, f64))> = Vec::new();
    let mut pending: Vec<(Timestamp, Payload)> = Vec::new();
    let mut next_epoch = BOOT_S;
    for k in 0..(total / step).round() as u64 {
        let s = k as f64 * step;
        let (v, w) = if s < BOOT_S {
            (0.0, 0.0)
        } else {
            let mut at = s - BOOT_S;
            legs.iter()
                .find_map(|&(d, v, w)| {
                    if at < d {
                        Some((v, w))
                    } else {
                        at -= d;
                        None
                    }
                })
                .unwrap_or((0.0, 0.0))
        };
        if s >= BOOT_S {
            sim.vehicle_mut().force_motion(Some(ForcedMotion {
                v,
                wheel_yaw_rate: w,
                gyro_z: w + bias,
            }));
        }
        let truth = sim.vehicle().truth();
        let (sy, cy) = truth.yaw.sin_cos();
        // The antenna's velocity in the map frame (it swings out in turns).
        let velocity = (
            truth.v * cy - truth.w * (sy * antenna[0] + cy * antenna[1]),
            truth.v * sy + truth.w * (cy * antenna[0] - sy * antenna[1]),
        );
        history.push((s, velocity));
        if let Some(r) = receiver
            && s >= next_epoch
        {
            next_epoch += 1.0 / r.rate_hz;
            epoch += 1;
            let quality = r.qualities[(epoch / 20) as usize % r.qualities.len()];
            if epoch.is_multiple_of(r.step.0) {
                slow.0 += r.step.1 * noise.normal();
                slow.1 += r.step.1 * noise.normal();
            }
            slow.0 += 0.05 * noise.normal();
            slow.1 += 0.05 * noise.normal();
            let wild = if epoch.is_multiple_of(r.wild_every) {
                300.0 + 100.0 * noise.normal()
            } else {
                0.0
            };
            let en = (
                truth.x + cy * antenna[0] - sy * antenna[1]
                    + slow.0
                    + r.white_m * noise.normal()
                    + wild,
                truth.y + sy * antenna[0] + cy * antenna[1] + slow.1 + r.white_m * noise.normal(),
            );
            let late = s - r.course_lag_s;
            let (ve, vn) = history
                .iter()
                .rev()
                .find(|(t, _)| *t <= late)
                .map_or(velocity, |(_, v)| *v);
            let speed = ve.hypot(vn);
            let noisy = {
                let n = r.course_noise_mps / speed.max(0.05);
                (ve.atan2(vn) + n * noise.normal()).to_degrees()
            };
            let course = match smoothed {
                Some(c) => c * r.course_smoothing + noisy * (1.0 - r.course_smoothing),
                None => noisy,
            };
            smoothed = Some(course);
            let course = if epoch.is_multiple_of(r.garbage_every) {
                360.0 * noise.normal().abs().fract()
            } else {
                course
            };
            let g = frame.to_geodetic(&nalgebra::Vector3::new(en.0, en.1, 0.0));
            let t = START.saturating_add(std::time::Duration::from_secs_f64(s));
            let mut bytes = Epoch {
                utc_us: t.as_micros() as i64,
                quality,
                position: (g.lat_deg, g.lon_deg, g.h_m),
                hdop: 1.0,
                velocity: Some((speed + r.course_noise_mps * noise.normal().abs(), course)),
            }
            .sentences()
            .to_vec();
            if let Some(offset) = r.heading_offset_deg {
                let mut hdt = String::new();
                // The simulated receiver's heading noise (0.3°, as configured).
                let heading = 90.0 - truth.yaw.to_degrees() + offset + 0.3 * noise.normal();
                sentence(
                    &mut hdt,
                    &format!("GNHDT,{:.2},T", heading.rem_euclid(360.0)),
                );
                bytes.extend_from_slice(hdt.as_bytes());
            }
            let arrives = t.saturating_add(std::time::Duration::from_secs_f64(r.latency_s));
            pending.push((arrives, Payload::Serial(bytes.into())));
        }
        while let Some(i) = pending.iter().position(|(at, _)| *at <= sim.time()) {
            let (_, payload) = pending.remove(i);
            sim.input(GNSS_SOURCE, payload, &mut sink);
        }
        sim.step(no_fix, &mut sink);
    }
    sink
}

/// The largest difference of the two runs' odom yaw, tick by tick.
fn largest_difference(a: &[(Timestamp, f64)], b: &[(Timestamp, f64)]) -> f64 {
    assert_eq!(a.len(), b.len(), "the runs ticked alike");
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            assert_eq!(x.0, y.0);
            (x.1 - y.1).abs()
        })
        .fold(0.0, f64::max)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn no_lesser_receiver_changes_the_odom_frames_yaw(
        legs in legs(),
        bias in -0.01f64..0.01,
        receiver in receiver(),
        seed in any::<u64>(),
    ) {
        let without = run(&legs, bias, None, seed);
        let with = run(&legs, bias, Some(&receiver), seed);
        prop_assert!(without.0.len() > 1000);
        // The receiver's fixes placed the vehicle: the map filter took them.
        prop_assert!(without.1 == 0 && with.1 > 0, "no map pose: {receiver:?}");
        let d = largest_difference(&without.0, &with.0);
        prop_assert!(d == 0.0, "the odom yaw moved by {d} rad with {receiver:?}");
    }
}

/// The harness sees a correction: an RTK-fixed dual-antenna heading teaches the odom frame
/// a gyro bias the standstill did not see (the bias changes after the boot).
#[test]
fn an_rtk_fixed_heading_does_correct_the_odom_frames_yaw() {
    let legs: Vec<Leg> = (0..8).map(|_| (10.0, 1.0, 0.0)).collect();
    let receiver = Receiver {
        rate_hz: 5.0,
        qualities: vec![FixQuality::RtkFixed],
        latency_s: 0.0,
        white_m: 0.01,
        step: (1_000_000, 0.0),
        wild_every: 1_000_000,
        course_lag_s: 0.0,
        course_smoothing: 0.0,
        course_noise_mps: 0.02,
        garbage_every: 1_000_000,
        heading_offset_deg: Some(0.0),
    };
    // The boot's standstill sees the gyro at rest: zero; then the gyro reads 0.005 rad/s
    // more than the turn.
    let without = run(&legs, 0.005, None, 3);
    let with = run(&legs, 0.005, Some(&receiver), 3);
    assert!(with.1 > 0, "no map pose");
    let d = largest_difference(&without.0, &with.0);
    assert!(d > 0.05, "no correction seen: {d} rad");
}
