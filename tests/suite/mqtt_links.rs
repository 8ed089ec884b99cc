//! Several MQTT links at once, on real mosquitto brokers with real clients: the site's
//! broker carries `rtk`, the platform's `root` and `device`. Each command is answered on the
//! broker it came from; a platform link publishes nothing outside the vehicle's own topics,
//! and the ACL docs/fleet.md gives confines it (a broker that denies it is noticed and
//! logged); one link down holds up neither the other nor the vehicle; a platform link fails
//! over to the next broker of its list.

use crate::common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::mqtt::{Mosquitto, Subscriber, TestPki};
use common::process::Proc;

const WAIT: Duration = Duration::from_secs(15);
/// The vehicle's id and serial number on the platform (docs/fleet.md's example's).
const VEHICLE_ID: &str = "robot1";
const SERIAL: &str = "SN1";

/// A vehicle with no devices but its links: `rtk` on the site's broker at `site_port`, `root`
/// and `device` on the platform's at `platform_port`, with `platform_extra` in that link.
fn two_links(dir: &Path, site_port: u16, platform_port: u16, platform_extra: &str) -> PathBuf {
    let path = dir.join("vehicle.toml");
    let text = format!(
        "[vehicle]\nname = \"fleet1\"\n\n[gnss]\nport = \"{}\"\n\n\
         [[mqtt.link]]\nname = \"site\"\nport = {site_port}\ndialects = [\"rtk\"]\n\
         reconnect_max_s = 0.5\n\n\
         [[mqtt.link]]\nname = \"platform\"\nplatform = true\nport = {platform_port}\n\
         dialects = [\"root\", \"device\"]\nreconnect_min_s = 0.1\nreconnect_max_s = 0.5\n\
         {platform_extra}\n\n\
         [mqtt.rtk]\n[mqtt.root]\nvehicle_id = \"{VEHICLE_ID}\"\n\
         [mqtt.device]\nserial_number = \"{SERIAL}\"\n",
        dir.join("no-such-receiver").display(),
    );
    std::fs::write(&path, text).expect("config written");
    path
}

/// `chassisd run` on `config`, once both links have subscribed.
fn run(config: &Path) -> Proc {
    let mut p = Proc::start(&["run".as_ref(), "--config".as_ref(), config.as_os_str()]);
    wait_count(&mut p, "MQTT subscribed", 2);
    p
}

/// Waits until the daemon's log holds `text` at least `n` times.
fn wait_count(p: &mut Proc, text: &str, n: usize) {
    let deadline = Instant::now() + WAIT;
    while p.log_count(text) < n {
        assert!(Instant::now() < deadline, "{text:?} not seen {n} times");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Every (topic, payload) `sub` receives in `span`.
fn gather(sub: &Subscriber, span: Duration) -> Vec<(String, String)> {
    let end = Instant::now() + span;
    let mut all = Vec::new();
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        if let Some(m) = sub.next(left) {
            all.push(m);
        }
    }
    all
}

/// Whether `topic` lies under one of the vehicle's platform prefixes.
fn confined(topic: &str) -> bool {
    [format!("/root/{VEHICLE_ID}/"), format!("device/{SERIAL}/")]
        .iter()
        .any(|p| topic.starts_with(p.as_str()))
}

#[test]
fn each_command_is_answered_on_the_broker_it_came_from() {
    let dir = common::tempdir("links-answers");
    let site = Mosquitto::start();
    let platform = Mosquitto::start();
    let on_site = site.subscribe(&["#"]);
    let on_platform = platform.subscribe(&["#"]);
    let config = two_links(&dir, site.port, platform.port, "");
    let recording = dir.join("recording");
    let mut daemon = Proc::start(&[
        "run".as_ref(),
        "--config".as_ref(),
        config.as_os_str(),
        "--record".as_ref(),
        recording.as_os_str(),
    ]);
    wait_count(&mut daemon, "MQTT subscribed", 2);

    // rtk's request on the site's broker: answered there, never on the platform's.
    site.publish(
        "mqtt_control",
        r#"{"cmd_type": "task_control", "cmd": "no_such"}"#,
    );
    // root's and device's requests on the platform's broker: answered there.
    platform.publish(
        &format!("/root/{VEHICLE_ID}/heartbeat/set"),
        r#"{"messageId": 1, "clientId": "op"}"#,
    );
    platform.publish(&format!("device/{SERIAL}/goal"), "{not json");
    let site_seen = gather(&on_site, Duration::from_secs(3));
    let platform_seen = gather(&on_platform, Duration::from_secs(1));

    let topics = |seen: &[(String, String)]| {
        let mut t: Vec<String> = seen.iter().map(|(t, _)| t.clone()).collect();
        t.sort();
        t.dedup();
        t
    };
    let (site_topics, platform_topics) = (topics(&site_seen), topics(&platform_seen));
    assert!(site_topics.contains(&"feedback".into()), "{site_topics:?}");
    assert!(
        site_topics.contains(&"base_status".into()),
        "{site_topics:?}"
    );
    assert!(
        site_topics.iter().all(|t| !confined(t)),
        "the platform's dialects reached the site's broker: {site_topics:?}"
    );
    for answer in [
        format!("/root/{VEHICLE_ID}/heartbeat/notify"),
        format!("device/{SERIAL}/goal/ack"),
    ] {
        assert!(
            platform_topics.contains(&answer),
            "{answer}: {platform_topics:?}"
        );
    }
    // Nothing on the platform's broker lies outside the vehicle's own topics: not the
    // answers, not the reports, not chassisd's retained online status.
    let outside: Vec<&String> = platform_topics.iter().filter(|t| !confined(t)).collect();
    assert!(
        outside.is_empty(),
        "outside the vehicle's topics: {outside:?}"
    );
    let online = platform.subscribe(&[&format!("/root/{VEHICLE_ID}/chassisd/status")]);
    assert_eq!(
        online.next(WAIT).map(|(_, p)| p).as_deref(),
        Some("online"),
        "the platform link's retained status"
    );
    // Each link's commands are recorded under its own source; the log names the link.
    assert!(daemon.log_count("link=\"platform\"") + daemon.log_count("link=platform") > 0);
    daemon.stop();
    // The recording holds each link's commands as its own source, and replays them.
    let replayed = common::replay(&recording);
    let summary = String::from_utf8_lossy(&replayed.stderr);
    assert!(
        summary.contains("mqtt-platform 3") && summary.contains("mqtt-site 2"),
        "{summary}"
    );
    assert!(summary.contains("3 commands (2 refused)"), "{summary}");

    // `check` shows each link with its broker.
    let out = std::process::Command::new(common::chassisd())
        .args(["check", "--config"])
        .arg(&config)
        .output()
        .expect("check runs");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    for (link, port) in [("mqtt-site", site.port), ("mqtt-platform", platform.port)] {
        let row = text
            .lines()
            .find(|l| l.contains(link))
            .unwrap_or_else(|| panic!("no {link} in check:\n{text}"));
        assert!(row.contains(&format!("127.0.0.1:{port}")), "{row}");
        assert!(row.contains("accepts the connection"), "{row}");
    }
}

#[test]
fn one_link_down_holds_up_neither_the_other_nor_the_vehicle() {
    let dir = common::tempdir("links-apart");
    let site = Mosquitto::start();
    let mut platform = Mosquitto::start();
    let mut daemon = run(&two_links(&dir, site.port, platform.port, ""));
    let status = site.subscribe(&["base_status"]);
    status.next_on("base_status", WAIT).expect("base_status");
    platform.kill();
    // The site's base_status keeps its 10 Hz while the platform's broker is gone and the
    // platform link retries.
    let mut last = Instant::now();
    let mut longest = Duration::ZERO;
    let mut count = 0;
    let end = Instant::now() + Duration::from_secs(3);
    while Instant::now() < end {
        status
            .next_on("base_status", WAIT)
            .expect("base_status goes on");
        longest = longest.max(last.elapsed());
        last = Instant::now();
        count += 1;
    }
    assert!(count >= 25, "{count} base_status in 3 s");
    assert!(longest < Duration::from_millis(400), "a gap of {longest:?}");
    wait_count(&mut daemon, "MQTT connection lost", 1);
    // The platform's broker returns: the link connects and is online again.
    platform.restart();
    wait_count(&mut daemon, "MQTT subscribed", 3);
    let online = platform.subscribe(&[&format!("/root/{VEHICLE_ID}/chassisd/status")]);
    assert_eq!(online.next(WAIT).map(|(_, p)| p).as_deref(), Some("online"));
}

#[test]
fn a_platform_link_fails_over_to_the_next_broker() {
    let dir = common::tempdir("links-failover");
    let site = Mosquitto::start();
    let mut first = Mosquitto::start();
    let second = Mosquitto::start();
    let extra = format!("failover = [\"localhost:{}\"]", second.port);
    let mut daemon = run(&two_links(&dir, site.port, first.port, &extra));
    first.kill();
    // The next broker of the list, named (and resolved again) at each attempt.
    let acks = second.subscribe(&[&format!("/root/{VEHICLE_ID}/heartbeat/notify")]);
    wait_count(&mut daemon, "MQTT subscribed", 3);
    second.publish(
        &format!("/root/{VEHICLE_ID}/heartbeat/set"),
        r#"{"messageId": 2, "clientId": "op"}"#,
    );
    acks.next(WAIT).expect("answered on the failover broker");
    let log = daemon.stop_log().join("\n");
    assert!(
        log.contains(&format!("localhost:{}", second.port)),
        "the log names the broker it failed over to"
    );
}

/// The mosquitto ACL of docs/fleet.md, as the page gives it.
fn documented_acl() -> String {
    let page = std::fs::read_to_string(common::repo().join("docs/fleet.md")).expect("fleet.md");
    let start = page
        .find("# mosquitto acl_file")
        .expect("the page's mosquitto ACL");
    let block = &page[start..];
    block[..block.find("```").expect("the block's end")].to_owned()
}

#[test]
fn the_documented_acl_confines_the_vehicle_and_a_refusal_is_logged_and_safe() {
    let dir = common::tempdir("links-acl");
    let site = Mosquitto::start();
    let acl = documented_acl();
    let platform = Mosquitto::start_with_acl(
        &dir,
        &[("operator", "op-secret"), (VEHICLE_ID, "robot-secret")],
        &acl,
    );
    let extra = format!("username = \"{VEHICLE_ID}\"\npassword = \"robot-secret\"");
    let mut daemon = run(&two_links(&dir, site.port, platform.port, &extra));
    // The operator reaches the vehicle through the broker, and the answer comes back.
    let acks = platform.subscribe(&[&format!("/root/{VEHICLE_ID}/heartbeat/notify")]);
    platform.publish(
        &format!("/root/{VEHICLE_ID}/heartbeat/set"),
        r#"{"messageId": 3, "clientId": "op"}"#,
    );
    acks.next(WAIT).expect("answered through the ACL");
    // The broker delivers the link's own status back: no complaint once its wait is over.
    std::thread::sleep(Duration::from_secs(6));
    assert_eq!(daemon.log_count("refused subscriptions"), 0);
    assert_eq!(daemon.log_count("did not deliver the link's own"), 0);
    daemon.stop();

    // The same vehicle under another vehicle's id: the broker drops everything it publishes
    // and delivers nothing (mosquitto grants the subscriptions and filters silently).
    // chassisd notices its own status never comes back and says so; the site's link and the
    // vehicle go on.
    let other = dir.join("other");
    std::fs::create_dir_all(&other).expect("dir");
    let text = std::fs::read_to_string(two_links(&other, site.port, platform.port, &extra))
        .expect("config")
        .replace("vehicle_id = \"robot1\"", "vehicle_id = \"robot2\"")
        .replace("serial_number = \"SN1\"", "serial_number = \"SN2\"");
    let config = other.join("vehicle.toml");
    std::fs::write(&config, text).expect("config");
    let mut refused = Proc::start(&["run".as_ref(), "--config".as_ref(), config.as_os_str()]);
    refused.wait_log(WAIT, "did not deliver the link's own `online` back");
    let status = site.subscribe(&["base_status"]);
    status
        .next_on("base_status", WAIT)
        .expect("the site's link goes on");
}

#[test]
fn a_platform_link_over_tls_with_a_client_certificate_works_beside_the_site_link() {
    // The platform's broker wants TLS and a client certificate, takes its common name as the
    // user name, and confines it with the documented ACL; the site's broker is plain.
    let dir = common::tempdir("links-client-cert");
    let pki = TestPki::create(&dir, "platform");
    let platform =
        Mosquitto::start_with_client_certificates(&dir, &pki, &documented_acl(), "operator");
    let site = Mosquitto::start();
    let (cert, key) = pki.client(VEHICLE_ID);
    let tls = format!(
        "[mqtt.link.tls]\nca_file = \"{}\"\nclient_cert_file = \"{}\"\nclient_key_file = \"{}\"",
        pki.ca.display(),
        cert.display(),
        key.display()
    );
    let mut daemon = run(&two_links(&dir, site.port, platform.port, &tls));

    // A platform command is answered on the platform, a site command on the site.
    let acks = platform.subscribe(&[&format!("/root/{VEHICLE_ID}/heartbeat/notify")]);
    platform.publish(
        &format!("/root/{VEHICLE_ID}/heartbeat/set"),
        r#"{"messageId": 4, "clientId": "op"}"#,
    );
    acks.next(WAIT).expect("answered over TLS, through the ACL");
    let feedback = site.subscribe(&["feedback"]);
    site.publish(
        "mqtt_control",
        r#"{"cmd": "cancel_task", "cmd_type": "task_control"}"#,
    );
    feedback
        .next_on("feedback", WAIT)
        .expect("the site's link answers beside it");
    // The broker delivers the link's own status back: its ACL lets the certificate's user in.
    std::thread::sleep(Duration::from_secs(6));
    assert_eq!(daemon.log_count("did not deliver the link's own"), 0);
    assert_eq!(daemon.log_count("MQTT connect failed"), 0);
    daemon.stop();
}
