//! The `[mqtt]` section's checks, in both forms.
use super::*;
use std::path::Path;

/// The error of the default configuration changed by `edit`.
fn error_with(edit: impl FnOnce(&mut MqttConfig)) -> String {
    let mut m = MqttConfig::default();
    edit(&mut m);
    m.validate(Path::new("v.toml")).unwrap_err().to_string()
}

fn tls() -> TlsConfig {
    TlsConfig {
        ca_file: "ca.pem".into(),
        client_cert_file: None,
        client_key_file: None,
        cert_file: None,
        key_file: None,
    }
}

#[test]
fn each_check_names_its_key_and_the_problem() {
    assert!(MqttConfig::default().validate(Path::new("v.toml")).is_ok());
    for (e, expected) in [
        (
            error_with(|m| m.first_mut().host = " ".into()),
            "`mqtt.host`: is empty",
        ),
        (error_with(|m| m.first_mut().port = 0), "`mqtt.port`: is 0"),
        (
            error_with(|m| m.first_mut().password = Some("x".into())),
            "`mqtt.password`: is set without a username",
        ),
        (
            error_with(|m| m.first_mut().client_id = Some("x".repeat(129))),
            "`mqtt.client_id`: must be 1 to 128 characters",
        ),
        (
            error_with(|m| m.first_mut().reserved_client_ids = vec!["app".into(), "a/b".into()]),
            "`mqtt.reserved_client_ids`: \"a/b\" is not a client id a broker can route",
        ),
        (
            error_with(|m| m.first_mut().status_topic = Some("robots/#".into())),
            "`mqtt.status_topic`: must be a non-empty topic without wildcards",
        ),
        (
            error_with(|m| m.first_mut().keep_alive_s = Some(0.5)),
            "`mqtt.keep_alive_s`: 0.5 is outside 1..=600 s",
        ),
        (
            error_with(|m| m.first_mut().reconnect_max_s = Some(-1.0)),
            "`mqtt.reconnect_max_s`: -1 is outside 0.1..=600 s",
        ),
        (
            error_with(|m| m.first_mut().keep_alive_s = Some(f64::NAN)),
            "`mqtt.keep_alive_s`: NaN is outside 1..=600 s",
        ),
        (
            error_with(|m| m.first_mut().command_qos = 2),
            "`mqtt.command_qos`: 2 is not 0 or 1",
        ),
        (
            error_with(|m| m.first_mut().command_rate_hz = 0.0),
            "`mqtt.command_rate_hz`: 0 is outside 0.1..=100000 per s",
        ),
        (
            error_with(|m| m.first_mut().reply_queue = 0),
            "`mqtt.reply_queue`: 0 is outside 1..=100000",
        ),
        (
            error_with(|m| {
                m.root = Some(RootDialectConfig {
                    vehicle_id: "robot1".into(),
                    heartbeat_timeout_s: 3.0,
                    require_heartbeat: false,
                    heartbeat_client_id: Some(String::new()),
                })
            }),
            "`mqtt.root.heartbeat_client_id`: is empty",
        ),
        (
            error_with(|m| {
                m.root = Some(RootDialectConfig {
                    vehicle_id: "robot/1".into(),
                    heartbeat_timeout_s: 3.0,
                    require_heartbeat: false,
                    heartbeat_client_id: None,
                })
            }),
            "`mqtt.root.vehicle_id`: must be one non-empty topic level",
        ),
        (
            error_with(|m| {
                m.device = Some(DeviceDialectConfig {
                    serial_number: "SN1".into(),
                    mapping_forward: Some("nav/+".into()),
                })
            }),
            "`mqtt.device.mapping_forward`: must be a non-empty topic prefix",
        ),
        (
            error_with(|m| {
                m.first_mut().tls = Some(TlsConfig {
                    client_cert_file: Some("client.pem".into()),
                    ..tls()
                })
            }),
            "`mqtt.tls.client_key_file`: a client certificate needs its key",
        ),
        (
            error_with(|m| {
                m.first_mut().tls = Some(TlsConfig {
                    key_file: Some("broker.key".into()),
                    ..tls()
                })
            }),
            "`mqtt.tls.cert_file`: is the embedded broker's certificate",
        ),
        (
            error_with(|m| {
                m.first_mut().embedded_broker = true;
                m.first_mut().embedded_max_clients = 0;
            }),
            "`mqtt.embedded_max_clients`: 0 is outside 1..=1024",
        ),
    ] {
        assert!(e.contains(expected), "{expected}: {e}");
    }
}

#[test]
fn the_first_part_in_error_is_reported() {
    // Each link's address, identity, status topic, limits, TLS and embedded broker; then
    // the dialects.
    let e = error_with(|m| {
        m.first_mut().port = 0;
        m.first_mut().client_id = Some(String::new());
    });
    assert!(e.contains("`mqtt.port`"), "{e}");
    let e = error_with(|m| {
        m.first_mut().status_topic = Some(String::new());
        m.first_mut().max_payload = 0;
    });
    assert!(e.contains("`mqtt.status_topic`"), "{e}");
    let e = error_with(|m| {
        m.first_mut().max_payload = 0;
        m.device = Some(DeviceDialectConfig {
            serial_number: String::new(),
            mapping_forward: None,
        });
    });
    assert!(e.contains("`mqtt.max_payload`"), "{e}");
    let e = error_with(|m| {
        m.device = Some(DeviceDialectConfig {
            serial_number: String::new(),
            mapping_forward: None,
        });
        m.first_mut().tls = Some(TlsConfig {
            client_key_file: Some("client.key".into()),
            ..tls()
        });
    });
    assert!(e.contains("`mqtt.tls.client_key_file`"), "{e}");
}

/// The section parsed from `text` under `[mqtt]`, then checked.
fn parsed(text: &str) -> Result<MqttConfig, String> {
    #[derive(serde::Deserialize)]
    struct File {
        mqtt: MqttConfig,
    }
    let file: File = toml::from_str(text).map_err(|e| e.to_string())?;
    file.mqtt
        .validate(Path::new("v.toml"))
        .map_err(|e| e.to_string())?;
    Ok(file.mqtt)
}

/// The typical vehicle: `rtk` on its embedded broker for the site's app, `root` and `device`
/// on the platform's broker over TLS.
const TWO_LINKS: &str = r#"
[[mqtt.link]]
name = "site"
embedded_broker = true
dialects = ["rtk"]

[[mqtt.link]]
name = "platform"
platform = true
host = "mqtt.fleet.example.com"
port = 8883
failover = ["node2.fleet.example.com:8883", "[2001:db8::2]:8883"]
command_qos = 0
username = "robot1"
password = "secret"
dialects = ["root", "device"]
[mqtt.link.tls]
ca_file = "fleet-ca.pem"

[mqtt.rtk]
[mqtt.root]
vehicle_id = "robot1"
[mqtt.device]
serial_number = "SN1"
"#;

#[test]
fn the_fleet_form_spreads_the_dialects_over_its_links() {
    let m = parsed(TWO_LINKS).expect("valid");
    assert!(m.listed);
    let [site, platform] = &m.links[..] else {
        panic!("two links: {:?}", m.links)
    };
    assert_eq!(m.dialects_of(site), [DialectName::Rtk]);
    assert_eq!(
        m.dialects_of(platform),
        [DialectName::Root, DialectName::Device]
    );
    assert_eq!(
        m.link_of(DialectName::Device).map(|l| &l.name[..]),
        Some("platform")
    );
    assert_eq!(m.embedded().map(|l| &l.name[..]), Some("site"));
    assert_eq!(
        platform
            .brokers()
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>(),
        [
            "mqtt.fleet.example.com:8883",
            "node2.fleet.example.com:8883",
            "[2001:db8::2]:8883"
        ]
    );
    // The platform's last will lies under the vehicle's own prefix; the site's does not
    // need to.
    assert_eq!(
        platform.status_topic("mower"),
        "/root/robot1/chassisd/status"
    );
    assert_eq!(site.status_topic("mower"), "chassisd/mower/status");
    assert_eq!(m.prefixes(platform), ["/root/robot1", "device/SN1"]);
    assert_eq!((site.command_qos, platform.command_qos), (1, 0));
}

#[test]
fn the_one_link_form_is_one_link_carrying_every_dialect() {
    let m = parsed("[mqtt]\nhost = \"10.0.0.2\"\n[mqtt.root]\nvehicle_id = \"r1\"\n[mqtt.rtk]\n")
        .expect("valid");
    assert!(!m.listed);
    assert_eq!(m.links.len(), 1);
    assert_eq!(m.links[0].name, "mqtt");
    assert_eq!(m.links[0].host, "10.0.0.2");
    assert_eq!(
        m.dialects_of(&m.links[0]),
        [DialectName::Rtk, DialectName::Root]
    );
}

#[test]
fn both_forms_are_written_back_as_they_were_read() {
    for text in [
        TWO_LINKS,
        "[mqtt]\nhost = \"10.0.0.2\"\nkeep_alive_s = 9.0\n[mqtt.root]\nvehicle_id = \"r1\"\n",
    ] {
        let m = parsed(text).expect("valid");
        #[derive(serde::Serialize)]
        struct File<'a> {
            mqtt: &'a MqttConfig,
        }
        let written = toml::to_string(&File { mqtt: &m }).expect("serialises");
        assert_eq!(parsed(&written).as_ref(), Ok(&m), "{written}");
    }
}

#[test]
fn fleet_form_mistakes_are_named() {
    let with = |from: &str, to: &str| {
        assert!(TWO_LINKS.contains(from), "{from}");
        parsed(&TWO_LINKS.replacen(from, to, 1)).unwrap_err()
    };
    for (e, expected) in [
        (
            with("name = \"platform\"", "name = \"site\""),
            "`mqtt.link[1].name`: \"site\" names another link too",
        ),
        (
            with("name = \"platform\"", "name = \"Platform 1\""),
            "`mqtt.link[1].name`: \"Platform 1\" is not 1 to 32 lowercase",
        ),
        (
            with("dialects = [\"rtk\"]", "dialects = [\"rtk\", \"root\"]"),
            "`mqtt.link[1].dialects`: names \"root\", which another link carries",
        ),
        (
            with("dialects = [\"root\", \"device\"]", "dialects = [\"root\"]"),
            "`mqtt.device`: is configured, and no link carries it",
        ),
        (
            with("[mqtt.rtk]\n", ""),
            "`mqtt.link[0].dialects`: names \"rtk\", and [mqtt.rtk] is not configured",
        ),
        (
            with(
                "dialects = [\"root\", \"device\"]",
                "dialects = [\"root\", \"device\", \"rtk\"]",
            ),
            "names \"rtk\", which another link carries",
        ),
        (
            with("failover = [", "failover = [\"node3\", "),
            "`mqtt.link[1].failover`: \"node3\" has no port",
        ),
        (
            with(
                "[[mqtt.link]]\nname = \"site\"",
                "[mqtt]\nhost = \"10.0.0.1\"\n[[mqtt.link]]\nname = \"site\"",
            ),
            "mqtt.host is a link's key, and [[mqtt.link]] lists the links",
        ),
        (
            with("port = 8883\n", "port = 8883\nembedded_broker = true\n"),
            "`mqtt.link[1].failover`: is set on the link of the embedded broker",
        ),
    ] {
        assert!(e.contains(expected), "{expected}: {e}");
    }
    // Two links with the same client id would take each other's sessions.
    let twin = TWO_LINKS
        .replacen(
            "dialects = [\"rtk\"]",
            "dialects = [\"rtk\"]\nclient_id = \"car\"",
            1,
        )
        .replacen(
            "password = \"secret\"",
            "password = \"secret\"\nclient_id = \"car\"",
            1,
        );
    let e = parsed(&twin).unwrap_err();
    assert!(
        e.contains("`mqtt.link[1].client_id`: is another link's client id too"),
        "{e}"
    );
}

#[test]
fn a_platform_link_keeps_to_the_vehicles_own_topics() {
    let with = |from: &str, to: &str| {
        assert!(TWO_LINKS.contains(from), "{from}");
        parsed(&TWO_LINKS.replacen(from, to, 1)).unwrap_err()
    };
    for (e, expected) in [
        (
            with(
                "password = \"secret\"",
                "password = \"secret\"\nstatus_topic = \"fleet/online\"",
            ),
            "`mqtt.link[1].status_topic`: \"fleet/online\" lies outside the vehicle's topics",
        ),
        (
            with(
                "serial_number = \"SN1\"",
                "serial_number = \"SN1\"\nmapping_forward = \"nav/SN1\"",
            ),
            "`mqtt.device.mapping_forward`: \"nav/SN1\" lies outside the vehicle's topics",
        ),
    ] {
        assert!(e.contains(expected), "{expected}: {e}");
    }
    // rtk on a platform link: bare topics, refused.
    let e = parsed(
        "[[mqtt.link]]\nname = \"site\"\ndialects = [\"root\"]\n\
         [[mqtt.link]]\nname = \"platform\"\nplatform = true\ndialects = [\"rtk\"]\n\
         [mqtt.rtk]\n[mqtt.root]\nvehicle_id = \"robot1\"\n",
    )
    .unwrap_err();
    assert!(
        e.contains("`mqtt.link[1].dialects`: carries \"rtk\" on a platform link"),
        "{e}"
    );
    // A status topic under the device's prefix is fine; so is a forward under it.
    let fine = TWO_LINKS
        .replacen(
            "password = \"secret\"",
            "password = \"secret\"\nstatus_topic = \"device/SN1/online\"",
            1,
        )
        .replacen(
            "serial_number = \"SN1\"",
            "serial_number = \"SN1\"\nmapping_forward = \"device/SN1/nav\"",
            1,
        );
    parsed(&fine).expect("confined");
}
