//! The GNSS gate of autonomous work: autonomous motion and the cutter go on only while the
//! fix is good enough to keep to the zones (its quality, the position's σ, its age and the
//! corrections' age). The gate closes at the first bad sample and opens again only after
//! the signals have stayed good for the resume time without a break, so a fix that
//! flickers between fixed and float keeps it closed rather than flapping.
//!
//! The signals are the ones the status shows (the fresh fix quality, the map pose's
//! covariance, the correction age), read at the same tick, never a copy kept aside.

use std::fmt;
use std::time::Duration;

use crate::config::zones::{GateQuality, ZonesConfig};
use crate::devices::gnss::FixQuality;
use crate::time::Timestamp;

/// The gate's thresholds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateConfig {
    /// The least fix quality.
    pub min_quality: GateQuality,
    /// The largest horizontal σ of the position, m.
    pub max_sigma_m: f64,
    /// The oldest fix.
    pub max_fix_age: Duration,
    /// The oldest corrections, when a correction source is configured.
    pub max_correction_age: Option<Duration>,
    /// How long the signals must stay good before work resumes.
    pub resume_after: Duration,
}

impl GateConfig {
    /// The gate of `[zones]`; `corrections` says whether a correction source is configured.
    pub fn from_zones(zones: &ZonesConfig, corrections: bool) -> Self {
        Self {
            min_quality: zones.min_quality,
            max_sigma_m: zones.max_sigma_m,
            max_fix_age: Duration::from_secs_f64(zones.max_fix_age_s),
            max_correction_age: corrections
                .then(|| Duration::from_secs_f64(zones.max_correction_age_s)),
            resume_after: Duration::from_secs_f64(zones.resume_after_s),
        }
    }
}

/// What the gate reads at a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateSignals {
    /// The fix quality the status shows (`Invalid` once stale or with the link down).
    pub quality: FixQuality,
    /// The age of the latest valid position; `None` before the first.
    pub fix_age: Option<Duration>,
    /// The map pose's horizontal σ (the larger axis of its covariance), m; `None` while the
    /// vehicle is not placed.
    pub sigma_m: Option<f64>,
    /// The age of the last valid correction frame; `None` before the first.
    pub correction_age: Option<Duration>,
}

/// Why the gate is closed.
#[derive(Debug, Clone, PartialEq)]
pub enum GateReason {
    /// No valid fix, or a stale one.
    NoFix,
    /// The fix is valid but below the least quality.
    Quality {
        /// The quality now.
        have: FixQuality,
        /// The least taken.
        need: GateQuality,
    },
    /// The fix is older than the limit.
    FixAge {
        /// Its age, s.
        age_s: f64,
        /// The limit, s.
        max_s: f64,
    },
    /// The position is not placed in the map frame yet.
    Unplaced,
    /// The position's σ is beyond the limit.
    Sigma {
        /// σ now, m.
        sigma_m: f64,
        /// The limit, m.
        max_m: f64,
    },
    /// No correction frame yet.
    NoCorrections,
    /// The corrections are older than the limit.
    CorrectionAge {
        /// Their age, s.
        age_s: f64,
        /// The limit, s.
        max_s: f64,
    },
}

impl fmt::Display for GateReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoFix => write!(f, "no valid GNSS fix"),
            Self::Quality { have, need } => {
                write!(f, "fix quality {have}, below zones.min_quality = {need}")
            }
            Self::FixAge { age_s, max_s } => {
                write!(
                    f,
                    "fix {age_s:.1} s old, over {max_s} s (zones.max_fix_age_s)"
                )
            }
            Self::Unplaced => write!(f, "the position is not placed in the map yet"),
            Self::Sigma { sigma_m, max_m } => write!(
                f,
                "position σ {sigma_m:.3} m, over {max_m} m (zones.max_sigma_m)"
            ),
            Self::NoCorrections => write!(f, "no RTK corrections yet"),
            Self::CorrectionAge { age_s, max_s } => write!(
                f,
                "corrections {age_s:.1} s old, over {max_s} s (zones.max_correction_age_s)"
            ),
        }
    }
}

/// What changed at a tick.
#[derive(Debug, Clone, PartialEq)]
pub enum GateChange {
    /// The gate closed: work pauses.
    Closed(GateReason),
    /// The gate opened after the resume time: work goes on.
    Opened,
}

/// The gate.
#[derive(Debug, Clone)]
pub struct Gate {
    config: GateConfig,
    /// Why it is closed, and since when the signals have been good (`None`: bad now).
    closed: Option<(GateReason, Option<Timestamp>)>,
}

impl Gate {
    /// A gate closed until the signals have been good for the resume time.
    pub fn new(config: GateConfig) -> Self {
        Self {
            config,
            closed: Some((GateReason::NoFix, None)),
        }
    }

    /// Why the gate is closed, when it is.
    pub fn closed(&self) -> Option<&GateReason> {
        self.closed.as_ref().map(|(reason, _)| reason)
    }

    /// The first of the signals at a tick that fails the gate, if any.
    pub fn judge(&self, s: &GateSignals) -> Option<GateReason> {
        let c = &self.config;
        if !s.quality.is_valid() {
            return Some(GateReason::NoFix);
        }
        if !c.min_quality.admits(s.quality) {
            return Some(GateReason::Quality {
                have: s.quality,
                need: c.min_quality,
            });
        }
        match s.fix_age {
            None => return Some(GateReason::NoFix),
            Some(age) if age > c.max_fix_age => {
                return Some(GateReason::FixAge {
                    age_s: age.as_secs_f64(),
                    max_s: c.max_fix_age.as_secs_f64(),
                });
            }
            Some(_) => {}
        }
        match s.sigma_m {
            None => return Some(GateReason::Unplaced),
            // A NaN σ fails too.
            Some(sigma) if sigma.is_nan() || sigma > c.max_sigma_m => {
                return Some(GateReason::Sigma {
                    sigma_m: sigma,
                    max_m: c.max_sigma_m,
                });
            }
            Some(_) => {}
        }
        if let Some(max) = c.max_correction_age {
            match s.correction_age {
                None => return Some(GateReason::NoCorrections),
                Some(age) if age > max => {
                    return Some(GateReason::CorrectionAge {
                        age_s: age.as_secs_f64(),
                        max_s: max.as_secs_f64(),
                    });
                }
                Some(_) => {}
            }
        }
        None
    }

    /// The signals at `t`: closes at once on a bad one, opens after the resume time of
    /// good ones in a row.
    pub fn update(&mut self, t: Timestamp, signals: &GateSignals) -> Option<GateChange> {
        let bad = self.judge(signals);
        match (&mut self.closed, bad) {
            (None, None) => None,
            (None, Some(reason)) => {
                self.closed = Some((reason.clone(), None));
                Some(GateChange::Closed(reason))
            }
            (Some(closed), Some(reason)) => {
                *closed = (reason, None);
                None
            }
            (Some((_, good_since)), None) => {
                let since = *good_since.get_or_insert(t);
                if t.saturating_since(since) >= self.config.resume_after {
                    self.closed = None;
                    Some(GateChange::Opened)
                } else {
                    None
                }
            }
        }
    }
}

/// The horizontal σ of a position covariance (var x, cov xy, var y, m²): the square root
/// of its larger eigenvalue, m.
pub fn horizontal_sigma(xx: f64, xy: f64, yy: f64) -> f64 {
    let mean = (xx + yy) / 2.0;
    let spread = ((xx - yy) / 2.0).hypot(xy);
    (mean + spread).max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The refusal speaks the configuration's words and says the command is not kept.
    #[test]
    fn the_refusal_names_the_key_in_its_own_words_and_is_not_a_queue() {
        let reason = GateReason::Quality {
            have: FixQuality::RtkFloat,
            need: GateQuality::RtkFixed,
        };
        let refusal = crate::vehicle::chassis::CommandRejected::GnssGate(reason).to_string();
        assert!(
            refusal.starts_with(
                "the GNSS gate is closed (fix quality RTK float, below zones.min_quality = \
                 rtk_fixed): autonomous work is refused"
            ),
            "{refusal}"
        );
        assert!(refusal.contains("send the command again"), "{refusal}");
    }

    fn config() -> GateConfig {
        GateConfig {
            min_quality: GateQuality::RtkFixed,
            max_sigma_m: 0.1,
            max_fix_age: Duration::from_secs(1),
            max_correction_age: Some(Duration::from_secs(10)),
            resume_after: Duration::from_secs(10),
        }
    }

    fn good() -> GateSignals {
        GateSignals {
            quality: FixQuality::RtkFixed,
            fix_age: Some(Duration::from_millis(100)),
            sigma_m: Some(0.02),
            correction_age: Some(Duration::from_secs(1)),
        }
    }

    fn s(v: u64) -> Timestamp {
        Timestamp::from_micros(v * 1_000_000)
    }

    #[test]
    fn each_signal_closes_the_gate_with_its_reason() {
        let gate = Gate::new(config());
        assert_eq!(gate.judge(&good()), None);
        let cases = [
            (
                GateSignals {
                    quality: FixQuality::Invalid,
                    ..good()
                },
                "no valid GNSS fix",
            ),
            (
                GateSignals {
                    quality: FixQuality::RtkFloat,
                    ..good()
                },
                "zones.min_quality",
            ),
            (
                GateSignals {
                    fix_age: Some(Duration::from_millis(1500)),
                    ..good()
                },
                "zones.max_fix_age_s",
            ),
            (
                GateSignals {
                    sigma_m: Some(0.2),
                    ..good()
                },
                "zones.max_sigma_m",
            ),
            (
                GateSignals {
                    sigma_m: Some(f64::NAN),
                    ..good()
                },
                "zones.max_sigma_m",
            ),
            (
                GateSignals {
                    sigma_m: None,
                    ..good()
                },
                "not placed",
            ),
            (
                GateSignals {
                    correction_age: None,
                    ..good()
                },
                "no RTK corrections",
            ),
            (
                GateSignals {
                    correction_age: Some(Duration::from_secs(11)),
                    ..good()
                },
                "zones.max_correction_age_s",
            ),
        ];
        for (signals, says) in cases {
            let reason = gate.judge(&signals).expect("closed").to_string();
            assert!(reason.contains(says), "{reason} should say {says}");
        }
    }

    #[test]
    fn without_a_correction_source_their_age_is_not_asked() {
        let gate = Gate::new(GateConfig {
            max_correction_age: None,
            ..config()
        });
        let signals = GateSignals {
            correction_age: None,
            ..good()
        };
        assert_eq!(gate.judge(&signals), None);
    }

    #[test]
    fn it_opens_only_after_the_resume_time_of_good_signals_in_a_row() {
        let mut gate = Gate::new(config());
        assert_eq!(gate.closed(), Some(&GateReason::NoFix));
        assert_eq!(gate.update(s(0), &good()), None);
        assert_eq!(gate.update(s(9), &good()), None);
        assert_eq!(gate.update(s(10), &good()), Some(GateChange::Opened));
        let float = GateSignals {
            quality: FixQuality::RtkFloat,
            ..good()
        };
        assert!(matches!(
            gate.update(s(11), &float),
            Some(GateChange::Closed(GateReason::Quality { .. }))
        ));
        // Flickering: each bad sample starts the wait again.
        for t in 12..40 {
            let signals = if t % 5 == 0 { float } else { good() };
            assert_eq!(gate.update(s(t), &signals), None, "at {t} s");
        }
        // The last bad one was at 35 s, good ones from 36 s.
        assert_eq!(gate.update(s(45), &good()), None);
        assert_eq!(gate.update(s(46), &good()), Some(GateChange::Opened));
    }

    #[test]
    fn the_larger_axis_of_the_covariance_is_the_sigma() {
        assert!((horizontal_sigma(0.04, 0.0, 0.01) - 0.2).abs() < 1e-12);
        assert!((horizontal_sigma(0.01, 0.0, 0.04) - 0.2).abs() < 1e-12);
        // 45° ellipse with axes² 0.05 and 0.01.
        assert!((horizontal_sigma(0.03, 0.02, 0.03) - 0.05f64.sqrt()).abs() < 1e-12);
        assert_eq!(horizontal_sigma(0.0, 0.0, 0.0), 0.0);
    }
}
