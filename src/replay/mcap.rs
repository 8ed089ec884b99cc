//! `chassisd export --mcap`: a recording replayed through the engine into one MCAP file, the
//! raw inputs beside what chassisd made of them, for Foxglove and any MCAP reader.

use std::path::Path;

use crate::config::VehicleConfig;
use crate::engine::{Engine, EngineOutput};
use crate::interchange::InterchangeError;
use crate::interchange::derived::{self, DerivedChannels};
use crate::interchange::mcap_out::McapOut;
use crate::interchange::raw::{Message, RawChannels};
use crate::record::Record;
use crate::time::Timestamp;

use super::{Consumer, ReplayError, ReplayOptions, ReplaySummary, replay_into};

/// What an export wrote, beside the replay's own summary.
#[derive(Debug, Clone, Default)]
pub struct ExportSummary {
    /// Messages written.
    pub messages: u64,
    /// Their bytes before compression.
    pub message_bytes: u64,
    /// The file's size.
    pub file_bytes: u64,
}

/// Replays `recording` (a recording folder or a plain NMEA log) into the MCAP file `out`.
pub fn export(
    recording: &Path,
    options: &ReplayOptions,
    out: &Path,
) -> Result<(ReplaySummary, ExportSummary), ReplayError> {
    let file = McapOut::create(out).map_err(interchange)?;
    let mut exporter = Exporter {
        file,
        raw: RawChannels::default(),
        derived: DerivedChannels::default(),
        zones: None,
        clock: Timestamp::from_nanos(0),
        messages: Vec::new(),
        timed: Vec::new(),
    };
    let summary = replay_into(recording, options, Engine::emit_poses, &mut exporter)?;
    let (messages, message_bytes) = exporter.file.written();
    exporter.file.finish().map_err(interchange)?;
    let file_bytes = std::fs::metadata(out)?.len();
    Ok((
        summary,
        ExportSummary {
            messages,
            message_bytes,
            file_bytes,
        },
    ))
}

fn interchange(e: InterchangeError) -> ReplayError {
    ReplayError::Output(std::io::Error::other(e))
}

/// The replay's consumer: every record and output into the file.
struct Exporter {
    file: McapOut,
    raw: RawChannels,
    derived: DerivedChannels,
    /// The zones in force at the start, written at the first record's time.
    zones: Option<String>,
    /// The latest time seen (records, ticks): an event is logged at it.
    clock: Timestamp,
    /// Scratch: one record's messages, and the outputs' timed ones.
    messages: Vec<Message>,
    timed: Vec<(Timestamp, Message)>,
}

impl Exporter {
    fn write(&mut self, t: Timestamp, message: &Message) -> std::io::Result<()> {
        self.file
            .write(&message.topic, &message.schema, t, &message.body)
            .map_err(std::io::Error::other)
    }
}

impl Consumer for Exporter {
    fn begin(&mut self, vehicle: &VehicleConfig, nmea_sources: &[String]) {
        self.raw = RawChannels::new(nmea_sources.iter().map(String::as_str));
        self.zones = vehicle.zones.as_ref().map(|z| z.set.to_geojson());
    }

    fn record(&mut self, record: &Record) -> std::io::Result<()> {
        self.clock = self.clock.max(record.t);
        if let Some(geojson) = self.zones.take() {
            self.write(record.t, &derived::zones(&geojson))?;
        }
        let mut messages = std::mem::take(&mut self.messages);
        self.raw.messages(record, &mut messages);
        for m in messages.drain(..) {
            self.write(record.t, &m)?;
        }
        self.messages = messages;
        Ok(())
    }

    /// Outputs are written on the engine's time line, as the records are: a plain log's clock
    /// jumps (the offset) are left out, so the file has one continuous time.
    fn take(&mut self, outputs: &mut Vec<EngineOutput>, _offset_ns: i128) -> std::io::Result<()> {
        let mut timed = std::mem::take(&mut self.timed);
        for output in outputs.drain(..) {
            match &output {
                EngineOutput::Status(s) => self.clock = self.clock.max(s.time),
                EngineOutput::Poses(t, _) => self.clock = self.clock.max(*t),
                _ => {}
            }
            self.derived.messages(&output, self.clock, &mut timed);
        }
        for (t, m) in timed.drain(..) {
            self.write(t, &m)?;
        }
        self.timed = timed;
        Ok(())
    }
}
