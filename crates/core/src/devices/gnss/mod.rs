//! GNSS receivers speaking NMEA 0183 and u-blox UBX: bytes in, [`GnssFix`] updates out.

pub mod decode;
pub mod encode;
mod false_sync;
pub mod fix;
pub mod framer;
pub mod rtcm;
pub mod sentence;
pub mod ubx;
pub mod utc;

use std::collections::BTreeMap;

pub use decode::{DecodeError, FixQuality, GnssSentence};
pub use fix::{FixAssembler, GeoPosition, GnssFix, Timed};
pub use framer::{Frame, FramerStats, GnssFramer};
pub use sentence::Sentence;
pub use ubx::{MonVer, UbxMessage};

use ubx::{RtcmUse, RxmRtcm};

use crate::time::Timestamp;

/// Counters for one receiver's stream.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GnssStats {
    /// Framing counters.
    pub framer: FramerStats,
    /// Valid sentences and UBX messages by type (`GGA`, `RMC`, `PSTI`, `NAV-PVT`, ...).
    pub sentences_by_kind: BTreeMap<String, u64>,
    /// Sentences of a used type whose fields did not decode.
    pub decode_errors: u64,
    /// The most recent decode error, for the periodic summary.
    pub last_decode_error: Option<DecodeError>,
    /// What the receiver said of the RTCM messages it took in (u-blox RXM-RTCM).
    pub corrections: CorrectionUse,
}

/// The RTCM messages a receiver reports taking in, by what it did with them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CorrectionUse {
    /// Used in the solution.
    pub used: u64,
    /// Taken in but not used.
    pub not_used: u64,
    /// Taken in, use not stated.
    pub unstated: u64,
    /// Failed their CRC at the receiver.
    pub crc_failed: u64,
    /// The last message's type.
    pub last_type: Option<u16>,
}

impl CorrectionUse {
    fn count(&mut self, rtcm: &RxmRtcm) {
        if rtcm.crc_failed {
            self.crc_failed += 1;
        } else {
            match rtcm.used {
                RtcmUse::Used => self.used += 1,
                RtcmUse::NotUsed => self.not_used += 1,
                RtcmUse::Unknown => self.unstated += 1,
            }
        }
        self.last_type = Some(rtcm.message_type);
    }

    /// Messages reported in all.
    pub fn total(&self) -> u64 {
        self.used + self.not_used + self.unstated + self.crc_failed
    }
}

/// A sans-IO GNSS receiver: framer, decoders and fix assembler for one serial stream of
/// NMEA, UBX, or both.
#[derive(Debug, Default)]
pub struct GnssReceiver {
    framer: GnssFramer,
    assembler: FixAssembler,
    stats: GnssStats,
    /// The receiver's own description (u-blox MON-VER), once it sent one.
    version: Option<MonVer>,
    /// A description not yet announced.
    news: Option<String>,
}

impl GnssReceiver {
    /// A receiver with no data yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds a chunk read at host time `rx`. `on_fix` sees the fix after every decoded
    /// sentence or message that went into it.
    pub fn push(&mut self, rx: Timestamp, bytes: &[u8], mut on_fix: impl FnMut(&GnssFix)) {
        let assembler = &mut self.assembler;
        let stats = &mut self.stats;
        let version = &mut self.version;
        let news = &mut self.news;
        self.framer.push_frames(bytes, |frame| match frame {
            Frame::Text(body) => {
                let sentence = Sentence::parse(body);
                count_kind(&mut stats.sentences_by_kind, sentence.kind);
                match decode::decode(&sentence) {
                    Ok(Some(decoded)) => {
                        assembler.apply(rx, &decoded);
                        on_fix(assembler.fix());
                    }
                    Ok(None) => {}
                    Err(e) => stats.failed(e),
                }
            }
            Frame::Ubx(frame) => {
                count_kind(&mut stats.sentences_by_kind, &ubx::kind_of(&frame));
                match ubx::decode(&frame) {
                    Ok(Some(UbxMessage::RxmRtcm(rtcm))) => stats.corrections.count(&rtcm),
                    Ok(Some(UbxMessage::MonVer(v))) => {
                        if version.as_ref() != Some(&v) {
                            *news = Some(format!("GNSS receiver: {}", v.summary()));
                            *version = Some(v);
                        }
                    }
                    Ok(Some(message)) => {
                        if assembler.apply_ubx(rx, &message) {
                            on_fix(assembler.fix());
                        }
                    }
                    Ok(None) => {}
                    Err(e) => stats.failed(e),
                }
            }
        });
    }

    /// The receiver's own description, once it sent one (u-blox MON-VER).
    pub fn version(&self) -> Option<&MonVer> {
        self.version.as_ref()
    }

    /// A line for the log when the receiver described itself anew, once.
    pub fn take_news(&mut self) -> Option<String> {
        self.news.take()
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

impl GnssStats {
    fn failed(&mut self, e: DecodeError) {
        self.decode_errors += 1;
        self.last_decode_error = Some(e);
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
