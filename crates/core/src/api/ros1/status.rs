//! The spec's `std_msgs/Int16` status topics, from what the core reports. Each is published
//! when its code changes (latched, so a late subscriber gets the current one at once), and
//! only where chassisd knows the state:
//!
//! | topic | codes |
//! |---|---|
//! | `/androidmsg_initstatus` | 12 every drive set up and enabled-able; 11 a drive booting, unreachable or faulted, or its bus down (with drives only) |
//! | `/androidmsg_emergencystatus` | 31 an emergency stop holds the vehicle (input or software); 32 released (with drives only) |
//! | `/androidmsg_chargestatus` | 41 not charging; 44 the charging action failed; 45 charging after `/autocharge`; 46 charging by hand (no action asked for it); 47, 48 the same, ended full (with a BMS only) |
//! | `/androidmsg_locationstatus` | 10 located (LOCATE_TRUE); 9 not (lost, or never placed) |
//! | `/androidmsg_navigationstatus` | 1 a motion started; 2 it succeeded; 3 it failed or timed out; 7 stopped by a stop (`/navi_stop`, `set_navi_cmd` 5, an operator's stop); 83 cancelled otherwise (replaced, a velocity command took over); 84 ended or refused for want of localisation; 51 the charging action could not reach the dock; 52 no dock is configured |
//! | `/power_report` | the state of charge, % (with a fresh BMS reading only) |
//!
//! The codes the spec lists for maps, floors and the deprecated 42/43 have no counterpart here.

use crate::control::mission::MissionEvent;
use crate::control::outcome::{AbortReason, CancelReason};
use crate::control::{MotionResult, MotionTag, Outcome};
use crate::devices::bms::ChargeState;
use crate::vehicle::chassis::status_bits;
use crate::vehicle::{Localization, Navigation, VehicleStatus};

/// `/androidmsg_initstatus`: initialisation failed.
pub const INIT_FAILED: i16 = 11;
/// Initialisation succeeded.
pub const INIT_OK: i16 = 12;
/// `/androidmsg_emergencystatus`: emergency stop.
pub const ESTOP: i16 = 31;
/// Released.
pub const ESTOP_RELEASED: i16 = 32;
/// `/androidmsg_chargestatus`: not charging.
pub const NOT_CHARGING: i16 = 41;
/// The charging action failed.
pub const CHARGE_FAILED: i16 = 44;
/// Charging after `/autocharge`.
pub const AUTO_CHARGING: i16 = 45;
/// Charging, not asked for (on a charger by hand).
pub const MANUAL_CHARGING: i16 = 46;
/// Charged full after `/autocharge`.
pub const AUTO_CHARGED: i16 = 47;
/// Charged full by hand.
pub const MANUAL_CHARGED: i16 = 48;
/// `/androidmsg_locationstatus`: the position is lost.
pub const LOCATION_LOST: i16 = 9;
/// Located.
pub const LOCATED: i16 = 10;
/// `/androidmsg_navigationstatus`: navigation started.
pub const NAV_STARTED: i16 = 1;
/// Reached the goal.
pub const NAV_SUCCEEDED: i16 = 2;
/// Failed after trying.
pub const NAV_FAILED: i16 = 3;
/// Stopped by a stop command.
pub const NAV_STOPPED: i16 = 7;
/// The way to the dock failed, so charging failed.
pub const NAV_DOCK_FAILED: i16 = 51;
/// No dock is set.
pub const NAV_NO_DOCK: i16 = 52;
/// Cancelled.
pub const NAV_CANCELLED: i16 = 83;
/// The position is lost: locate before navigating.
pub const NAV_LOCATION_LOST: i16 = 84;

/// A state of charge at or above this is full, %.
const FULL_PCT: f64 = 99.5;

/// One of the status topics (its name and type are in [`super::topics::TOPICS`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Topic {
    /// `/androidmsg_initstatus`.
    Init,
    /// `/androidmsg_emergencystatus`.
    Emergency,
    /// `/androidmsg_chargestatus`.
    Charge,
    /// `/androidmsg_locationstatus`.
    Location,
    /// `/androidmsg_navigationstatus`.
    Navigation,
    /// `/power_report`.
    Power,
    /// `/androidmsg_virtualmapstatus`: an edit of the virtual walls and regions.
    VirtualMap,
}

impl Topic {
    /// Every topic, in the order of the spec.
    pub const ALL: [Topic; 7] = [
        Topic::Init,
        Topic::Emergency,
        Topic::Charge,
        Topic::Power,
        Topic::Location,
        Topic::Navigation,
        Topic::VirtualMap,
    ];
}

/// The navigation code of a motion's end.
pub fn navigation_code(outcome: &Outcome) -> i16 {
    match outcome {
        Outcome::Succeeded => NAV_SUCCEEDED,
        Outcome::Cancelled(CancelReason::StopRequested | CancelReason::StoppedByOperator) => {
            NAV_STOPPED
        }
        Outcome::Cancelled(_) => NAV_CANCELLED,
        Outcome::Aborted(why) if matches!(why.root(), AbortReason::LocalisationLost(_)) => {
            NAV_LOCATION_LOST
        }
        Outcome::TimedOut | Outcome::Aborted(_) => NAV_FAILED,
    }
}

/// `/androidmsg_virtualmapstatus`: the edit was made.
pub const VIRTUAL_MAP_MADE: i16 = 62;
/// `/androidmsg_virtualmapstatus`: the edit was refused.
pub const VIRTUAL_MAP_REFUSED: i16 = 63;

/// The charging action's state, as far as the node asked for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Action {
    /// None asked for since the vehicle last ran on its battery.
    None,
    /// Asked for: on the way to the dock, or waiting there for the BMS.
    Running,
    /// It reached charging.
    Done,
    /// It failed.
    Failed,
}

/// The status topics' codes, published on change.
#[derive(Debug, Clone)]
pub struct StatusTopics {
    last: [Option<i16>; 7],
    action: Action,
    /// The battery was last seen charging (to tell "charged full" from "never charged").
    was_charging: bool,
    /// The navigation code last published.
    navigation: Option<i16>,
}

impl Default for StatusTopics {
    fn default() -> Self {
        Self {
            last: [None; 7],
            action: Action::None,
            was_charging: false,
            navigation: None,
        }
    }
}

impl StatusTopics {
    fn index(topic: Topic) -> usize {
        Topic::ALL.iter().position(|t| *t == topic).unwrap_or(0)
    }

    /// Queues `code` on `topic` if it differs from the last one there.
    fn set(&mut self, topic: Topic, code: Option<i16>, out: &mut Vec<(Topic, i16)>) {
        let last = &mut self.last[Self::index(topic)];
        if let Some(code) = code
            && *last != Some(code)
        {
            *last = Some(code);
            out.push((topic, code));
        }
    }

    /// The codes last published, for a new registration's latched topics.
    pub fn current(&self) -> Vec<(Topic, i16)> {
        Topic::ALL
            .iter()
            .zip(self.last)
            .filter_map(|(topic, code)| {
                let code = if *topic == Topic::Navigation {
                    self.navigation
                } else {
                    code
                };
                code.map(|c| (*topic, c))
            })
            .collect()
    }

    /// An edit of the virtual walls or regions was answered: 62 made, 63 refused (each
    /// edit gets its code, the same as the last or not).
    pub fn on_zone_edit(&mut self, made: bool, out: &mut Vec<(Topic, i16)>) {
        let code = if made {
            VIRTUAL_MAP_MADE
        } else {
            VIRTUAL_MAP_REFUSED
        };
        self.last[Self::index(Topic::VirtualMap)] = Some(code);
        out.push((Topic::VirtualMap, code));
    }

    /// The node's own motion request was accepted; `charging` when it is `/autocharge`.
    pub fn on_request_accepted(&mut self, charging: bool, out: &mut Vec<(Topic, i16)>) {
        if charging {
            self.action = Action::Running;
        }
        self.navigation = Some(NAV_STARTED);
        out.push((Topic::Navigation, NAV_STARTED));
    }

    /// A motion ended.
    pub fn on_motion_ended(&mut self, result: &MotionResult, out: &mut Vec<(Topic, i16)>) {
        let code = navigation_code(&result.outcome);
        self.navigation = Some(code);
        out.push((Topic::Navigation, code));
    }

    /// A mission made progress; only the node's own (its charging action) counts here.
    pub fn on_mission(
        &mut self,
        tag: Option<MotionTag>,
        event: &MissionEvent,
        out: &mut Vec<(Topic, i16)>,
    ) {
        if tag.is_none_or(|t| t.owner != super::OWNER) {
            return;
        }
        let MissionEvent::Ended(outcome) = event else {
            return;
        };
        self.action = match outcome {
            Outcome::Succeeded => Action::Done,
            _ => Action::Failed,
        };
        if let Outcome::Aborted(why) = outcome {
            let code = match why.root() {
                AbortReason::NoDock => NAV_NO_DOCK,
                AbortReason::NotCharging { .. } => NAV_FAILED,
                _ => NAV_DOCK_FAILED,
            };
            self.navigation = Some(code);
            out.push((Topic::Navigation, code));
        }
        if self.action == Action::Failed {
            self.set(Topic::Charge, Some(CHARGE_FAILED), out);
        }
    }

    /// A status tick: the codes that changed go to `out`.
    pub fn on_status(&mut self, status: &VehicleStatus, out: &mut Vec<(Topic, i16)>) {
        if let Some(chassis) = &status.chassis {
            let bits = chassis.status_bits;
            let init = if bits
                & (status_bits::NOT_READY | status_bits::FAULT | status_bits::BUS_DOWN)
                != 0
            {
                INIT_FAILED
            } else {
                INIT_OK
            };
            self.set(Topic::Init, Some(init), out);
            let estop = if bits & status_bits::ESTOP != 0 {
                ESTOP
            } else {
                ESTOP_RELEASED
            };
            self.set(Topic::Emergency, Some(estop), out);
        }
        let location = match status.localization {
            Localization::Good => LOCATED,
            Localization::Lost | Localization::Uninitialized => LOCATION_LOST,
        };
        self.set(Topic::Location, Some(location), out);
        if let Some(battery) = status
            .battery
            .filter(|b| !b.stale && b.reading.rx.is_some())
        {
            let soc = battery.reading.soc_pct;
            self.set(
                Topic::Power,
                soc.map(|p| p.round().clamp(0.0, 100.0) as i16),
                out,
            );
            let charge = self.charge_code(battery.reading.charge_state, soc);
            self.set(Topic::Charge, charge, out);
        }
        // A motion under way that was not announced: started by another channel, or the
        // one that replaced the motion whose end was just published.
        if status.navigation == Navigation::Running && self.navigation != Some(NAV_STARTED) {
            self.navigation = Some(NAV_STARTED);
            out.push((Topic::Navigation, NAV_STARTED));
        }
    }

    /// The charge code from the BMS and the charging action.
    fn charge_code(&mut self, state: Option<ChargeState>, soc: Option<f64>) -> Option<i16> {
        let full = soc.is_some_and(|p| p >= FULL_PCT);
        let auto = matches!(self.action, Action::Running | Action::Done);
        match state? {
            ChargeState::Charging => {
                self.was_charging = true;
                if self.action == Action::Failed {
                    // A charger found after all (by hand): the failure is over.
                    self.action = Action::None;
                }
                Some(match (auto, full) {
                    (true, false) => AUTO_CHARGING,
                    (true, true) => AUTO_CHARGED,
                    (false, false) => MANUAL_CHARGING,
                    (false, true) => MANUAL_CHARGED,
                })
            }
            ChargeState::Idle if self.was_charging && full => {
                Some(if auto { AUTO_CHARGED } else { MANUAL_CHARGED })
            }
            ChargeState::Idle if self.action == Action::Running => Some(AUTO_CHARGING),
            ChargeState::Idle | ChargeState::Discharging => {
                if self.action == Action::Failed {
                    return Some(CHARGE_FAILED);
                }
                if state == Some(ChargeState::Discharging) {
                    // Off the charger: the next charge starts a new story.
                    self.was_charging = false;
                    if self.action == Action::Done {
                        self.action = Action::None;
                    }
                }
                Some(NOT_CHARGING)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::bms::BmsReading;
    use crate::time::Timestamp;
    use crate::vehicle::{BatteryStatus, chassis::ChassisStatus};

    fn status(bits: u32, battery: Option<(ChargeState, f64)>) -> VehicleStatus {
        VehicleStatus {
            time: Timestamp::from_nanos(1),
            imu_ok: true,
            chassis: Some(ChassisStatus {
                status_bits: bits,
                ..Default::default()
            }),
            battery: battery.map(|(state, soc)| BatteryStatus {
                reading: BmsReading {
                    soc_pct: Some(soc),
                    charge_state: Some(state),
                    rx: Some(Timestamp::from_nanos(1)),
                    ..Default::default()
                },
                stale: false,
            }),
            gnss: Default::default(),
            pose: Default::default(),
            pose_covariance: None,
            odom: None,
            frames: None,
            localization: Localization::Good,
            ..Default::default()
        }
    }

    fn codes(topics: &mut StatusTopics, s: &VehicleStatus) -> Vec<(Topic, i16)> {
        let mut out = Vec::new();
        topics.on_status(s, &mut out);
        out
    }

    #[test]
    fn codes_go_out_once_per_change() {
        let mut t = StatusTopics::default();
        let s = status(status_bits::ENABLED, Some((ChargeState::Discharging, 80.4)));
        assert_eq!(
            codes(&mut t, &s),
            [
                (Topic::Init, INIT_OK),
                (Topic::Emergency, ESTOP_RELEASED),
                (Topic::Location, LOCATED),
                (Topic::Power, 80),
                (Topic::Charge, NOT_CHARGING),
            ]
        );
        assert!(codes(&mut t, &s).is_empty(), "nothing changed");
        let s = status(
            status_bits::ESTOP | status_bits::NOT_READY,
            Some((ChargeState::Discharging, 80.0)),
        );
        assert_eq!(
            codes(&mut t, &s),
            [(Topic::Init, INIT_FAILED), (Topic::Emergency, ESTOP)]
        );
    }

    #[test]
    fn the_charging_action_is_told_from_a_charger_plugged_by_hand() {
        let mut t = StatusTopics::default();
        let charge = |t: &mut StatusTopics, state, soc| {
            codes(t, &status(0, Some((state, soc))))
                .into_iter()
                .filter(|(topic, _)| *topic == Topic::Charge)
                .map(|(_, c)| c)
                .collect::<Vec<_>>()
        };
        assert_eq!(
            charge(&mut t, ChargeState::Charging, 50.0),
            [MANUAL_CHARGING]
        );
        assert_eq!(charge(&mut t, ChargeState::Idle, 100.0), [MANUAL_CHARGED]);
        assert_eq!(
            charge(&mut t, ChargeState::Discharging, 99.0),
            [NOT_CHARGING]
        );
        let mut out = Vec::new();
        t.on_request_accepted(true, &mut out);
        assert_eq!(out, [(Topic::Navigation, NAV_STARTED)]);
        assert_eq!(charge(&mut t, ChargeState::Idle, 60.0), [AUTO_CHARGING]);
        let tag = Some(MotionTag {
            owner: super::super::OWNER,
            id: 0,
        });
        t.on_mission(tag, &MissionEvent::Ended(Outcome::Succeeded), &mut out);
        assert!(charge(&mut t, ChargeState::Charging, 60.0).is_empty());
        assert_eq!(charge(&mut t, ChargeState::Charging, 100.0), [AUTO_CHARGED]);
        assert_eq!(
            charge(&mut t, ChargeState::Discharging, 99.0),
            [NOT_CHARGING]
        );
        assert_eq!(
            charge(&mut t, ChargeState::Charging, 99.0),
            [MANUAL_CHARGING]
        );
    }

    #[test]
    fn a_failed_action_says_why_on_both_topics() {
        let mut t = StatusTopics::default();
        let mut out = Vec::new();
        t.on_request_accepted(true, &mut out);
        out.clear();
        let tag = Some(MotionTag {
            owner: super::super::OWNER,
            id: 0,
        });
        let at = crate::control::outcome::StepAt {
            index: 0,
            action: "CHARGING",
        };
        let failed = Outcome::Aborted(AbortReason::Step(at, Box::new(AbortReason::NoDock)));
        t.on_mission(tag, &MissionEvent::Ended(failed), &mut out);
        assert_eq!(
            out,
            [
                (Topic::Navigation, NAV_NO_DOCK),
                (Topic::Charge, CHARGE_FAILED)
            ]
        );
        out.clear();
        // Another channel's mission is not the node's charging action.
        t.on_mission(None, &MissionEvent::Ended(Outcome::Succeeded), &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn every_end_has_its_navigation_code() {
        assert_eq!(navigation_code(&Outcome::Succeeded), NAV_SUCCEEDED);
        assert_eq!(navigation_code(&Outcome::TimedOut), NAV_FAILED);
        assert_eq!(
            navigation_code(&Outcome::Cancelled(CancelReason::StopRequested)),
            NAV_STOPPED
        );
        assert_eq!(
            navigation_code(&Outcome::Cancelled(CancelReason::StoppedByOperator)),
            NAV_STOPPED
        );
        assert_eq!(
            navigation_code(&Outcome::Cancelled(CancelReason::NewMotion)),
            NAV_CANCELLED
        );
        assert_eq!(
            navigation_code(&Outcome::Aborted(AbortReason::LocalisationLost(
                crate::control::outcome::LostDuring::Goal
            ))),
            NAV_LOCATION_LOST
        );
        assert_eq!(
            navigation_code(&Outcome::Aborted(AbortReason::SafetyStop("e-stop".into()))),
            NAV_FAILED
        );
    }

    #[test]
    fn a_motion_from_elsewhere_is_announced_once() {
        let mut t = StatusTopics::default();
        let mut s = status(0, None);
        s.navigation = Navigation::Running;
        let nav = |out: Vec<(Topic, i16)>| {
            out.into_iter()
                .filter(|(topic, _)| *topic == Topic::Navigation)
                .count()
        };
        assert_eq!(nav(codes(&mut t, &s)), 1);
        assert_eq!(nav(codes(&mut t, &s)), 0);
    }
}
