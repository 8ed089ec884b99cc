//! CANopen (CiA 301) building blocks: identifiers, NMT, heartbeat, SDO, EMCY and PDO.

pub mod emcy;
pub mod nmt;
pub mod pdo;
pub mod sdo;

use super::can::Frame;

/// A CANopen node id, 1 to 127.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct NodeId(u8);

impl NodeId {
    /// The node id, if it is in 1..=127.
    pub const fn new(id: u8) -> Option<Self> {
        if id >= 1 && id <= 127 {
            Some(Self(id))
        } else {
            None
        }
    }

    /// The raw id.
    pub fn get(self) -> u8 {
        self.0
    }
}

/// An object dictionary address: index and sub-index. In configuration files it is written
/// `"0x6040:0"`.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Deserialize, serde::Serialize,
)]
#[serde(try_from = "String", into = "String")]
pub struct ObjectAddress {
    /// Index (0x1000–0xFFFF).
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
}

/// CiA 301's device type object, which every CANopen node has.
pub const DEVICE_TYPE: ObjectAddress = ObjectAddress::new(0x1000, 0);

impl ObjectAddress {
    /// Index and sub-index.
    pub const fn new(index: u16, sub: u8) -> Self {
        Self { index, sub }
    }
}

impl std::fmt::Display for ObjectAddress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "0x{:04X}:{}", self.index, self.sub)
    }
}

impl TryFrom<String> for ObjectAddress {
    type Error = String;

    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

impl From<ObjectAddress> for String {
    fn from(a: ObjectAddress) -> String {
        a.to_string()
    }
}

impl std::str::FromStr for ObjectAddress {
    type Err = String;

    /// Parses `0x6040:0` or `0x6040` (sub-index 0).
    fn from_str(s: &str) -> Result<Self, String> {
        let (index, sub) = s.split_once(':').unwrap_or((s, "0"));
        let index = index
            .strip_prefix("0x")
            .or_else(|| index.strip_prefix("0X"))
            .and_then(|h| u16::from_str_radix(h, 16).ok())
            .ok_or_else(|| format!("{s:?}: the index must be hex like 0x6040"))?;
        let sub = match sub.strip_prefix("0x") {
            Some(h) => u8::from_str_radix(h, 16).ok(),
            None => sub.parse().ok(),
        }
        .ok_or_else(|| format!("{s:?}: the sub-index must be 0..255"))?;
        Ok(Self { index, sub })
    }
}

/// The role of a frame on a CANopen bus, from its 11-bit identifier (pre-defined
/// connection set).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cob {
    /// NMT command (0x000).
    Nmt,
    /// SYNC (0x080).
    Sync,
    /// Emergency from a node (0x081–0x0FF).
    Emcy(NodeId),
    /// Transmit PDO 1–4 from a node (0x180/0x280/0x380/0x480 + node).
    Tpdo(u8, NodeId),
    /// Receive PDO 1–4 to a node (0x200/0x300/0x400/0x500 + node).
    Rpdo(u8, NodeId),
    /// SDO response, server to client (0x580 + node).
    SdoResponse(NodeId),
    /// SDO request, client to server (0x600 + node).
    SdoRequest(NodeId),
    /// Heartbeat or boot-up (0x700 + node).
    Heartbeat(NodeId),
    /// Anything else (time stamp, LSS, vendor ids).
    Other,
}

impl Cob {
    /// Classifies a frame; extended frames are never CANopen.
    pub fn of(frame: &Frame) -> Self {
        if frame.is_extended() {
            return Self::Other;
        }
        let id = frame.id();
        let function = id & 0x780;
        let node = NodeId::new((id & 0x7F) as u8);
        match (function, node) {
            (0x000, None) if id == 0 => Self::Nmt,
            (0x080, None) => Self::Sync,
            (0x080, Some(n)) => Self::Emcy(n),
            (0x180, Some(n)) => Self::Tpdo(1, n),
            (0x280, Some(n)) => Self::Tpdo(2, n),
            (0x380, Some(n)) => Self::Tpdo(3, n),
            (0x480, Some(n)) => Self::Tpdo(4, n),
            (0x200, Some(n)) => Self::Rpdo(1, n),
            (0x300, Some(n)) => Self::Rpdo(2, n),
            (0x400, Some(n)) => Self::Rpdo(3, n),
            (0x500, Some(n)) => Self::Rpdo(4, n),
            (0x580, Some(n)) => Self::SdoResponse(n),
            (0x600, Some(n)) => Self::SdoRequest(n),
            (0x700, Some(n)) => Self::Heartbeat(n),
            _ => Self::Other,
        }
    }
}

/// The default COB-ID of TPDO `n` (1–4) of `node`.
pub fn tpdo_cob_id(n: u8, node: NodeId) -> u32 {
    0x080 + 0x100 * u32::from(n) + u32::from(node.get())
}

/// The default COB-ID of RPDO `n` (1–4) of `node`.
pub fn rpdo_cob_id(n: u8, node: NodeId) -> u32 {
    0x100 + 0x100 * u32::from(n) + u32::from(node.get())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn n(id: u8) -> NodeId {
        NodeId::new(id).unwrap()
    }

    #[test]
    fn classifies_the_predefined_connection_set() {
        let cob = |id| Cob::of(&Frame::standard(id, &[]).unwrap());
        assert_eq!(cob(0x000), Cob::Nmt);
        assert_eq!(cob(0x080), Cob::Sync);
        assert_eq!(cob(0x081), Cob::Emcy(n(1)));
        assert_eq!(cob(0x182), Cob::Tpdo(1, n(2)));
        assert_eq!(cob(0x4FF), Cob::Tpdo(4, n(127)));
        assert_eq!(cob(0x201), Cob::Rpdo(1, n(1)));
        assert_eq!(cob(0x581), Cob::SdoResponse(n(1)));
        assert_eq!(cob(0x601), Cob::SdoRequest(n(1)));
        assert_eq!(cob(0x77F), Cob::Heartbeat(n(127)));
        assert_eq!(cob(0x700), Cob::Other);
        assert_eq!(Cob::of(&Frame::extended(0x181, &[]).unwrap()), Cob::Other);
        assert_eq!(tpdo_cob_id(2, n(5)), 0x285);
        assert_eq!(rpdo_cob_id(1, n(5)), 0x205);
    }

    #[test]
    fn parses_object_addresses() {
        assert_eq!(
            "0x60FF:3".parse::<ObjectAddress>(),
            Ok(ObjectAddress::new(0x60FF, 3))
        );
        assert_eq!(
            "0x6040".parse::<ObjectAddress>(),
            Ok(ObjectAddress::new(0x6040, 0))
        );
        assert_eq!(
            "0x1A00:0x02".parse::<ObjectAddress>(),
            Ok(ObjectAddress::new(0x1A00, 2))
        );
        assert!("6040:0".parse::<ObjectAddress>().is_err());
        assert!("0x6040:300".parse::<ObjectAddress>().is_err());
    }
}
