//! The configuration chassisd asks of a u-blox receiver (protocol 27 and later: ZED-F9P,
//! F9R, F9H): CFG-VALSET to set items, CFG-VALGET to read them back.
//!
//! A key id says its value's size in bits 28..30 (1 one bit in a byte, 2 one byte, 3 two,
//! 4 four, 5 eight). A VALSET of an unknown key, or without a layer, is refused with
//! ACK-NAK and changes nothing.

use super::frame;
use crate::devices::gnss::decode::DecodeError;

/// CFG class and the ids used here.
const CLASS_CFG: u8 = 0x06;
const ID_VALSET: u8 = 0x8a;
const ID_VALGET: u8 = 0x8b;
/// At most this many items per VALSET or VALGET.
pub const MAX_ITEMS: usize = 64;

/// One configuration item: its key id and value (little-endian, of the key's size).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Item {
    /// Key id.
    pub key: u32,
    /// Value.
    pub value: u64,
}

/// The bytes a key's value takes, from its id.
pub fn value_size(key: u32) -> Option<usize> {
    match (key >> 28) & 0x7 {
        1 | 2 => Some(1),
        3 => Some(2),
        4 => Some(4),
        5 => Some(8),
        _ => None,
    }
}

/// Where a VALSET writes: RAM only (lost at power off), or RAM and flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layers {
    /// RAM: in effect now, gone at the next power cycle.
    Ram,
    /// RAM and flash: in effect now and after every power cycle.
    RamAndFlash,
}

impl Layers {
    fn bits(self) -> u8 {
        match self {
            Self::Ram => 0x01,
            Self::RamAndFlash => 0x01 | 0x04,
        }
    }
}

/// Why a configuration message could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// More than [`MAX_ITEMS`] items.
    #[error("{0} items where a message takes at most {MAX_ITEMS}")]
    TooMany(usize),
    /// A key whose id gives no value size.
    #[error("key {0:#010x} has no value size")]
    BadKey(u32),
}

/// A CFG-VALSET frame that sets `items` in `layers`.
pub fn valset(layers: Layers, items: &[Item]) -> Result<Vec<u8>, ConfigError> {
    if items.len() > MAX_ITEMS {
        return Err(ConfigError::TooMany(items.len()));
    }
    let mut payload = vec![0x00, layers.bits(), 0x00, 0x00];
    for item in items {
        let size = value_size(item.key).ok_or(ConfigError::BadKey(item.key))?;
        payload.extend_from_slice(&item.key.to_le_bytes());
        payload.extend_from_slice(&item.value.to_le_bytes()[..size]);
    }
    Ok(frame::encode(CLASS_CFG, ID_VALSET, &payload).expect("at most 64 items of 12 bytes"))
}

/// A CFG-VALGET poll for `keys` in RAM (the configuration in effect).
pub fn valget_poll(keys: &[u32]) -> Result<Vec<u8>, ConfigError> {
    if keys.len() > MAX_ITEMS {
        return Err(ConfigError::TooMany(keys.len()));
    }
    let mut payload = vec![0x00, 0x00, 0x00, 0x00];
    for key in keys {
        payload.extend_from_slice(&key.to_le_bytes());
    }
    Ok(frame::encode(CLASS_CFG, ID_VALGET, &payload).expect("at most 64 keys"))
}

/// A MON-VER poll: the message with no payload.
pub fn mon_ver_poll() -> Vec<u8> {
    frame::encode(0x0a, 0x04, &[]).expect("empty payload")
}

/// CFG-VALGET's answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ValGetAnswer {
    /// The layer read (0 RAM, 1 BBR, 2 flash, 7 defaults).
    pub layer: u8,
    /// The items, in the receiver's order.
    pub items: Vec<Item>,
}

impl ValGetAnswer {
    /// Decodes an answer's payload; a value cut short, or a key without a size, is an error.
    pub fn decode(payload: &[u8]) -> Result<Self, DecodeError> {
        let error = |reason: String| DecodeError {
            kind: "CFG-VALGET".into(),
            reason,
        };
        let (header, mut rest) = payload
            .split_at_checked(4)
            .ok_or_else(|| error(format!("{} bytes where 4 are needed", payload.len())))?;
        if header[0] != 0x01 {
            return Err(error(format!("version {} is not an answer's 1", header[0])));
        }
        let mut items = Vec::new();
        while !rest.is_empty() {
            let (key, after) = rest
                .split_first_chunk::<4>()
                .ok_or_else(|| error("a key cut short".into()))?;
            let key = u32::from_le_bytes(*key);
            let size =
                value_size(key).ok_or_else(|| error(format!("key {key:#010x} has no size")))?;
            let (value, after) = after
                .split_at_checked(size)
                .ok_or_else(|| error(format!("the value of {key:#010x} cut short")))?;
            let mut bytes = [0u8; 8];
            bytes[..size].copy_from_slice(value);
            items.push(Item {
                key,
                value: u64::from_le_bytes(bytes),
            });
            rest = after;
        }
        Ok(Self {
            layer: header[1],
            items,
        })
    }
}

/// The receiver's port chassisd reads: the message-rate keys differ by port.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Port {
    /// UART1.
    Uart1,
    /// UART2.
    Uart2,
    /// USB (`/dev/ttyACM*`).
    Usb,
}

impl Port {
    /// Offset of this port's rate key from UART1's: u-blox numbers each message's rate keys
    /// I2C, UART1, UART2, USB, SPI.
    fn rate_offset(self) -> u32 {
        match self {
            Self::Uart1 => 0,
            Self::Uart2 => 1,
            Self::Usb => 2,
        }
    }

    /// The group of this port's input-protocol keys; output is the next group.
    fn in_protocol_group(self) -> u32 {
        match self {
            Self::Uart1 => 0x73,
            Self::Uart2 => 0x75,
            Self::Usb => 0x77,
        }
    }
}

/// A configuration item chassisd needs, with what it is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wanted {
    /// The item.
    pub item: Item,
    /// Its u-blox name.
    pub name: &'static str,
}

/// The rate keys (UART1) of the messages chassisd reads, each once per navigation epoch.
const MESSAGES: [(u32, &str); 6] = [
    (0x2091_0007, "CFG-MSGOUT-UBX_NAV_PVT"),
    (0x2091_0034, "CFG-MSGOUT-UBX_NAV_HPPOSLLH"),
    (0x2091_0084, "CFG-MSGOUT-UBX_NAV_COV"),
    (0x2091_008e, "CFG-MSGOUT-UBX_NAV_RELPOSNED"),
    (0x2091_0039, "CFG-MSGOUT-UBX_NAV_DOP"),
    (0x2091_0269, "CFG-MSGOUT-UBX_RXM_RTCM"),
];

/// What chassisd sets on a u-blox receiver's `port`: UBX out, RTCM in (the corrections
/// chassisd relays), and each message it reads once per epoch. NMEA output and the
/// navigation rate are left as the owner set them.
pub fn wanted(port: Port) -> Vec<Wanted> {
    let group = port.in_protocol_group();
    let mut out = vec![
        Wanted {
            item: Item {
                key: 0x1000_0001 | ((group + 1) << 16),
                value: 1,
            },
            name: "CFG-*OUTPROT-UBX",
        },
        Wanted {
            item: Item {
                key: 0x1000_0004 | (group << 16),
                value: 1,
            },
            name: "CFG-*INPROT-RTCM3X",
        },
    ];
    out.extend(MESSAGES.iter().map(|&(key, name)| Wanted {
        item: Item {
            key: key + port.rate_offset(),
            value: 1,
        },
        name,
    }));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_ids_for_each_port_match_u_blox_tables() {
        let keys = |port| wanted(port).iter().map(|w| w.item.key).collect::<Vec<_>>();
        // ZED-F9P interface description: UART1OUTPROT-UBX, UART1INPROT-RTCM3X, NAV-PVT UART1.
        assert_eq!(
            &keys(Port::Uart1)[..3],
            [0x1074_0001, 0x1073_0004, 0x2091_0007]
        );
        // USB: USBOUTPROT-UBX, USBINPROT-RTCM3X, NAV-PVT USB, NAV-HPPOSLLH USB.
        assert_eq!(
            &keys(Port::Usb)[..4],
            [0x1078_0001, 0x1077_0004, 0x2091_0009, 0x2091_0036]
        );
        assert_eq!(keys(Port::Uart2)[2], 0x2091_0008);
    }

    #[test]
    fn valset_lays_out_keys_and_values_by_size() {
        let frame = valset(
            Layers::Ram,
            &[
                Item {
                    key: 0x1074_0001,
                    value: 1,
                },
                Item {
                    key: 0x3021_0001,
                    value: 100,
                },
            ],
        )
        .unwrap();
        assert_eq!(&frame[..6], [0xb5, 0x62, 0x06, 0x8a, 4 + 5 + 6, 0]);
        assert_eq!(&frame[6..10], [0, 1, 0, 0]);
        assert_eq!(&frame[10..15], [0x01, 0x00, 0x74, 0x10, 1]);
        assert_eq!(&frame[15..21], [0x01, 0x00, 0x21, 0x30, 100, 0]);
        assert!(
            valset(
                Layers::RamAndFlash,
                &[Item {
                    key: 0x7000_0000,
                    value: 0
                }]
            )
            .is_err()
        );
        assert_eq!(valset(Layers::RamAndFlash, &[]).unwrap()[7], 0x05);
    }

    #[test]
    fn valget_answers_decode_and_cut_values_are_errors() {
        let mut p = vec![1, 0, 0, 0];
        p.extend_from_slice(&0x2091_0007u32.to_le_bytes());
        p.push(1);
        p.extend_from_slice(&0x3021_0001u32.to_le_bytes());
        p.extend_from_slice(&200u16.to_le_bytes());
        let a = ValGetAnswer::decode(&p).unwrap();
        assert_eq!(
            a.items,
            [
                Item {
                    key: 0x2091_0007,
                    value: 1
                },
                Item {
                    key: 0x3021_0001,
                    value: 200
                }
            ]
        );
        assert!(ValGetAnswer::decode(&p[..p.len() - 1]).is_err());
        assert!(ValGetAnswer::decode(&[0, 0, 0, 0]).is_err());
        assert!(ValGetAnswer::decode(&[1, 0]).is_err());
    }
}
