//! The integration tests, one module per capability, in one binary: it links once against
//! the crates instead of once per file. Each module opens with a `//!` header saying what it
//! shows and how (`head -q -n 4 tests/suite/*.rs`). One module alone:
//! `cargo test --release --test suite -- MODULE::` (for example `gnss_properties::`).
//! The CAN tests (`tests/vcan.rs`) stay a binary of their own: they run inside the VM.

#[path = "../common/mod.rs"]
mod common;

mod bag_import;
mod calibrate;
mod check;
mod check_receivers;
mod control_bench;
mod device_cia402;
mod device_daly_bms;
mod device_dbc_bms;
mod device_imu;
mod device_zlac8015d;
mod docs_book;
mod docs_topic_tables;
mod documented_examples;
mod drive_latency;
mod fleet_bench;
mod fleet_rabbitmq;
mod fusion_bench;
mod fusion_dead_reckoning;
mod fusion_husky;
mod fusion_localizer;
mod fusion_real;
mod fusion_standstill;
mod gnss_conformance;
mod gnss_decoders;
mod gnss_properties;
mod gnss_ubx;
mod heap_release;
mod hostile_commands;
mod hostile_recordings;
mod layers;
mod mcap_export;
mod motion_cutter;
mod motion_mission;
mod motion_moves;
mod motion_safety;
mod mqtt_crash;
mod mqtt_device;
mod mqtt_embedded;
mod mqtt_flood;
mod mqtt_hostile;
mod mqtt_links;
mod mqtt_root;
mod mqtt_rtk;
mod mqtt_secure;
mod ntrip_casters;
mod ntrip_client;
mod panic_containment;
mod progress;
mod record_listen;
mod recording_format;
mod replay_golden;
mod replay_hostile_files;
mod replay_time;
mod ros1_node;
mod ros2_node;
mod rtcm_ntrip_data;
mod safety_properties;
mod serial_pty;
mod sim_console;
mod sim_faults;
mod sim_frames;
mod sim_replay;
mod slow_disk;
mod stalled_output;
mod stdin_channel;
mod systemd_notify;
mod websocket;
mod zones_bench;
mod zones_plan;
mod zones_properties;
mod zones_run;
