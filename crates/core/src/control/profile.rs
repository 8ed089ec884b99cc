//! Time-optimal rest-to-rest motion profiles: how far, how fast and how hard a move may go at
//! each moment, within a speed, an acceleration, a deceleration and (optionally) a jerk limit.
//! Without a jerk limit the profile is the trapezoid (or triangle); with one it is the S-curve
//! whose acceleration ramps at the jerk limit. Units are whatever the limits are in: metres
//! for distance moves, radians for turns.

/// The limits a profile stays within. Every value is positive; `jerk` infinite means none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Peak speed, units/s.
    pub speed: f64,
    /// Acceleration, units/s².
    pub accel: f64,
    /// Deceleration, units/s².
    pub decel: f64,
    /// Jerk, units/s³ (`f64::INFINITY`: not limited).
    pub jerk: f64,
}

/// One speed change from rest to `peak` (or back), with its acceleration shaped by the jerk
/// limit: ramp up, hold, ramp down.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ramp {
    /// Acceleration reached (≤ the limit), units/s².
    accel: f64,
    /// Time spent ramping the acceleration up (and, again, down), s.
    jerk_time: f64,
    /// Time at constant acceleration, s.
    hold_time: f64,
}

impl Ramp {
    /// The quickest change of speed by `dv` ≥ 0 under acceleration `accel` and `jerk`.
    fn new(dv: f64, accel: f64, jerk: f64) -> Self {
        if dv <= 0.0 {
            return Self {
                accel: 0.0,
                jerk_time: 0.0,
                hold_time: 0.0,
            };
        }
        if jerk.is_infinite() || dv >= accel * accel / jerk {
            let jerk_time = if jerk.is_infinite() {
                0.0
            } else {
                accel / jerk
            };
            Self {
                accel,
                jerk_time,
                hold_time: dv / accel - jerk_time,
            }
        } else {
            // Too small a change to reach the acceleration limit: a triangle of acceleration.
            let accel = (dv * jerk).sqrt();
            Self {
                accel,
                jerk_time: accel / jerk,
                hold_time: 0.0,
            }
        }
    }

    fn duration(&self) -> f64 {
        2.0 * self.jerk_time + self.hold_time
    }

    /// Acceleration magnitude `t` s into the ramp.
    fn accel_at(&self, t: f64) -> f64 {
        let (tj, th) = (self.jerk_time, self.hold_time);
        if t <= 0.0 || t >= self.duration() {
            0.0
        } else if t < tj {
            self.accel * t / tj
        } else if t <= tj + th {
            self.accel
        } else {
            self.accel * (self.duration() - t) / tj
        }
    }

    /// Speed gained `t` s into the ramp (from 0).
    fn speed_at(&self, t: f64) -> f64 {
        let (a, tj, th) = (self.accel, self.jerk_time, self.hold_time);
        let t = t.clamp(0.0, self.duration());
        if t < tj {
            a * t * t / (2.0 * tj)
        } else if t <= tj + th {
            a * tj / 2.0 + a * (t - tj)
        } else {
            let r = self.duration() - t;
            a * tj / 2.0 + a * th + a * tj / 2.0 - a * r * r / (2.0 * tj)
        }
    }

    /// Distance covered `t` s into a ramp from rest.
    fn distance_at(&self, t: f64) -> f64 {
        let (a, tj, th) = (self.accel, self.jerk_time, self.hold_time);
        let t = t.clamp(0.0, self.duration());
        let jerk_up = |t: f64| {
            if tj > 0.0 {
                a * t * t * t / (6.0 * tj)
            } else {
                0.0
            }
        };
        let v1 = a * tj / 2.0;
        let d1 = jerk_up(tj);
        if t < tj {
            return jerk_up(t);
        }
        if t <= tj + th {
            let u = t - tj;
            return d1 + v1 * u + a * u * u / 2.0;
        }
        let v2 = v1 + a * th;
        let d2 = d1 + v1 * th + a * th * th / 2.0;
        let u = t - tj - th;
        // Acceleration falls from `a` to 0 over `tj`.
        d2 + v2 * u + a * u * u / 2.0
            - if tj > 0.0 {
                a * u * u * u / (6.0 * tj)
            } else {
                0.0
            }
    }

    /// Distance of the whole ramp from rest to its peak speed.
    fn distance(&self) -> f64 {
        self.distance_at(self.duration())
    }
}

/// Where the profile is at a moment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Distance from the start, units.
    pub position: f64,
    /// Speed, units/s.
    pub speed: f64,
    /// Acceleration, units/s² (negative while slowing).
    pub accel: f64,
}

/// A rest-to-rest profile over a distance ≥ 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    distance: f64,
    peak: f64,
    up: Ramp,
    cruise_time: f64,
    down: Ramp,
}

impl Profile {
    /// The time-optimal profile over `distance` (its magnitude) within `limits`.
    pub fn plan(distance: f64, limits: Limits) -> Self {
        let distance = if distance.is_finite() {
            distance.abs()
        } else {
            0.0
        };
        let ramps = |v: f64| {
            (
                Ramp::new(v, limits.accel, limits.jerk),
                Ramp::new(v, limits.decel, limits.jerk),
            )
        };
        let reach = |v: f64| {
            let (up, down) = ramps(v);
            up.distance() + down.distance()
        };
        // The highest peak whose speed-up and slow-down fit in the distance (ramp distance
        // grows with the peak, so bisection finds it).
        let peak = if reach(limits.speed) <= distance {
            limits.speed
        } else {
            let (mut lo, mut hi) = (0.0, limits.speed);
            for _ in 0..100 {
                let mid = (lo + hi) / 2.0;
                if reach(mid) <= distance {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        let (up, down) = ramps(peak);
        let cruise_time = if peak > 0.0 {
            ((distance - up.distance() - down.distance()) / peak).max(0.0)
        } else {
            0.0
        };
        Self {
            distance,
            peak,
            up,
            cruise_time,
            down,
        }
    }

    /// The distance, units.
    pub fn distance(&self) -> f64 {
        self.distance
    }

    /// The peak speed, units/s.
    pub fn peak_speed(&self) -> f64 {
        self.peak
    }

    /// How long the profile takes, s.
    pub fn duration(&self) -> f64 {
        self.up.duration() + self.cruise_time + self.down.duration()
    }

    /// The profile `t` s after its start (before: at rest at 0; after: at rest at the end).
    pub fn sample(&self, t: f64) -> Sample {
        let t_up = self.up.duration();
        let t_cruise = t_up + self.cruise_time;
        if t <= 0.0 {
            return Sample {
                position: 0.0,
                speed: 0.0,
                accel: 0.0,
            };
        }
        if t < t_up {
            return Sample {
                position: self.up.distance_at(t),
                speed: self.up.speed_at(t),
                accel: self.up.accel_at(t),
            };
        }
        if t < t_cruise {
            return Sample {
                position: self.up.distance() + self.peak * (t - t_up),
                speed: self.peak,
                accel: 0.0,
            };
        }
        let u = t - t_cruise;
        if u >= self.down.duration() {
            return Sample {
                position: self.distance,
                speed: 0.0,
                accel: 0.0,
            };
        }
        // The slow-down is the speed-up run backwards from the end.
        let r = self.down.duration() - u;
        Sample {
            position: self.distance - self.down.distance_at(r),
            speed: self.down.speed_at(r),
            accel: -self.down.accel_at(r),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const TRAPEZOID: Limits = Limits {
        speed: 1.5,
        accel: 1.0,
        decel: 1.5,
        jerk: f64::INFINITY,
    };

    #[test]
    fn trapezoid_times_match_the_closed_form() {
        // 5 m: 1.125 m to reach 1.5 m/s, 0.75 m to stop, 3.125 m at 1.5 m/s.
        let p = Profile::plan(5.0, TRAPEZOID);
        let expected = 1.5 / 1.0 + 1.5 / 1.5 + 3.125 / 1.5;
        assert!((p.duration() - expected).abs() < 1e-9, "{}", p.duration());
        // 0.1 m: a triangle, t = √(2d(1/a + 1/b)).
        let p = Profile::plan(0.1, TRAPEZOID);
        let expected = (2.0 * 0.1 * (1.0 + 1.0 / 1.5_f64)).sqrt();
        assert!((p.duration() - expected).abs() < 1e-6, "{}", p.duration());
        assert!((p.sample(p.duration()).position - 0.1).abs() < 1e-12);
    }

    #[test]
    fn zero_and_bad_distances_are_empty() {
        for d in [0.0, f64::NAN, f64::INFINITY] {
            let p = Profile::plan(d, TRAPEZOID);
            assert_eq!(p.duration(), 0.0);
            assert_eq!(p.sample(1.0).position, 0.0);
        }
    }

    fn limits() -> impl Strategy<Value = Limits> {
        (
            0.05..3.0,
            0.1..5.0,
            0.1..5.0,
            prop_oneof![Just(f64::INFINITY), 0.5..50.0],
        )
            .prop_map(|(speed, accel, decel, jerk)| Limits {
                speed,
                accel,
                decel,
                jerk,
            })
    }

    proptest! {
        /// Every profile ends at its distance, at rest, and never leaves its limits: the
        /// speed, the acceleration, and the jerk between samples.
        #[test]
        fn profiles_stay_within_their_limits(distance in 0.0..20.0f64, l in limits()) {
            let p = Profile::plan(distance, l);
            let end = p.sample(p.duration() + 1.0);
            prop_assert!((end.position - distance).abs() < 1e-6 * distance.max(1.0));
            prop_assert_eq!(end.speed, 0.0);
            let dt = p.duration() / 2000.0;
            let mut last = p.sample(0.0);
            for i in 1..=2000 {
                let s = p.sample(i as f64 * dt);
                prop_assert!(s.speed <= l.speed + 1e-9 && s.speed >= -1e-9);
                prop_assert!(s.accel <= l.accel + 1e-9 && -s.accel <= l.decel + 1e-9);
                prop_assert!(s.position >= last.position - 1e-9, "never backwards");
                // Speed is the derivative of position (trapezoid rule, O(dt²)).
                let mean = (s.speed + last.speed) / 2.0;
                prop_assert!((s.position - last.position - mean * dt).abs()
                    <= 1e-9 + l.accel.max(l.decel) * dt * dt);
                if l.jerk.is_finite() {
                    prop_assert!((s.accel - last.accel).abs() <= l.jerk * dt * 1.001 + 1e-9);
                }
                last = s;
            }
        }

        /// No faster profile exists: with the speed limit not reached, stopping any earlier
        /// would need more than the deceleration limit.
        #[test]
        fn trapezoids_are_time_optimal(distance in 0.001..20.0f64, l in limits()) {
            let l = Limits { jerk: f64::INFINITY, ..l };
            let p = Profile::plan(distance, l);
            let v = p.peak_speed();
            let best = if v < l.speed - 1e-6 {
                (2.0 * distance * (1.0 / l.accel + 1.0 / l.decel)).sqrt()
            } else {
                distance / l.speed + l.speed / (2.0 * l.accel) + l.speed / (2.0 * l.decel)
            };
            prop_assert!((p.duration() - best).abs() < 1e-6 * best.max(1.0));
        }
    }
}
