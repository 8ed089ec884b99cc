//! Imports a plain receiver log (such as gpsd's regression logs: NMEA, u-blox UBX, or both)
//! as a stream of records.
//!
//! Such logs have `#` comment lines and no host timestamps, so time comes from the
//! sentences: each line becomes one serial chunk stamped with the UTC time of the timed
//! sentence or message it holds (GGA, GNS, RMC, GST, ZDA, KSXT, a UBX NAV-PVT or NAV-SOL with
//! a valid time), or of the last one before it; but a position report that has no time (a receiver
//! without a fix) is the receiver's next epoch, one period on, so that it never voids the
//! fix before it. The date comes from RMC, ZDA or NAV-PVT; lines before the first date take
//! it from the first dated sentence, and the date rolls over at midnight. Binary data and
//! broken sentences are kept byte for byte. A line is a comment only where a frame may
//! start, and only when no letter follows its `#` (Unicore's `#UNIHEADINGA` logs are data,
//! and so is a `#` inside a UBX frame that follows a `0A` byte).
//!
//! Receivers boot with a default date and set their clock later, so a log's time can jump.
//! A step back of more than [`BACKSTEP_TOLERANCE`], or forward by more than the configured
//! gap, starts a new segment: the records' time (the engine's, which never steps) continues
//! one receiver period after the last record, and the jump is reported with its line. Smaller
//! steps back (a ZDA stamped for the coming second) keep the time before them.
//!
//! The log is read twice, line by line (the first pass finds the first date), so memory does
//! not grow with its length or the span it covers.

use std::io::{BufRead, BufReader, Cursor, Read};
use std::path::Path;
use std::time::Duration;

use bytes::Bytes;
use chrono::{NaiveDate, NaiveDateTime, NaiveTime};

use super::{Payload, Record, RecordError};
use crate::devices::gnss::decode::{GnssSentence, decode};
use crate::devices::gnss::ubx::{self, UbxFrame};
use crate::devices::gnss::utc::UtcTracker;
use crate::devices::gnss::{Frame, GnssFramer, Sentence, UbxMessage};
use crate::time::Timestamp;

/// Source name given to imported chunks.
pub const IMPORT_SOURCE: &str = crate::sources::GNSS;
/// Steps back up to this long are the order of sentences within an epoch, not a new clock.
pub const BACKSTEP_TOLERANCE: Duration = Duration::from_secs(1);
/// The default largest forward step within one segment.
pub const DEFAULT_MAX_GAP: Duration = Duration::from_secs(10);
/// A line longer than this is imported as several chunks (binary data without newlines).
const MAX_CHUNK: usize = 4096;
/// How many jumps are kept for the report; the rest are only counted.
const KEEP_JUMPS: usize = 100;

/// How a log is imported.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImportOptions {
    /// A forward step longer than this starts a new segment.
    pub max_gap: Duration,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            max_gap: DEFAULT_MAX_GAP,
        }
    }
}

/// A jump of the log's clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockJump {
    /// One-based line of the log where the new time starts.
    pub line: u64,
    /// The time before the jump.
    pub from: NaiveDateTime,
    /// The time after it.
    pub to: NaiveDateTime,
}

/// What the import found.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ImportReport {
    /// Chunks imported.
    pub chunks: usize,
    /// Comment lines dropped.
    pub comment_lines: usize,
    /// False when no sentence carried a date and 1970-01-01 was assumed.
    pub date_known: bool,
    /// Clock jumps, the first hundred.
    pub jumps: Vec<ClockJump>,
    /// Clock jumps, all of them.
    pub jump_count: u64,
    /// Chunks whose time stepped back within the tolerance and kept the time before.
    pub retimed: u64,
    /// A read error that ended the log early.
    pub read_error: Option<String>,
}

/// Where a log's time starts: the date of its first lines, and its first time.
#[derive(Debug, Clone, Copy)]
struct Start {
    date: NaiveDate,
    date_known: bool,
    first: NaiveDateTime,
}

/// Splits `log` into records (the whole log in memory; for tests and small inputs).
pub fn import_nmea_log(log: &[u8]) -> Result<(Vec<Record>, ImportReport), RecordError> {
    let mut reader = NmeaLogReader::new(
        || Ok(Box::new(Cursor::new(log.to_vec())) as Box<dyn BufRead>),
        ImportOptions::default(),
    )?;
    let records: Vec<Record> = reader.by_ref().collect();
    Ok((records, reader.report().clone()))
}

/// Lines of a log in bounded chunks, with their one-based line numbers; comment lines are
/// counted and dropped.
struct Lines {
    input: Box<dyn BufRead>,
    line_no: u64,
    /// The last chunk did not end its line.
    mid_line: bool,
    /// The line being read is a comment.
    in_comment: bool,
    comment_lines: usize,
    read_error: Option<String>,
    /// Bytes read so far.
    bytes: u64,
}

impl Lines {
    fn new(input: Box<dyn BufRead>) -> Self {
        Self {
            input,
            bytes: 0,
            line_no: 0,
            mid_line: false,
            in_comment: false,
            comment_lines: 0,
            read_error: None,
        }
    }

    /// The next chunk and its line, or `None` at the end (or at a read error). `mid_frame`
    /// says the framer is inside a frame, where a `#` is data.
    fn next_chunk(&mut self, mid_frame: bool) -> Option<(u64, Vec<u8>)> {
        loop {
            let mut buf = Vec::with_capacity(128);
            let mut bounded = Read::take(&mut self.input, MAX_CHUNK as u64);
            match bounded.read_until(b'\n', &mut buf) {
                Ok(0) => return None,
                Ok(n) => self.bytes += n as u64,
                Err(e) => {
                    self.read_error = Some(e.to_string());
                    return None;
                }
            }
            if !self.mid_line {
                self.line_no += 1;
                self.in_comment = !mid_frame && is_comment(&buf);
                self.comment_lines += usize::from(self.in_comment);
            }
            self.mid_line = buf.last() != Some(&b'\n');
            if !self.in_comment {
                return Some((self.line_no, buf));
            }
        }
    }
}

/// Whether a line that starts where a frame may start is a comment: `#` and no letter.
fn is_comment(line: &[u8]) -> bool {
    line.first() == Some(&b'#') && !line.get(1).is_some_and(u8::is_ascii_alphabetic)
}

/// The time of day (and date, where given) a frame states.
fn frame_time(frame: &Frame<'_>) -> Option<(NaiveTime, Option<NaiveDate>)> {
    match frame {
        Frame::Text(body) => sentence_time(body),
        Frame::Ubx(frame) => ubx_utc(frame).map(|utc| (utc.time(), Some(utc.date()))),
    }
}

/// A solution frame (NAV-PVT, NAV-SOL) decoded; other frames are not decoded at all.
fn solution(frame: &UbxFrame<'_>) -> Option<UbxMessage> {
    if ![ubx::NAV_PVT, ubx::NAV_SOL].contains(&(frame.class, frame.id)) {
        return None;
    }
    ubx::decode(frame).ok().flatten()
}

/// The UTC a solution frame states (NAV-SOL's GPS time with the leap seconds of its date).
fn ubx_utc(frame: &UbxFrame<'_>) -> Option<NaiveDateTime> {
    match solution(frame)? {
        UbxMessage::NavPvt(pvt) => pvt.utc,
        UbxMessage::NavSol(sol) => sol.utc(None),
        _ => None,
    }
}

/// The time of day (and date, where given) of a timed sentence. The engine decodes every
/// sentence again, so those whose time is their first field and that carry no date are
/// read only that far.
fn sentence_time(body: &str) -> Option<(NaiveTime, Option<NaiveDate>)> {
    let sentence = Sentence::parse(body);
    if sentence.talker != "P" && matches!(sentence.kind, "GGA" | "GNS" | "GST") {
        return sentence
            .fields()
            .next_time()
            .ok()
            .flatten()
            .map(|t| (t, None));
    }
    match decode(&sentence) {
        Ok(Some(GnssSentence::Rmc(r))) => r.time.map(|t| (t, r.date)),
        Ok(Some(GnssSentence::Zda(z))) => z.time.map(|t| (t, z.date)),
        Ok(Some(GnssSentence::Ksxt(k))) => k.position.time.map(|t| (t, k.date)),
        _ => None,
    }
}

/// Whether `frame` is a position report (GGA, GNS, RMC, KSXT, NAV-PVT), whose time
/// `frame_time` found absent.
fn is_position_report(frame: &Frame<'_>) -> bool {
    match frame {
        Frame::Text(body) => {
            let sentence = Sentence::parse(body);
            sentence.talker != "P" && matches!(sentence.kind, "GGA" | "GNS" | "RMC" | "KSXT")
        }
        Frame::Ubx(frame) => solution(frame).is_some(),
    }
}

/// The first pass: the first timed sentence and the first dated one.
fn find_start(input: Box<dyn BufRead>) -> Result<Start, RecordError> {
    let mut lines = Lines::new(input);
    let mut framer = GnssFramer::new();
    let mut first: Option<(NaiveTime, Option<NaiveDate>)> = None;
    let mut first_dated: Option<(NaiveTime, NaiveDate)> = None;
    while first_dated.is_none()
        && let Some((_, chunk)) = lines.next_chunk(framer.pending() > 0)
    {
        framer.push_frames(&chunk, |frame| {
            if let Some((time, date)) = frame_time(&frame) {
                first.get_or_insert((time, date));
                if let Some(d) = date {
                    first_dated.get_or_insert((time, d));
                }
            }
        });
    }
    if let Some(e) = lines.read_error {
        return Err(RecordError::Import(format!("reading the log: {e}")));
    }
    let (first_time, first_date) = first.ok_or_else(|| {
        RecordError::Import("no sentence, NAV-PVT or NAV-SOL with a UTC time in the log".into())
    })?;
    let date = match first_dated {
        // Lines before the first date that show a later time of day were on the day before.
        Some((dated_time, date)) if first_time > dated_time => date.pred_opt().unwrap_or(date),
        Some((_, date)) => date,
        None => NaiveDate::default(),
    };
    Ok(Start {
        date,
        date_known: first_dated.is_some(),
        first: first_date.unwrap_or(date).and_time(first_time),
    })
}

/// A plain NMEA log read as time-stamped records, in segments across clock jumps.
pub struct NmeaLogReader {
    lines: Lines,
    framer: GnssFramer,
    tracker: UtcTracker,
    options: ImportOptions,
    /// The log's time of the last chunk (the latest, within a segment) ...
    last_logged: NaiveDateTime,
    /// ... and the time records carry for it.
    last_time: Timestamp,
    /// The last step between two chunk times: the receiver's period.
    last_step: Option<Duration>,
    /// Records' time minus the log's time in the current segment, ns.
    offset_ns: i128,
    /// The last timed chunk started a segment.
    just_jumped: bool,
    /// An untimed position report was placed one period after the last timed chunk.
    untimed_placed: bool,
    report: ImportReport,
}

impl NmeaLogReader {
    /// Opens the log at `path`.
    pub fn open(path: &Path, options: ImportOptions) -> Result<Self, RecordError> {
        Self::new(
            || {
                // A FIFO or device would hang the second pass, or never end.
                super::open_regular(path)
                    .map(|f| Box::new(BufReader::with_capacity(1 << 16, f)) as Box<dyn BufRead>)
            },
            options,
        )
    }

    /// Reads the log that `open` opens: once to find where its time starts, then as
    /// records. Fails when no sentence carries a UTC time.
    fn new(
        open: impl Fn() -> Result<Box<dyn BufRead>, RecordError>,
        options: ImportOptions,
    ) -> Result<Self, RecordError> {
        let start = find_start(open()?)?;
        let first = to_timestamp(start.first)
            .ok_or_else(|| RecordError::Import(format!("time {} is before 1970", start.first)))?;
        Ok(Self {
            lines: Lines::new(open()?),
            framer: GnssFramer::new(),
            tracker: UtcTracker::starting_on(start.date),
            options,
            last_logged: start.first,
            last_time: first,
            last_step: None,
            offset_ns: 0,
            just_jumped: false,
            untimed_placed: false,
            report: ImportReport {
                date_known: start.date_known,
                ..ImportReport::default()
            },
        })
    }

    /// Bytes of the log read as records so far.
    pub fn bytes_read(&self) -> u64 {
        self.lines.bytes
    }

    /// What the import found so far (all of it once the reader is exhausted).
    pub fn report(&self) -> &ImportReport {
        &self.report
    }

    /// The log's time minus the records' time in the current segment, ns: what turns the
    /// time of the last record handed out (and of ticks up to the next one) back into the
    /// time the log shows.
    pub fn logged_offset_ns(&self) -> i128 {
        -self.offset_ns
    }

    /// The records' time for a chunk the log stamps `logged`, starting a new segment on a
    /// jump.
    fn place(&mut self, line: u64, logged: NaiveDateTime) -> Timestamp {
        let Some(logged_t) = to_timestamp(logged) else {
            return self.last_time;
        };
        let back = self.last_logged - logged;
        let jumped = back.to_std().is_ok_and(|b| b > BACKSTEP_TOLERANCE)
            || (logged - self.last_logged)
                .to_std()
                .is_ok_and(|f| f > self.options.max_gap);
        if jumped && self.just_jumped && logged.time() == self.last_logged.time() {
            // The epoch's time-only sentences came first, on the old date; its RMC or ZDA
            // now brings the new date. One jump, to the new date.
            self.offset_ns =
                i128::from(self.last_time.as_nanos()) - i128::from(logged_t.as_nanos());
            if self.report.jump_count <= KEEP_JUMPS as u64
                && let Some(jump) = self.report.jumps.last_mut()
            {
                jump.to = logged;
            }
            self.last_logged = logged;
            return self.last_time;
        }
        self.just_jumped = jumped;
        let time = if jumped {
            // The receiver's clock was set: carry on one receiver period after the last
            // record, in the log's new time.
            let step = self
                .last_step
                .unwrap_or(Duration::from_secs(1))
                .min(self.options.max_gap);
            let time = self.last_time.saturating_add(step);
            self.offset_ns = i128::from(time.as_nanos()) - i128::from(logged_t.as_nanos());
            self.report.jump_count += 1;
            if self.report.jumps.len() < KEEP_JUMPS {
                self.report.jumps.push(ClockJump {
                    line,
                    from: self.last_logged,
                    to: logged,
                });
            }
            self.last_logged = logged;
            time
        } else {
            let shifted = i128::from(logged_t.as_nanos()) + self.offset_ns;
            let time = Timestamp::from_nanos(u64::try_from(shifted.max(0)).unwrap_or(u64::MAX));
            self.last_logged = self.last_logged.max(logged);
            if time < self.last_time {
                self.report.retimed += 1;
                return self.last_time;
            }
            time
        };
        if time > self.last_time {
            self.last_step = Some(time.saturating_since(self.last_time));
        }
        self.last_time = time;
        time
    }
}

impl Iterator for NmeaLogReader {
    type Item = Record;

    fn next(&mut self) -> Option<Record> {
        let Some((line, chunk)) = self.lines.next_chunk(self.framer.pending() > 0) else {
            self.report.comment_lines = self.lines.comment_lines;
            self.report.read_error = self.lines.read_error.clone();
            return None;
        };
        let mut stamp = None;
        let mut untimed_report = false;
        let tracker = &mut self.tracker;
        self.framer.push_frames(&chunk, |frame| {
            if let Some((time, date)) = frame_time(&frame) {
                let dt = tracker.observe(time, date);
                stamp = stamp.or(dt);
            } else {
                untimed_report |= is_position_report(&frame);
            }
        });
        let t = match stamp {
            Some(logged) => {
                self.untimed_placed = false;
                self.place(line, logged)
            }
            // A position report without a time (`$GPGGA,,,,,,0,...` from a receiver that
            // lost its fix) is the receiver's next epoch: one period after the last, never
            // the time of the fix before it, which it would void.
            None if untimed_report && !self.untimed_placed => {
                self.untimed_placed = true;
                let step = self
                    .last_step
                    .unwrap_or(Duration::from_secs(1))
                    .min(self.options.max_gap);
                self.last_time = self.last_time.saturating_add(step);
                self.last_time
            }
            None => self.last_time,
        };
        self.report.chunks += 1;
        Some(Record {
            t,
            source: IMPORT_SOURCE.to_owned(),
            payload: Payload::Serial(Bytes::from(chunk)),
        })
    }
}

fn to_timestamp(dt: NaiveDateTime) -> Option<Timestamp> {
    u64::try_from(dt.and_utc().timestamp_micros())
        .ok()
        .map(Timestamp::from_micros)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::gnss::framer::checksum;

    fn line(body: &str) -> String {
        format!("${body}*{:02X}\r\n", checksum(body.as_bytes()))
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
    fn a_report_without_a_time_is_the_next_epoch_not_the_last_fixs() {
        let log = format!(
            "{}{}{}{}{}",
            line("GPGGA,120000.00,5104.0859,N,11405.7387,W,1,8,0.9,1.0,M,0,M,,"),
            line("GPRMC,120000.50,A,5104.0859,N,11405.7387,W,0.0,,010122,,,A"),
            line("GPGGA,,,,,,0,00,99.99,,,,,,"),
            line("GPRMC,,V,,,,,,,,,,N"),
            line("GPGGA,120001.50,5104.0859,N,11405.7387,W,1,8,0.9,1.0,M,0,M,,"),
        );
        let (records, _) = import_nmea_log(log.as_bytes()).unwrap();
        let s: Vec<String> = records.iter().map(|r| r.t.to_string()).collect();
        // The untimed reports come one period (0.5 s) after the fix; the next timed one
        // carries on from its own time.
        assert_eq!(
            s,
            [
                "1641038400.000000",
                "1641038400.500000",
                "1641038401.000000",
                "1641038401.000000",
                "1641038401.500000"
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
    fn a_hash_inside_a_frame_or_before_a_log_name_is_data() {
        // A UBX frame whose payload holds a line feed and then `# `, as gpsd's u-blox logs
        // do; a Unicore `#` log; then a comment, which alone is dropped.
        let frame = crate::devices::gnss::ubx::frame::encode(0x01, 0x26, b"ab\n# c").unwrap();
        let mut data = frame.clone();
        data.extend_from_slice(b"#UNIHEADINGA,97;INSUFFICIENT_OBS*ee072604\r\n");
        data.extend_from_slice(rmc("120000.00", "010122").as_bytes());
        let mut log = data.clone();
        log.extend_from_slice(b"# a note\n");
        let (records, report) = import_nmea_log(&log).unwrap();
        let joined: Vec<u8> = records
            .iter()
            .flat_map(|r| match &r.payload {
                Payload::Serial(b) => b.to_vec(),
                other => panic!("unexpected {other:?}"),
            })
            .collect();
        assert_eq!(joined, data);
        assert_eq!(report.comment_lines, 1);
    }

    #[test]
    fn small_steps_back_keep_the_time_before_them() {
        let log = format!(
            "{}{}{}",
            line("GPZDA,120010.00,01,01,2022,00,00"),
            line("GPGGA,120009.000,5104.0859,N,11405.7387,W,1,8,0.9,1.0,M,0,M,,"),
            line("GPGGA,120011.000,5104.0859,N,11405.7387,W,1,8,0.9,1.0,M,0,M,,"),
        );
        let (records, report) = import_nmea_log(log.as_bytes()).unwrap();
        assert_eq!(records[0].t, records[1].t);
        assert_eq!(records[2].t.to_string(), "1641038411.000000");
        assert_eq!((report.retimed, report.jump_count), (1, 0));
    }

    fn rmc(time: &str, date: &str) -> String {
        line(&format!(
            "GPRMC,{time},A,5104.0859,N,11405.7387,W,0.0,,{date},,,A"
        ))
    }

    #[test]
    fn a_clock_set_after_boot_starts_a_segment_one_period_on() {
        // Three epochs on the receiver's default date, then the real one.
        let log = [
            rmc("000039.00", "010108"),
            rmc("000040.00", "010108"),
            rmc("000041.00", "010108"),
            "# a comment between\n".to_owned(),
            rmc("073658.00", "090710"),
            rmc("073659.00", "090710"),
        ]
        .concat();
        let (records, report) = import_nmea_log(log.as_bytes()).unwrap();
        let s: Vec<String> = records.iter().map(|r| r.t.to_string()).collect();
        // 2008-01-01T00:00:39Z onwards, one second apart across the jump.
        assert_eq!(
            s,
            [
                "1199145639.000000",
                "1199145640.000000",
                "1199145641.000000",
                "1199145642.000000",
                "1199145643.000000"
            ]
        );
        assert_eq!(report.jump_count, 1);
        assert_eq!(report.jumps[0].line, 5);
        assert_eq!(report.jumps[0].from.to_string(), "2008-01-01 00:00:41");
        assert_eq!(report.jumps[0].to.to_string(), "2010-07-09 07:36:58");
    }

    #[test]
    fn backward_jumps_and_week_rollovers_are_segments_too() {
        // A week rollover: 1980-01-05, 1980-01-12, then 2008; and a jump back at the end.
        let log = [
            rmc("235959.00", "050180"),
            rmc("000000.00", "060180"),
            rmc("000000.50", "120180"),
            rmc("120000.00", "230808"),
            rmc("120000.10", "230808"),
            rmc("110000.00", "230808"),
        ]
        .concat();
        let (records, report) = import_nmea_log(log.as_bytes()).unwrap();
        assert_eq!(report.jump_count, 3, "{:?}", report.jumps);
        let lines: Vec<u64> = report.jumps.iter().map(|j| j.line).collect();
        assert_eq!(lines, [3, 4, 6]);
        // Time never runs back, and each segment continues one period (the last step) on.
        let t: Vec<u64> = records.iter().map(|r| r.t.as_micros()).collect();
        let steps: Vec<u64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        assert_eq!(steps, [1_000_000, 1_000_000, 1_000_000, 100_000, 100_000]);
    }

    #[test]
    fn the_gap_that_starts_a_segment_is_configurable() {
        let log = [rmc("120000.00", "010122"), rmc("120030.00", "010122")].concat();
        let (_, report) = import_nmea_log(log.as_bytes()).unwrap();
        assert_eq!(report.jump_count, 1);
        let bytes = log.into_bytes();
        let mut wide = NmeaLogReader::new(
            || Ok(Box::new(Cursor::new(bytes.clone())) as Box<dyn BufRead>),
            ImportOptions {
                max_gap: Duration::from_secs(60),
            },
        )
        .unwrap();
        let t: Vec<u64> = wide.by_ref().map(|r| r.t.as_micros()).collect();
        assert_eq!(t[1] - t[0], 30_000_000);
        assert_eq!(wide.report().jump_count, 0);
    }

    #[test]
    fn long_lines_are_cut_into_bounded_chunks() {
        let mut log = vec![b'x'; 3 * MAX_CHUNK + 10];
        log.push(b'\n');
        log.extend_from_slice(rmc("120000.00", "010122").as_bytes());
        let (records, _) = import_nmea_log(&log).unwrap();
        assert_eq!(records.len(), 5);
        assert!(records.iter().all(|r| match &r.payload {
            Payload::Serial(b) => b.len() <= MAX_CHUNK,
            _ => false,
        }));
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
