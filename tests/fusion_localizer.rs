//! The localiser on synthetic data: convergence and tracking, late measurements handled by
//! time, gating of a jump and recovery from a relocation, and consistency (NEES) across
//! seeds.

use chassisd::fusion::ekf::{BIAS, X, Y, YAW, wrap};
use chassisd::fusion::localizer::{Localizer, LocalizerConfig, LocateState, Measurement};
use chassisd::time::Timestamp;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const ANTENNA: (f64, f64) = (0.3, 0.1);
const GYRO_BIAS: f64 = 0.01;

fn config() -> LocalizerConfig {
    LocalizerConfig {
        antenna: ANTENNA,
        ..LocalizerConfig::default()
    }
}

fn ms(v: u64) -> Timestamp {
    Timestamp::from_micros(v * 1000)
}

/// The truth and the measurements of a drive on a circle (1 m/s, 0.1 rad/s), every 10 ms.
struct Drive {
    rng: ChaCha8Rng,
    x: f64,
    y: f64,
    yaw: f64,
    v: f64,
    w: f64,
    /// The slowly wandering part of the fix error, east and north (m), as the filter
    /// models it: a Gauss–Markov process of the configured share and correlation time.
    gnss_slow: Option<(f64, f64)>,
}

impl Drive {
    fn new(seed: u64) -> Drive {
        Drive {
            rng: ChaCha8Rng::seed_from_u64(seed),
            x: 0.0,
            y: 0.0,
            yaw: 0.3,
            v: 1.0,
            w: 0.1,
            gnss_slow: None,
        }
    }

    fn noise(&mut self, sigma: f64) -> f64 {
        Normal::new(0.0, sigma).unwrap().sample(&mut self.rng)
    }

    /// Advances 10 ms and returns the measurements of tick `k` (time `t`).
    fn step(&mut self, k: u64) -> Vec<(Timestamp, Measurement)> {
        let dt = 0.01;
        self.x += self.v * self.yaw.cos() * dt;
        self.y += self.v * self.yaw.sin() * dt;
        self.yaw = wrap(self.yaw + self.w * dt);
        let t = ms(k * 10);
        let c = config();
        let mut out = vec![(
            t,
            Measurement::Gyro {
                wz: self.w + GYRO_BIAS + self.noise(c.gyro_sigma),
            },
        )];
        if k.is_multiple_of(2) {
            let (base, rel) = c.odometry_sigma;
            let v = self.v + self.noise(base + rel * self.v);
            let w = self.w + self.noise(c.odometry_yaw_rate_sigma);
            out.push((t, Measurement::Odometry { v, w }));
        }
        if k.is_multiple_of(20) {
            let (s, co) = self.yaw.sin_cos();
            let sigma = 0.02;
            let slow_sigma = sigma * c.gnss_correlated_fraction;
            let white_sigma = (sigma * sigma - slow_sigma * slow_sigma).sqrt();
            let phi = (-0.2 / c.noise.gnss_correlation_s).exp();
            let slow = match self.gnss_slow {
                None => (self.noise(slow_sigma), self.noise(slow_sigma)),
                Some((se, sn)) => {
                    let drive = slow_sigma * (1.0 - phi * phi).sqrt();
                    (phi * se + self.noise(drive), phi * sn + self.noise(drive))
                }
            };
            self.gnss_slow = Some(slow);
            let e = self.x + co * ANTENNA.0 - s * ANTENNA.1 + slow.0 + self.noise(white_sigma);
            let n = self.y + s * ANTENNA.0 + co * ANTENNA.1 + slow.1 + self.noise(white_sigma);
            out.push((
                t,
                Measurement::Heading {
                    yaw: wrap(self.yaw + self.noise(c.heading_sigma_rad)),
                    sigma: c.heading_sigma_rad,
                },
            ));
            out.push((
                t,
                Measurement::Position {
                    en: (e, n),
                    sigma: (sigma, sigma),
                },
            ));
        }
        out
    }
}

#[test]
fn converges_and_tracks_a_circle() {
    let mut drive = Drive::new(1);
    let mut loc = Localizer::new(config());
    for k in 1..=6000 {
        for (t, m) in drive.step(k) {
            loc.add(t, m);
        }
    }
    let ekf = loc.ekf().expect("initialised");
    let err = ((ekf.x[X] - drive.x).powi(2) + (ekf.x[Y] - drive.y).powi(2)).sqrt();
    assert!(err < 0.03, "position error {err} m");
    assert!(wrap(ekf.x[YAW] - drive.yaw).abs() < 0.5f64.to_radians());
    assert!(
        (ekf.x[BIAS] - GYRO_BIAS).abs() < 0.002,
        "bias {}",
        ekf.x[BIAS]
    );
    assert_eq!(loc.locate(ms(60_000)), LocateState::Good);
    assert_eq!(loc.stats().rejected, 0);
}

#[test]
fn late_measurements_give_the_same_result_as_in_order() {
    let mut drive = Drive::new(2);
    let mut stream = Vec::new();
    for k in 1..=2000 {
        stream.extend(drive.step(k));
    }
    let mut in_order = Localizer::new(config());
    for (t, m) in &stream {
        in_order.add(*t, *m);
    }
    // The same measurements, with every GNSS one after the first second arriving 80 ms late
    // (after the gyro and odometry samples of the next eight ticks). Both start alike: the
    // filter starts at a fix, and slowly forgotten states (the wheels' scale, the bias's
    // rate) would remember a start 80 ms apart.
    let mut arrivals: Vec<(Timestamp, Timestamp, Measurement)> = stream
        .iter()
        .map(|(t, m)| {
            let delay = match m {
                Measurement::Position { .. } | Measurement::Heading { .. }
                    if t.as_micros() > 1_000_000 =>
                {
                    80_000
                }
                _ => 0,
            };
            (Timestamp::from_micros(t.as_micros() + delay), *t, *m)
        })
        .collect();
    arrivals.sort_by_key(|(arrival, _, _)| *arrival);
    let mut late = Localizer::new(config());
    for (_, t, m) in &arrivals {
        late.add(*t, *m);
    }
    assert!(late.stats().late > 50, "{:?}", late.stats());
    let (a, b) = (in_order.ekf().unwrap(), late.ekf().unwrap());
    assert!((a.x - b.x).norm() < 1e-6, "{} vs {}", a.x, b.x);
    assert!((a.p - b.p).norm() < 1e-9);
}

#[test]
fn a_jump_is_rejected_and_a_relocation_is_accepted() {
    let mut drive = Drive::new(3);
    let mut loc = Localizer::new(config());
    let mut k = 0;
    let mut run = |loc: &mut Localizer, drive: &mut Drive, ticks: u64, offset: f64| {
        for _ in 0..ticks {
            k += 1;
            for (t, m) in drive.step(k) {
                let m = match m {
                    Measurement::Position { en, sigma } => Measurement::Position {
                        en: (en.0 + offset, en.1),
                        sigma,
                    },
                    other => other,
                };
                loc.add(t, m);
            }
        }
    };
    run(&mut loc, &mut drive, 2000, 0.0);
    // One fix 5 m east: rejected, and the estimate does not move.
    let before = loc.stats().rejected;
    run(&mut loc, &mut drive, 20, 5.0);
    assert_eq!(loc.stats().rejected, before + 1);
    run(&mut loc, &mut drive, 100, 0.0);
    let ekf = loc.ekf().unwrap();
    assert!((ekf.x[X] - drive.x).abs() < 0.05);
    // The vehicle really is 5 m further east (it was carried): after 3 s of rejected fixes the
    // filter takes the GNSS position, and keeps tracking.
    run(&mut loc, &mut drive, 600, 5.0);
    assert_eq!(loc.stats().resets, 1);
    let ekf = loc.ekf().unwrap();
    assert!(
        (ekf.x[X] - (drive.x + 5.0)).abs() < 0.05,
        "{} vs {}",
        ekf.x[X],
        drive.x + 5.0
    );
}

#[test]
fn estimation_error_is_consistent_across_seeds() {
    // Normalised estimation error squared of (x, y, yaw) once a second after convergence:
    // 3 on average for a consistent filter. Samples a second apart are correlated, so the
    // bounds are wider than the χ² interval of independent samples.
    let mut total = 0.0;
    let mut samples = 0;
    for seed in 0..20 {
        let mut drive = Drive::new(100 + seed);
        let mut loc = Localizer::new(config());
        for k in 1..=3000 {
            for (t, m) in drive.step(k) {
                loc.add(t, m);
            }
            if k >= 500 && k.is_multiple_of(100) {
                let ekf = loc.ekf().unwrap();
                let e = nalgebra::Vector3::new(
                    ekf.x[X] - drive.x,
                    ekf.x[Y] - drive.y,
                    wrap(ekf.x[YAW] - drive.yaw),
                );
                let p = ekf.p.fixed_view::<3, 3>(0, 0).into_owned();
                total += (e.transpose() * p.try_inverse().unwrap() * e)[(0, 0)];
                samples += 1;
            }
        }
    }
    let mean = total / f64::from(samples);
    eprintln!("mean NEES {mean:.2} over {samples} samples (3 for a consistent filter)");
    assert!(
        (1.5..=4.5).contains(&mean),
        "mean NEES {mean} over {samples} samples"
    );
}

/// Receivers at any legal rate start the filter, including those whose heading of an epoch
/// comes after its position, so that at each position the last heading is a whole period
/// old (a 1 Hz receiver once never started: the heading had to be younger than 1 s). The
/// first position starts it with the heading unknown (`LOCATE_FALSE`); the heading that
/// follows resolves it.
#[test]
fn starts_at_every_receiver_rate_with_the_heading_after_the_position() {
    for period_ms in [50, 100, 200, 500, 999, 1000, 1001, 2000, 5000] {
        let mut loc = Localizer::new(config());
        for epoch in 0..4u64 {
            let t = epoch * period_ms;
            loc.add(
                ms(t),
                Measurement::Position {
                    en: (1.0, 2.0),
                    sigma: (0.02, 0.02),
                },
            );
            assert!(loc.ekf().is_some(), "{period_ms} ms: not started");
            if epoch == 0 {
                assert_eq!(loc.locate(ms(t)), LocateState::Lost, "{period_ms} ms");
                assert!(loc.ekf().unwrap().yaw_sigma() > 1.0);
            }
            // The same epoch's heading, taken just after its position.
            loc.add(
                ms(t),
                Measurement::Heading {
                    yaw: 0.5,
                    sigma: 0.01,
                },
            );
        }
        let e = loc.ekf().unwrap();
        let t = 3 * period_ms;
        assert!(
            (e.x[YAW] - 0.5).abs() < 0.01,
            "{period_ms} ms: yaw {}",
            e.x[YAW]
        );
        assert_eq!(loc.locate(ms(t)), LocateState::Good, "{period_ms} ms");
    }
}
