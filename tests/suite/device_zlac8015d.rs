//! The ZLAC8015D dual-channel profile (SDO set-up, SDO polling, both wheels through
//! 0x60FF:3): frame vectors from its object dictionary, and the driver against a simulated
//! ZLAC8015D.

use crate::common;

use chassisd::devices::can::Frame;
use chassisd::devices::canopen::ObjectAddress;
use chassisd::devices::canopen::sdo::{SdoResponse, decode_response};
use chassisd::devices::cia402::DriveState;
use chassisd::devices::cia402::node::Phase;
use common::canbus::Rig;

#[test]
fn setup_writes_vendor_objects() {
    let mut rig = Rig::new("zlac8015d.toml", 1);
    rig.start();
    rig.run(200, false, &[0.0, 0.0]);
    let sent = rig.sent();
    assert_eq!(
        &sent[..11],
        [
            "000#8201",             // NMT reset communication
            "601#2B17100064000000", // heartbeat producer 100 ms
            "601#2B002000FA000000", // 0x2000 communication offline time 250 ms
            "601#2F60600003000000", // profile velocity mode
            "601#23FF600300000000", // 0x60FF:3 both targets 0
            "601#2B0F200001000000", // 0x200F = 1: synchronous control
            "601#2383600164000000", // 0x6083:1 acceleration time 100 ms
            "601#2383600264000000", // 0x6083:2
            "601#2384600164000000", // 0x6084:1 deceleration time 100 ms
            "601#2384600264000000", // 0x6084:2
            "000#0101",             // NMT start
        ]
    );
    assert_eq!(rig.node.phase(), Phase::Running);
    // Polling reads the 32-bit statusword and both velocities and positions.
    for read in [
        "601#4041600000000000",
        "601#406C600100000000",
        "601#406C600200000000",
        "601#4064600100000000",
        "601#4064600200000000",
    ] {
        assert!(sent.iter().any(|f| f == read), "{read} never sent");
    }
}

#[test]
fn both_wheels_in_one_write_and_readback_in_tenths() {
    let mut rig = Rig::new("zlac8015d.toml", 1);
    rig.start();
    // Left forward 100 r/min, right backward 100 r/min (the motors face each other).
    rig.run(600, true, &[100.0, -100.0]);
    assert!(rig.node.is_enabled(), "{:?}", rig.node.drive_state());
    // 0x60FF:3 = right (0xFF9C) << 16 | left (0x0064).
    assert!(rig.sent().iter().any(|f| f == "601#23FF600364009CFF"));
    let report = rig.sim.report();
    assert!((report[0].rpm - 100.0).abs() < 1e-6 && (report[1].rpm + 100.0).abs() < 1e-6);
    // Actual velocity comes back in 0.1 r/min.
    assert_eq!(rig.node.axes()[0].velocity, Some(1000));
    assert_eq!(rig.node.axes()[1].velocity, Some(-1000));
    assert!(rig.node.axes()[0].position.unwrap() > 0 && rig.node.axes()[1].position.unwrap() < 0);
    // The sequence went 6, 7, 0x0F through SDO writes to 0x6040.
    let cws: Vec<String> = rig
        .sent()
        .into_iter()
        .filter(|f| f.starts_with("601#2B406000"))
        .collect();
    assert_eq!(
        cws,
        [
            "601#2B40600006000000",
            "601#2B40600007000000",
            "601#2B4060000F000000"
        ]
    );
}

#[test]
fn decodes_packed_statusword_and_tenths() {
    // A read of 0x6041 answering both motors: left 0x0637 (enabled), right 0x0637.
    let f = Frame::std(0x581, [0x43, 0x41, 0x60, 0x00, 0x37, 0x06, 0x37, 0x06]);
    let SdoResponse::Data(addr, data) = decode_response(&f).unwrap() else {
        panic!()
    };
    assert_eq!(addr, ObjectAddress::new(0x6041, 0));
    let v = data.as_u32();
    assert_eq!(
        DriveState::from_statusword((v & 0xFFFF) as u16),
        DriveState::OperationEnabled
    );
    assert_eq!(
        DriveState::from_statusword((v >> 16) as u16),
        DriveState::OperationEnabled
    );
    // 0x606C:2 = -1000 (0.1 r/min): -100 r/min.
    let f = Frame::std(0x581, [0x43, 0x6C, 0x60, 0x02, 0x18, 0xFC, 0xFF, 0xFF]);
    let SdoResponse::Data(_, data) = decode_response(&f).unwrap() else {
        panic!()
    };
    assert_eq!(data.as_i32(), -1000);
}

#[test]
fn the_vendor_timeout_stops_both_motors_when_chassisd_is_gone() {
    let mut rig = Rig::new("zlac8015d.toml", 1);
    rig.start();
    rig.run(800, true, &[200.0, -200.0]);
    assert!(rig.sim.report().iter().all(|a| a.rpm.abs() > 199.0));
    // chassisd dies: its SDO commands and polls stop.
    rig.master_alive = false;
    rig.run(250 + 20, true, &[200.0, -200.0]);
    assert_eq!(rig.sim.master_losses(), 1, "offline time 250 ms reached");
    rig.run(500, true, &[200.0, -200.0]);
    for axis in rig.sim.report() {
        assert_eq!(axis.rpm, 0.0, "{axis:?}");
        assert_eq!(axis.target, 0);
    }
}
