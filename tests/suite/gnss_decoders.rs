//! GNSS decoder vectors: fixed sentences (NMEA 0183 examples and receiver-manual style
//! output, checksums included) through the real framer and decoders, every field checked.

use crate::common;

use chassisd::devices::gnss::decode::{GnssSentence, decode};
use chassisd::devices::gnss::{FixQuality, GnssFramer, GnssReceiver, Sentence};
use chassisd::time::Timestamp;

/// Frames one wire sentence and decodes it.
fn decode_wire(wire: &str) -> GnssSentence {
    let mut framer = GnssFramer::new();
    let mut decoded = None;
    framer.push(format!("{wire}\r\n").as_bytes(), |body| {
        decoded = Some(decode(&Sentence::parse(body)).expect("decodes"));
    });
    assert_eq!(framer.stats().checksum_errors, 0, "{wire}");
    decoded.expect("one sentence").expect("a used type")
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn gga_classic() {
    let GnssSentence::Gga(g) =
        decode_wire("$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47")
    else {
        panic!("not GGA")
    };
    assert_eq!(g.time.unwrap().to_string(), "12:35:19");
    assert!(close(g.latitude.unwrap(), 48.0 + 7.038 / 60.0));
    assert!(close(g.longitude.unwrap(), 11.0 + 31.0 / 60.0));
    assert_eq!(g.quality, FixQuality::Single);
    assert_eq!(g.satellites, Some(8));
    assert_eq!(g.hdop, Some(0.9));
    assert_eq!(g.altitude_msl, Some(545.4));
    assert_eq!(g.geoid_separation, Some(46.9));
    assert_eq!((g.diff_age_s, g.diff_station), (None, None));
}

#[test]
fn gga_high_precision_with_differential_age() {
    // u-blox high-precision mode: seven decimals of minutes, 89 bytes on the wire.
    let GnssSentence::Gga(g) = decode_wire(
        "$GNGGA,092725.00,4717.1136157,N,00833.9157641,E,4,12,0.99,499.6312,M,48.0,M,1.0,0000*5C",
    ) else {
        panic!("not GGA")
    };
    assert!(close(g.latitude.unwrap(), 47.0 + 17.1136157 / 60.0));
    assert!(close(g.longitude.unwrap(), 8.0 + 33.9157641 / 60.0));
    assert_eq!(g.quality, FixQuality::RtkFixed);
    assert_eq!(g.altitude_msl, Some(499.6312));
    assert_eq!(g.diff_age_s, Some(1.0));
    assert_eq!(g.diff_station, Some(0));
}

#[test]
fn gga_longer_than_the_nmea_crate_accepts() {
    let wire = "$GNGGA,092725.0000,4717.1136157123,N,00833.9157641234,E,4,12,0.99,1499.631234,M,48.012345,M,1.00,0000*6E";
    assert!(wire.len() > 102);
    let GnssSentence::Gga(g) = decode_wire(wire) else {
        panic!("not GGA")
    };
    assert!(close(g.latitude.unwrap(), 47.0 + 17.1136157123 / 60.0));
    assert!(close(g.longitude.unwrap(), 8.0 + 33.9157641234 / 60.0));
    assert_eq!(g.diff_age_s, Some(1.0));
}

#[test]
fn rmc_classic_and_rtk_mode() {
    let GnssSentence::Rmc(r) =
        decode_wire("$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A")
    else {
        panic!("not RMC")
    };
    assert_eq!(r.date.unwrap().to_string(), "1994-03-23");
    assert_eq!(r.quality, FixQuality::Single);
    let v = r.velocity.unwrap();
    assert!(close(v.speed_mps, 22.4 * 1852.0 / 3600.0));
    assert_eq!(v.course_deg, Some(84.4));

    let GnssSentence::Rmc(r) = decode_wire(
        "$GNRMC,092725.00,A,4717.1136157,N,00833.9157641,E,0.004,77.52,091202,,,R,V*2B",
    ) else {
        panic!("not RMC")
    };
    assert_eq!(r.quality, FixQuality::RtkFixed);
    assert_eq!(r.velocity.unwrap().course_deg, Some(77.52));
}

#[test]
fn vtg_classic() {
    let GnssSentence::Vtg(v) = decode_wire("$GPVTG,054.7,T,034.4,M,005.5,N,010.2,K*48") else {
        panic!("not VTG")
    };
    assert_eq!(v.course_deg, Some(54.7));
    assert!(close(v.speed_mps, 5.5 * 1852.0 / 3600.0));
}

#[test]
fn gst_error_statistics() {
    let GnssSentence::Gst(g) = decode_wire("$GPGST,024603.00,3.2,6.6,4.7,47.3,5.8,5.6,22.0*58")
    else {
        panic!("not GST")
    };
    assert_eq!(g.time.unwrap().to_string(), "02:46:03");
    assert_eq!(
        (g.rms_m, g.semi_major_m, g.semi_minor_m, g.orientation_deg),
        (Some(3.2), Some(6.6), Some(4.7), Some(47.3))
    );
    assert_eq!(
        (g.latitude_sd_m, g.longitude_sd_m, g.altitude_sd_m),
        (Some(5.8), Some(5.6), Some(22.0))
    );
}

#[test]
fn gns_with_one_mode_letter_per_constellation() {
    let GnssSentence::Gns(g) =
        decode_wire("$GNGNS,014035.00,4332.69262,S,17235.48549,E,RR,13,0.9,25.63,11.24,,*70")
    else {
        panic!("not GNS")
    };
    assert!(close(g.latitude.unwrap(), -(43.0 + 32.69262 / 60.0)));
    assert!(close(g.longitude.unwrap(), 172.0 + 35.48549 / 60.0));
    assert_eq!(g.quality, FixQuality::RtkFixed);
    assert_eq!(g.satellites, Some(13));
    assert_eq!(g.altitude_msl, Some(25.63));
    assert_eq!(g.geoid_separation, Some(11.24));

    // Four constellations (GPS float, GLONASS autonomous, Galileo DGPS, BeiDou none): the
    // nmea crate rejects this field; the best letter wins.
    let GnssSentence::Gns(g) = decode_wire(
        "$GNGNS,103600.01,5114.51176,N,00012.29380,W,FADN,07,1.18,111.5,45.6,2.0,0031,V*2C",
    ) else {
        panic!("not GNS")
    };
    assert_eq!(g.quality, FixQuality::RtkFloat);
    assert!(close(g.longitude.unwrap(), -(12.29380 / 60.0)));
    assert_eq!((g.diff_age_s, g.diff_station), (Some(2.0), Some(31)));
}

#[test]
fn hdt_and_ths_headings() {
    let GnssSentence::Hdt(h) = decode_wire("$GPHDT,274.07,T*03") else {
        panic!("not HDT")
    };
    assert_eq!(h.heading_deg, Some(274.07));
    let GnssSentence::Ths(h) = decode_wire("$GNTHS,77.52,A*2E") else {
        panic!("not THS")
    };
    assert_eq!(h.heading_deg, Some(77.52));
    // Estimated (dead-reckoned) headings are not used.
    let GnssSentence::Ths(h) = decode_wire("$GNTHS,77.52,E*2A") else {
        panic!("not THS")
    };
    assert_eq!(h.heading_deg, None);
}

#[test]
fn zda_date() {
    let GnssSentence::Zda(z) = decode_wire("$GPZDA,201530.00,04,07,2002,00,00*60") else {
        panic!("not ZDA")
    };
    assert_eq!(z.date.unwrap().to_string(), "2002-07-04");
    assert_eq!(z.time.unwrap().to_string(), "20:15:30");
}

#[test]
fn receiver_counts_malformed_sentences_and_keeps_going() {
    let mut receiver = GnssReceiver::new();
    let stream = "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*48\r\n\
                  $GPGGA,123519,4807.038,X,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*51\r\n\
                  $GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n";
    let mut fixes = 0;
    receiver.push(Timestamp::from_micros(1), stream.as_bytes(), |_| fixes += 1);
    let stats = receiver.stats();
    assert_eq!(stats.framer.checksum_errors, 1);
    assert_eq!(stats.decode_errors, 1);
    assert_eq!(fixes, 1);
    assert_eq!(receiver.fix().quality, FixQuality::Single);
    assert!(stats.last_decode_error.unwrap().to_string().contains("GGA"));
}

/// The vendors' dual-antenna headings on the wire (examples from Trimble's, Septentrio's,
/// Applanix's and Unicore's own documents, checksums as sent).
#[test]
fn vendor_headings_on_the_wire() {
    let heading = |wire: &str| match decode_wire(wire) {
        GnssSentence::Heading(h) => (h.heading_deg, h.sigma_deg),
        other => panic!("{wire}: {other:?}"),
    };
    assert_eq!(
        heading("$PTNL,AVR,181059.6,+149.4688,Yaw,+0.0134,Tilt,,,60.191,3,2.5,6*00"),
        (Some(149.4688), None)
    );
    assert_eq!(
        heading("$PSSN,HRP,142657.80,061222,152.236,,-0.708,0.084,,0.181,21,2,2.400,E*23"),
        (Some(152.236), Some(0.084))
    );
    assert_eq!(
        heading("$PASHR,183944.821,74.52,T,-1.63,1.51,0.14,0.020,0.020,0.012,2,1*05"),
        (Some(74.52), Some(0.012))
    );
    assert_eq!(
        heading("$GNHPR,081212.00,341.48,-00.64,000.00,4,46,0.00,0999*4F"),
        (Some(341.48), None)
    );
}

/// Trimble's GNS epoch: the combined `$GNGNS`, then each constellation's with its
/// satellites and no position. The epoch keeps the combined fix (before, it was voided:
/// a Trimble R2 log gave no fix at all).
#[test]
fn a_trimble_gns_epoch_keeps_its_fix() {
    let mut receiver = GnssReceiver::new();
    let epoch = [
        "GNGNS,014035.00,4332.69262,S,17235.48549,E,RR,13,0.9,25.63,11.24,,,U",
        "GPGNS,014035.00,,,,,,8,,,,1.0,23",
        "GLGNS,014035.00,,,,,,5,,,,1.0,23",
    ];
    let wire: String = epoch
        .iter()
        .map(|body| format!("${body}*{:02X}\r\n", checksum(body)))
        .collect();
    receiver.push(Timestamp::from_micros(1), wire.as_bytes(), |_| {});
    let fix = receiver.fix();
    assert_eq!(fix.quality, FixQuality::RtkFixed);
    let p = fix.position.expect("a position").value;
    assert!(close(p.latitude_deg, -(43.0 + 32.69262 / 60.0)));
    assert_eq!(receiver.stats().decode_errors, 0);
}

fn checksum(body: &str) -> u8 {
    body.bytes().fold(0, |c, b| c ^ b)
}

/// Unicore's sentences as a UM98x sent them (../shared/data/gnss/unicore-um98x-nmea.log,
/// one capture of each): every one frames and decodes, the fixed headings are shown, and
/// the second antenna's `H` positions never become the vehicle's.
#[test]
fn the_unicore_capture_gives_headings_and_keeps_the_second_antenna_apart() {
    let log = std::fs::read(common::shared_gnss_dir().join("unicore-um98x-nmea.log"))
        .expect("the Unicore capture");
    let mut receiver = GnssReceiver::new();
    let mut headings = Vec::new();
    receiver.push(Timestamp::from_micros(1), &log, |fix| {
        if let Some(h) = fix.heading_deg {
            headings.push(h.value);
        }
    });
    let stats = receiver.stats();
    assert_eq!(stats.framer.checksum_errors, 0);
    assert_eq!(stats.decode_errors, 0, "{:?}", stats.last_decode_error);
    for kind in [
        "GNGGAH", "GNRMCH", "GNGNSH", "GNGSTH", "HPR", "GNHPR2", "GNTRA2", "GNTHS2",
    ] {
        assert_eq!(stats.sentences_by_kind.get(kind), Some(&1), "{kind}");
    }
    headings.dedup();
    assert_eq!(headings, [88.364, 320.961, 88.364, 88.36]);
    assert_eq!(receiver.fix().position, None);
}
