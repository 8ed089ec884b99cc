//! Imports a plain NMEA text log (such as gpsd's regression logs) as a recording.
//!
//! Such logs have `#` comment lines and no host timestamps, so time comes from the
//! sentences: each line becomes one serial chunk stamped with the UTC time of the timed
//! sentence it holds (GGA, GNS, RMC, GST, ZDA), or of the last one before it. The date comes
//! from RMC or ZDA; lines before the first date take it from the first dated sentence, and
//! the date rolls over at midnight. Time never runs backwards: a sentence whose time steps
//! back is stamped with the time before it. Binary data and broken sentences are kept
//! byte for byte.

use bytes::Bytes;
use chrono::{NaiveDate, NaiveDateTime, NaiveTime};

use super::{Payload, Record, RecordError};
use crate::devices::gnss::decode::{GnssSentence, decode};
use crate::devices::gnss::utc::UtcTracker;
use crate::devices::gnss::{NmeaFramer, Sentence};
use crate::time::Timestamp;

/// Source name given to imported chunks.
pub const IMPORT_SOURCE: &str = "gnss";

/// What the import found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImportReport {
    /// Chunks (lines) imported.
    pub chunks: usize,
    /// Comment lines dropped.
    pub comment_lines: usize,
    /// False when no sentence carried a date and 1970-01-01 was assumed.
    pub date_known: bool,
}

/// Time fields of the sentences in one chunk, in order.
type ChunkTimes = Vec<(NaiveTime, Option<NaiveDate>)>;

/// Splits `log` into records. Fails only when no sentence carries a UTC time.
pub fn import_nmea_log(log: &[u8]) -> Result<(Vec<Record>, ImportReport), RecordError> {
    let mut comment_lines = 0;
    let chunks: Vec<&[u8]> = log
        .split_inclusive(|&b| b == b'\n')
        .filter(|line| {
            let comment = line.first() == Some(&b'#');
            comment_lines += usize::from(comment);
            !comment
        })
        .collect();

    let times = sentence_times(&chunks);
    let all = times.iter().flatten();
    let first_time = all
        .clone()
        .next()
        .map(|(t, _)| *t)
        .ok_or_else(|| RecordError::Import("no sentence with a UTC time in the log".into()))?;
    let first_dated = all.clone().find_map(|(t, d)| d.map(|d| (*t, d)));
    let start_date = match first_dated {
        // Lines before the first date that show a later time of day were on the day before.
        Some((dated_time, date)) if first_time > dated_time => date.pred_opt().unwrap_or(date),
        Some((_, date)) => date,
        None => NaiveDate::default(),
    };

    let mut tracker = UtcTracker::starting_on(start_date);
    let mut stamps: Vec<Option<NaiveDateTime>> = Vec::with_capacity(chunks.len());
    for chunk_times in &times {
        let mut first = None;
        for (time, date) in chunk_times {
            let dt = tracker.observe(*time, *date);
            first = first.or(dt);
        }
        stamps.push(first);
    }

    let first_stamp = stamps.iter().flatten().next().copied();
    let mut current = first_stamp.map(to_timestamp).transpose()?;
    let mut records = Vec::with_capacity(chunks.len());
    for (chunk, stamp) in chunks.iter().zip(stamps) {
        if let Some(dt) = stamp {
            let t = to_timestamp(dt)?;
            current = Some(current.map_or(t, |c| c.max(t)));
        }
        let Some(t) = current else { continue };
        records.push(Record {
            t,
            source: IMPORT_SOURCE.to_owned(),
            payload: Payload::Serial(Bytes::copy_from_slice(chunk)),
        });
    }
    let report = ImportReport {
        chunks: records.len(),
        comment_lines,
        date_known: first_dated.is_some(),
    };
    Ok((records, report))
}

/// The time (and date, where given) of every timed sentence, per chunk. One framer runs
/// across all chunks, as the receiver's stream would.
fn sentence_times(chunks: &[&[u8]]) -> Vec<ChunkTimes> {
    let mut framer = NmeaFramer::new();
    chunks
        .iter()
        .map(|chunk| {
            let mut found = Vec::new();
            framer.push(chunk, |body| {
                let time_date = match decode(&Sentence::parse(body)) {
                    Ok(Some(GnssSentence::Gga(r) | GnssSentence::Gns(r))) => {
                        r.time.map(|t| (t, None))
                    }
                    Ok(Some(GnssSentence::Rmc(r))) => r.time.map(|t| (t, r.date)),
                    Ok(Some(GnssSentence::Gst(g))) => g.time.map(|t| (t, None)),
                    Ok(Some(GnssSentence::Zda(z))) => z.time.map(|t| (t, z.date)),
                    _ => None,
                };
                found.extend(time_date);
            });
            found
        })
        .collect()
}

fn to_timestamp(dt: NaiveDateTime) -> Result<Timestamp, RecordError> {
    u64::try_from(dt.and_utc().timestamp_micros())
        .map(Timestamp::from_micros)
        .map_err(|_| RecordError::Import(format!("time {dt} is before 1970")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::gnss::framer::checksum;

    fn line(body: &str) -> String {
        format!("${body}*{:02X}\r\n", checksum(body.as_bytes()))
    }

    fn stamps(log: &str) -> Vec<String> {
        let (records, _) = import_nmea_log(log.as_bytes()).unwrap();
        records.iter().map(|r| r.t.to_string()).collect()
    }

    #[test]
    fn times_come_from_sentences_and_comments_are_dropped() {
        let log = format!(
            "# a comment\r\n{}{}{}{}",
            line("GPGGA,235959.000,5104.0859,N,11405.7387,W,1,8,0.9,1.0,M,0,M,,"),
            line("GPGSA,A,3,04,09,,,,,,,,,,,1.21,0.94,0.76"),
            line("GPRMC,000000.500,A,5104.0859,N,11405.7387,W,0.09,194.17,010122,,,A"),
            line("GPGGA,000001.000,5104.0859,N,11405.7387,W,1,8,0.9,1.0,M,0,M,,"),
        );
        let (records, report) = import_nmea_log(log.as_bytes()).unwrap();
        assert_eq!(report.comment_lines, 1);
        assert!(report.date_known);
        // 2021-12-31T23:59:59Z, the same for the untimed GSA, then across midnight.
        let s: Vec<String> = records.iter().map(|r| r.t.to_string()).collect();
        assert_eq!(
            s,
            [
                "1640995199.000000",
                "1640995199.000000",
                "1640995200.500000",
                "1640995201.000000"
            ]
        );
    }

    #[test]
    fn keeps_binary_bytes_exactly() {
        let mut log = b"\xb5\x62\x01\x02\n".to_vec();
        log.extend_from_slice(
            line("GPRMC,120000.00,A,5104.0859,N,11405.7387,W,0.0,,010122,,,A").as_bytes(),
        );
        let (records, _) = import_nmea_log(&log).unwrap();
        let mut joined = Vec::new();
        for r in &records {
            match &r.payload {
                Payload::Serial(b) => joined.extend_from_slice(b),
                other => panic!("unexpected {other:?}"),
            }
        }
        assert_eq!(joined, log);
        assert_eq!(records[0].t, records[1].t);
    }

    #[test]
    fn never_runs_backwards_and_survives_gaps() {
        let log = format!(
            "{}{}{}",
            line("GPZDA,120010.00,01,01,2022,00,00"),
            line("GPGGA,120009.000,5104.0859,N,11405.7387,W,1,8,0.9,1.0,M,0,M,,"),
            line("GPGGA,130000.000,5104.0859,N,11405.7387,W,1,8,0.9,1.0,M,0,M,,"),
        );
        let s = stamps(&log);
        assert_eq!(s[0], s[1]);
        assert_eq!(s[2], "1641042000.000000");
    }

    #[test]
    fn without_a_date_assumes_the_epoch_day() {
        let log = line("GPGGA,000010.000,5104.0859,N,11405.7387,W,1,8,0.9,1.0,M,0,M,,");
        let (records, report) = import_nmea_log(log.as_bytes()).unwrap();
        assert!(!report.date_known);
        assert_eq!(records[0].t.to_string(), "10.000000");
        assert!(import_nmea_log(b"no nmea here\n").is_err());
    }
}
