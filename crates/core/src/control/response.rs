//! How quickly the drives follow a speed command: the time constant of a first-order lag,
//! learnt online from the wheel speed commanded and the wheel speed reported. Moves lead their
//! command by it and set their feedback gains from it, so the same controller suits a nimble
//! mower and a heavy delivery vehicle without a plant figure in the configuration.

use crate::time::Timestamp;

/// Assumed until the drives have shown their own, s: on the slow side, so the first moves'
/// gains are gentle rather than oscillating.
pub const DEFAULT_RESPONSE_S: f64 = 0.1;
/// The estimate stays within these, s.
const RANGE_S: (f64, f64) = (0.01, 1.0);
/// Speed errors smaller than this carry no information about the lag (noise and encoder
/// steps dominate), m/s at the wheel.
const MIN_EXCITATION_MPS: f64 = 0.02;
/// Each new observation weighs old ones down by this (memory of some hundred feedbacks).
const FORGET: f64 = 0.995;
/// Excitation needed before the estimate replaces the default, (m/s)².
const MIN_INFORMATION: f64 = 0.05;
/// Feedback older than this breaks an interval (drives silent): s.
const MAX_INTERVAL_S: f64 = 0.2;

/// One wheel's side of the estimate: its last reading and the command since.
#[derive(Debug, Clone, Copy, Default)]
struct WheelLag {
    /// The last reading: when its speed was sent, and the speed (m/s).
    last_feedback: Option<(Timestamp, f64)>,
    /// The command in force: since when, and the speed (m/s).
    command: Option<(Timestamp, f64)>,
    /// ∫ command dt since the last reading.
    command_integral: f64,
}

impl WheelLag {
    /// A reading of speed `measured` sent at `at`: the excitation x = c̄ − v (the mean
    /// command over the interval since the last reading, less the speed then), the change
    /// y = Δv, and the interval, when this is a new reading after a usable one.
    fn feedback(&mut self, at: Timestamp, measured: f64) -> Option<(f64, f64, f64)> {
        if self.last_feedback.is_some_and(|(t0, _)| t0 == at) {
            return None;
        }
        // A reading from before the command in force has no command history to pair with.
        if self.command.is_some_and(|(since, _)| at < since) {
            self.last_feedback = None;
            return None;
        }
        self.integrate_command(at);
        let before = self.last_feedback.replace((at, measured));
        let integral = std::mem::take(&mut self.command_integral);
        let (t0, v0) = before?;
        let dt = at.saturating_since(t0).as_secs_f64();
        (dt > 0.0 && dt <= MAX_INTERVAL_S).then(|| (integral / dt - v0, measured - v0, dt))
    }

    fn command(&mut self, t: Timestamp, command: f64) {
        self.integrate_command(t);
        self.command = Some((t, command));
    }

    fn integrate_command(&mut self, t: Timestamp) {
        if let Some((since, c)) = &mut self.command {
            self.command_integral += *c * t.saturating_since(*since).as_secs_f64();
            *since = t;
        }
    }
}

/// The drives' speed response, learnt from commands and feedback.
#[derive(Debug, Clone, Default)]
pub struct ResponseEstimator {
    wheels: [WheelLag; 2],
    /// Least-squares sums of Δv = α·(c̄ − v), α = 1 − e^(−Δt/τ) ...
    sxx: f64,
    sxy: f64,
    /// ... and the mean feedback interval Δt they were taken over (weighted alike), s.
    sdt: f64,
}

impl ResponseEstimator {
    /// The estimated time constant, s (the default until enough motion was seen).
    pub fn time_constant(&self) -> f64 {
        if self.sxx < MIN_INFORMATION || self.sxy <= 0.0 {
            return DEFAULT_RESPONSE_S;
        }
        // The exact step response of a first-order lag over the feedback interval.
        let alpha = (self.sxy / self.sxx).min(0.999);
        let dt = self.sdt / self.sxx;
        (-dt / (1.0 - alpha).ln()).clamp(RANGE_S.0, RANGE_S.1)
    }

    /// The wheel speeds reported (m/s, left and right), each with the time it was sent
    /// (drives report more slowly than the control loop runs, so a reading seen again is no
    /// new feedback, and a reading is as old as its arrival, not the tick that reads it).
    pub fn feedback(&mut self, left: (Timestamp, f64), right: (Timestamp, f64)) {
        for (wheel, (at, measured)) in self.wheels.iter_mut().zip([left, right]) {
            let Some((x, y, dt)) = wheel.feedback(at, measured) else {
                continue;
            };
            if x.abs() >= MIN_EXCITATION_MPS {
                self.sxx = self.sxx * FORGET + x * x;
                self.sxy = self.sxy * FORGET + x * y;
                self.sdt = self.sdt * FORGET + x * x * dt;
            }
        }
    }

    /// The drives do not follow speed commands for now (a stop, a quick stop): what they
    /// do until the next command says nothing about their lag.
    pub fn interrupt(&mut self) {
        self.wheels = Default::default();
    }

    /// The wheel speeds commanded from `t` on (m/s, left and right).
    pub fn command(&mut self, t: Timestamp, command: (f64, f64)) {
        self.wheels[0].command(t, command.0);
        self.wheels[1].command(t, command.1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A first-order wheel of time constant `tau` sending its speed every 20 ms at `phase_ms`
    /// into the period, read by a 10 ms control loop that then commands a square wave.
    fn learn(tau: f64, phase_ms: u64) -> f64 {
        let mut e = ResponseEstimator::default();
        let mut v = 0.0;
        let mut c = 0.0;
        let mut sent = (Timestamp::from_micros(0), 0.0);
        for ms in 0..20_000u64 {
            let t = Timestamp::from_micros(ms * 1000);
            v += (c - v) * (0.001 / tau);
            if ms % 20 == phase_ms {
                sent = (t, v);
            }
            if ms % 10 == 0 {
                e.feedback(sent, sent);
                c = if (ms / 1500) % 2 == 0 { 0.8 } else { -0.3 };
                e.command(t, (c, c));
            }
        }
        e.time_constant()
    }

    #[test]
    fn learns_the_lag_of_nimble_and_slow_drives() {
        assert_eq!(
            ResponseEstimator::default().time_constant(),
            DEFAULT_RESPONSE_S
        );
        for tau in [0.03, 0.05, 0.1, 0.3] {
            for phase_ms in [0, 7, 13] {
                let learnt = learn(tau, phase_ms);
                assert!(
                    (learnt - tau).abs() < 0.05 * tau + 0.002,
                    "{tau} at phase {phase_ms} ms: {learnt}"
                );
            }
        }
    }
}
