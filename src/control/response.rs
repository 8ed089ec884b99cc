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

/// The drives' speed response, learnt from commands and feedback.
#[derive(Debug, Clone, Default)]
pub struct ResponseEstimator {
    /// The last distinct feedback: time and wheel speeds (m/s).
    last_feedback: Option<(Timestamp, (f64, f64))>,
    /// The command in force since the last tick: time and wheel speeds (m/s).
    command: Option<(Timestamp, (f64, f64))>,
    /// ∫ command dt since the last distinct feedback, per wheel.
    command_integral: (f64, f64),
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

    /// The wheel speeds reported at `t` (m/s). A value unchanged since the last is no new
    /// feedback (drives report more slowly than the control loop runs).
    pub fn feedback(&mut self, t: Timestamp, measured: (f64, f64)) {
        self.integrate_command(t);
        let Some((t0, v0)) = self.last_feedback else {
            self.last_feedback = Some((t, measured));
            self.command_integral = (0.0, 0.0);
            return;
        };
        if measured == v0 {
            return;
        }
        let dt = t.saturating_since(t0).as_secs_f64();
        if dt > 0.0 && dt <= MAX_INTERVAL_S {
            for (integral, before, now) in [
                (self.command_integral.0, v0.0, measured.0),
                (self.command_integral.1, v0.1, measured.1),
            ] {
                // x = c̄ − v (the mean command over the interval), y = Δv.
                let x = integral / dt - before;
                if x.abs() >= MIN_EXCITATION_MPS {
                    self.sxx = self.sxx * FORGET + x * x;
                    self.sxy = self.sxy * FORGET + x * (now - before);
                    self.sdt = self.sdt * FORGET + x * x * dt;
                }
            }
        }
        self.last_feedback = Some((t, measured));
        self.command_integral = (0.0, 0.0);
    }

    /// The drives do not follow speed commands for now (a stop, a quick stop): what they
    /// do until the next command says nothing about their lag.
    pub fn interrupt(&mut self) {
        self.last_feedback = None;
        self.command = None;
        self.command_integral = (0.0, 0.0);
    }

    /// The wheel speeds commanded from `t` on (m/s).
    pub fn command(&mut self, t: Timestamp, command: (f64, f64)) {
        self.integrate_command(t);
        self.command = Some((t, command));
    }

    fn integrate_command(&mut self, t: Timestamp) {
        if let Some((since, c)) = &mut self.command {
            let dt = t.saturating_since(*since).as_secs_f64();
            self.command_integral.0 += c.0 * dt;
            self.command_integral.1 += c.1 * dt;
            *since = t;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A first-order wheel of time constant `tau` reporting every 20 ms, commanded by a
    /// square wave every 10 ms.
    fn learn(tau: f64) -> f64 {
        let mut e = ResponseEstimator::default();
        let mut v = 0.0;
        for ms in 0..20_000u64 {
            let t = Timestamp::from_micros(ms * 1000);
            let c = if (ms / 1500) % 2 == 0 { 0.8 } else { -0.3 };
            if ms % 10 == 0 {
                e.command(t, (c, c));
            }
            v += (c - v) * (0.001 / tau);
            if ms % 20 == 0 {
                e.feedback(t, (v, v));
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
            let learnt = learn(tau);
            assert!((learnt - tau).abs() < 0.15 * tau + 0.005, "{tau}: {learnt}");
        }
    }
}
