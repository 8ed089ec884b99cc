//! The generic CiA 402 drive (profile velocity mode, PDO feedback and commands): frame
//! vectors worked from CiA 301/402, and the driver against a simulated drive.

use crate::common;

use chassisd::devices::can::Frame;
use chassisd::devices::canopen::NodeId;
use chassisd::devices::canopen::emcy::Emcy;
use chassisd::devices::canopen::nmt::{NmtState, heartbeat_frame};
use chassisd::devices::cia402::DriveState;
use chassisd::devices::cia402::node::{DriveFault, Phase};
use common::canbus::{Rig, ms};

#[test]
fn boot_and_sdo_setup_sequence() {
    let mut rig = Rig::new("cia402-generic.toml", 1);
    rig.start();
    rig.run(200, false, &[0.0]);
    let sent = rig.sent();
    // NMT reset communication, then the set-up writes in order, then NMT start.
    let setup: Vec<&str> = sent.iter().map(String::as_str).take(28).collect();
    assert_eq!(
        setup,
        [
            "000#8201",             // NMT reset communication, node 1
            "601#2B17100064000000", // 0x1017 heartbeat producer 100 ms
            "601#23161001FA007F00", // 0x1016:1 consume node 0x7F's heartbeat, 250 ms
            "601#2B07600003000000", // 0x6007 abort connection: quick stop
            "601#2F60600003000000", // 0x6060 mode of operation 3: profile velocity
            "601#23FF600000000000", // 0x60FF target velocity 0
            "601#2300180181010080", // TPDO1 off
            "601#2F001802FF000000", //   event-driven
            "601#2B00180514000000", //   event timer 20 ms
            "601#2F001A0000000000", //   clear mapping
            "601#23001A0110004160", //   0x6041:0 statusword, 16 bits
            "601#23001A0220006C60", //   0x606C:0 actual velocity, 32 bits
            "601#2F001A0002000000", //   two entries
            "601#2300180181010000", // TPDO1 on, COB-ID 0x181
            "601#2301180181020080", // TPDO2 off
            "601#2F011802FF000000",
            "601#2B01180514000000",
            "601#2F011A0000000000",
            "601#23011A0120006460", //   0x6064:0 actual position, 32 bits
            "601#2F011A0001000000",
            "601#2301180181020000", // TPDO2 on, COB-ID 0x281
            "601#2300140101020080", // RPDO1 off
            "601#2F001402FF000000", //   asynchronous
            "601#2F00160000000000",
            "601#2300160110004060", //   0x6040:0 controlword, 16 bits
            "601#230016022000FF60", //   0x60FF:0 target velocity, 32 bits
            "601#2F00160002000000",
            "601#2300140101020000", // RPDO1 on, COB-ID 0x201
        ]
    );
    assert_eq!(sent[28], "601#23836000B80B0000"); // 0x6083 acceleration 3000 r/min/s
    assert_eq!(sent[29], "601#2384600070170000"); // 0x6084 deceleration 6000 r/min/s
    assert_eq!(sent[30], "000#0101"); // NMT start node 1
    assert_eq!(rig.node.phase(), Phase::Running);
    assert_eq!(rig.sim.nmt_state(), NmtState::Operational);
    // Not asked to enable: the drive is switched on, not enabled.
    assert_eq!(rig.node.drive_state(), Some(DriveState::SwitchedOn));
}

#[test]
fn enable_sequence_and_velocity_both_directions() {
    let mut rig = Rig::new("cia402-generic.toml", 1);
    rig.start();
    rig.run(200, false, &[0.0]);
    let before = rig.log.len();
    rig.run(200, true, &[100.0]);
    // RPDO1 carries controlword and target velocity: 0x0F with 0, then +100 r/min.
    let rpdos: Vec<String> = rig.log[before..]
        .iter()
        .filter(|(_, mine, f)| *mine && f.id() == 0x201)
        .map(|(_, _, f)| f.to_string())
        .collect();
    assert_eq!(rpdos[0], "201#0F0000000000"); // 0x0F enable operation (switched on → enabled)
    assert!(rpdos.contains(&"201#0F0064000000".to_string()), "{rpdos:?}"); // +100 r/min
    assert!(rig.node.is_enabled());
    let axis = rig.sim.report()[0].clone();
    assert!((axis.rpm - 100.0).abs() < 1e-6, "{axis:?}");
    // Feedback by TPDO.
    let fb = rig.node.axes()[0];
    assert_eq!(fb.velocity, Some(100));
    assert!(fb.position.unwrap() > 0);
    // Reverse: -100 r/min is 0xFFFFFF9C.
    rig.run(300, true, &[-100.0]);
    assert!(rig.sent().contains(&"201#0F009CFFFFFF".to_string()));
    assert_eq!(rig.node.axes()[0].velocity, Some(-100));
    // Disable: controlword 0x07, target 0.
    rig.run(100, false, &[0.0]);
    assert!(rig.sent().contains(&"201#070000000000".to_string()));
    assert_eq!(rig.node.drive_state(), Some(DriveState::SwitchedOn));
}

#[test]
fn shutdown_switch_on_enable_from_switch_on_disabled() {
    // The full 6 → 7 → 0x0F sequence from switch on disabled, as after power-up.
    let mut rig = Rig::new("cia402-generic.toml", 1);
    rig.start();
    rig.run(300, true, &[0.0]);
    let cws: Vec<u8> = rig
        .log
        .iter()
        .filter(|(_, mine, f)| *mine && f.id() == 0x201)
        .map(|(_, _, f)| f.data()[0])
        .collect();
    let mut seq: Vec<u8> = cws.clone();
    seq.dedup();
    assert_eq!(&seq[..3], &[0x06, 0x07, 0x0F], "{cws:?}");
    assert!(rig.node.is_enabled());
}

#[test]
fn lost_heartbeat_faults_within_timeout_and_commands_zero() {
    let mut rig = Rig::new("cia402-generic.toml", 1);
    rig.start();
    rig.run(500, true, &[200.0]);
    assert!(rig.node.is_enabled());
    let silent_from = rig.now_ms;
    rig.sim.set_heartbeat(false);
    let mut faulted_at = None;
    for _ in 0..100 {
        rig.run(10, true, &[200.0]);
        if rig.node.fault().is_some() {
            faulted_at = Some(rig.now_ms);
            break;
        }
    }
    let faulted_at = faulted_at.expect("heartbeat loss detected");
    assert_eq!(rig.node.fault(), Some(DriveFault::HeartbeatLost));
    // Timeout 350 ms after the last heartbeat (sent every 100 ms), checked every 10 ms.
    assert!(
        faulted_at - silent_from <= 350 + 100 + 10,
        "{}",
        faulted_at - silent_from
    );
    // The stop went out at once: zero target, quick stop.
    let stop = rig
        .log
        .iter()
        .find(|(t, mine, f)| *t == faulted_at && *mine && f.id() == 0x201)
        .map(|(_, _, f)| f.to_string());
    assert_eq!(stop.as_deref(), Some("201#020000000000"));
    rig.run(200, true, &[200.0]);
    assert_eq!(rig.sim.report()[0].target, 0);
    assert!(rig.sim.report()[0].rpm.abs() < 1e-9);
}

#[test]
fn emcy_faults_and_needs_a_reset() {
    let mut rig = faulted_rig(0);
    match rig.node.fault() {
        Some(DriveFault::Emcy(e)) => assert_eq!(e.code, 0x2310),
        other => panic!("{other:?}"),
    }
    assert_eq!(rig.node.drive_state(), Some(DriveState::Fault));
    // Still asked to move, but nothing happens until the fault is reset.
    rig.run(200, true, &[50.0]);
    assert!(!rig.node.is_enabled());
    assert!(rig.node.reset_fault(ms(rig.now_ms)));
    rig.run(300, true, &[50.0]);
    assert!(rig.node.is_enabled(), "{:?}", rig.node.drive_state());
    assert!(
        rig.sent().iter().any(|f| f == "201#800000000000"),
        "fault reset sent"
    );
}

/// The controlwords chassisd sent in RPDO1 (node 1), in order.
fn controlwords(rig: &Rig) -> Vec<u16> {
    rig.log
        .iter()
        .filter(|(_, mine, f)| *mine && f.id() == 0x201)
        .map(|(_, _, f)| u16::from_le_bytes([f.data()[0], f.data()[1]]))
        .collect()
}

/// Rising edges of bit 7 in a controlword sequence.
fn rising_edges(words: &[u16]) -> usize {
    words
        .windows(2)
        .filter(|w| w[0] & 0x80 == 0 && w[1] & 0x80 != 0)
        .count()
}

/// A generic drive enabled at 50 r/min, then faulted (EMCY 0x2310) so that it ignores its
/// first `refused` reset edges.
fn faulted_rig(refused: u32) -> Rig {
    let mut rig = Rig::new("cia402-generic.toml", 1);
    rig.start();
    rig.run(400, true, &[50.0]);
    let mut out = Vec::new();
    rig.sim.refuse_resets(refused);
    rig.sim.inject_fault(0, 0x2310, &mut out);
    rig.deliver(out, Vec::new());
    rig.run(50, true, &[50.0]);
    rig
}

#[test]
fn fault_reset_makes_a_new_edge_each_attempt_and_keeps_the_fault_until_it_clears() {
    let mut rig = faulted_rig(2);
    assert_eq!(rig.node.drive_state(), Some(DriveState::Fault));
    let before = controlwords(&rig).len();
    assert!(rig.node.reset_fault(ms(rig.now_ms)));
    // The fault stays reported while the drive is in Fault, through the failed attempts.
    while rig.node.is_resetting() {
        assert!(
            rig.node.fault().is_some(),
            "fault hidden at {} ms",
            rig.now_ms
        );
        assert!(!rig.node.is_ready());
        rig.run(10, true, &[50.0]);
        assert!(rig.now_ms < 5_000, "the reset never ended");
    }
    assert_eq!(rig.node.fault(), None, "the third attempt clears it");
    assert_eq!(rig.sim.reset_edges(), 3);
    let words = controlwords(&rig)[before - 1..].to_vec();
    assert_eq!(rising_edges(&words), 3, "{words:04X?}");
    // Bit 7 is low for at least one frame before every edge.
    for w in words
        .windows(2)
        .filter(|w| w[1] & 0x80 != 0 && w[0] & 0x80 == 0)
    {
        assert_eq!(w[0], 0x0000);
    }
    rig.run(300, true, &[50.0]);
    assert!(rig.node.is_enabled(), "{:?}", rig.node.drive_state());
}

#[test]
fn a_drive_stuck_in_fault_gives_up_after_the_attempts_and_can_be_retried() {
    let mut rig = faulted_rig(4);
    assert!(rig.node.reset_fault(ms(rig.now_ms)));
    rig.run(2_000, true, &[50.0]);
    assert!(!rig.node.is_resetting(), "bounded attempts");
    assert_eq!(rig.sim.reset_edges(), 3);
    assert!(matches!(rig.node.fault(), Some(DriveFault::Emcy(_))));
    // A later deliberate reset starts over with new edges; the fourth refusal and then it
    // clears.
    assert!(rig.node.reset_fault(ms(rig.now_ms)));
    rig.run(2_000, true, &[50.0]);
    assert_eq!(rig.sim.reset_edges(), 5);
    assert_eq!(rig.node.fault(), None);
}

#[test]
fn the_drive_quick_stops_by_itself_when_chassisd_is_gone() {
    let mut rig = Rig::new("cia402-generic.toml", 1);
    rig.start();
    rig.run(500, true, &[300.0]);
    assert!((rig.sim.report()[0].rpm - 300.0).abs() < 1e-6);
    // chassisd dies: no heartbeat, no frames at all.
    rig.master_alive = false;
    let gone = rig.now_ms;
    let mut stopped_braking = None;
    let mut first_quick_stop = None;
    for _ in 0..100 {
        rig.run(5, true, &[300.0]);
        let axis = &rig.sim.report()[0];
        if axis.state == "quick stop active" && first_quick_stop.is_none() {
            first_quick_stop = Some(rig.now_ms - gone);
        }
        if axis.rpm == 0.0 {
            stopped_braking = Some(rig.now_ms - gone);
            break;
        }
    }
    let reacted = first_quick_stop.expect("quick stop on the lost heartbeat");
    // The last heartbeat came up to 50 ms before; the consumer time is 250 ms.
    assert!((200..=260).contains(&reacted), "reacted after {reacted} ms");
    assert!(stopped_braking.is_some(), "the motor came to rest");
    assert_eq!(rig.sim.report()[0].state, "switch on disabled");
    assert_eq!(rig.sim.master_losses(), 1);
}

/// The generic profile watching chassisd's SYNC instead of its heartbeat.
fn sync_watching_rig() -> Rig {
    let p = common::canbus::profile_edited("cia402-generic.toml", |text| {
        text.replace("watch = \"heartbeat\"", "watch = \"sync\"")
    });
    let mut rig = Rig::with_profile(p, 1);
    rig.sync_ms = Some(20);
    rig
}

#[test]
fn a_drive_watching_sync_is_set_up_for_it_and_stops_when_sync_ends() {
    let mut rig = sync_watching_rig();
    rig.start();
    rig.run(500, true, &[300.0]);
    let sent = rig.sent();
    // 0x1006 communication cycle 20000 µs and 0x6007 quick stop, instead of 0x1016.
    assert!(
        sent.contains(&"601#23061000204E0000".to_owned()),
        "{sent:?}"
    );
    assert!(
        sent.contains(&"601#2B07600003000000".to_owned()),
        "{sent:?}"
    );
    assert!(
        !sent.iter().any(|f| f.starts_with("601#231610")),
        "{sent:?}"
    );
    assert!((rig.sim.report()[0].rpm - 300.0).abs() < 1e-6);
    // SYNC stops while chassisd's heartbeat goes on: the drive watches SYNC, so it stops.
    rig.sync_ms = None;
    let silent = rig.now_ms;
    let mut reacted = None;
    for _ in 0..200 {
        rig.run(1, true, &[300.0]);
        if rig.sim.report()[0].state == "quick stop active" {
            reacted = Some(rig.now_ms - silent);
            break;
        }
    }
    let reacted = reacted.expect("quick stop on the lost SYNC");
    // The last SYNC up to 20 ms before; two missed cycles.
    assert!((20..=45).contains(&reacted), "reacted after {reacted} ms");
    assert_eq!(rig.sim.master_losses(), 1);
}

#[test]
fn a_drive_watching_sync_runs_on_while_sync_flows() {
    let mut rig = sync_watching_rig();
    rig.start();
    rig.run(300, true, &[200.0]);
    rig.run(2_000, true, &[200.0]);
    assert_eq!(rig.sim.report()[0].state, "operation enabled");
    assert_eq!(rig.sim.master_losses(), 0);
}

#[test]
fn stale_feedback_faults_while_the_heartbeat_goes_on() {
    let mut rig = Rig::new("cia402-generic.toml", 1);
    rig.start();
    rig.run(500, true, &[100.0]);
    assert!(rig.node.is_enabled());
    rig.sim.set_tpdos(false);
    let silent = rig.now_ms;
    while rig.node.fault().is_none() {
        rig.run(10, true, &[100.0]);
        assert!(rig.now_ms - silent < 1_000, "stale feedback not noticed");
    }
    assert_eq!(
        rig.node.fault(),
        Some(DriveFault::FeedbackStale { axis: 0 })
    );
    // Last TPDO up to 20 ms before; timeout 250 ms; checked every 10 ms.
    assert!(rig.now_ms - silent <= 250 + 10, "{}", rig.now_ms - silent);
    assert!(rig.node.stats().heartbeats > 0);
    // A reset does not clear it while the feedback is still missing...
    assert!(!rig.node.reset_fault(ms(rig.now_ms)));
    // ...and does once it flows again.
    rig.sim.set_tpdos(true);
    rig.run(50, false, &[0.0]);
    assert!(rig.node.reset_fault(ms(rig.now_ms)));
    assert_eq!(rig.node.fault(), None);
}

#[test]
fn tpdo_bytes_decode_into_feedback() {
    let mut rig = Rig::new("cia402-generic.toml", 1);
    rig.start();
    rig.run(200, false, &[0.0]);
    // TPDO1: statusword 0x0637 (operation enabled), actual velocity -250 r/min;
    // TPDO2: position 123456 counts.
    let tpdo1 = Frame::std(0x181, [0x37, 0x06, 0x06, 0xFF, 0xFF, 0xFF]);
    let tpdo2 = Frame::std(0x281, [0x40, 0xE2, 0x01, 0x00]);
    let mut out = Vec::new();
    rig.node.on_frame(ms(rig.now_ms), &tpdo1, &mut out);
    rig.node.on_frame(ms(rig.now_ms), &tpdo2, &mut out);
    let fb = rig.node.axes()[0];
    assert_eq!(fb.statusword, Some(0x0637));
    assert_eq!(fb.velocity, Some(-250));
    assert_eq!(fb.position, Some(123_456));
    assert_eq!(rig.node.drive_state(), Some(DriveState::OperationEnabled));
    // A TPDO shorter than its mapping is counted and ignored.
    rig.node
        .on_frame(ms(rig.now_ms), &Frame::std(0x181, [0x37, 0x06]), &mut out);
    assert_eq!(rig.node.stats().short_tpdos, 1);
    assert_eq!(rig.node.axes()[0].velocity, Some(-250));
}

#[test]
fn frame_vectors() {
    let node = NodeId::new(1).unwrap();
    assert_eq!(
        heartbeat_frame(node, NmtState::Operational).to_string(),
        "701#05"
    );
    let e = Emcy::decode(&Frame::std(0x081, [0x30, 0x81, 0x11, 0, 0, 0, 0, 0])).unwrap();
    assert_eq!(e.code, 0x8130);
    assert_eq!(e.description(), "life guard or heartbeat error");
    let _ = ms(0);
}
