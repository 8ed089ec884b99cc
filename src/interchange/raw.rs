//! The recorded inputs as MCAP messages, one channel per source: serial chunks as they were
//! read (and an NMEA source's sentences as text), CAN frames with their direction, commands
//! with their channel, and link events.
//!
//! Topics: `/raw/<source>` (the chunk, frame or command), `/raw/<source>/nmea` (the
//! sentences), `/raw/<source>/link` (up and down).

use std::collections::HashMap;

use base64::Engine as _;
use std::fmt::Write as _;

use serde::Serialize;
use serde_json::{Value, json};
use socketcan::{CanAnyFrame, EmbeddedFrame, Frame as _};

use super::schemas::{self, Schema};
use crate::record::{Payload, Record};
use crate::time::Timestamp;
use crate::vehicle::LinkState;

/// One message for the file: its topic, schema and JSON.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    /// The topic.
    pub topic: String,
    /// Its schema.
    pub schema: Schema,
    /// The JSON, serialised.
    pub body: Vec<u8>,
}

impl Message {
    /// A message of `body` serialised (a `serde_json::Value`, or a struct of the schema's
    /// fields where a channel is busy enough for the difference to count).
    pub fn new(topic: impl Into<String>, schema: Schema, body: &impl Serialize) -> Self {
        Self {
            topic: topic.into(),
            schema,
            // Serialising plain data into a vector cannot fail.
            body: serde_json::to_vec(body).unwrap_or_default(),
        }
    }

    /// The JSON, parsed back (for tests and checks).
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or(Value::Null)
    }
}

/// A time as Foxglove's schemas write one.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Time {
    sec: u64,
    nsec: u64,
}

impl From<Timestamp> for Time {
    fn from(t: Timestamp) -> Self {
        let nanos = t.as_nanos();
        Self {
            sec: nanos / 1_000_000_000,
            nsec: nanos % 1_000_000_000,
        }
    }
}

/// chassisd.CanFrame, written field by field: a bus's frames are most of a recording.
#[derive(Serialize)]
struct CanFrameJson<'a> {
    timestamp: Time,
    interface: &'a str,
    id: u32,
    extended: bool,
    remote: bool,
    error: bool,
    fd: bool,
    dlc: usize,
    data: &'a [u8],
    direction: &'static str,
    candump: String,
}

/// The longest NMEA sentence kept while it is assembled, bytes: NMEA allows 82, the
/// proprietary high-precision forms run to some 200; beyond this the partial line is
/// dropped (binary between sentences), so a source without line ends costs nothing.
const MAX_SENTENCE: usize = 512;

/// `{"sec", "nsec"}` of `t`, as Foxglove's JSON schemas write a time.
pub fn time_json(t: Timestamp) -> Value {
    json!(Time::from(t))
}

/// Turns records into messages; keeps each NMEA source's unfinished sentence.
#[derive(Debug, Default)]
pub struct RawChannels {
    /// The serial sources that speak NMEA 0183 (sentences are cut from their chunks), and
    /// the sentence each has begun.
    nmea: HashMap<String, Vec<u8>>,
}

impl RawChannels {
    /// Channels for a recording whose NMEA sources are `nmea_sources`.
    pub fn new<'a>(nmea_sources: impl IntoIterator<Item = &'a str>) -> Self {
        Self {
            nmea: nmea_sources
                .into_iter()
                .map(|s| (s.to_owned(), Vec::new()))
                .collect(),
        }
    }

    /// The messages of `record`, appended to `out`.
    pub fn messages(&mut self, record: &Record, out: &mut Vec<Message>) {
        let source = record.source.as_str();
        let timestamp = time_json(record.t);
        match &record.payload {
            Payload::Serial(bytes) => {
                out.push(Message::new(
                    format!("/raw/{source}"),
                    schemas::SERIAL_CHUNK,
                    &json!({
                        "timestamp": timestamp,
                        "source": source,
                        "data": base64::engine::general_purpose::STANDARD.encode(bytes),
                    }),
                ));
                if let Some(line) = self.nmea.get_mut(source) {
                    sentences(line, bytes, |sentence| {
                        out.push(Message::new(
                            format!("/raw/{source}/nmea"),
                            schemas::NMEA_SENTENCE,
                            &json!({
                                "timestamp": timestamp,
                                "source": source,
                                "sentence": sentence,
                            }),
                        ));
                    });
                }
            }
            Payload::Link(state) => out.push(Message::new(
                format!("/raw/{source}/link"),
                schemas::LINK_EVENT,
                &json!({
                    "timestamp": timestamp,
                    "source": source,
                    "state": match state {
                        LinkState::Up => "up",
                        LinkState::Down => "down",
                    },
                }),
            )),
            Payload::Can(frame) | Payload::CanTx(frame) => out.push(Message::new(
                format!("/raw/{source}"),
                schemas::CAN_FRAME,
                &can_frame(
                    record.t,
                    source,
                    frame,
                    matches!(record.payload, Payload::CanTx(_)),
                ),
            )),
            Payload::Command { topic, payload } => {
                out.push(Message::new(format!("/raw/{source}"), schemas::COMMAND, &{
                    let mut m = json!({
                        "timestamp": timestamp,
                        "source": source,
                        "topic": topic,
                        "payload": base64::engine::general_purpose::STANDARD.encode(payload),
                    });
                    // The text only when the payload is UTF-8: the schema has no null.
                    if let Ok(text) = std::str::from_utf8(payload) {
                        m["text"] = json!(text);
                    }
                    m
                }))
            }
        }
    }
}

/// A CAN frame as a CAN user reads it: the identifier as a number, its flags, the data bytes,
/// and the frame in candump's `ID#DATA` form.
fn can_frame<'a>(
    t: Timestamp,
    interface: &'a str,
    frame: &'a CanAnyFrame,
    sent: bool,
) -> CanFrameJson<'a> {
    let extended = frame.is_extended();
    let id = frame.raw_id();
    let data = frame.data();
    let mut hex = String::with_capacity(2 * data.len());
    for b in data {
        let _ = write!(hex, "{b:02X}");
    }
    let candump = match frame {
        CanAnyFrame::Remote(_) => format!("{}#R", id_text(id, extended)),
        CanAnyFrame::Fd(_) => format!("{}##0{hex}", id_text(id, extended)),
        _ => format!("{}#{hex}", id_text(id, extended)),
    };
    CanFrameJson {
        timestamp: t.into(),
        interface,
        id,
        extended,
        remote: matches!(frame, CanAnyFrame::Remote(_)),
        error: matches!(frame, CanAnyFrame::Error(_)),
        fd: matches!(frame, CanAnyFrame::Fd(_)),
        dlc: frame.dlc(),
        data,
        direction: if sent { "tx" } else { "rx" },
        candump,
    }
}

/// The identifier as candump writes it: three hex digits, or eight for an extended one.
fn id_text(id: u32, extended: bool) -> String {
    if extended {
        format!("{id:08X}")
    } else {
        format!("{id:03X}")
    }
}

/// Appends `bytes` to the sentence begun in `line` and hands over each sentence completed:
/// from its `$` (or `!`) to its line end, printable ASCII only. Bytes outside a sentence (a
/// binary protocol between them) are passed over.
fn sentences(line: &mut Vec<u8>, bytes: &[u8], mut each: impl FnMut(&str)) {
    for &b in bytes {
        match b {
            b'$' | b'!' => {
                line.clear();
                line.push(b);
            }
            b'\r' | b'\n' => {
                if let Ok(text) = std::str::from_utf8(line)
                    && line.len() > 1
                {
                    each(text);
                }
                line.clear();
            }
            0x20..=0x7e if !line.is_empty() && line.len() < MAX_SENTENCE => line.push(b),
            // Binary inside a sentence, or a line too long: not a sentence.
            _ => line.clear(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytes::Bytes;

    fn serial(bytes: &'static [u8]) -> Record {
        Record {
            t: Timestamp::from_micros(1_700_000_000_123_456),
            source: "gnss".into(),
            payload: Payload::Serial(Bytes::from_static(bytes)),
        }
    }

    #[test]
    fn sentences_are_cut_across_chunks_and_binary_between_them_is_passed_over() {
        let mut raw = RawChannels::new(["gnss"]);
        let mut out = Vec::new();
        raw.messages(&serial(b"\xb5\x62\x01\x07$GPGGA,1"), &mut out);
        raw.messages(&serial(b"23519.00,4807*1F\r\n\xb5$GPG"), &mut out);
        raw.messages(&serial(b"ST,1*2\r\n"), &mut out);
        let sentences: Vec<String> = out
            .iter()
            .filter(|m| m.topic == "/raw/gnss/nmea")
            .map(|m| m.json()["sentence"].as_str().unwrap().to_owned())
            .collect();
        assert_eq!(sentences, ["$GPGGA,123519.00,4807*1F", "$GPGST,1*2"]);
        let chunks = out.iter().filter(|m| m.topic == "/raw/gnss").count();
        assert_eq!(chunks, 3);
        assert_eq!(
            out[0].json()["timestamp"],
            json!({"sec": 1_700_000_000, "nsec": 123_456_000})
        );
        assert_eq!(out[0].json()["data"], "tWIBByRHUEdHQSwx");
    }

    #[test]
    fn a_can_frame_reads_as_candump_writes_it() {
        let frame = socketcan::CanDataFrame::new(
            socketcan::StandardId::new(0x181).unwrap(),
            &[0x37, 0x02, 0, 0],
        )
        .unwrap();
        let record = Record {
            t: Timestamp::from_micros(5),
            source: "can0".into(),
            payload: Payload::CanTx(CanAnyFrame::Normal(frame)),
        };
        let mut out = Vec::new();
        RawChannels::default().messages(&record, &mut out);
        let m = &out[0].json();
        assert_eq!(out[0].topic, "/raw/can0");
        assert_eq!(m["id"], 0x181);
        assert_eq!(m["data"], json!([0x37, 2, 0, 0]));
        assert_eq!(m["candump"], "181#37020000");
        assert_eq!(m["direction"], "tx");
        assert_eq!(m["dlc"], 4);
    }
}
