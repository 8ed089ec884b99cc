//! `chassisd check --config FILE`: after the configuration has loaded (every key checked),
//! each device is probed once and the results are printed as a table: ok with what was
//! seen, or the reason and the fix. The probes only listen, except the drives' SDO read,
//! the Daly BMS's poll and the broker's connection.
//!
//! - A serial port opens and valid NMEA sentences or UBX frames (GNSS) or frames (IMU) arrive.
//! - A u-blox receiver (`gnss.receiver = "ublox"`) answers MON-VER with its firmware and
//!   protocol; with `--configure`, takes CFG-VALSET of the messages chassisd reads and reads
//!   them back (RAM only, unless flash is asked for).
//! - A CAN interface exists and is up.
//! - Each drive answers an SDO read of its device type (0x1000).
//! - The BMS answers its poll (Daly) or its messages arrive (DBC).
//! - The broker accepts a connection.
//! - The NTRIP caster answers, lists the mountpoint, accepts the credentials, and sends
//!   valid RTCM 3 frames.

use std::fmt::Write as _;
use std::time::{Duration, Instant};

use tokio::io::AsyncReadExt;
use tokio_serial::SerialPortBuilderExt;

use std::net::ToSocketAddrs;

use crate::config::mqtt::{BrokerAddress, MqttLinkConfig};
use crate::config::zones::ZonesConfig;
use crate::config::{GnssConfig, ReceiverKind, VehicleConfig};
use crate::devices::can::Received;
use crate::devices::canopen::sdo::{SdoRequest, SdoResponse, decode_response};
use crate::devices::canopen::{DEVICE_TYPE, NodeId};
use crate::devices::gnss::GnssReceiver;
use crate::devices::gnss::encode::GgaFix;
use crate::devices::gnss::ubx::config::Layers;
use crate::devices::imu::ImuDecoder;
use crate::geodesy::{Enu, Geodetic};
use crate::runtime::drivers::serial_open;
use crate::runtime::drivers::ublox::{Dialogue, port_name};
use crate::runtime::links::broker::BrokerHealth;
use crate::time::Timestamp;
use crate::zones::ZoneKind;

/// How long a serial port is listened to.
const SERIAL_LISTEN: Duration = Duration::from_secs(3);
/// How long a drive may take to answer its SDO read, per attempt ...
const SDO_WAIT: Duration = Duration::from_millis(300);
/// ... and how many attempts it gets.
const SDO_ATTEMPTS: u32 = 3;
/// How long the BMS may take.
const BMS_WAIT: Duration = Duration::from_secs(3);
/// How long the broker may take to accept.
const BROKER_WAIT: Duration = Duration::from_secs(5);

/// One probe's result.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// The device, as the configuration names it.
    pub device: String,
    /// What was probed.
    pub what: String,
    /// `Ok(what was seen)` or `Err((reason, fix))`.
    pub result: Result<String, (String, String)>,
}

impl Probe {
    fn new(device: &str, what: &str, result: Result<String, (String, String)>) -> Self {
        Self {
            device: device.to_owned(),
            what: what.to_owned(),
            result,
        }
    }
}

/// The results as a table, one probe per line and the fix under a failure.
pub fn table(probes: &[Probe]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "{:<14} {:<28} result", "device", "probe");
    for p in probes {
        match &p.result {
            Ok(seen) => {
                let _ = writeln!(out, "{:<14} {:<28} ok: {seen}", p.device, p.what);
            }
            Err((reason, fix)) => {
                let _ = writeln!(out, "{:<14} {:<28} FAILED: {reason}", p.device, p.what);
                let _ = writeln!(out, "{:<14} {:<28} fix: {fix}", "", "");
            }
        }
    }
    let failed = probes.iter().filter(|p| p.result.is_err()).count();
    let _ = writeln!(
        out,
        "{} of {} probes ok",
        probes.len() - failed,
        probes.len()
    );
    out
}

fn fail(reason: impl Into<String>, fix: impl Into<String>) -> Result<String, (String, String)> {
    Err((reason.into(), fix.into()))
}

/// Runs every probe the configuration calls for; `configure` sets a u-blox receiver's
/// messages in those layers.
pub async fn run(config: &VehicleConfig, configure: Option<Layers>) -> Vec<Probe> {
    let mut probes = Vec::new();
    if let Some(g) = &config.gnss {
        let listener = Listener::Gnss {
            receiver: Box::default(),
            // A Unicore UM98x is there for its two antennas' heading.
            expect_heading: g.receiver == ReceiverKind::Unicore,
        };
        let result = probe_serial(&g.port, g.baud, listener).await;
        probes.push(Probe::new(
            "gnss",
            &format!("NMEA/UBX on {}", g.port),
            result,
        ));
        if g.receiver == ReceiverKind::Ublox {
            probes.extend(probe_ublox(g, configure).await);
        }
    }
    if let Some(i) = &config.imu {
        let decoder = crate::engine::imu_decoder(i.protocol);
        let result = probe_serial(&i.port, i.baud, Listener::Imu(decoder)).await;
        let what = format!("{} on {}", i.protocol.name(), i.port);
        probes.push(Probe::new("imu", &what, result));
    }
    for bus in &config.can {
        let name = bus.interface.as_str();
        let socket = match crate::runtime::drivers::can::open(name) {
            Ok(s) => s,
            Err(e) => {
                probes.push(Probe::new(name, "interface up", fail(e, can_fix(name))));
                // What sits on it cannot be reached: said, not left out.
                for drive in config.drive.iter().filter(|d| d.bus == name) {
                    let what = format!("SDO read, node {}", drive.node);
                    let result = fail(
                        format!("not probed: {name} is not up"),
                        format!("bring {name} up first"),
                    );
                    probes.push(Probe::new(&drive.name, &what, result));
                }
                if config.bms.as_ref().is_some_and(|b| b.bus == name) {
                    let result = fail(
                        format!("not probed: {name} is not up"),
                        format!("bring {name} up first"),
                    );
                    probes.push(Probe::new("bms", &format!("answers on {name}"), result));
                }
                continue;
            }
        };
        probes.push(Probe::new(name, "interface up", Ok("up".into())));
        for drive in config.drive.iter().filter(|d| d.bus == name) {
            let what = format!("SDO read, node {}", drive.node);
            let result = if bus.listen_only {
                Ok("not probed: the interface is listen-only".into())
            } else {
                probe_sdo(&socket, drive.node).await
            };
            probes.push(Probe::new(&drive.name, &what, result));
        }
        if let Some(bms) = config.bms.as_ref().filter(|b| b.bus == name) {
            let result = probe_bms(&socket, bms, bus.listen_only).await;
            probes.push(Probe::new("bms", &format!("answers on {name}"), result));
        }
    }
    if let Some(n) = &config.ntrip {
        match n.spec() {
            Ok(spec) => {
                let fallback = n
                    .fallback_position
                    .map(|p| GgaFix::fallback(p.lat, p.lon, p.height));
                let caster = spec.url.to_string();
                for (what, result) in crate::runtime::links::ntrip::probe(&spec, fallback).await {
                    probes.push(Probe::new("ntrip", &format!("{what} ({caster})"), result));
                }
            }
            Err(e) => probes.push(Probe::new(
                "ntrip",
                "settings",
                fail(
                    e,
                    "check the [ntrip] key the message names (ntrip.password_file, \
                     ntrip.ca_file as PEM, or the system's CA roots: install ca-certificates)",
                ),
            )),
        }
    }
    if let Some(z) = &config.zones {
        let what = z
            .file
            .as_ref()
            .map_or("inline".into(), |f| f.display().to_string());
        probes.push(Probe::new("zones", &what, probe_zones(config, z)));
    }
    // Each link, and on each link each broker it may fail over to.
    for link in config.mqtt.iter().flat_map(|m| &m.links) {
        for broker in link.brokers() {
            let what = format!("broker {broker}");
            let result = if link.embedded_broker {
                probe_embedded_broker(config, link).await
            } else {
                probe_broker(config, link, &broker, None).await
            };
            probes.push(Probe::new(&link.source(), &what, result));
        }
    }
    #[cfg(feature = "ros2")]
    if let Some(r) = &config.ros2 {
        let what = format!("node {}/{}", r.namespace, r.node_name);
        probes.push(Probe::new("ros2", &what, probe_ros2(r)));
    }
    probes
}

/// Where the ROS 2 node would join: its domain and the addresses DDS would use.
#[cfg(feature = "ros2")]
fn probe_ros2(r: &crate::config::ros2::Ros2Config) -> Result<String, (String, String)> {
    let file = std::path::Path::new("[ros2]");
    match crate::runtime::links::ros2::interface::resolve(r, file) {
        Ok(joining) => {
            let domain = joining.domain;
            let on = joining.networks.map_or("every interface".to_owned(), |n| {
                n.iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            });
            let commands = if r.accept_commands {
                "takes commands"
            } else {
                "publishes only"
            };
            let middleware = match joining.middleware {
                crate::config::ros2::Middleware::Fastdds => "Fast DDS",
                crate::config::ros2::Middleware::Cyclonedds => "Cyclone DDS",
            };
            Ok(format!(
                "domain {domain} on {on}; {commands}; the action framed as {middleware}'s"
            ))
        }
        Err(crate::config::ConfigError::Invalid { problem, fix, .. }) => fail(problem, fix),
        Err(other) => fail(other.to_string(), "check [ros2]"),
    }
}

/// The zones' kinds (they were checked on load), and whether they lie near the datum: a
/// file with latitude and longitude swapped lies thousands of kilometres away.
fn probe_zones(config: &VehicleConfig, zones: &ZonesConfig) -> Result<String, (String, String)> {
    let count = |kind: ZoneKind| zones.set.zones().iter().filter(|z| z.kind == kind).count();
    let seen = format!(
        "boundaries: {}, keep-out zones: {}, walls: {}",
        count(ZoneKind::Boundary),
        count(ZoneKind::KeepOut),
        count(ZoneKind::Wall)
    );
    let Some([lat_deg, lon_deg, h_m]) = config.localization.as_ref().and_then(|l| l.datum) else {
        return Ok(format!(
            "{seen} (no localization.datum configured: placed where the first valid fix, of \
             any quality, becomes the origin)"
        ));
    };
    let frame = Enu::new(Geodetic {
        lat_deg,
        lon_deg,
        h_m,
    });
    let farthest = zones
        .set
        .positions()
        .map(|[lon_deg, lat_deg]| {
            let p = frame.to_enu(&Geodetic {
                lat_deg,
                lon_deg,
                h_m,
            });
            p.x.hypot(p.y)
        })
        .fold(0.0, f64::max);
    if farthest > MAX_ZONE_REACH_M {
        return fail(
            format!("a zone lies {:.0} km from the datum", farthest / 1000.0),
            "positions are [longitude, latitude] (RFC 7946): check the order, and the datum",
        );
    }
    Ok(format!("{seen}, within {farthest:.0} m of the datum"))
}

/// How far from the datum a zone may lie before `check` doubts the file, m.
const MAX_ZONE_REACH_M: f64 = 50_000.0;

/// What listens on a serial port.
enum Listener {
    Gnss {
        receiver: Box<GnssReceiver>,
        /// No dual-antenna heading is a failure.
        expect_heading: bool,
    },
    Imu(ImuDecoder),
}

/// A broker's refusal of the connection in words, and what to do about it.
fn connack_words(code: rumqttc::ConnectReturnCode) -> (&'static str, &'static str) {
    use rumqttc::ConnectReturnCode as C;
    match code {
        C::BadUserNamePassword | C::NotAuthorized => (
            "user name or password not accepted",
            "check mqtt.username and mqtt.password against the broker's users",
        ),
        C::ServiceUnavailable => (
            "the broker is unavailable or full",
            "the embedded broker takes mqtt.embedded_max_clients at once: close a client or \
             raise it; another broker: see its log",
        ),
        C::BadClientId => (
            "client id refused",
            "check mqtt.client_id (the broker may limit its length or characters)",
        ),
        C::RefusedProtocolVersion => (
            "MQTT 3.1.1 not spoken",
            "point mqtt.host and mqtt.port at an MQTT 3.1.1 or 5 broker",
        ),
        C::Success => ("accepted", ""),
    }
}

/// What to do about the CAN interface `name` that did not open: it may be missing (an
/// adapter unplugged, a name misspelt) or down, and only its devices know its bit rate.
fn can_fix(name: &str) -> String {
    if std::path::Path::new("/sys/class/net").join(name).exists() {
        format!(
            "bring it up at the bit rate its devices use (chassisd does not set it): `sudo ip \
             link set {name} type can bitrate RATE && sudo ip link set {name} up` (a vcan \
             needs only `ip link set {name} up`)"
        )
    } else {
        format!(
            "no interface {name}: check can[].interface against `ip -br link` and that the \
             CAN adapter is plugged in (for a test bus: `sudo ip link add dev {name} type vcan \
             && sudo ip link set {name} up`)"
        )
    }
}

async fn probe_serial(
    port: &str,
    baud: u32,
    mut listener: Listener,
) -> Result<String, (String, String)> {
    let mut serial = match tokio_serial::new(port, baud).open_native_async() {
        Ok(s) => s,
        Err(e) => {
            return fail(
                format!("cannot open {port}: {e}"),
                serial_open::advice(port, &e),
            );
        }
    };
    let end = Instant::now() + SERIAL_LISTEN;
    let mut buf = [0u8; 4096];
    let (mut bytes, mut samples) = (0usize, 0u64);
    let mut heading = None;
    let mut located = false;
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        let n = match tokio::time::timeout(left, serial.read(&mut buf)).await {
            Ok(Ok(0)) | Err(_) => break,
            Ok(Ok(n)) => n,
            Ok(Err(e)) => return fail(format!("reading {port}: {e}"), "check the cable"),
        };
        bytes += n;
        let chunk = buf.get(..n).unwrap_or_default();
        match &mut listener {
            Listener::Gnss { receiver, .. } => {
                receiver.push(Timestamp::default(), chunk, |fix| {
                    heading = fix.heading_deg.map(|h| h.value).or(heading);
                    located |= fix.quality.is_valid();
                });
            }
            Listener::Imu(d) => d.push(Timestamp::default(), chunk, |_| samples += 1),
        }
    }
    let secs = SERIAL_LISTEN.as_secs_f64();
    match listener {
        Listener::Gnss {
            receiver,
            expect_heading,
        } => {
            let stats = receiver.stats();
            let kinds: Vec<String> = stats
                .sentences_by_kind
                .iter()
                .map(|(k, n)| format!("{k} {n}"))
                .collect();
            let seen = format!(
                "{} valid sentences and {} UBX frames in {secs:.0} s ({})",
                stats.framer.sentences,
                stats.framer.ubx_frames,
                kinds.join(", ")
            );
            // Unicore's `H` forms are its second antenna's: never the vehicle's position.
            let second_antenna_only = !located
                && stats
                    .sentences_by_kind
                    .keys()
                    .any(|k| ["GGAH", "RMCH", "GNSH"].iter().any(|h| k.ends_with(h)));
            if second_antenna_only {
                fail(
                    format!(
                        "{seen}; only the second antenna's positions (GGAH, RMCH, GNSH), which \
                         are not the vehicle's"
                    ),
                    "enable GGA (or GNS) and RMC of the first antenna on this port",
                )
            } else if stats.framer.sentences + stats.framer.ubx_frames > 0 {
                match heading {
                    Some(h) => Ok(format!("{seen}; dual-antenna heading {h:.2}°")),
                    None if expect_heading => fail(
                        format!("{seen}; but no valid dual-antenna heading"),
                        "enable the receiver's heading output on this port (HPR, TRA, \
                         UNIHEADINGA or KSXT) and check that both antennas see the sky with \
                         RTK fixed; a one-antenna receiver has none: set gnss.receiver = \
                         \"nmea\"",
                    ),
                    None => Ok(seen),
                }
            } else if bytes == 0 {
                fail(
                    format!("no data in {secs:.0} s"),
                    "is the receiver powered, and set to send NMEA or UBX on this port?",
                )
            } else {
                fail(
                    format!(
                        "{bytes} bytes but no valid sentence or UBX frame in {secs:.0} s \
                         ({} checksum errors, {} UBX checksum errors)",
                        stats.framer.checksum_errors, stats.framer.ubx_checksum_errors
                    ),
                    "check gnss.baud against the receiver's rate, and that it sends NMEA or UBX",
                )
            }
        }
        Listener::Imu(_) if samples > 0 => Ok(format!(
            "{samples} samples in {secs:.0} s ({:.0} Hz)",
            samples as f64 / secs
        )),
        Listener::Imu(_) if bytes == 0 => fail(
            format!("no data in {secs:.0} s"),
            "is the IMU powered and connected to this port?",
        ),
        Listener::Imu(_) => fail(
            format!("{bytes} bytes but no valid frame in {secs:.0} s"),
            "check imu.baud and imu.protocol against the IMU's settings",
        ),
    }
}

/// MON-VER, and with `configure` the CFG-VALSET and its read-back, each a probe.
async fn probe_ublox(g: &GnssConfig, configure: Option<Layers>) -> Vec<Probe> {
    let serial = match tokio_serial::new(&g.port, g.baud).open_native_async() {
        Ok(s) => s,
        Err(e) => {
            let result = fail(
                format!("cannot open {}: {e}", g.port),
                serial_open::advice(&g.port, &e),
            );
            return vec![Probe::new("gnss", "u-blox MON-VER", result)];
        }
    };
    let mut dialogue = Dialogue::new(serial);
    let version = match dialogue.identify().await {
        Ok(v) => v,
        Err(r) => return vec![Probe::new("gnss", "u-blox MON-VER", fail(r.reason, r.fix))],
    };
    let mut probes = vec![Probe::new("gnss", "u-blox MON-VER", Ok(version.summary()))];
    if let Some(layers) = configure {
        let port = g.ublox_port();
        let what = format!("u-blox configure ({})", port_name(port));
        let result = match dialogue.configure(&version, port, layers).await {
            Ok(set) => Ok(format!(
                "{} items set in {} and read back: {}",
                set.len(),
                match layers {
                    Layers::Ram => "RAM (lost at power off)",
                    Layers::RamAndFlash => "RAM and flash",
                },
                set.iter().map(|w| w.name).collect::<Vec<_>>().join(", ")
            )),
            Err(r) => fail(r.reason, r.fix),
        };
        probes.push(Probe::new("gnss", &what, result));
    }
    probes
}

async fn probe_sdo(
    socket: &socketcan::tokio::CanSocket,
    node: u8,
) -> Result<String, (String, String)> {
    let Some(id) = NodeId::new(node) else {
        return fail(
            format!("node {node} is not a CANopen node id"),
            "use 1 to 127",
        );
    };
    let request = SdoRequest::Read(DEVICE_TYPE).frame(id);
    let reply_id = 0x580 + u32::from(node);
    for _ in 0..SDO_ATTEMPTS {
        if let Err(e) = socket.write_frame(request.to_socketcan()).await {
            return fail(format!("cannot send: {e}"), "check the interface");
        }
        let end = Instant::now() + SDO_WAIT;
        while let Some(left) = end.checked_duration_since(Instant::now()) {
            let Ok(Ok(frame)) = tokio::time::timeout(left, socket.read_frame()).await else {
                break;
            };
            let Received::Data(frame) =
                Received::from_socketcan(&socketcan::CanAnyFrame::from(frame))
            else {
                continue;
            };
            if frame.id() != reply_id || frame.is_extended() {
                continue;
            }
            return match decode_response(&frame) {
                Ok(SdoResponse::Data(_, data)) => {
                    Ok(format!("device type 0x{:08X}", data.as_u32()))
                }
                Ok(SdoResponse::Abort(_, code)) => fail(
                    format!("the drive aborted the read ({code})"),
                    "the node answers but refuses 0x1000: is it a CiA 402 drive?",
                ),
                Ok(_) => fail(
                    "the node answered with another SDO reply than a read's",
                    "check drive[].node: another device may have this id",
                ),
                Err(e) => fail(format!("malformed answer: {e}"), "check the node id"),
            };
        }
    }
    fail(
        format!("no answer to {SDO_ATTEMPTS} SDO reads from node {node}"),
        "check drive[].node against the drive's node id, the bit rate, the termination and \
         the drive's power",
    )
}

async fn probe_bms(
    socket: &socketcan::tokio::CanSocket,
    config: &crate::config::chassis::BmsConfig,
    listen_only: bool,
) -> Result<String, (String, String)> {
    let Some(mut bms) = crate::engine::drivetrain::bms_device(config) else {
        return fail("its profile did not load", "check bms.profile");
    };
    let end = Instant::now() + BMS_WAIT;
    let start = Instant::now();
    let mut next_poll = Instant::now();
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        if !listen_only && Instant::now() >= next_poll {
            let mut out = Vec::new();
            let t = Timestamp::from_nanos(start.elapsed().as_nanos() as u64);
            bms.poll(t, &mut out);
            for f in out {
                let _ = socket.write_frame(f.to_socketcan()).await;
            }
            next_poll = Instant::now() + Duration::from_millis(100);
        }
        let wait = left.min(Duration::from_millis(100));
        let Ok(Ok(frame)) = tokio::time::timeout(wait, socket.read_frame()).await else {
            continue;
        };
        let Received::Data(frame) = Received::from_socketcan(&socketcan::CanAnyFrame::from(frame))
        else {
            continue;
        };
        let t = Timestamp::from_nanos(start.elapsed().as_nanos() as u64);
        if bms.on_frame(t, &frame) {
            let r = bms.reading();
            return Ok(match (r.voltage_v, r.soc_pct) {
                (Some(v), Some(soc)) => format!("{v:.1} V, {soc:.0} %"),
                (Some(v), None) => format!("{v:.1} V"),
                _ => "answers".into(),
            });
        }
    }
    fail(
        format!("nothing from the BMS in {:.0} s", BMS_WAIT.as_secs_f64()),
        "check bms.address and the profile against the pack, its CAN wiring and that it is \
         awake",
    )
}

/// The embedded broker: not running (chassisd run starts it), or running, with the health
/// the daemon publishes (clients, restarts, refusals).
async fn probe_embedded_broker(
    config: &VehicleConfig,
    link: &MqttLinkConfig,
) -> Result<String, (String, String)> {
    let free = (link.host.as_str(), link.port)
        .to_socket_addrs()
        .ok()
        .and_then(|mut a| a.next())
        .is_some_and(|a| std::net::TcpListener::bind(a).is_ok());
    if free {
        return Ok("embedded: not running now; `chassisd run` starts it".into());
    }
    let at = link.brokers().swap_remove(0);
    let health = link.broker_health_topic(&config.vehicle.name);
    probe_broker(config, link, &at, Some(health)).await
}

/// The embedded broker's health in words.
fn describe_health(h: &BrokerHealth) -> String {
    let count = |k: &str| h.counters.get(k).copied().unwrap_or(0);
    let mut text = format!(
        "embedded, running: {} clients, {} restarts",
        h.connected.map_or("?".into(), |n| n.to_string()),
        h.restarts
    );
    if let Some(why) = &h.last_exit {
        let _ = write!(text, " (last: {why})");
    }
    let _ = write!(
        text,
        "; refused since the last restart: {} credentials, {} full, {} protocol, {} reserved, \
         {} malformed, {} over budget; holding {} retained messages ({} bytes)",
        count("refused_credentials"),
        count("refused_full"),
        count("refused_protocol"),
        count("refused_reserved"),
        count("malformed"),
        count("over_budget"),
        count("retained"),
        count("retained_bytes")
    );
    text
}

/// Connects to the broker once; with `health`, also waits for the embedded broker's
/// retained health on that topic and describes it.
async fn probe_broker(
    config: &VehicleConfig,
    link: &MqttLinkConfig,
    broker: &BrokerAddress,
    health: Option<String>,
) -> Result<String, (String, String)> {
    // A client id of its own (the daemon's stays connected) and no last will.
    let client_id = format!("{}-check", link.base_client_id(&config.vehicle.name));
    let options = match crate::runtime::links::mqtt::client_options_at(link, broker, client_id) {
        Ok(o) => o,
        Err(e) => return fail(format!("{e:#}"), "check the link's tls files"),
    };
    let (client, mut events) = rumqttc::AsyncClient::new(options, 10);
    // Set once the embedded broker let the probe in, so a missing health report is told
    // apart from a broker that does not answer.
    let mut accepted = false;
    let result = tokio::time::timeout(BROKER_WAIT, async {
        loop {
            match events.poll().await {
                Ok(rumqttc::Event::Incoming(rumqttc::Packet::ConnAck(ack))) => match ack.code {
                    rumqttc::ConnectReturnCode::Success => match &health {
                        None => return Ok("accepts the connection".into()),
                        Some(topic) => {
                            accepted = true;
                            if client
                                .try_subscribe(topic.as_str(), rumqttc::QoS::AtMostOnce)
                                .is_err()
                            {
                                return Ok("accepts the connection".into());
                            }
                        }
                    },
                    code => {
                        let (why, fix) = connack_words(code);
                        return fail(format!("refused: {why}"), fix);
                    }
                },
                Ok(rumqttc::Event::Incoming(rumqttc::Packet::Publish(p))) => {
                    return match serde_json::from_slice::<BrokerHealth>(&p.payload) {
                        Ok(h) => Ok(describe_health(&h)),
                        Err(_) => Ok("embedded, running (its health report is unreadable)".into()),
                    };
                }
                Ok(_) => {}
                Err(e) => {
                    return fail(
                        format!("cannot connect: {e}"),
                        format!(
                            "is the broker running at {broker} (e.g. `systemctl status mosquitto`)? \
                             With TLS, check the certificates"
                        ),
                    );
                }
            }
        }
    })
    .await
    .unwrap_or_else(|_| {
        if accepted {
            return Ok("embedded, running (no health report yet: it comes every 5 s)".into());
        }
        fail(
            format!("no answer in {:.0} s", BROKER_WAIT.as_secs_f64()),
            "check the link's host, port (or failover) and the network",
        )
    });
    let _ = client.try_disconnect();
    result
}
