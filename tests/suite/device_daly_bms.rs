//! Daly BMS over CAN: request and reply frames worked from the Daly CAN protocol V1.0
//! (29-bit ids `0x18 cmd bms host` / `0x18 cmd host bms`, big-endian payloads).

use chassisd::devices::bms::daly::{DalyBms, failure_alarms, reply_frame, request_id};
use chassisd::devices::bms::{ChargeState, alarm};
use chassisd::devices::can::Frame;
use chassisd::time::Timestamp;

fn t(ms: u64) -> Timestamp {
    Timestamp::from_micros(ms * 1000)
}

#[test]
fn polls_every_message_in_turn() {
    let mut bms = DalyBms::new(1, 0x40, 1.0, 2.0);
    let mut out = Vec::new();
    // Two rounds a second of five messages: one request every 100 ms.
    for ms in (0..500).step_by(10) {
        bms.poll(t(ms), &mut out);
    }
    let sent: Vec<String> = out.iter().map(|f| f.to_string()).collect();
    assert_eq!(
        sent,
        [
            "18900140#0000000000000000",
            "18910140#0000000000000000",
            "18920140#0000000000000000",
            "18930140#0000000000000000",
            "18980140#0000000000000000",
        ]
    );
    assert_eq!(request_id(0x90, 2, 0x40), 0x1890_0240);
}

#[test]
fn decodes_each_reply() {
    let mut bms = DalyBms::new(1, 0x40, 1.0, 1.0);
    // 0x90: 52.3 V, current raw 29875 (-12.5 A), SOC 87.6 %.
    assert!(bms.on_frame(
        t(1),
        &reply_frame(
            0x90,
            1,
            0x40,
            [0x02, 0x0B, 0x02, 0x0B, 0x74, 0xB3, 0x03, 0x6C]
        )
    ));
    // 0x91: highest cell 3.312 V (cell 5), lowest 3.298 V (cell 12).
    assert!(bms.on_frame(
        t(2),
        &reply_frame(0x91, 1, 0x40, [0x0C, 0xF0, 0x05, 0x0C, 0xE2, 0x0C, 0, 0])
    ));
    // 0x92: highest 31 °C, lowest 25 °C (offset 40).
    assert!(bms.on_frame(
        t(3),
        &reply_frame(0x92, 1, 0x40, [0x47, 0x01, 0x41, 0x02, 0, 0, 0, 0])
    ));
    // 0x93: discharging, both MOSFETs on, 48 500 mAh left.
    assert!(bms.on_frame(
        t(4),
        &reply_frame(
            0x93,
            1,
            0x40,
            [0x02, 0x01, 0x01, 0x2A, 0x00, 0x00, 0xBD, 0x74]
        )
    ));
    let r = bms.reading();
    assert_eq!(r.voltage_v, Some(52.3));
    assert_eq!(r.current_a, Some(-12.5));
    assert_eq!(r.soc_pct, Some(87.6));
    assert_eq!(r.cell_voltage_range_v, Some((3.312, 3.298)));
    assert_eq!(r.temperature_c, Some(31.0));
    assert_eq!(r.charge_state, Some(ChargeState::Discharging));
    assert_eq!(
        (r.charge_mosfet, r.discharge_mosfet),
        (Some(true), Some(true))
    );
    assert_eq!(r.remaining_capacity_ah, Some(48.5));
    assert_eq!(r.rx, Some(t(4)));
    // 0x98: cell voltage low (level 1) and short-circuit protection.
    assert!(bms.on_frame(
        t(5),
        &reply_frame(0x98, 1, 0x40, [0x04, 0, 0, 0, 0, 0, 0x04, 0])
    ));
    assert_eq!(
        bms.reading().alarms,
        alarm::CELL_UNDERVOLTAGE | alarm::SHORT_CIRCUIT | alarm::PROTECTION_TRIPPED
    );
}

#[test]
fn current_direction_follows_the_profile() {
    // Firmware that counts discharge above the offset: the same bytes read +12.5 A.
    let mut bms = DalyBms::new(1, 0x40, -1.0, 1.0);
    bms.on_frame(
        t(1),
        &reply_frame(
            0x90,
            1,
            0x40,
            [0x02, 0x0B, 0x02, 0x0B, 0x74, 0xB3, 0x03, 0x6C],
        ),
    );
    assert_eq!(bms.reading().current_a, Some(12.5));
}

#[test]
fn failure_bits_map_by_level() {
    // Level 1 cell-low is a warning; level 2 has tripped the protection.
    assert_eq!(
        failure_alarms([0x04, 0, 0, 0, 0, 0, 0, 0]),
        alarm::CELL_UNDERVOLTAGE
    );
    assert_eq!(
        failure_alarms([0x08, 0, 0, 0, 0, 0, 0, 0]),
        alarm::CELL_UNDERVOLTAGE | alarm::PROTECTION_TRIPPED
    );
    assert_eq!(
        failure_alarms([0, 0x10, 0x40, 0x01, 0x01, 0x09, 0, 0]),
        alarm::DISCHARGE_OVER_TEMPERATURE
            | alarm::SOC_LOW
            | alarm::CELL_IMBALANCE
            | alarm::MOSFET_FAULT
            | alarm::HARDWARE_FAULT
    );
    assert_eq!(
        failure_alarms([0, 0, 0, 0, 0, 0x40, 0, 0]),
        alarm::COMMUNICATION_FAULT
    );
    assert_eq!(failure_alarms([0; 8]), 0);
}

#[test]
fn ignores_other_packs_and_counts_malformed_replies() {
    let mut bms = DalyBms::new(1, 0x40, 1.0, 1.0);
    // Pack 2's reply and a request (not a reply) are not ours.
    assert!(!bms.on_frame(t(1), &reply_frame(0x90, 2, 0x40, [0; 8])));
    assert!(!bms.on_frame(t(1), &Frame::ext(request_id(0x90, 1, 0x40), [0; 8])));
    // A short reply is counted, never trusted.
    assert!(!bms.on_frame(t(1), &Frame::extended(0x1890_4001, &[0x02, 0x0B]).unwrap()));
    assert_eq!(bms.malformed(), 1);
    assert_eq!(bms.reading().rx, None);
}
