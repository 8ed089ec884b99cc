//! Property tests: the framer, decoders, receiver and log importer never panic on arbitrary
//! input, frame the same stream identically however it is chunked, and recover every valid
//! sentence from between binary garbage.

use chassisd::devices::gnss::decode::decode;
use chassisd::devices::gnss::framer::checksum;
use chassisd::devices::gnss::{GnssFramer, GnssReceiver, Sentence};
use chassisd::record::nmea_import::import_nmea_log;
use chassisd::time::Timestamp;
use proptest::prelude::*;

fn frame(chunks: &[&[u8]]) -> (Vec<String>, chassisd::devices::gnss::FramerStats, usize) {
    let mut framer = GnssFramer::new();
    let mut out = Vec::new();
    for chunk in chunks {
        framer.push(chunk, |s| out.push(s.to_owned()));
    }
    (out, framer.stats(), framer.pending())
}

/// Splits `data` at the given (sorted, deduplicated) cut points.
fn split_at<'a>(data: &'a [u8], cuts: &[usize]) -> Vec<&'a [u8]> {
    let mut points: Vec<usize> = cuts.iter().map(|c| c % (data.len() + 1)).collect();
    points.sort_unstable();
    points.dedup();
    let mut chunks = Vec::new();
    let mut start = 0;
    for p in points {
        chunks.push(&data[start..p]);
        start = p;
    }
    chunks.push(&data[start..]);
    chunks
}

/// Sentence bodies of the types chassisd decodes, with plausible but random fields.
fn sentence_body() -> impl Strategy<Value = String> {
    (
        prop::sample::select(vec!["GP", "GN", "GL", "GA", "GB"]),
        prop::sample::select(vec![
            "GGA", "RMC", "VTG", "GST", "GNS", "HDT", "THS", "ZDA", "GSA", "GSV",
        ]),
        prop::collection::vec("[0-9]{0,3}(\\.[0-9]{0,8})?|[NSEWAVDTRFMK]|", 0..20),
    )
        .prop_map(|(talker, kind, fields)| format!("{talker}{kind},{}", fields.join(",")))
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 512,
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn framer_survives_anything_and_accounts_for_every_byte(
        data in prop::collection::vec(any::<u8>(), 0..2048),
    ) {
        let (out, stats, pending) = frame(&[&data]);
        let accounted = out.iter().map(|s| s.len() as u64 + 4).sum::<u64>()
            + stats.bytes_skipped
            + pending as u64;
        let line_endings = data.iter().filter(|&&b| b == b'\r' || b == b'\n').count() as u64;
        prop_assert_eq!(stats.bytes_in, data.len() as u64);
        prop_assert!(accounted <= stats.bytes_in);
        prop_assert!(stats.bytes_in - accounted <= line_endings);
    }

    #[test]
    fn chunking_never_changes_the_result(
        data in prop::collection::vec(
            prop_oneof![any::<u8>(), Just(b'$'), Just(b'*'), Just(b'\r'), Just(b'\n'), Just(b'A')],
            0..1024,
        ),
        cuts in prop::collection::vec(any::<usize>(), 0..40),
    ) {
        let whole = frame(&[&data]);
        let chunked = frame(&split_at(&data, &cuts));
        prop_assert_eq!(whole, chunked);
    }

    #[test]
    fn every_valid_sentence_is_recovered_from_garbage(
        bodies in prop::collection::vec(sentence_body(), 1..20),
        garbage in prop::collection::vec(
            prop::collection::vec(any::<u8>().prop_map(|b| if b == b'$' { b'#' } else { b }), 0..64),
            20,
        ),
        cuts in prop::collection::vec(any::<usize>(), 0..20),
    ) {
        let mut stream = Vec::new();
        for (body, junk) in bodies.iter().zip(&garbage) {
            stream.extend_from_slice(junk);
            stream.extend_from_slice(format!("${body}*{:02X}\r\n", checksum(body.as_bytes())).as_bytes());
        }
        let (out, _, _) = frame(&split_at(&stream, &cuts));
        prop_assert_eq!(out, bodies);
    }

    #[test]
    fn decoders_never_panic(body in sentence_body()) {
        let _ = decode(&Sentence::parse(&body));
    }

    #[test]
    fn decoders_never_panic_on_any_printable_text(
        kind in prop::sample::select(vec!["GPGGA", "GNRMC", "GNVTG", "GPGST", "GNGNS", "GNHDT", "GNTHS", "GPZDA"]),
        rest in "[ -~]{0,200}",
    ) {
        let body = format!("{kind},{rest}");
        let _ = decode(&Sentence::parse(&body));
    }

    #[test]
    fn receiver_and_importer_never_panic(
        bodies in prop::collection::vec(sentence_body(), 0..10),
        junk in prop::collection::vec(any::<u8>(), 0..256),
    ) {
        let mut stream = junk.clone();
        for body in &bodies {
            stream.extend_from_slice(format!("${body}*{:02X}\n", checksum(body.as_bytes())).as_bytes());
        }
        stream.extend_from_slice(&junk);
        let mut receiver = GnssReceiver::new();
        let mut fixes = 0;
        receiver.push(Timestamp::from_micros(1), &stream, |_| fixes += 1);
        let stats = receiver.stats();
        prop_assert!(fixes as u64 <= stats.framer.sentences);
        let _ = import_nmea_log(&stream);
    }
}
