//! The safety envelope of autonomous work, as the core runs it each control tick:
//! - the GNSS gate ([`super::gate`]): while it is closed, autonomous motion pauses at rest
//!   (a path task or a mission holds; a goal or a move, which cannot hold, ends), the blade
//!   stops in the same tick, and nothing autonomous starts; when it opens again, what it
//!   paused goes on by itself;
//! - the zones at run time ([`super::zones`]): a braking way into a zone is a cause for the
//!   supervisor, which latches the stop with it; in manual mode `zones.manual = "warn"`
//!   only reports it.

use std::sync::Arc;

use super::chassis::{CONTROL_PERIOD, Chassis, CommandRejected};
use super::gate::{Gate, GateChange, GateConfig, GateReason, GateSignals, horizontal_sigma};
use super::safety::Cause;
use super::zones::{Braking, NearestZone, ZoneGuard};
use crate::config::zones::ManualPolicy;
use crate::fusion::localizer::Localizer;
use crate::time::Timestamp;
use crate::zones::local::ZoneOutline;

/// The pose the run-time check uses is at most this old, in control periods.
const POSE_AGE_PERIODS: f64 = 1.0;

/// The zones and the gate, and what they hold.
#[derive(Debug, Clone)]
pub struct Envelope {
    guard: ZoneGuard,
    gate: Gate,
    manual: ManualPolicy,
    /// The gate paused a task or a mission, to go on when it opens.
    paused: bool,
    /// The zone last reported to a manual driver under `warn`, while it stays ahead.
    warned: Option<String>,
}

/// The envelope as a status shows it, when zones are configured.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvelopeStatus {
    /// Why the GNSS gate is closed; `None` while it is open.
    pub gate_closed: Option<GateReason>,
    /// The zones in the map frame, once it is placed: the same `Arc` until they change.
    pub zones: Option<Arc<[ZoneOutline]>>,
    /// The zone nearest the footprint, once placed.
    pub nearest: Option<NearestZone>,
    /// The footprint's circumscribed radius, m.
    pub footprint_m: f64,
    /// The map position's horizontal σ, m (once placed).
    pub sigma_m: Option<f64>,
    /// The braking way at the measured speed, m (0 without drives).
    pub braking_m: f64,
}

impl EnvelopeStatus {
    /// What the run-time check keeps beyond the footprint now: σ and the braking way, m.
    pub fn margin_m(&self) -> Option<f64> {
        self.sigma_m.map(|sigma| sigma + self.braking_m)
    }
}

impl Envelope {
    /// The status at `t`: the gate, the zones, and how near the vehicle stands to them
    /// against what it keeps.
    pub fn status(
        &mut self,
        localizer: &Localizer,
        chassis: Option<&Chassis>,
        t: Timestamp,
    ) -> EnvelopeStatus {
        let placed = localizer.map_placement().zip(localizer.published(t));
        let speed = chassis.map_or(0.0, |c| {
            c.speeds_ahead(t)
                .iter()
                .map(|(v, _)| v.abs())
                .fold(0.0, f64::max)
        });
        EnvelopeStatus {
            gate_closed: self.gate.closed().cloned(),
            zones: placed.map(|(placement, _)| self.guard.outlines(placement)),
            nearest: placed.and_then(|(placement, pose)| {
                let (x, y, _) = pose.map_pose;
                self.guard.nearest(placement, (x, y))
            }),
            footprint_m: self.guard.footprint_m(),
            sigma_m: map_sigma(localizer, t),
            braking_m: chassis.map_or(0.0, |c| braking(c).distance(speed)),
        }
    }

    /// The zones of `guard`, the gate of `gate` and the manual policy.
    pub fn new(guard: ZoneGuard, gate: GateConfig, manual: ManualPolicy) -> Self {
        Self {
            guard,
            gate: Gate::new(gate),
            manual,
            paused: false,
            warned: None,
        }
    }

    /// The zones.
    pub fn guard(&mut self) -> &mut ZoneGuard {
        &mut self.guard
    }

    /// Why the gate is closed, when it is.
    pub fn gate_closed(&self) -> Option<&GateReason> {
        self.gate.closed()
    }

    /// Refuses autonomous work while the gate is closed.
    pub fn may_start(&self) -> Result<(), CommandRejected> {
        match self.gate.closed() {
            Some(reason) => Err(CommandRejected::GnssGate(reason.clone())),
            None => Ok(()),
        }
    }
}

impl Envelope {
    /// The gate's judgement of `signals` at `t`: whether it closed or opened.
    pub(super) fn update_gate(
        &mut self,
        t: Timestamp,
        signals: &GateSignals,
    ) -> Option<GateChange> {
        self.gate.update(t, signals)
    }

    /// Notes whether the gate's closing paused work that goes on when it opens.
    pub(super) fn hold_paused(&mut self, paused: bool) {
        self.paused = paused;
    }

    /// Whether the gate paused work, forgetting it: asked once, when the gate opens.
    pub(super) fn take_paused(&mut self) -> bool {
        std::mem::take(&mut self.paused)
    }
}

/// Whether the gate lets the blade run now (always, without zones).
pub(super) fn lets_blade_run(envelope: Option<&Envelope>) -> bool {
    envelope.is_none_or(|e| e.gate_closed().is_none())
}

/// Refuses autonomous work while the gate is closed (without zones, nothing to refuse).
pub(super) fn may_start(envelope: Option<&Envelope>) -> Result<(), CommandRejected> {
    envelope.map_or(Ok(()), Envelope::may_start)
}

/// How the drives brake, as the zone checks take it: from the decision (the pose's age and
/// a control period, and the drives' learnt response) at the chassis's deceleration limit.
pub(super) fn braking(chassis: &Chassis) -> Braking {
    Braking {
        reaction_s: (POSE_AGE_PERIODS + 1.0) * CONTROL_PERIOD.as_secs_f64()
            + chassis.response_time(),
        decel_mps2: chassis.braking_decel(),
    }
}

/// The map pose's horizontal σ at `t`, m (`None` while not placed).
pub(super) fn map_sigma(localizer: &Localizer, t: Timestamp) -> Option<f64> {
    localizer.published(t).map(|p| {
        let [xx, xy, yy, _] = p.map_covariance;
        horizontal_sigma(xx, xy, yy)
    })
}

/// The run-time zone check of a control tick, just before the supervisor's tick: the
/// braking ways from the map pose, at the speeds the wheels measure and are about to be
/// sent, with the footprint grown by the position's σ. What it finds becomes the
/// supervisor's zone cause; under `zones.manual = "warn"` a manual driver is told instead
/// (what is said goes into `events`).
pub(super) fn zone_tick(
    envelope: &mut Envelope,
    localizer: &Localizer,
    chassis: &mut Chassis,
    t: Timestamp,
    events: &mut Vec<String>,
) {
    let (Some(placement), Some(pose)) = (localizer.map_placement(), localizer.published(t)) else {
        // Not placed: no way can be checked. Autonomous work is held by the gate; a manual
        // driver drives on what they see.
        chassis.zone_ahead(None);
        return;
    };
    let [xx, xy, yy, _] = pose.map_covariance;
    let sigma = horizontal_sigma(xx, xy, yy);
    let braking = braking(chassis);
    let ways: Vec<_> = chassis
        .speeds_ahead(t)
        .iter()
        .map(|&(v, w)| braking.way(pose.map_pose, v, w))
        .collect();
    let conflict = envelope.guard.check_ahead(placement, &ways, sigma);
    let manual = !chassis.is_autonomous();
    let zone = match conflict {
        Some(c) if manual && envelope.manual == ManualPolicy::Warn => {
            if envelope.warned.as_deref() != Some(c.name.as_str()) {
                events.push(format!(
                    "the {} zone {:?} is in the braking way at ({:.2}, {:.2}) m; driving on \
                     (zones.manual = \"warn\")",
                    c.kind.name(),
                    c.name,
                    c.at.0,
                    c.at.1
                ));
                envelope.warned = Some(c.name);
            }
            None
        }
        Some(c) => {
            envelope.warned = None;
            // Said once, when it latches: the supervisor's cause carries no place.
            let latched_for_it = matches!(
                chassis.safety().latched(),
                Some(Cause::Zone { name, .. }) if *name == c.name
            );
            if !latched_for_it {
                events.push(format!(
                    "stopping: the {} zone {:?} is in the braking way at ({:.2}, {:.2}) m \
                     (σ {sigma:.3} m)",
                    c.kind.name(),
                    c.name,
                    c.at.0,
                    c.at.1
                ));
            }
            Some((c.kind.name(), c.name))
        }
        None => {
            envelope.warned = None;
            None
        }
    };
    chassis.zone_ahead(zone);
}
