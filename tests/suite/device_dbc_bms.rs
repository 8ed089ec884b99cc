//! A broadcast BMS described by a DBC file: the shipped Pylontech-protocol DBC and mapping
//! decoded from fixed frames, and signal extraction in both byte orders.

use std::path::Path;

use chassisd::config::chassis::LoadProfile;
use chassisd::devices::bms::dbc::{DbcBms, physical, raw_bits};
use chassisd::devices::bms::profile::BmsProfile;
use chassisd::devices::bms::{ChargeState, alarm};
use chassisd::devices::can::Frame;
use chassisd::time::Timestamp;

fn pylontech() -> DbcBms {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("devices/pylontech-bms.toml");
    let BmsProfile::Dbc(profile) = BmsProfile::load_file(&path).expect("shipped profile") else {
        panic!("not a DBC profile")
    };
    DbcBms::new(&profile).expect("mapping resolves")
}

#[test]
fn decodes_the_pylontech_messages() {
    let mut bms = pylontech();
    let t = Timestamp::from_micros(1);
    // 0x356: 53.12 V, -8.5 A (discharging), 24.3 °C.
    assert!(bms.on_frame(t, &Frame::std(0x356, [0xC0, 0x14, 0xAB, 0xFF, 0xF3, 0x00])));
    // 0x355: SOC 76 %, SOH 99 %.
    assert!(bms.on_frame(t, &Frame::std(0x355, [0x4C, 0x00, 0x63, 0x00])));
    let r = bms.reading();
    assert!((r.voltage_v.unwrap() - 53.12).abs() < 1e-9);
    assert!((r.current_a.unwrap() + 8.5).abs() < 1e-9);
    assert!((r.temperature_c.unwrap() - 24.3).abs() < 1e-9);
    assert_eq!(r.soc_pct, Some(76.0));
    assert_eq!(r.charge_state, Some(ChargeState::Discharging));
    assert_eq!(r.remaining_capacity_ah, None);
    // 0x359: cell under-voltage protection (byte 0 bit 2), high-temperature alarm (byte 2
    // bit 3), one module, "PN".
    assert!(bms.on_frame(
        t,
        &Frame::std(0x359, [0x04, 0x00, 0x08, 0x00, 0x01, 0x50, 0x4E])
    ));
    assert_eq!(
        bms.reading().alarms,
        alarm::CELL_UNDERVOLTAGE | alarm::PROTECTION_TRIPPED | alarm::DISCHARGE_OVER_TEMPERATURE
    );
    // Cleared flags clear the bits.
    bms.on_frame(t, &Frame::std(0x359, [0, 0, 0, 0, 0x01, 0x50, 0x4E]));
    assert_eq!(bms.reading().alarms, 0);
    // Unmapped ids and short frames change nothing.
    assert!(!bms.on_frame(t, &Frame::std(0x35E, *b"PYLON\0\0\0")));
    assert!(!bms.on_frame(t, &Frame::std(0x356, [0xC0])));
}

#[test]
fn extracts_motorola_and_signed_signals() {
    let dbc = can_dbc::Dbc::try_from(
        "VERSION \"\"\n\nNS_ :\n\nBS_:\n\nBU_: X\n\nBO_ 291 m: 8 X\n \
         SG_ be16 : 7|16@0+ (1,0) [0|65535] \"\" X\n \
         SG_ be12s : 23|12@0- (0.5,1) [0|0] \"\" X\n \
         SG_ le4 : 36|4@1+ (1,0) [0|15] \"\" X\n",
    )
    .expect("test DBC parses");
    let signals = &dbc.messages[0].signals;
    let data = [0x12, 0x34, 0xFF, 0xE0, 0xA0, 0, 0, 0];
    assert_eq!(raw_bits(&signals[0], &data), Some(0x1234));
    // 0xFFE (12 bits, big-endian from bit 23) is -2: -2 × 0.5 + 1 = 0.
    assert_eq!(raw_bits(&signals[1], &data), Some(0xFFE));
    assert_eq!(physical(&signals[1], &data), Some(0.0));
    // Bits 36..40 of the little-endian word: high nibble of byte 4.
    assert_eq!(raw_bits(&signals[2], &data), Some(0xA));
    assert_eq!(raw_bits(&signals[0], &data[..1]), None);
}
