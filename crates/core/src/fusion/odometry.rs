//! The `odom` frame of REP-105: a pose dead-reckoned from the wheels and the gyro alone. It
//! starts at (0, 0, 0) when the drives first report, is continuous and never jumps, with or
//! without GNSS. Distance comes from the wheel encoders; yaw from the gyro, less a bias
//! learnt whenever the wheels stand still (a zero-velocity update), or from the wheels when
//! no gyro is live.

use std::collections::VecDeque;
use std::time::Duration;

use super::planar::wrap;
use crate::time::Timestamp;

/// Wheels slower than this stand still, m/s.
pub const STILL_MPS: f64 = 0.002;
/// A standstill's gyro readings give the bias only when their spread is within this, rad/s
/// (a vehicle being loaded or pushed is not still).
const QUIET_RPS: f64 = 0.02;
/// Readings a standstill needs before its mean counts as the bias.
const MIN_STILL_SAMPLES: u64 = 10;
/// A standstill's gyro readings count for the bias only from this long after the wheels
/// stopped to this long before they move again: the wheels report their motion late (feedback
/// latency, the motors' lag), and a turn's first or last rates would bias the mean.
const STILL_GUARD: Duration = Duration::from_millis(200);
/// Gyro readings held while their standstill is not yet confirmed, at most (1 kHz over the
/// guard).
const MAX_PENDING: usize = 256;
/// A gyro counts as live while its last sample is younger than this many of its periods.
const LIVE_PERIODS: f64 = 5.0;
/// ... and never less than this.
const MIN_LIVE: Duration = Duration::from_millis(50);

/// One wheel-odometry reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelReading {
    /// Left and right wheel ground speeds, m/s.
    pub speeds: (f64, f64),
    /// Left and right wheel travel since start, m, when the encoders report it.
    pub travel: Option<(f64, f64)>,
}

/// The odometry pose: x, y (m) and yaw (rad) in the `odom` frame, with its speed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OdomPose {
    /// Forward, m, along the heading at start.
    pub x: f64,
    /// Left, m.
    pub y: f64,
    /// Yaw, rad, counter-clockwise from the heading at start.
    pub yaw: f64,
    /// Forward speed, m/s.
    pub v: f64,
    /// Yaw rate, rad/s.
    pub w: f64,
}

/// Running mean and spread (Welford).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Spread {
    n: u64,
    mean: f64,
    m2: f64,
}

impl Spread {
    fn add(&mut self, x: f64) {
        self.n += 1;
        let d = x - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (x - self.mean);
    }

    fn sigma(&self) -> f64 {
        if self.n < 2 {
            return f64::INFINITY;
        }
        (self.m2 / (self.n - 1) as f64).sqrt()
    }
}

/// The gyro bias as the standstills so far showed it: a random walk's estimate, each
/// standstill's mean an update of it (a short standstill's few readings would otherwise
/// replace a long one's good mean).
#[derive(Debug, Clone, Copy, PartialEq)]
struct BiasBelief {
    mean: f64,
    /// rad²/s².
    variance: f64,
    at: Timestamp,
}

impl BiasBelief {
    /// The belief at `t`, the bias having walked since.
    fn at(self, t: Timestamp, walk: f64) -> Self {
        let dt = t.saturating_since(self.at).as_secs_f64();
        Self {
            variance: self.variance + walk * walk * dt,
            at: t.max(self.at),
            ..self
        }
    }

    /// Combined with a measurement of the bias.
    fn with(self, mean: f64, variance: f64) -> Self {
        let gain = self.variance / (self.variance + variance);
        Self {
            mean: self.mean + gain * (mean - self.mean),
            variance: self.variance * (1.0 - gain),
            at: self.at,
        }
    }
}

/// A gyro reading while the wheels stand still, held until the standstill is confirmed
/// around it: in the confirmed middle it is the bias's; at either end it may hold a turn's
/// start or end, and turns the pose.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PendingRate {
    at: Timestamp,
    /// The reading, bias included, rad/s.
    rate: f64,
    /// The interval it closes, s, and the turn over it by the trapezoid rule, bias included.
    dt: f64,
    turn: f64,
}

/// The `odom` frame's dead reckoning.
#[derive(Debug, Clone, Default)]
pub struct Odometry {
    track_m: f64,
    pose: Option<OdomPose>,
    last_wheels: Option<(Timestamp, WheelReading)>,
    still: bool,
    /// Yaw turned by the gyro since the last wheel reading, rad.
    gyro_turn: f64,
    last_gyro: Option<Timestamp>,
    /// The last gyro rate (bias included), rad/s: the turn between two samples is their mean
    /// times the interval, so a turn's start and end are not counted a sample early.
    last_rate: Option<f64>,
    /// Smoothed gyro sample interval, s.
    gyro_period: Option<f64>,
    /// The gyro bias, rad/s, once a standstill has shown it.
    bias: Option<f64>,
    /// What the standstills before the current one showed of the bias.
    bias_belief: Option<BiasBelief>,
    /// How fast the bias walks, rad/s/√s: how much an older standstill's bias still counts.
    bias_walk: f64,
    /// When the pose's yaw rate applies: the middle of the last wheel interval when it is
    /// the gyro's mean over it, else the reading's time.
    yaw_rate_at: Option<Timestamp>,
    standstill: Spread,
    /// From when the current standstill's gyro readings are the bias's: [`STILL_GUARD`] after
    /// its first still wheel reading, or that reading itself when the drives' first report
    /// is still (no motion before it to end).
    bias_from: Option<Timestamp>,
    /// Gyro readings of the standstill not yet confirmed by [`STILL_GUARD`] of still wheels.
    pending_still: VecDeque<PendingRate>,
}

impl Odometry {
    /// Dead reckoning for wheels `track_m` apart, on a gyro whose bias walks at `bias_walk`
    /// rad/s/√s.
    pub fn new(track_m: f64, bias_walk: f64) -> Self {
        Self {
            track_m,
            bias_walk: if bias_walk.is_finite() {
                bias_walk.abs()
            } else {
                0.0
            },
            ..Self::default()
        }
    }

    /// The pose, once the drives have reported.
    pub fn pose(&self) -> Option<OdomPose> {
        self.pose
    }

    /// When the pose was last moved: the time of the last wheel reading.
    pub fn updated_at(&self) -> Option<Timestamp> {
        self.last_wheels.map(|(t, _)| t)
    }

    /// When the pose's yaw rate applies (a mean over the last interval applies at its
    /// middle).
    pub fn yaw_rate_at(&self) -> Option<Timestamp> {
        self.yaw_rate_at
    }

    /// The gyro bias learnt at standstill, rad/s.
    pub fn gyro_bias(&self) -> Option<f64> {
        self.bias
    }

    /// How well the bias the yaw is turned by is known at `t`, 1σ rad/s: the current
    /// standstill's belief, else the last one's (or a GNSS correction's) aged by the bias's
    /// walk; `None` before any.
    pub fn gyro_bias_sigma(&self, t: Timestamp) -> Option<f64> {
        self.bias?;
        let belief = self
            .still
            .then(|| self.standstill_belief(t))
            .flatten()
            .or_else(|| self.bias_belief.map(|b| b.at(t, self.bias_walk)))?;
        Some(belief.variance.sqrt())
    }

    /// Corrects the gyro bias by `delta` rad/s, known to 1σ `sigma`, at `t`: a drift GNSS
    /// proved while moving ([`super::gyro_drift`]). The next standstill weighs its own
    /// mean against it.
    pub fn correct_bias(&mut self, t: Timestamp, delta: f64, sigma: f64) {
        if !(delta.is_finite() && sigma.is_finite()) {
            return;
        }
        let bias = self.bias.unwrap_or(0.0) + delta;
        self.bias = Some(bias);
        self.bias_belief = Some(BiasBelief {
            mean: bias,
            variance: sigma * sigma,
            at: t,
        });
    }

    fn gyro_live(&self, t: Timestamp) -> bool {
        let Some(last) = self.last_gyro else {
            return false;
        };
        let window = self
            .gyro_period
            .map_or(MIN_LIVE, |p| Duration::from_secs_f64(p * LIVE_PERIODS))
            .max(MIN_LIVE);
        t.saturating_since(last) <= window
    }

    /// A gyro yaw rate (bias included) at `t`, rad/s.
    pub fn gyro(&mut self, t: Timestamp, wz: f64) {
        let Some(last) = self.last_gyro.filter(|&l| t > l) else {
            self.last_gyro = self.last_gyro.max(Some(t));
            return;
        };
        let dt = t.saturating_since(last).as_secs_f64();
        self.last_gyro = Some(t);
        let previous = self.last_rate.replace(wz);
        // Gaps (a lost link) do not enter the rate estimate beyond a few periods.
        self.gyro_period = Some(match self.gyro_period {
            Some(p) => p + (dt.min(p * LIVE_PERIODS) - p) * 0.05,
            None => dt,
        });
        // Across a gap (a lost link) only the newest sample stands for the interval.
        let gap = self.gyro_period.is_some_and(|p| dt > p * LIVE_PERIODS);
        let rate = match previous {
            Some(before) if !gap => (before + wz) / 2.0,
            _ => wz,
        };
        if self.still {
            if self.pending_still.len() >= MAX_PENDING
                && let Some(oldest) = self.pending_still.pop_front()
            {
                self.turn_by(oldest);
            }
            self.pending_still.push_back(PendingRate {
                at: t,
                rate: wz,
                dt,
                turn: rate * dt,
            });
            return;
        }
        if self.pose.is_some() {
            self.gyro_turn += (rate - self.bias.unwrap_or(0.0)) * dt;
        }
    }

    /// A held reading turns the pose after all (it was not the confirmed standstill's).
    fn turn_by(&mut self, reading: PendingRate) {
        if self.pose.is_some() {
            self.gyro_turn += reading.turn - self.bias.unwrap_or(0.0) * reading.dt;
        }
    }

    /// The wheels still stand at `t`: the gyro readings of the standstill older than the
    /// guard are its bias's.
    fn confirm_still(&mut self, t: Timestamp) {
        let Some(bias_from) = self.bias_from else {
            return;
        };
        while let Some(&reading) = self.pending_still.front() {
            if t.saturating_since(reading.at) < STILL_GUARD {
                break;
            }
            self.pending_still.pop_front();
            if reading.at >= bias_from {
                self.standstill.add(reading.rate);
            } else {
                // The standstill's first readings may hold the end of a turn.
                self.turn_by(reading);
            }
        }
        if let Some(belief) = self.standstill_belief(t) {
            self.bias = Some(belief.mean);
        }
    }

    /// The bias with this standstill's readings, once they are enough and quiet.
    fn standstill_belief(&self, t: Timestamp) -> Option<BiasBelief> {
        let s = &self.standstill;
        if s.n < MIN_STILL_SAMPLES || s.sigma() > QUIET_RPS {
            return None;
        }
        let variance = s.sigma().powi(2) / s.n as f64;
        let own = BiasBelief {
            mean: s.mean,
            variance,
            at: t,
        };
        Some(match self.bias_belief.map(|b| b.at(t, self.bias_walk)) {
            // A standstill more than 3σ from the belief shows the bias moved faster than its
            // walk (a power cycle, a warming sensor): it starts afresh.
            Some(b) if (s.mean - b.mean).powi(2) <= 9.0 * (b.variance + variance) => {
                b.with(s.mean, variance)
            }
            _ => own,
        })
    }

    /// A wheel reading at `t`: moves the pose.
    pub fn wheels(&mut self, t: Timestamp, reading: WheelReading) {
        let (vl, vr) = reading.speeds;
        let still = vl.abs() < STILL_MPS && vr.abs() < STILL_MPS;
        if still && !self.still {
            self.standstill = Spread::default();
            let after_motion = self.last_wheels.is_some();
            self.bias_from = Some(if after_motion {
                t.saturating_add(STILL_GUARD)
            } else {
                t
            });
            self.pending_still.clear();
        } else if still {
            self.confirm_still(t);
        } else {
            // Moving again: the last readings of the standstill may hold the start of a turn.
            while let Some(reading) = self.pending_still.pop_front() {
                self.turn_by(reading);
            }
            if self.still
                && let Some(belief) = self.standstill_belief(t)
            {
                self.bias_belief = Some(belief);
            }
        }
        let gyro_live = self.gyro_live(t);
        let Some((t0, before)) = self.last_wheels.replace((t, reading)) else {
            self.pose = Some(OdomPose::default());
            self.still = still;
            self.gyro_turn = 0.0;
            return;
        };
        let dt = t.saturating_since(t0).as_secs_f64();
        // Travel from the encoders where both readings have it, else from the speeds.
        let (dl, dr) = match (before.travel, reading.travel) {
            (Some((l0, r0)), Some((l1, r1))) => (l1 - l0, r1 - r0),
            _ => (
                (before.speeds.0 + vl) / 2.0 * dt,
                (before.speeds.1 + vr) / 2.0 * dt,
            ),
        };
        // A live gyro turns the pose at either end of a standstill too (its middle's readings
        // are the bias's and not integrated).
        let turn = if gyro_live {
            self.gyro_turn
        } else if still {
            0.0
        } else {
            (dr - dl) / self.track_m
        };
        self.gyro_turn = 0.0;
        self.still = still;
        let ds = if still { 0.0 } else { (dl + dr) / 2.0 };
        if let Some(p) = &mut self.pose {
            let mid = p.yaw + turn / 2.0;
            p.x += ds * mid.cos();
            p.y += ds * mid.sin();
            p.yaw = wrap(p.yaw + turn);
            // Speeds from the drives' reports, not from the travel since the last tick: the
            // encoders report less often than the control loop runs, so the travel comes in
            // steps (twice the speed, then nothing).
            p.v = if still { 0.0 } else { (vl + vr) / 2.0 };
            let mean_over_interval = !still && gyro_live && dt > 0.0;
            p.w = if still {
                0.0
            } else if mean_over_interval {
                turn / dt
            } else {
                (vr - vl) / self.track_m
            };
            self.yaw_rate_at = Some(if mean_over_interval {
                t0.saturating_add(t.saturating_since(t0) / 2)
            } else {
                t
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_micros(ms * 1000)
    }

    fn wheels(v: (f64, f64), travel: (f64, f64)) -> WheelReading {
        WheelReading {
            speeds: v,
            travel: Some(travel),
        }
    }

    #[test]
    fn starts_at_zero_and_drives_straight_on_the_encoders() {
        let mut o = Odometry::new(0.5, 2e-5);
        assert_eq!(o.pose(), None);
        for k in 0..=100u64 {
            let s = k as f64 * 0.01;
            o.wheels(at(10 * k), wheels((1.0, 1.0), (s, s)));
        }
        let p = o.pose().unwrap();
        assert!((p.x - 1.0).abs() < 1e-12 && p.y.abs() < 1e-12 && p.yaw == 0.0);
    }

    #[test]
    fn a_still_vehicle_stays_put_and_learns_the_gyro_bias() {
        let mut o = Odometry::new(0.5, 2e-5);
        // 60 s still at 100 Hz with a biased, noisy gyro.
        for k in 0..6000u64 {
            let noise = if k % 2 == 0 { 0.003 } else { -0.003 };
            o.gyro(at(10 * k + 5), 0.01 + noise);
            o.wheels(at(10 * k), wheels((0.0, 0.0), (0.0, 0.0)));
        }
        let p = o.pose().unwrap();
        assert_eq!((p.x, p.y, p.yaw), (0.0, 0.0, 0.0));
        assert!((o.gyro_bias().unwrap() - 0.01).abs() < 1e-4);
        // Known to the readings' spread over their root count: 0.003 / √5980.
        let sigma = o.gyro_bias_sigma(at(60_000)).unwrap();
        assert!((sigma - 0.003 / 5980f64.sqrt()).abs() < 2e-6, "{sigma}");
        // Then it turns on the bias-corrected gyro: 0.5 rad/s for 1 s.
        for k in 6000..6100u64 {
            o.gyro(at(10 * k + 5), 0.51);
            o.wheels(at(10 * k + 10), wheels((-0.1, 0.1), (0.0, 0.0)));
        }
        let yaw = o.pose().unwrap().yaw;
        assert!((yaw - 0.5).abs() < 0.01, "{yaw}");
    }

    /// Stands `ms` at `from` (ms) with a gyro reading `bias` ± `noise`, then drives 1 s.
    fn stop_and_go(o: &mut Odometry, from: u64, ms: u64, bias: f64, noise: f64) -> u64 {
        for k in 0..ms / 10 {
            let n = if k % 2 == 0 { noise } else { -noise };
            o.gyro(at(from + 10 * k + 5), bias + n);
            o.wheels(at(from + 10 * k), wheels((0.0, 0.0), (0.0, 0.0)));
        }
        let moving = from + ms;
        for k in 0..100 {
            o.gyro(at(moving + 10 * k + 5), bias);
            o.wheels(at(moving + 10 * k), wheels((0.5, 0.5), (0.0, 0.0)));
        }
        moving + 1000
    }

    #[test]
    fn a_short_stop_refines_the_bias_and_a_far_one_replaces_it() {
        let mut o = Odometry::new(0.5, 2e-5);
        // 30 s still: the bias to 0.003 / √2600 ≈ 6e-5.
        let t = stop_and_go(&mut o, 0, 30_000, 0.01, 0.003);
        assert!((o.gyro_bias().unwrap() - 0.01).abs() < 1e-5);
        // A 0.6 s stop whose few readings average 0.0101 (the first and last 200 ms are left
        // out): the bias stays near the long stop's.
        let t = stop_and_go(&mut o, t, 600, 0.0101, 0.003);
        let refined = o.gyro_bias().unwrap();
        assert!(refined > 0.01 && refined < 0.01005, "{refined}");
        // A stop far from it (the sensor was power-cycled): its own mean.
        stop_and_go(&mut o, t, 3000, 0.02, 0.003);
        assert!((o.gyro_bias().unwrap() - 0.02).abs() < 1e-4);
    }

    #[test]
    fn a_turn_the_wheels_report_late_counts_whole() {
        let mut o = Odometry::new(0.5, 2e-5);
        // Wheels at 20 Hz, gyro at 100 Hz with a bias of 0.01 rad/s. 5 s still teach the bias;
        // then a turn on the spot at 1 rad/s for 1.5 s, which the wheels report 100 ms late at
        // either end; then 2 s still.
        let (start, end) = (5_000u64, 6_500u64);
        let late = 100;
        for ms in (0..8_500u64).step_by(10) {
            let turning = (start..end).contains(&ms);
            o.gyro(at(ms + 5), 0.01 + if turning { 1.0 } else { 0.0 });
            if ms % 50 == 0 {
                let moving = (start + late..=end + late).contains(&ms);
                let v = if moving { 0.125 } else { 0.0 };
                o.wheels(at(ms), wheels((-v, v), (0.0, 0.0)));
            }
        }
        let yaw = o.pose().unwrap().yaw;
        assert!((yaw - 1.5).abs() < 0.005, "{yaw}");
        assert!((o.gyro_bias().unwrap() - 0.01).abs() < 1e-9);
    }

    #[test]
    fn without_a_live_gyro_the_wheels_turn_it() {
        let mut o = Odometry::new(0.5, 2e-5);
        o.gyro(at(0), 0.0);
        o.gyro(at(10), 0.0);
        // The gyro falls silent; the wheels turn the vehicle by (0.25 - (-0.25)) / 0.5 = 1 rad.
        for k in 0..=100u64 {
            let s = k as f64 * 0.0025;
            o.wheels(at(1000 + 10 * k), wheels((-0.25, 0.25), (-s, s)));
        }
        assert!((o.pose().unwrap().yaw - 1.0).abs() < 1e-9);
    }

    #[test]
    fn a_noisy_standstill_does_not_set_the_bias() {
        let mut o = Odometry::new(0.5, 2e-5);
        for k in 0..200u64 {
            o.gyro(at(10 * k + 5), if k % 2 == 0 { 0.2 } else { -0.1 });
            o.wheels(at(10 * k), wheels((0.0, 0.0), (0.0, 0.0)));
        }
        assert_eq!(o.gyro_bias(), None);
    }
}
