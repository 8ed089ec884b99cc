//! `chassisd bench fleet`, shortened: simulated vehicles in one process on two mosquitto
//! nodes, node 0 killed while the operators command them. Every vehicle comes back on the
//! other node, every command sent while its vehicle was connected is answered exactly once,
//! and the reports keep their period. (The full run, and its figures, are the benchmark's.)

use crate::common;

#[test]
fn a_fleet_fails_over_when_a_node_dies_and_no_command_is_lost_or_doubled() {
    let summary = common::passing_bench(
        &[
            "bench",
            "fleet",
            "--vehicles",
            "60",
            "--nodes",
            "2",
            "--steady",
            "3",
        ],
        "a fleet of 60 on two nodes",
    );
    let failover = &summary["failover"];
    assert_eq!(failover["vehicles_down"], 30, "{summary}");
    assert_eq!(failover["vehicles_back"], 30, "{summary}");
    // Returns are spread by the jittered back-off: more than one second holds them, and
    // they all add up to the vehicles that came back.
    let per_second = common::connects_per_second(&summary);
    assert!(
        per_second.iter().filter(|n| **n > 0).count() >= 2,
        "{per_second:?}"
    );
    assert_eq!(per_second.iter().sum::<u64>(), 30);
    let commands = &summary["commands"];
    assert_eq!(
        (&commands["lost"], &commands["twice"]),
        (&0.into(), &0.into())
    );
    assert!(commands["once"].as_u64().unwrap_or(0) > 50, "{summary}");
}
