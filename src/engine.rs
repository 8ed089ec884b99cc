//! The sans-IO engine: routes recorded or live records through the device decoders into the
//! vehicle core and schedules the status ticks. Live mode and replay both drive this one
//! type, so a live run and the replay of its recording produce the same output.
//!
//! Ticks fall on whole multiples of the status period (100 ms) of the record clock. A tick at
//! `T` sees every record stamped at or before `T`. Time seen by the core never runs
//! backwards: a record stamped before the previous record is processed at that record's
//! time, and one stamped at or before an emitted tick is processed 1 µs after it. Equal
//! stamps from different sources are ordered by source name, as the recording reader
//! orders them. [`Engine::handle`] returns the time it used, which is what a recording
//! must store.

use std::collections::BTreeMap;
use std::time::Duration;

use crate::core::{CoreConfig, Device, Input, Output, Vehicle};
use crate::devices::gnss::{GnssStats, NmeaReceiver};
use crate::record::{Payload, Record};
use crate::time::Timestamp;

/// The status period of base_status (10 Hz).
pub const STATUS_PERIOD: Duration = Duration::from_millis(100);

/// The smallest time step of the record clock.
const ONE_MICRO: Duration = Duration::from_micros(1);

/// The decoder a source's bytes go through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decoder {
    /// NMEA 0183 from a GNSS receiver.
    Nmea,
}

impl Decoder {
    /// The decoder for a recording's `protocol` name.
    pub fn for_protocol(protocol: &str) -> Option<Self> {
        match protocol {
            "nmea0183" => Some(Self::Nmea),
            _ => None,
        }
    }
}

/// Counters of what went through the engine.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct EngineStats {
    /// Records by source.
    pub records_by_source: BTreeMap<String, u64>,
    /// Records from sources with no decoder (CAN before its devices exist, unknown names).
    pub undecoded: u64,
    /// Commands received (no dialect consumes them yet).
    pub commands: u64,
    /// Records whose time was moved forward to keep the core's time monotonic.
    pub reordered: u64,
    /// Status ticks emitted.
    pub ticks: u64,
}

/// Records and ticks in, core outputs out.
pub struct Engine {
    vehicle: Vehicle,
    nmea: BTreeMap<String, NmeaReceiver>,
    next_tick: Option<Timestamp>,
    /// Time and source of the last record processed.
    last_record: Option<(Timestamp, String)>,
    /// Time of the last tick emitted.
    last_tick: Option<Timestamp>,
    stats: EngineStats,
}

impl Engine {
    /// An engine whose `sources` (name and decoder) feed a core with `config`.
    pub fn new(config: CoreConfig, sources: &[(String, Decoder)]) -> Self {
        let nmea = sources
            .iter()
            .filter(|(_, d)| *d == Decoder::Nmea)
            .map(|(name, _)| (name.clone(), NmeaReceiver::new()))
            .collect();
        Self {
            vehicle: Vehicle::new(config),
            nmea,
            next_tick: None,
            last_record: None,
            last_tick: None,
            stats: EngineStats::default(),
        }
    }

    /// Sets the first tick to the first period boundary at or after `t` (live mode calls it
    /// at start; replay lets the first record set it).
    pub fn start_at(&mut self, t: Timestamp) {
        if self.next_tick.is_none() {
            self.next_tick = Some(t.ceil_to(STATUS_PERIOD));
        }
    }

    /// The time of the next tick, once known.
    pub fn next_tick(&self) -> Option<Timestamp> {
        self.next_tick
    }

    /// Processes one record; outputs (including statuses of ticks that fell due before it)
    /// go to `out`. Returns the time the core saw.
    pub fn handle(&mut self, record: &Record, out: &mut Vec<Output>) -> Timestamp {
        let t = self.effective_time(record);
        self.start_at(t);
        self.emit_ticks(|tick| tick < t, out);
        self.last_record = Some((t, record.source.clone()));
        match self.stats.records_by_source.get_mut(&record.source) {
            Some(n) => *n += 1,
            None => {
                self.stats
                    .records_by_source
                    .insert(record.source.clone(), 1);
            }
        }

        let vehicle = &mut self.vehicle;
        match (&record.payload, self.nmea.get_mut(&record.source)) {
            (Payload::Serial(bytes), Some(receiver)) => {
                receiver.push(t, bytes, |fix| {
                    out.extend(vehicle.handle(t, Input::Gnss(fix)));
                });
            }
            (Payload::Link(state), Some(_)) => {
                out.extend(vehicle.handle(t, Input::Link(Device::Gnss, *state)));
            }
            (Payload::Command { .. }, _) => self.stats.commands += 1,
            _ => self.stats.undecoded += 1,
        }
        t
    }

    /// Emits every tick at or before `t`.
    pub fn advance_to(&mut self, t: Timestamp, out: &mut Vec<Output>) {
        self.emit_ticks(|tick| tick <= t, out);
    }

    fn emit_ticks(&mut self, due: impl Fn(Timestamp) -> bool, out: &mut Vec<Output>) {
        while let Some(tick) = self.next_tick.filter(|&tick| due(tick)) {
            out.extend(self.vehicle.handle(tick, Input::Tick));
            self.stats.ticks += 1;
            self.last_tick = Some(tick);
            self.next_tick = Some(tick.saturating_add(STATUS_PERIOD));
        }
    }

    /// The record's time, moved forward where needed so the core's time never runs back.
    fn effective_time(&mut self, record: &Record) -> Timestamp {
        let mut t = record.t;
        if let Some(tick) = self.last_tick {
            t = t.max(tick.saturating_add(ONE_MICRO));
        }
        if let Some((last, last_source)) = &self.last_record {
            if t < *last {
                t = *last;
            }
            if t == *last && record.source.as_str() < last_source.as_str() {
                t = t.saturating_add(ONE_MICRO);
            }
        }
        if t != record.t {
            self.stats.reordered += 1;
        }
        t
    }

    /// Engine counters.
    pub fn stats(&self) -> &EngineStats {
        &self.stats
    }

    /// Counters of each NMEA source.
    pub fn gnss_stats(&self) -> impl Iterator<Item = (&str, GnssStats)> {
        self.nmea.iter().map(|(name, r)| (name.as_str(), r.stats()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::LinkState;

    fn rec(us: u64, source: &str) -> Record {
        Record {
            t: Timestamp::from_micros(us),
            source: source.into(),
            payload: Payload::Link(LinkState::Up),
        }
    }

    fn engine() -> Engine {
        Engine::new(
            CoreConfig::default(),
            &[("a".into(), Decoder::Nmea), ("b".into(), Decoder::Nmea)],
        )
    }

    fn ticks(out: &[Output]) -> Vec<u64> {
        out.iter()
            .map(|o| match o {
                Output::Status(s) => s.time.as_micros(),
            })
            .collect()
    }

    #[test]
    fn ticks_fall_on_period_boundaries_after_records_at_the_same_time() {
        let mut e = engine();
        let mut out = Vec::new();
        assert_eq!(
            e.handle(&rec(100_000, "a"), &mut out),
            Timestamp::from_micros(100_000)
        );
        assert!(
            out.is_empty(),
            "the tick at 0.1 s waits for records stamped 0.1 s"
        );
        e.handle(&rec(350_000, "a"), &mut out);
        assert_eq!(ticks(&out), [100_000, 200_000, 300_000]);
        out.clear();
        e.advance_to(Timestamp::from_micros(400_000), &mut out);
        assert_eq!(ticks(&out), [400_000]);
    }

    #[test]
    fn stragglers_move_after_the_tick_and_the_last_record() {
        let mut e = engine();
        let mut out = Vec::new();
        e.start_at(Timestamp::from_micros(0));
        e.advance_to(Timestamp::from_micros(100_000), &mut out);
        // Stamped before the tick that was already emitted.
        assert_eq!(e.handle(&rec(99_000, "b"), &mut out).as_micros(), 100_001);
        // Stamped before the previous record.
        assert_eq!(e.handle(&rec(50_000, "b"), &mut out).as_micros(), 100_001);
        // Same time, but a source that sorts first: after, as the reader would order it.
        assert_eq!(e.handle(&rec(100_001, "a"), &mut out).as_micros(), 100_002);
        assert_eq!(e.stats().reordered, 3);
    }
}
