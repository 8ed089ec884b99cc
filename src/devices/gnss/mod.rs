//! GNSS receivers speaking NMEA 0183: bytes in, [`GnssFix`] updates out.

pub mod decode;
pub mod encode;
pub mod fix;
pub mod framer;
pub mod rtcm;
pub mod sentence;
pub mod utc;

use std::collections::BTreeMap;

pub use decode::{DecodeError, FixQuality, GnssSentence};
pub use fix::{FixAssembler, GeoPosition, GnssFix, Timed};
pub use framer::{FramerStats, NmeaFramer};
pub use sentence::Sentence;

use crate::time::Timestamp;

/// Counters for one receiver's stream.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GnssStats {
    /// Framing counters.
    pub framer: FramerStats,
    /// Valid sentences by type (`GGA`, `RMC`, `PSTI`, ...).
    pub sentences_by_kind: BTreeMap<String, u64>,
    /// Sentences of a used type whose fields did not decode.
    pub decode_errors: u64,
    /// The most recent decode error, for the periodic summary.
    pub last_decode_error: Option<DecodeError>,
}

/// A sans-IO NMEA receiver: framer, decoder and fix assembler for one serial stream.
#[derive(Debug, Default)]
pub struct NmeaReceiver {
    framer: NmeaFramer,
    assembler: FixAssembler,
    stats: GnssStats,
}

impl NmeaReceiver {
    /// A receiver with no data yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds a chunk read at host time `rx`. `on_fix` sees the fix after every decoded
    /// sentence that went into it.
    pub fn push(&mut self, rx: Timestamp, bytes: &[u8], mut on_fix: impl FnMut(&GnssFix)) {
        let assembler = &mut self.assembler;
        let stats = &mut self.stats;
        self.framer.push(bytes, |body| {
            let sentence = Sentence::parse(body);
            count_kind(&mut stats.sentences_by_kind, sentence.kind);
            match decode::decode(&sentence) {
                Ok(Some(decoded)) => {
                    assembler.apply(rx, &decoded);
                    on_fix(assembler.fix());
                }
                Ok(None) => {}
                Err(e) => {
                    stats.decode_errors += 1;
                    stats.last_decode_error = Some(e);
                }
            }
        });
    }

    /// The fix as assembled so far.
    pub fn fix(&self) -> &GnssFix {
        self.assembler.fix()
    }

    /// Counters so far.
    pub fn stats(&self) -> GnssStats {
        GnssStats {
            framer: self.framer.stats(),
            ..self.stats.clone()
        }
    }
}

fn count_kind(counts: &mut BTreeMap<String, u64>, kind: &str) {
    match counts.get_mut(kind) {
        Some(n) => *n += 1,
        None => {
            counts.insert(kind.to_owned(), 1);
        }
    }
}
