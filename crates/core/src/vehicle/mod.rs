//! The sans-IO vehicle core: owns the vehicle state and is driven only by
//! [`Vehicle::handle`], which takes the time as an argument and never reads a clock.
//!
//! The vehicle is its parts, each with one job: the localisation feed
//! ([`localisation`]), the task executive ([`executive`]: motion, mission, cutter), the
//! drive train's supervisor ([`chassis`]), the safety envelope ([`envelope`]), the RTK
//! corrections' watch ([`corrections`]) and the status assembly ([`assembly`]).
//! [`Vehicle::handle`] only routes each input to the part whose job it is.

mod assembly;
pub mod chassis;
mod core_config;
pub mod corrections;
pub mod envelope;
mod event;
mod executive;
pub mod feedback;
pub mod gate;
mod localisation;
mod messages;
pub mod safety;
pub mod status;
#[cfg(test)]
mod test_rig;
pub mod zones;

use std::time::Duration;

use crate::devices::bms::{BmsReading, ChargeState, is_stale};
use crate::devices::gnss::GnssFix;
use crate::fusion::odometry::OdomPose;
use crate::time::Timestamp;
pub use chassis::DriveMode;
use chassis::{Chassis, CommandRejected};
pub use core_config::CoreConfig;
pub use event::Event;
use executive::{Executive, Plant};
use localisation::Localisation;
pub use messages::{Command, Device, Input, LinkState, Output, PathPoints, PathRequest};
use safety::SafetyConfig;
pub use status::{
    BatteryStatus, FrameTree, GnssStatus, HostUsage, Localization, MqttLinkStatus, Navigation,
    Pose2D, PoseCovariance, PoseReport, VehicleStatus,
};

/// The vehicle core.
#[derive(Debug, Clone)]
pub struct Vehicle {
    config: CoreConfig,
    /// Where the vehicle is: the receiver, the IMU, the odom frame and the localiser.
    place: Localisation,
    /// The drive train; `None` without drives.
    chassis: Option<Chassis>,
    /// The motion, the mission and the cutter.
    executive: Executive,
    bms: Option<BmsReading>,
    /// The host's load, when sampled.
    host: Option<HostUsage>,
    /// RTK corrections, when a correction source is configured.
    corrections: Option<corrections::Corrections>,
    /// The zones and the GNSS gate, when zones are configured.
    envelope: Option<envelope::Envelope>,
}

impl Vehicle {
    /// A core with nothing known yet.
    pub fn new(config: CoreConfig) -> Self {
        Self {
            chassis: config.chassis.map(|c| {
                Chassis::new(
                    c,
                    SafetyConfig {
                        cmd_timeout: c.cmd_timeout(),
                        quick_stop: c.quick_stop(),
                        reset_timeout: c.reset_timeout(),
                        control_link: config.control_link,
                        enable_on_start: c.enable_on_start,
                    },
                )
            }),
            place: Localisation::new(&config),
            executive: Executive::new(&config),
            config,
            bms: None,
            host: None,
            corrections: config
                .corrections_stale_after
                .map(corrections::Corrections::new),
            envelope: None,
        }
    }

    /// The core, keeping to the zones and the GNSS gate of `envelope`: every motion's way is
    /// checked before it starts, the braking way every control tick.
    pub fn with_envelope(mut self, envelope: envelope::Envelope) -> Self {
        self.envelope = Some(envelope);
        self
    }

    /// The `odom` frame's pose (wheels and gyro), once the drives have reported.
    pub fn odom_pose(&self) -> Option<OdomPose> {
        self.place.odom_pose()
    }

    /// The drives' speed response time learnt so far, s; `None` without drives.
    pub fn response_time(&self) -> Option<f64> {
        self.chassis.as_ref().map(Chassis::response_time)
    }

    /// The receiver's latest fix, as the core holds it.
    pub fn gnss_fix(&self) -> Option<&GnssFix> {
        self.place.gnss_fix()
    }

    /// The age of the last valid correction frame at `t`, when a source is configured and
    /// one has arrived.
    pub fn correction_age(&self, t: Timestamp) -> Option<Duration> {
        self.corrections.as_ref().and_then(|c| c.age(t))
    }

    /// The `odom` pose and the map pose at `t`, without the rest of a status.
    pub fn pose_report(&self, t: Timestamp) -> PoseReport {
        self.place.pose_report(t)
    }

    /// Handles one input at time `t` and returns what it produced: each input goes to the
    /// part whose job it is.
    pub fn handle(&mut self, t: Timestamp, input: Input<'_>) -> Vec<Output> {
        match input {
            Input::Gnss(fix) => events(self.place.gnss(t, fix), Event::Localisation),
            Input::Link(Device::Gnss, state) => {
                self.place.gnss_link(state == LinkState::Up);
                Vec::new()
            }
            Input::Link(Device::Imu, state) => {
                self.place.imu_link(state == LinkState::Up);
                Vec::new()
            }
            Input::Link(Device::Corrections, state) => {
                if let Some(c) = &mut self.corrections {
                    c.link(t, state == LinkState::Up);
                }
                Vec::new()
            }
            Input::Corrections { frames, bytes } => events(
                self.corrections
                    .as_mut()
                    .and_then(|c| c.frames(t, frames, bytes)),
                Event::Corrections,
            ),
            Input::Imu(sample) => {
                self.place.imu(sample);
                Vec::new()
            }
            Input::Chassis(feedback) => {
                if let (Some(c), Some(cfg)) = (&mut self.chassis, self.config.chassis) {
                    c.feedback(feedback.clone());
                    self.place.wheels(t, feedback, cfg.wheel_radius_m);
                }
                Vec::new()
            }
            Input::Bms(reading) => {
                self.bms = Some(*reading);
                Vec::new()
            }
            Input::Host(usage) => {
                self.host = Some(usage);
                Vec::new()
            }
            Input::Command(command) => {
                let mut out = Vec::new();
                let result = self.command(t, command, &mut out);
                out.push(Output::CommandResult(result));
                out
            }
            Input::ControlTick => self.control_tick(t),
            Input::Tick => self.tick(t),
        }
    }

    /// A command's result, from the part it concerns (what else it produced into `out`).
    fn command(
        &mut self,
        t: Timestamp,
        command: Command,
        out: &mut Vec<Output>,
    ) -> Result<(), CommandRejected> {
        let (executive, mut plant) = self.executive_and_plant();
        match command {
            Command::Velocity { vx, wz } => executive.velocity(t, &mut plant, vx, wz),
            Command::Move(kind) => executive.start_move(t, &mut plant, kind),
            Command::Goal { goal, tag } => executive.goal(t, &mut plant, goal, tag),
            Command::FollowPath { path, tag } => executive.follow_path(t, &mut plant, &path, tag),
            Command::Mission { steps, tag } => executive.start_mission(t, &mut plant, &steps, tag),
            Command::Pause => executive.pause(t, &mut plant),
            Command::Continue => executive.resume(t, &mut plant),
            Command::CancelMotion => executive.cancel_motion(t, &mut plant),
            Command::Stop => executive.stop(t, &mut plant),
            Command::SetMode(mode) => executive.set_mode(t, &mut plant, mode),
            Command::Reset => self.with_chassis(|c| c.reset(t)),
            Command::EmergencyStop { engaged } => self.with_chassis(|c| {
                c.software_estop(t, engaged);
                Ok(())
            }),
            Command::ControlHeartbeat => {
                if let Some(c) = &mut self.chassis {
                    c.control_heartbeat(t);
                }
                Ok(())
            }
            // The motion's goal or heading is in the map: moving the map would move the goal.
            Command::ZeroLocalFrame | Command::SetPose { .. } | Command::SetDatum(_)
                if self.executive.uses_map_frame() =>
            {
                Err(CommandRejected::MoveUnderWay)
            }
            Command::ZeroLocalFrame => self.place.zero_here(t),
            Command::SetPose { x, y, yaw } => self.place.set_pose(t, x, y, yaw),
            Command::SetDatum(datum) => self.place.set_datum(datum),
            Command::EditZones(edit) => self.edit_zones(&edit, out),
        }
    }

    /// The executive, and the parts it works with and on.
    fn executive_and_plant(&mut self) -> (&mut Executive, Plant<'_>) {
        (
            &mut self.executive,
            Plant {
                chassis: self.chassis.as_mut(),
                place: &self.place,
                envelope: self.envelope.as_mut(),
            },
        )
    }

    /// One control step (with drives): the executive steps the work under the envelope,
    /// and the drive train decides what reaches the wheels.
    fn control_tick(&mut self, t: Timestamp) -> Vec<Output> {
        let gate = self.envelope.is_some().then(|| self.gate_signals(t));
        let charging = self.charging(t);
        let (executive, mut plant) = self.executive_and_plant();
        executive.control_tick(t, &mut plant, gate.as_ref(), charging)
    }

    /// The GNSS gate's signals at `t`: the ones the status shows.
    fn gate_signals(&self, t: Timestamp) -> gate::GateSignals {
        let position = self.place.gnss_fix().and_then(|f| f.position);
        gate::GateSignals {
            quality: self.place.fresh_fix_quality(t),
            fix_age: position.map(|p| t.saturating_since(p.rx)),
            sigma_m: envelope::map_sigma(self.place.localizer(), t),
            correction_age: self.correction_age(t),
        }
    }

    /// The status tick: the corrections' watch, then the status.
    fn tick(&mut self, t: Timestamp) -> Vec<Output> {
        let corrections = self.corrections.as_mut().map(|c| c.tick(t));
        let event = corrections.as_ref().and_then(|(_, e)| e.clone());
        let mut status = assembly::status(
            t,
            assembly::Parts {
                place: &mut self.place,
                chassis: self.chassis.as_ref(),
                executive: &self.executive,
                envelope: self.envelope.as_mut(),
                bms: self.bms,
                bms_stale_after: self.config.bms_stale_after,
                host: self.host,
            },
        );
        status.corrections = corrections.map(|(s, _)| s);
        let mut outputs = vec![Output::Status(Box::new(status))];
        outputs.extend(event.map(|e| Output::Event(Event::Corrections(e))));
        outputs
    }

    /// Whether a fresh BMS reading says the vehicle charges (a mission's CHARGING waits
    /// for it).
    fn charging(&self, t: Timestamp) -> bool {
        self.bms.is_some_and(|b| {
            b.charge_state == Some(ChargeState::Charging)
                && self
                    .config
                    .bms_stale_after
                    .is_some_and(|stale| !is_stale(&b, t, stale))
        })
    }

    /// Adds or removes a zone; the zones written back when they changed.
    fn edit_zones(
        &mut self,
        edit: &zones::ZoneEdit,
        out: &mut Vec<Output>,
    ) -> Result<(), CommandRejected> {
        let placement = self.place.localizer().map_placement();
        let result = match &mut self.envelope {
            None => Err(CommandRejected::ZoneEdit(
                "no zones are configured ([zones] in the configuration, or --zones FILE)".into(),
            )),
            Some(envelope) => envelope.guard().edit(placement, edit),
        };
        if let (Ok(id), Some(envelope)) = (&result, &mut self.envelope) {
            let what = match edit {
                zones::ZoneEdit::Add { name, kind, .. } => {
                    format!("{} zone {name:?} added", kind.name())
                }
                zones::ZoneEdit::Remove(_) => "zone removed".to_owned(),
            };
            out.push(Output::Event(Event::ZoneEdited { what, id: *id }));
            out.push(Output::ZonesChanged(envelope.guard().set().to_geojson()));
        }
        result.map(|_| ())
    }

    /// Runs `f` on the drive train; refused without one.
    fn with_chassis(
        &mut self,
        f: impl FnOnce(&mut Chassis) -> Result<(), CommandRejected>,
    ) -> Result<(), CommandRejected> {
        match &mut self.chassis {
            Some(c) => f(c),
            None => Err(CommandRejected::NoDrives),
        }
    }
}

/// Events for the operator's log, of the kind `kind`.
fn events(events: impl IntoIterator<Item = String>, kind: fn(String) -> Event) -> Vec<Output> {
    events.into_iter().map(|e| Output::Event(kind(e))).collect()
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::motion::MotionConfig;
    use crate::control::goal::GoalPose;
    use crate::devices::gnss::Timed;
    use crate::vehicle::test_rig::{self, at, drives_at_rest};

    fn with_drives() -> Vehicle {
        let chassis = test_rig::chassis();
        Vehicle::new(CoreConfig {
            chassis: Some(chassis),
            motion: Some(MotionConfig::default().settings(&chassis)),
            ..CoreConfig::default()
        })
    }

    /// An RTK fixed epoch with a dual-antenna heading, at `ms`.
    fn fixed_with_heading_at(ms: u64) -> GnssFix {
        GnssFix {
            heading_deg: Some(Timed {
                value: 90.0,
                rx: at(ms),
            }),
            ..test_rig::fixed_at(ms)
        }
    }

    fn results(out: &[Output]) -> Vec<Result<(), CommandRejected>> {
        out.iter()
            .filter_map(|o| match o {
                Output::CommandResult(r) => Some(r.clone()),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_tick_gives_one_status_and_a_command_one_result() {
        let mut v = Vehicle::new(CoreConfig::default());
        let out = v.handle(at(0), Input::Tick);
        assert!(matches!(out.as_slice(), [Output::Status(_)]), "{out:?}");
        assert_eq!(
            v.handle(at(0), Input::Command(Command::Stop)),
            vec![Output::CommandResult(Err(CommandRejected::NoDrives))]
        );
        assert_eq!(
            v.handle(at(0), Input::Command(Command::ControlHeartbeat)),
            vec![Output::CommandResult(Ok(()))]
        );
        assert!(v.handle(at(0), Input::ControlTick).is_empty());
    }

    #[test]
    fn a_zone_edit_without_zones_is_refused_with_the_fix() {
        let mut v = Vehicle::new(CoreConfig::default());
        let out = v.handle(
            at(0),
            Input::Command(Command::EditZones(zones::ZoneEdit::Remove(1))),
        );
        assert!(
            matches!(
                results(&out).as_slice(),
                [Err(CommandRejected::ZoneEdit(why))] if why.contains("--zones")
            ),
            "{out:?}"
        );
        assert_eq!(out.len(), 1, "nothing changed, nothing written back");
    }

    #[test]
    fn the_wheels_reach_the_odom_frame_only_through_a_drive_train() {
        let mut none = Vehicle::new(CoreConfig::default());
        none.handle(at(0), Input::Chassis(&drives_at_rest(0)));
        assert_eq!(none.odom_pose(), None);
        let mut v = with_drives();
        v.handle(at(0), Input::Chassis(&drives_at_rest(0)));
        assert!(v.odom_pose().is_some());
    }

    #[test]
    fn a_goal_under_way_keeps_the_map_frame_where_it_is() {
        let mut v = with_drives();
        for ms in (0..=2_000).step_by(100) {
            v.handle(at(ms), Input::Chassis(&drives_at_rest(ms)));
            v.handle(at(ms), Input::Gnss(&fixed_with_heading_at(ms)));
            v.handle(at(ms), Input::ControlTick);
        }
        let goal = GoalPose {
            x: 2.0,
            y: 0.0,
            yaw: 0.0,
        };
        let t = at(2_000);
        let out = v.handle(t, Input::Command(Command::Goal { goal, tag: None }));
        assert_eq!(results(&out), vec![Ok(())]);
        for moving_the_map in [
            Command::ZeroLocalFrame,
            Command::SetPose {
                x: 0.0,
                y: 0.0,
                yaw: 0.0,
            },
        ] {
            let out = v.handle(t, Input::Command(moving_the_map));
            assert_eq!(results(&out), vec![Err(CommandRejected::MoveUnderWay)]);
        }
        v.handle(t, Input::Command(Command::CancelMotion));
        let out = v.handle(t, Input::Command(Command::ZeroLocalFrame));
        assert_eq!(results(&out), vec![Ok(())]);
    }
}
