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

/// The controlword that moves a drive in `state` one step towards operation enabled (when
/// `enable`) or towards switched on (when not), the 6 → 7 → 0x0F sequence. A faulted drive
/// gets a fault reset only when `reset` is asked for; otherwise it is left alone.
pub fn next_controlword(state: DriveState, enable: bool, reset: bool) -> Option<u16> {
    use controlword::*;
    match state {
        DriveState::Fault if reset => Some(FAULT_RESET),
        DriveState::Fault | DriveState::FaultReactionActive => None,
        DriveState::NotReadyToSwitchOn => None,
        DriveState::SwitchOnDisabled => Some(SHUTDOWN),
        DriveState::ReadyToSwitchOn => Some(SWITCH_ON),
        DriveState::SwitchedOn if enable => Some(ENABLE_OPERATION),
        DriveState::SwitchedOn => Some(SWITCH_ON),
        DriveState::OperationEnabled if enable => Some(ENABLE_OPERATION),
        // Disable operation: back to switched on, the motor stops under the drive's ramp.
        DriveState::OperationEnabled => Some(SWITCH_ON),
        DriveState::QuickStopActive => Some(DISABLE_VOLTAGE),
    }
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
            let cw = next_controlword(state, true, false).unwrap();
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
            next_controlword(DriveState::OperationEnabled, false, false),
            Some(0x07)
        );
        assert_eq!(next_controlword(DriveState::Fault, true, false), None);
        assert_eq!(next_controlword(DriveState::Fault, true, true), Some(0x80));
    }
}
