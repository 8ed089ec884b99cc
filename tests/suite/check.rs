//! `chassisd check --config FILE` against real parts: a receiver on a pty sending NMEA, an
//! IMU port that does not exist, a CAN interface that is not there, a real mosquitto and a
//! port where no broker listens. Each gets a line: ok with what was seen, or the reason and
//! the fix; the exit status is 0 only when every probe passed. A configuration error exits
//! 78 before any probe. (The drives' SDO read and the BMS probe run on vcan in the VM:
//! tests/vcan.rs.)

use crate::common;

use std::sync::Mutex;

use common::mqtt::{Mosquitto, free_port};
use common::pty::{Port, Talker};

/// The pty tests take turns so no child inherits another test's descriptors.
static SERIAL: Mutex<()> = Mutex::new(());

fn check(config: &str, dir: &std::path::Path) -> (Option<i32>, String) {
    common::check(config, dir, &[])
}

/// The table's line for `device`, and the line after it.
fn line_of<'a>(table: &'a str, device: &str) -> (&'a str, &'a str) {
    let lines: Vec<&str> = table.lines().collect();
    let i = lines
        .iter()
        .position(|l| l.starts_with(device))
        .unwrap_or_else(|| panic!("{device} in\n{table}"));
    (lines[i], lines.get(i + 1).copied().unwrap_or_default())
}

#[test]
fn every_device_gets_ok_or_the_reason_and_the_fix() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let dir = common::tempdir("check-devices");
    let link = dir.join("gnss-port");
    let _receiver = Talker::start(Port::open_at(&link));
    let broker = Mosquitto::start();
    let config = format!(
        "[gnss]\nport = \"{}\"\n\n[imu]\nport = \"{}\"\nprotocol = \"hipnuc\"\n\n\
         [[can]]\ninterface = \"chk9\"\n\n[mqtt]\nhost = \"127.0.0.1\"\nport = {}\n",
        link.display(),
        dir.join("no-imu-here").display(),
        broker.address().rsplit(':').next().expect("port"),
    );
    let (code, table) = check(&config, &dir);
    assert_eq!(code, Some(1), "one probe failed:\n{table}");
    let (gnss, _) = line_of(&table, "gnss");
    assert!(gnss.contains("ok:") && gnss.contains("GGA"), "{table}");
    let (imu, fix) = line_of(&table, "imu");
    assert!(imu.contains("FAILED: cannot open"), "{table}");
    assert!(
        fix.contains("fix:") && fix.contains("no device at"),
        "{table}"
    );
    let (can, fix) = line_of(&table, "chk9");
    assert!(can.contains("FAILED"), "{table}");
    assert!(fix.contains("ip link set chk9 up"), "{table}");
    let (mqtt, _) = line_of(&table, "mqtt");
    assert!(mqtt.contains("ok: accepts the connection"), "{table}");
    assert!(table.contains("2 of 4 probes ok"), "{table}");
}

#[test]
fn all_ok_exits_0_and_an_absent_broker_is_named() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let dir = common::tempdir("check-ok");
    let link = dir.join("gnss-port");
    let _receiver = Talker::start(Port::open_at(&link));
    let broker = Mosquitto::start();
    let port = broker
        .address()
        .rsplit(':')
        .next()
        .expect("port")
        .to_owned();
    let ok = format!(
        "[gnss]\nport = \"{}\"\n\n[mqtt]\nhost = \"127.0.0.1\"\nport = {port}\n",
        link.display()
    );
    let (code, table) = check(&ok, &dir);
    assert_eq!(code, Some(0), "{table}");
    assert!(table.contains("2 of 2 probes ok"), "{table}");
    let nobody = free_port();
    let absent = ok.replace(&format!("port = {port}"), &format!("port = {nobody}"));
    let (code, table) = check(&absent, &dir);
    assert_eq!(code, Some(1), "{table}");
    let (mqtt, fix) = line_of(&table, "mqtt");
    assert!(mqtt.contains("FAILED: cannot connect"), "{table}");
    assert!(fix.contains(&format!("127.0.0.1:{nobody}")), "{table}");
}

#[test]
fn a_configuration_error_is_reported_before_any_probe() {
    let dir = common::tempdir("check-config");
    let (code, out) = check("[gnss]\nbaud = 12345\nport = \"/dev/x\"\n", &dir);
    assert_eq!(code, Some(78), "{out}");
    assert!(out.contains("gnss.baud") && out.contains("fix:"), "{out}");
}

#[test]
fn the_ntrip_caster_is_probed_step_by_step() {
    use common::caster::{Behaviour, Caster};
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let dir = common::tempdir("check-ntrip");
    let link = dir.join("gnss-port");
    let _receiver = Talker::start(Port::open_at(&link));
    let frames = std::fs::read(common::shared_data("rtcm").join("rtklib-testglo.rtcm3"))
        .expect("the stream");
    let streaming = Caster::start(Behaviour::Stream {
        head: "ICY 200 OK\r\n\r\n".into(),
        body: frames,
        chunks: vec![500],
        every: std::time::Duration::from_millis(10),
        repeat: true,
    });
    let config = |url: &str| {
        format!(
            "[gnss]\nport = \"{}\"\n\n[ntrip]\nurl = \"{url}\"\n\
             fallback_position = {{ lat = 48.1, lon = 11.5, height = 520 }}\n",
            link.display()
        )
    };
    let (code, table) = check(&config(&streaming.url()), &dir);
    assert_eq!(code, Some(0), "{table}");
    assert!(table.contains("5 of 5 probes ok"), "{table}");
    for step in [
        "caster reachable",
        "mountpoint in the table",
        "credentials accepted",
        "frames arriving",
    ] {
        let line = table
            .lines()
            .find(|l| l.starts_with("ntrip") && l.contains(step))
            .unwrap_or_else(|| panic!("{step} in\n{table}"));
        assert!(line.contains("ok:"), "{table}");
    }
    assert!(table.contains("MOUNT (wants GGA)"), "{table}");
    assert!(
        !table.contains("s3cret"),
        "the password in the table:\n{table}"
    );
    // A caster that refuses the credentials: said with the fix, and the frames not probed.
    let refusing = Caster::start(Behaviour::Unauthorized);
    let (code, table) = check(&config(&refusing.url()), &dir);
    assert_eq!(code, Some(1), "{table}");
    let from_auth = table
        .lines()
        .skip_while(|l| !l.contains("credentials accepted"))
        .collect::<Vec<_>>()
        .join("\n");
    let (auth, fix) = line_of(&from_auth, "ntrip");
    assert!(auth.contains("FAILED") && auth.contains("401"), "{table}");
    assert!(fix.contains("password"), "{table}");
}

#[test]
fn zones_are_counted_and_a_file_with_latitude_and_longitude_swapped_is_doubted() {
    let dir = common::tempdir("check-zones");
    let square = |lon: f64, lat: f64| {
        format!(
            r#"{{"type": "FeatureCollection", "features": [{{"type": "Feature",
            "properties": {{"kind": "keep_out", "name": "pond"}},
            "geometry": {{"type": "Polygon", "coordinates": [[[{lon}, {lat}], [{}, {lat}],
            [{}, {}], [{lon}, {}], [{lon}, {lat}]]]}}}}]}}"#,
            lon + 0.0003,
            lon + 0.0003,
            lat + 0.0002,
            lat + 0.0002
        )
    };
    let config = "[gnss]\nport = \"/dev/chassisd-no-such-port\"\n\
                  [localization]\ndatum = [47.3977, 8.5456, 480.0]\n\
                  [zones]\nfile = \"zones.geojson\"\n\
                  footprint = { front_m = 0.5, rear_m = 0.3, width_m = 0.6 }\n";
    std::fs::write(dir.join("zones.geojson"), square(8.5455, 47.3975)).expect("zones");
    let (_, table) = check(config, &dir);
    let (zones, _) = line_of(&table, "zones");
    assert!(
        zones.contains("ok: boundaries: 0, keep-out zones: 1, walls: 0, within 27 m of the datum"),
        "{table}"
    );
    std::fs::write(dir.join("zones.geojson"), square(47.3975, 8.5455)).expect("zones");
    let (code, table) = check(config, &dir);
    assert_ne!(code, Some(0), "{table}");
    let (zones, fix) = line_of(&table, "zones");
    assert!(zones.contains("FAILED: a zone lies"), "{table}");
    assert!(fix.contains("[longitude, latitude]"), "{table}");
    // A zones file that is not one is a configuration error, before any probe.
    std::fs::write(dir.join("zones.geojson"), "{\"type\": \"Feature\"}").expect("zones");
    let (code, out) = check(config, &dir);
    assert_eq!(code, Some(78), "{out}");
    assert!(out.contains("zones.geojson"), "{out}");
}
