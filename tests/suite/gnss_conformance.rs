//! Conformance against gpsd: every real receiver log in the shared data folder (NMEA, u-blox
//! UBX, or both) is decoded by chassisd and compared with gpsd's decoded output beside it
//! (`.log.chk`).
//!
//! For every gpsd TPV with a position, chassisd's fix for the same UTC epoch must have
//! latitude and longitude within 1e-7° and the same kind of fix (gpsd `status` 2 DGPS,
//! 3 RTK fixed, 4 RTK float, otherwise single; `mode` 1 no fix). gpsd sometimes emits a TPV
//! that still carries the previous epoch's time after a sentence of the next epoch (for
//! example, after an invalid RMC); such carry-overs are recognised by the producing sentence's
//! own time and not compared. TPVs without a time (before the first date) take the time of
//! day of the last timed sentence before them and the date of the next dated TPV.

use crate::common;

use std::collections::BTreeMap;

use chassisd::devices::gnss::decode::{GnssSentence, decode};
use chassisd::devices::gnss::{GnssFix, GnssReceiver, Sentence};
use chassisd::record::Payload;
use chassisd::record::nmea_import::import_nmea_log;
use chrono::{NaiveDateTime, NaiveTime};

/// One gpsd TPV to check.
#[derive(Debug)]
struct Expected {
    line: usize,
    time: Option<NaiveDateTime>,
    /// Time of day of the sentence that produced it, when that sentence has one.
    sentence_time: Option<NaiveTime>,
    /// Time of day of the last timed sentence before it.
    epoch_time: Option<NaiveTime>,
    position: Option<(f64, f64)>,
    rtk_status: &'static [u8],
    /// gpsd stated its GPS−UTC leap seconds (it guesses them until the receiver says).
    leap_known: bool,
}

fn sentence_time(line: &str) -> Option<NaiveTime> {
    let body = line.trim().strip_prefix('$')?.split('*').next()?;
    match decode(&Sentence::parse(body)).ok()?? {
        GnssSentence::Gga(r) | GnssSentence::Gns(r) => r.time,
        GnssSentence::Rmc(r) => r.time,
        GnssSentence::Gst(g) => g.time,
        GnssSentence::Zda(z) => z.time,
        _ => None,
    }
}

/// The `rtk.status` codes gpsd's fix kind allows: mode 0 or 1 is no fix; status 2 DGPS,
/// 3 RTK fixed, 4 RTK float; dead reckoning alone (5), a time-only fix at a surveyed
/// position (7) and a simulated one (8) are no navigation fix for chassisd; GNSS with dead
/// reckoning (6) is single or DGPS, as the receiver's differential flag says.
fn gpsd_kinds(tpv: &serde_json::Value) -> &'static [u8] {
    if matches!(tpv["mode"].as_u64(), Some(0 | 1)) {
        return &[0];
    }
    match tpv["status"].as_u64() {
        None | Some(0 | 1 | 9) => &[1],
        Some(2) => &[2],
        Some(3) => &[4],
        Some(4) => &[5],
        Some(6) => &[1, 2],
        Some(5 | 7 | 8) => &[0],
        Some(other) => panic!("gpsd status {other} has no rtk.status mapping"),
    }
}

fn expected_tpvs(chk: &str) -> Vec<Expected> {
    let mut out = Vec::new();
    let mut last_sentence_time = None;
    let mut epoch_time = None;
    for (i, line) in chk.lines().enumerate() {
        if line.starts_with('$') {
            last_sentence_time = sentence_time(line);
            epoch_time = last_sentence_time.or(epoch_time);
            continue;
        }
        let Ok(json) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        if json["class"] != "TPV" {
            continue;
        }
        let time = json["time"].as_str().map(|t| {
            NaiveDateTime::parse_from_str(t, "%Y-%m-%dT%H:%M:%S%.fZ")
                .unwrap_or_else(|e| panic!("line {}: time {t}: {e}", i + 1))
        });
        let position = match (json["lat"].as_f64(), json["lon"].as_f64()) {
            (Some(lat), Some(lon)) => Some((lat, lon)),
            _ => None,
        };
        out.push(Expected {
            line: i + 1,
            time,
            sentence_time: last_sentence_time,
            epoch_time,
            position,
            rtk_status: gpsd_kinds(&json),
            leap_known: json["leapseconds"].is_number(),
        });
    }
    // Before a binary receiver tells gpsd the leap seconds, gpsd stamps its TPVs with its
    // own default (18 s: four seconds off in 2007), so their time names no epoch.
    if out.iter().any(|e| e.leap_known) {
        out.retain(|e| e.leap_known);
    }
    // Undated TPVs take the date of the next dated one.
    let mut next_date = None;
    for e in out.iter_mut().rev() {
        match (e.time, e.epoch_time) {
            (Some(t), _) => next_date = Some(t.date()),
            (None, Some(tod)) => e.time = next_date.map(|d| d.and_time(tod)),
            (None, None) => {}
        }
    }
    out
}

/// chassisd's fix at the end of each UTC epoch of the log.
fn chassisd_epochs(log: &[u8]) -> BTreeMap<NaiveDateTime, GnssFix> {
    let (records, _) = import_nmea_log(log).expect("importable log");
    let mut receiver = GnssReceiver::new();
    let mut epochs = BTreeMap::new();
    for record in records {
        let Payload::Serial(bytes) = &record.payload else {
            panic!("import yields serial chunks only")
        };
        receiver.push(record.t, bytes, |fix| {
            if let Some(utc) = fix.utc {
                epochs.insert(utc, *fix);
            }
        });
    }
    epochs
}

#[test]
fn every_shared_log_matches_gpsd() {
    let mut total_positions = 0;
    let logs = [
        common::shared_gnss_logs(),
        common::shared_binary_gnss_logs(),
    ]
    .concat();
    for log_path in logs {
        let name = log_path.file_name().unwrap().to_string_lossy().into_owned();
        let chk_path = log_path.with_extension("log.chk");
        let chk =
            std::fs::read(&chk_path).unwrap_or_else(|e| panic!("{}: {e}", chk_path.display()));
        let expected = expected_tpvs(&String::from_utf8_lossy(&chk));
        let epochs = chassisd_epochs(&std::fs::read(&log_path).expect("readable log"));

        let mut positions = 0;
        let mut no_fix = 0;
        let mut carried_over = 0;
        // None invented: every epoch where chassisd has a valid fix is one gpsd reports, but
        // for the log's first epoch, which gpsd spends identifying a u-blox receiver, and its
        // last, whose cycle the log may cut before gpsd's end-of-cycle message.
        let gpsd_times: std::collections::BTreeSet<NaiveDateTime> =
            expected.iter().filter_map(|e| e.time).collect();
        let (first_report, last_report) = (gpsd_times.first().copied(), gpsd_times.last().copied());
        let invented: Vec<&NaiveDateTime> = epochs
            .iter()
            .filter(|(t, fix)| fix.quality.is_valid() && !gpsd_times.contains(*t))
            .map(|(t, _)| t)
            .collect();
        let before = invented
            .iter()
            .filter(|t| Some(***t) < first_report)
            .count();
        let after = invented.iter().filter(|t| Some(***t) > last_report).count();
        assert!(
            before <= 1 && after <= 1 && before + after == invented.len(),
            "{name}: fixes gpsd does not report at {invented:?}"
        );
        for e in &expected {
            let Some(time) = e.time else {
                panic!("{name}:{}: TPV whose time cannot be derived", e.line)
            };
            if e.sentence_time.is_some_and(|st| st != time.time()) {
                carried_over += 1;
                continue;
            }
            let fix = epochs
                .get(&time)
                .unwrap_or_else(|| panic!("{name}:{}: chassisd has no fix for {time}", e.line));
            assert!(
                e.rtk_status.contains(&fix.quality.rtk_status()),
                "{name}:{}: fix kind at {time} ({:?}), gpsd's allows {:?}",
                e.line,
                fix.quality,
                e.rtk_status
            );
            match e.position.filter(|_| e.rtk_status != [0]) {
                Some((lat, lon)) => {
                    let pos = fix
                        .position
                        .unwrap_or_else(|| panic!("{name}:{}: no position at {time}", e.line))
                        .value;
                    assert!(
                        (pos.latitude_deg - lat).abs() <= 1e-7
                            && (pos.longitude_deg - lon).abs() <= 1e-7,
                        "{name}:{}: at {time} chassisd ({}, {}) vs gpsd ({lat}, {lon})",
                        e.line,
                        pos.latitude_deg,
                        pos.longitude_deg
                    );
                    positions += 1;
                }
                None => no_fix += 1,
            }
        }
        eprintln!(
            "{name}: {positions} positioned TPVs and {no_fix} no-fix TPVs match; \
             {carried_over} carry-overs not compared; {} epochs before gpsd's first report or after its last",
            invented.len()
        );
        assert!(positions > 0, "{name}: nothing was compared");
        total_positions += positions;
    }
    assert!(total_positions > 100);
}
