//! Process data objects: mapping of object values into PDO frames, the SDO writes that
//! configure a node's TPDO or RPDO (CiA 301 §7.5.2.35–38), and packing and unpacking.

use super::ObjectAddress;
use super::sdo::{SdoData, SdoRequest};

/// One mapped object: its address and width in bits (8, 16 or 32). In configuration files
/// it is written `"0x6041:0:16"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(try_from = "String", into = "String")]
pub struct PdoEntry {
    /// The object.
    pub object: ObjectAddress,
    /// Width in bits.
    pub bits: u8,
}

impl PdoEntry {
    /// The mapping parameter value: index (16 bits), sub-index (8), length (8).
    pub fn mapping_value(&self) -> u32 {
        (u32::from(self.object.index) << 16)
            | (u32::from(self.object.sub) << 8)
            | u32::from(self.bits)
    }
}

impl std::fmt::Display for PdoEntry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.object, self.bits)
    }
}

impl TryFrom<String> for PdoEntry {
    type Error = String;

    fn try_from(s: String) -> Result<Self, String> {
        let (object, bits) = s
            .rsplit_once(':')
            .filter(|(o, _)| o.contains(':'))
            .ok_or_else(|| format!("{s:?}: expected index:sub:bits, e.g. 0x6041:0:16"))?;
        let bits: u8 = bits
            .parse()
            .map_err(|_| format!("{s:?}: bits must be 8, 16 or 32"))?;
        if !matches!(bits, 8 | 16 | 32) {
            return Err(format!("{s:?}: bits must be 8, 16 or 32"));
        }
        Ok(Self {
            object: object.parse()?,
            bits,
        })
    }
}

impl From<PdoEntry> for String {
    fn from(e: PdoEntry) -> String {
        e.to_string()
    }
}

/// A PDO mapping: entries packed little-endian in order, at most 64 bits.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PdoMapping {
    entries: Vec<PdoEntry>,
}

/// A mapping that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MappingError {
    /// Only whole bytes of 8, 16 or 32 bits are mapped.
    #[error("{0}: width {1} bits; use 8, 16 or 32")]
    Width(ObjectAddress, u8),
    /// The entries exceed eight bytes.
    #[error("the mapped objects need {0} bits; a PDO holds 64")]
    TooLong(u32),
    /// Nothing is mapped.
    #[error("the mapping is empty")]
    Empty,
}

/// How a TPDO is triggered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TpdoTrigger {
    /// Transmission type: 0xFE/0xFF event-driven, 1–240 every n-th SYNC.
    pub transmission_type: u8,
    /// Event timer, ms (0 = off); event-driven PDOs are also sent at this period.
    pub event_timer_ms: u16,
}

impl PdoMapping {
    /// A checked mapping.
    pub fn new(entries: Vec<PdoEntry>) -> Result<Self, MappingError> {
        if entries.is_empty() {
            return Err(MappingError::Empty);
        }
        let mut total = 0u32;
        for e in &entries {
            if !matches!(e.bits, 8 | 16 | 32) {
                return Err(MappingError::Width(e.object, e.bits));
            }
            total += u32::from(e.bits);
        }
        if total > 64 {
            return Err(MappingError::TooLong(total));
        }
        Ok(Self { entries })
    }

    /// The entries in order.
    pub fn entries(&self) -> &[PdoEntry] {
        &self.entries
    }

    /// Bytes a PDO with this mapping carries.
    pub fn byte_len(&self) -> usize {
        self.entries.iter().map(|e| usize::from(e.bits / 8)).sum()
    }

    /// Unpacks a PDO's data into (object, raw value) pairs, sign-extended from each entry's
    /// width. `None` when the frame is shorter than the mapping.
    pub fn unpack(&self, data: &[u8]) -> Option<Vec<(ObjectAddress, i64)>> {
        if data.len() < self.byte_len() {
            return None;
        }
        let mut at = 0;
        let mut values = Vec::with_capacity(self.entries.len());
        for e in &self.entries {
            let n = usize::from(e.bits / 8);
            let mut raw = [0u8; 8];
            raw[..n].copy_from_slice(data.get(at..at + n)?);
            let unsigned = u64::from_le_bytes(raw);
            let shift = 64 - u32::from(e.bits);
            values.push((e.object, ((unsigned << shift) as i64) >> shift));
            at += n;
        }
        Some(values)
    }

    /// Packs raw values (in entry order, truncated to each width) into PDO data.
    pub fn pack(&self, values: &[i64]) -> Vec<u8> {
        let mut data = Vec::with_capacity(self.byte_len());
        for (e, v) in self.entries.iter().zip(values) {
            let n = usize::from(e.bits / 8);
            data.extend_from_slice(&v.to_le_bytes()[..n]);
        }
        data
    }

    /// The SDO writes that configure TPDO `n` (1–4) of a node to send this mapping on
    /// `cob_id`: disable, set trigger, clear and fill the mapping, enable.
    pub fn tpdo_setup(&self, n: u8, cob_id: u32, trigger: TpdoTrigger) -> Vec<SdoRequest> {
        let k = u16::from(n.saturating_sub(1));
        let comm = 0x1800 + k;
        let map = 0x1A00 + k;
        let mut writes = vec![
            write32(comm, 1, cob_id | 0x8000_0000),
            SdoRequest::Write(
                ObjectAddress::new(comm, 2),
                SdoData::u8(trigger.transmission_type),
            ),
            SdoRequest::Write(
                ObjectAddress::new(comm, 5),
                SdoData::u16(trigger.event_timer_ms),
            ),
        ];
        self.mapping_writes(map, &mut writes);
        writes.push(write32(comm, 1, cob_id));
        writes
    }

    /// The SDO writes that configure RPDO `n` (1–4) of a node to receive this mapping on
    /// `cob_id`, acting on each frame as it arrives (transmission type 0xFF).
    pub fn rpdo_setup(&self, n: u8, cob_id: u32) -> Vec<SdoRequest> {
        let k = u16::from(n.saturating_sub(1));
        let comm = 0x1400 + k;
        let map = 0x1600 + k;
        let mut writes = vec![
            write32(comm, 1, cob_id | 0x8000_0000),
            SdoRequest::Write(ObjectAddress::new(comm, 2), SdoData::u8(0xFF)),
        ];
        self.mapping_writes(map, &mut writes);
        writes.push(write32(comm, 1, cob_id));
        writes
    }

    fn mapping_writes(&self, map: u16, writes: &mut Vec<SdoRequest>) {
        writes.push(SdoRequest::Write(
            ObjectAddress::new(map, 0),
            SdoData::u8(0),
        ));
        for (i, e) in self.entries.iter().enumerate() {
            writes.push(write32(map, (i + 1) as u8, e.mapping_value()));
        }
        writes.push(SdoRequest::Write(
            ObjectAddress::new(map, 0),
            SdoData::u8(self.entries.len() as u8),
        ));
    }
}

fn write32(index: u16, sub: u8, value: u32) -> SdoRequest {
    SdoRequest::Write(ObjectAddress::new(index, sub), SdoData::u32(value))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(index: u16, sub: u8, bits: u8) -> PdoEntry {
        PdoEntry {
            object: ObjectAddress::new(index, sub),
            bits,
        }
    }

    #[test]
    fn packs_and_unpacks_signed_values() {
        let m = PdoMapping::new(vec![entry(0x6041, 0, 16), entry(0x606C, 0, 32)]).unwrap();
        assert_eq!(m.byte_len(), 6);
        let data = m.pack(&[0x0637, -1500]);
        assert_eq!(data, vec![0x37, 0x06, 0x24, 0xFA, 0xFF, 0xFF]);
        let values = m.unpack(&data).unwrap();
        assert_eq!(values[0], (ObjectAddress::new(0x6041, 0), 0x0637));
        assert_eq!(values[1].1, -1500);
        assert!(m.unpack(&data[..5]).is_none());
    }

    #[test]
    fn rejects_bad_mappings() {
        assert_eq!(PdoMapping::new(vec![]), Err(MappingError::Empty));
        assert!(PdoMapping::new(vec![entry(0x6041, 0, 12)]).is_err());
        assert!(PdoMapping::new(vec![entry(1, 0, 32), entry(2, 0, 32), entry(3, 0, 8)]).is_err());
    }

    #[test]
    fn tpdo_setup_follows_cia_301() {
        let m = PdoMapping::new(vec![entry(0x6041, 0, 16), entry(0x606C, 0, 32)]).unwrap();
        let frames: Vec<String> = m
            .tpdo_setup(
                1,
                0x181,
                TpdoTrigger {
                    transmission_type: 0xFF,
                    event_timer_ms: 20,
                },
            )
            .iter()
            .map(|w| w.frame(super::super::NodeId::new(1).unwrap()).to_string())
            .collect();
        assert_eq!(
            frames,
            [
                "601#2300180181010080", // 0x1800:1 COB-ID 0x181 with bit 31: disabled
                "601#2F001802FF000000", // 0x1800:2 event-driven
                "601#2B00180514000000", // 0x1800:5 event timer 20 ms
                "601#2F001A0000000000", // 0x1A00:0 no entries
                "601#23001A0110004160", // 0x1A00:1 = 0x6041:0, 16 bits
                "601#23001A0220006C60", // 0x1A00:2 = 0x606C:0, 32 bits
                "601#2F001A0002000000", // 0x1A00:0 two entries
                "601#2300180181010000", // 0x1800:1 enabled
            ]
        );
    }
}
