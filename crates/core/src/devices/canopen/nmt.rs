//! NMT commands (master to nodes) and heartbeat / boot-up messages (nodes to master).

use super::NodeId;
use crate::devices::can::Frame;

/// An NMT command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtCommand {
    /// Start remote node: enter operational (0x01).
    Start,
    /// Stop remote node: enter stopped (0x02).
    Stop,
    /// Enter pre-operational (0x80).
    EnterPreOperational,
    /// Reset the node's application (0x81).
    ResetNode,
    /// Reset the node's communication (0x82).
    ResetCommunication,
}

impl NmtCommand {
    /// The command specifier byte.
    pub fn specifier(self) -> u8 {
        match self {
            Self::Start => 0x01,
            Self::Stop => 0x02,
            Self::EnterPreOperational => 0x80,
            Self::ResetNode => 0x81,
            Self::ResetCommunication => 0x82,
        }
    }

    /// The NMT frame addressing `node` (`None`: every node).
    pub fn frame(self, node: Option<NodeId>) -> Frame {
        let target = node.map_or(0, NodeId::get);
        Frame::std(0x000, [self.specifier(), target])
    }
}

/// A node's NMT state, as its heartbeat reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtState {
    /// Boot-up message: the node just (re)started and is entering pre-operational.
    BootUp,
    /// Stopped.
    Stopped,
    /// Operational: PDOs are exchanged.
    Operational,
    /// Pre-operational: SDO only.
    PreOperational,
}

impl NmtState {
    /// The state of a heartbeat byte (the toggle bit 7 of node guarding is ignored).
    pub fn from_heartbeat(byte: u8) -> Option<Self> {
        match byte & 0x7F {
            0x00 => Some(Self::BootUp),
            0x04 => Some(Self::Stopped),
            0x05 => Some(Self::Operational),
            0x7F => Some(Self::PreOperational),
            _ => None,
        }
    }

    /// The heartbeat byte of this state.
    pub fn heartbeat_byte(self) -> u8 {
        match self {
            Self::BootUp => 0x00,
            Self::Stopped => 0x04,
            Self::Operational => 0x05,
            Self::PreOperational => 0x7F,
        }
    }
}

/// The heartbeat frame `node` sends in `state`.
pub fn heartbeat_frame(node: NodeId, state: NmtState) -> Frame {
    Frame::std(0x700 + u32::from(node.get()), [state.heartbeat_byte()])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encodes_commands() {
        let node = NodeId::new(3).unwrap();
        assert_eq!(NmtCommand::Start.frame(Some(node)).to_string(), "000#0103");
        assert_eq!(
            NmtCommand::ResetCommunication.frame(None).to_string(),
            "000#8200"
        );
        assert_eq!(
            NmtCommand::EnterPreOperational
                .frame(Some(node))
                .to_string(),
            "000#8003"
        );
    }

    #[test]
    fn decodes_heartbeats() {
        assert_eq!(NmtState::from_heartbeat(0x05), Some(NmtState::Operational));
        assert_eq!(NmtState::from_heartbeat(0x85), Some(NmtState::Operational));
        assert_eq!(
            NmtState::from_heartbeat(0x7F),
            Some(NmtState::PreOperational)
        );
        assert_eq!(NmtState::from_heartbeat(0x00), Some(NmtState::BootUp));
        assert_eq!(NmtState::from_heartbeat(0x33), None);
        let node = NodeId::new(1).unwrap();
        assert_eq!(
            heartbeat_frame(node, NmtState::Operational).to_string(),
            "701#05"
        );
    }
}
