//! The localiser on synthetic drives where the truth is known exactly: a gyro drift proven
//! against GNSS headings becomes a bias correction of the right size, a standstill leaves
//! the heading as uncertain as the bias it taught, SBAS fixes with a step never prove one, an RTK-fixed course teaches it only after 5 s straight, and a vehicle
//! without wheels is placed by its fixes and lost when they stop.

use chassisd::fusion::localizer::{Localizer, LocalizerConfig, LocateState, Measurement};
use chassisd::fusion::map_filter::Trust;
use chassisd::fusion::odometry::OdomPose;
use chassisd::time::Timestamp;

fn at(s: f64) -> Timestamp {
    Timestamp::from_micros(1_000_000 + (s * 1e6).round() as u64)
}

/// A deterministic, zero-mean noise sample of unit spread for step `k`.
fn noise(k: u64) -> f64 {
    // A golden-ratio sequence folded to [-√3, √3): uniform, σ 1.
    ((k as f64 * 0.618_033_988_75).fract() * 2.0 - 1.0) * 3f64.sqrt()
}

/// Drives east at 1 m/s for `seconds`; the odom frame's yaw drifts at `drift` rad/s (the gyro
/// bias it learnt is off by that much), so its positions bend away from the truth. Odom
/// poses at 100 Hz; at 5 Hz a fix (RTK 1 cm, or SBAS 0.8 m with a 2 m step at 20 s) and, with
/// `headings`, a dual-antenna heading (0.5°). Every bias correction the localiser proves.
fn drive(seconds: f64, drift: f64, rtk: bool, headings: bool) -> (Localizer, Vec<(f64, f64)>) {
    let mut l = Localizer::new(LocalizerConfig::default());
    let mut corrections = Vec::new();
    let (mut ox, mut oy) = (0.0, 0.0);
    let steps = (seconds * 100.0) as u64;
    for k in 0..=steps {
        let s = k as f64 / 100.0;
        let yaw = drift * s;
        if k > 0 {
            ox += 0.01 * yaw.cos();
            oy += 0.01 * yaw.sin();
        }
        let pose = OdomPose {
            x: ox,
            y: oy,
            yaw,
            v: 1.0,
            w: drift,
        };
        l.add(at(s), Measurement::Odom(pose));
        if k % 20 == 0 {
            let (sigma, step) = if rtk {
                (0.01, 0.0)
            } else {
                (0.8, if s >= 20.0 { 2.0 } else { 0.0 })
            };
            let en = (s + sigma * noise(k), step + sigma * noise(k + 7));
            let trust = if rtk {
                Trust::OverWheels
            } else {
                Trust::UnderWheels
            };
            l.add(
                at(s),
                Measurement::Position {
                    en,
                    sigma: (sigma, sigma),
                    trust,
                    corrected: true,
                },
            );
            if headings {
                let sigma = 0.5f64.to_radians();
                l.add(
                    at(s),
                    Measurement::Heading {
                        yaw: sigma * noise(k + 3),
                        sigma,
                        trust,
                    },
                );
            }
            if let Some(d) = l.take_bias_correction() {
                corrections.push((d.rate, d.sigma));
            }
        }
    }
    (l, corrections)
}

#[test]
fn a_drift_proven_against_headings_corrects_the_bias_by_its_size() {
    let (_, corrections) = drive(40.0, 0.002, true, true);
    let &(rate, sigma) = corrections.first().expect("a drift proven within 40 s");
    assert!(
        (rate - 0.002).abs() <= 3.0 * sigma && sigma < 0.0004,
        "{rate} ± {sigma} against 0.002"
    );
    // Once corrected, nothing is proven again until it shows anew (this drive does not
    // correct its own odom frame, so it may; but never with the wrong sign).
    assert!(corrections.iter().all(|(r, _)| *r > 0.0), "{corrections:?}");
}

/// The map heading's variance after `drive` (no drift, RTK fixes and headings, 20 s), a 5 s
/// standstill whose bias the odom frame knows to `bias_sigma` rad/s, then 60 s at 1 m/s
/// without GNSS.
fn heading_variance_after_a_stop(bias_sigma: f64) -> f64 {
    let (mut l, _) = drive(20.0, 0.0, true, true);
    let (mut ox, mut s) = (20.0, 20.0);
    for k in 1..=6500u64 {
        s += 0.01;
        let moving = k > 500;
        if moving {
            ox += 0.01;
        }
        let v = if moving { 1.0 } else { 0.0 };
        l.set_gyro_bias_sigma(Some(bias_sigma));
        let pose = OdomPose {
            x: ox,
            y: 0.0,
            yaw: 0.0,
            v,
            w: 0.0,
        };
        l.add(at(s), Measurement::Odom(pose));
    }
    l.published(at(s)).expect("placed").map_covariance[3]
}

#[test]
fn a_standstill_leaves_the_heading_as_uncertain_as_the_bias_it_taught() {
    // Over the 60 s after the stop, a bias known to 1σ 3e-3 rad/s turns the heading by up to
    // 3e-3 · 60 = 0.18 rad (1σ) more than a bias known exactly.
    let (sigma, span) = (3e-3, 60.0);
    let known = heading_variance_after_a_stop(0.0);
    let taught = heading_variance_after_a_stop(sigma);
    let added = taught - known;
    let expected = (sigma * span) * (sigma * span);
    assert!(
        (added - expected).abs() <= 0.1 * expected,
        "{added} against {expected}"
    );
}

#[test]
fn no_drift_is_proven_where_there_is_none() {
    let (_, corrections) = drive(60.0, 0.0, true, true);
    assert!(corrections.is_empty(), "{corrections:?}");
}

#[test]
fn sbas_fixes_with_a_step_never_prove_a_drift() {
    let (l, corrections) = drive(120.0, 0.002, false, false);
    assert!(corrections.is_empty(), "{corrections:?}");
    // Still placed: the fixes agree with the wheels.
    assert!(l.published(at(120.0)).is_some());
}

#[test]
fn without_wheels_the_fixes_place_the_vehicle_until_they_stop() {
    let config = LocalizerConfig {
        antenna: (0.2, 0.0),
        ..LocalizerConfig::default()
    };
    let mut l = Localizer::new(config);
    assert_eq!(l.locate(at(0.0)), LocateState::Uninitialized);
    for k in 0..10 {
        let s = k as f64 * 0.2;
        l.add(
            at(s),
            Measurement::Heading {
                yaw: std::f64::consts::FRAC_PI_2,
                sigma: 0.01,
                trust: Trust::OverWheels,
            },
        );
        l.add(
            at(s),
            Measurement::Position {
                en: (3.0, 4.0 + s),
                sigma: (0.02, 0.02),
                trust: Trust::OverWheels,
                corrected: true,
            },
        );
    }
    let p = l.published(at(1.8)).expect("placed");
    assert_eq!(p.locate, LocateState::Good);
    // Facing north, the antenna 0.2 m ahead of the reference point.
    let (x, y, yaw) = p.map_pose;
    assert!(
        (x - 3.0).abs() < 1e-9 && (y - (4.0 + 1.8 - 0.2)).abs() < 1e-9,
        "{x} {y}"
    );
    assert!((yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    // The receiver falls silent: lost within 3 s.
    assert_eq!(l.locate(at(4.8)), LocateState::Lost);
}

/// Drives at 2 m/s in legs of `straight_s` straight and 0.5 s turning at 0.4 rad/s (left and
/// right in turn), the odom frame's yaw drifting at 0.003 rad/s. At 5 Hz: a single fix
/// (1 m, which never teaches) and an RTK-fixed epoch's course, true to 0.3°. Every bias
/// correction the localiser proves.
fn weave(seconds: f64, straight_s: f64) -> Vec<(f64, f64)> {
    const DRIFT: f64 = 0.003;
    let mut l = Localizer::new(LocalizerConfig::default());
    let mut corrections = Vec::new();
    let (mut x, mut y, mut yaw) = (0.0, 0.0, 0.0f64);
    let (mut ox, mut oy) = (0.0, 0.0);
    let leg = straight_s + 0.5;
    for k in 0..=(seconds * 100.0) as u64 {
        let s = k as f64 / 100.0;
        let in_leg = s % leg;
        let w = if in_leg >= straight_s {
            if ((s / leg) as u64).is_multiple_of(2) {
                0.4
            } else {
                -0.4
            }
        } else {
            0.0
        };
        if k > 0 {
            yaw += w * 0.01;
            x += 0.02 * yaw.cos();
            y += 0.02 * yaw.sin();
            let odom_yaw = yaw + DRIFT * s;
            ox += 0.02 * odom_yaw.cos();
            oy += 0.02 * odom_yaw.sin();
        }
        let pose = OdomPose {
            x: ox,
            y: oy,
            yaw: yaw + DRIFT * s,
            v: 2.0,
            w: w + DRIFT,
        };
        l.add(at(s), Measurement::Odom(pose));
        if k % 20 == 0 {
            l.add(
                at(s),
                Measurement::Position {
                    en: (x + noise(k), y + noise(k + 7)),
                    sigma: (1.0, 1.0),
                    trust: Trust::UnderWheels,
                    corrected: false,
                },
            );
            l.add(
                at(s),
                Measurement::Course {
                    yaw: yaw + 0.3f64.to_radians() * noise(k + 3),
                    speed: 2.0,
                    speed_sigma: 0.01,
                    trust: Trust::OverWheels,
                },
            );
            if let Some(d) = l.take_bias_correction() {
                corrections.push((d.rate, d.sigma));
            }
        }
    }
    corrections
}

/// docs/fusion.md: an RTK-fixed epoch's course teaches the gyro's bias only after 5 s
/// without a turn (a receiver's lag and smoothing, a lever arm and sideslip all err in and
/// just after turns). Straight legs of 4.5 s never let it; legs of 8 s do, and the drift is
/// proven from those courses alone.
#[test]
fn a_course_teaches_the_bias_only_after_five_seconds_straight() {
    let short = weave(180.0, 4.5);
    assert!(short.is_empty(), "{short:?}");
    let long = weave(180.0, 8.0);
    let &(rate, sigma) = long.first().expect("a drift proven on the long legs");
    assert!((rate - 0.003).abs() <= 3.0 * sigma, "{rate} ± {sigma}");
}
