//! The CiA 402 power state machine: statusword decoding and the controlword that moves a
//! drive one step towards the state wanted.

use std::fmt;

/// A drive's power state, from its statusword (CiA 402 §6.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DriveState {
    /// Not ready to switch on (initialising).
    NotReadyToSwitchOn,
    /// Switch on disabled: power stage off, waiting for "shutdown".
    SwitchOnDisabled,
    /// Ready to switch on.
    ReadyToSwitchOn,
    /// Switched on: power stage on, no torque.
    SwitchedOn,
    /// Operation enabled: the drive follows its target.
    OperationEnabled,
    /// Quick stop active.
    QuickStopActive,
    /// Fault reaction active.
    FaultReactionActive,
    /// Fault.
    Fault,
}

impl DriveState {
    /// Decodes bits 0–3, 5 and 6 of a statusword.
    pub fn from_statusword(sw: u16) -> Self {
        if sw & 0x004F == 0x0000 {
            Self::NotReadyToSwitchOn
        } else if sw & 0x004F == 0x0040 {
            Self::SwitchOnDisabled
        } else if sw & 0x006F == 0x0021 {
            Self::ReadyToSwitchOn
        } else if sw & 0x006F == 0x0023 {
            Self::SwitchedOn
        } else if sw & 0x006F == 0x0027 {
            Self::OperationEnabled
        } else if sw & 0x006F == 0x0007 {
            Self::QuickStopActive
        } else if sw & 0x004F == 0x000F {
            Self::FaultReactionActive
        } else if sw & 0x004F == 0x0008 {
            Self::Fault
        } else {
            // Combinations the standard leaves undefined read as not ready.
            Self::NotReadyToSwitchOn
        }
    }

    /// The statusword bits a drive in this state reports (for simulators and tests).
    pub fn statusword(self) -> u16 {
        match self {
            Self::NotReadyToSwitchOn => 0x0000,
            Self::SwitchOnDisabled => 0x0040,
            Self::ReadyToSwitchOn => 0x0021,
            Self::SwitchedOn => 0x0023,
            Self::OperationEnabled => 0x0027,
            Self::QuickStopActive => 0x0007,
            Self::FaultReactionActive => 0x000F,
            Self::Fault => 0x0008,
        }
    }

    /// Whether the drive is in a fault state.
    pub fn is_fault(self) -> bool {
        matches!(self, Self::Fault | Self::FaultReactionActive)
    }
}

impl fmt::Display for DriveState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NotReadyToSwitchOn => "not ready to switch on",
            Self::SwitchOnDisabled => "switch on disabled",
            Self::ReadyToSwitchOn => "ready to switch on",
            Self::SwitchedOn => "switched on",
            Self::OperationEnabled => "operation enabled",
            Self::QuickStopActive => "quick stop active",
            Self::FaultReactionActive => "fault reaction active",
            Self::Fault => "fault",
        })
    }
}

/// Statusword bits beyond the state.
pub mod statusword {
    /// Bit 4: voltage enabled.
    pub const VOLTAGE_ENABLED: u16 = 1 << 4;
    /// Bit 7: warning.
    pub const WARNING: u16 = 1 << 7;
    /// Bit 9: remote (controlled over the bus).
    pub const REMOTE: u16 = 1 << 9;
    /// Bit 10: target reached.
    pub const TARGET_REACHED: u16 = 1 << 10;
}

/// Controlword commands (CiA 402 §6.3).
pub mod controlword {
    /// Disable voltage: to switch on disabled.
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Quick stop.
    pub const QUICK_STOP: u16 = 0x0002;
    /// Shutdown: to ready to switch on.
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on (or disable operation): to switched on.
    pub const SWITCH_ON: u16 = 0x0007;
    /// Enable operation.
    pub const ENABLE_OPERATION: u16 = 0x000F;
    /// Fault reset (rising edge of bit 7).
    pub const FAULT_RESET: u16 = 0x0080;
}

/// Where the owner wants a drive's power stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Goal {
    /// Operation enabled: follow the target.
    Enabled,
    /// Switched on, no torque.
    Standby,
    /// Brake on the drive's quick-stop ramp.
    QuickStop,
    /// Power stage off (switch on disabled); a turning motor is quick-stopped first.
    Disabled,
}

/// The power-state transitions, as a table (CiA 402 §6.3.1): in `state`, to get towards
/// `goal`, write this controlword; `None` leaves the drive alone. Fault states have no entry:
/// a fault reset is its own handshake (a rising edge of bit 7).
const TRANSITIONS: [(DriveState, Goal, u16); 20] = {
    use DriveState::*;
    use Goal::*;
    use controlword::*;
    [
        (SwitchOnDisabled, Enabled, SHUTDOWN),
        (SwitchOnDisabled, Standby, SHUTDOWN),
        (SwitchOnDisabled, QuickStop, DISABLE_VOLTAGE),
        (SwitchOnDisabled, Disabled, DISABLE_VOLTAGE),
        (ReadyToSwitchOn, Enabled, SWITCH_ON),
        (ReadyToSwitchOn, Standby, SWITCH_ON),
        (ReadyToSwitchOn, QuickStop, QUICK_STOP),
        (ReadyToSwitchOn, Disabled, DISABLE_VOLTAGE),
        (SwitchedOn, Enabled, ENABLE_OPERATION),
        (SwitchedOn, Standby, SWITCH_ON),
        (SwitchedOn, QuickStop, QUICK_STOP),
        (SwitchedOn, Disabled, DISABLE_VOLTAGE),
        (OperationEnabled, Enabled, ENABLE_OPERATION),
        // Disable operation: the motor stops under the drive's profile deceleration.
        (OperationEnabled, Standby, SWITCH_ON),
        (OperationEnabled, QuickStop, QUICK_STOP),
        // Never let a turning motor coast: quick stop first, then disable voltage.
        (OperationEnabled, Disabled, QUICK_STOP),
        // Quick stop active leads only to switch on disabled (option codes 1–3).
        (QuickStopActive, Enabled, DISABLE_VOLTAGE),
        (QuickStopActive, Standby, DISABLE_VOLTAGE),
        (QuickStopActive, QuickStop, QUICK_STOP),
        (QuickStopActive, Disabled, DISABLE_VOLTAGE),
    ]
};

/// The controlword that moves a drive in `state` one step towards `goal` (the 6 → 7 → 0x0F
/// sequence towards operation enabled), from [`TRANSITIONS`]. `None` in not-ready and fault
/// states.
pub fn next_controlword(state: DriveState, goal: Goal) -> Option<u16> {
    TRANSITIONS
        .iter()
        .find(|(s, g, _)| *s == state && *g == goal)
        .map(|(_, _, cw)| *cw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_statuswords_with_extra_bits() {
        // Real drives set voltage-enabled, remote and target-reached around the state bits.
        assert_eq!(
            DriveState::from_statusword(0x0250),
            DriveState::SwitchOnDisabled
        );
        assert_eq!(
            DriveState::from_statusword(0x0231),
            DriveState::ReadyToSwitchOn
        );
        assert_eq!(DriveState::from_statusword(0x0233), DriveState::SwitchedOn);
        assert_eq!(
            DriveState::from_statusword(0x0637),
            DriveState::OperationEnabled
        );
        assert_eq!(
            DriveState::from_statusword(0x0617),
            DriveState::QuickStopActive
        );
        assert_eq!(DriveState::from_statusword(0x0218), DriveState::Fault);
        assert_eq!(
            DriveState::from_statusword(0x021F),
            DriveState::FaultReactionActive
        );
        for s in [
            DriveState::NotReadyToSwitchOn,
            DriveState::SwitchOnDisabled,
            DriveState::ReadyToSwitchOn,
            DriveState::SwitchedOn,
            DriveState::OperationEnabled,
            DriveState::QuickStopActive,
            DriveState::FaultReactionActive,
            DriveState::Fault,
        ] {
            assert_eq!(DriveState::from_statusword(s.statusword()), s);
        }
    }

    #[test]
    fn enable_sequence_is_6_7_f() {
        let mut state = DriveState::SwitchOnDisabled;
        let mut words = Vec::new();
        while state != DriveState::OperationEnabled {
            let cw = next_controlword(state, Goal::Enabled).unwrap();
            words.push(cw);
            state = match cw {
                0x06 => DriveState::ReadyToSwitchOn,
                0x07 => DriveState::SwitchedOn,
                0x0F => DriveState::OperationEnabled,
                other => panic!("unexpected controlword {other:#x}"),
            };
        }
        assert_eq!(words, [0x06, 0x07, 0x0F]);
        assert_eq!(
            next_controlword(DriveState::OperationEnabled, Goal::Standby),
            Some(0x07)
        );
        assert_eq!(next_controlword(DriveState::Fault, Goal::Enabled), None);
    }

    #[test]
    fn every_reachable_state_has_a_way_to_every_goal() {
        use DriveState::*;
        let states = [
            SwitchOnDisabled,
            ReadyToSwitchOn,
            SwitchedOn,
            OperationEnabled,
            QuickStopActive,
        ];
        for state in states {
            for goal in [
                Goal::Enabled,
                Goal::Standby,
                Goal::QuickStop,
                Goal::Disabled,
            ] {
                assert!(
                    next_controlword(state, goal).is_some(),
                    "{state} towards {goal:?}"
                );
            }
        }
        // A disabled goal never lets an enabled drive coast.
        assert_eq!(
            next_controlword(OperationEnabled, Goal::Disabled),
            Some(controlword::QUICK_STOP)
        );
    }
}
