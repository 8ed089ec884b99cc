//! The standard-input command channel against bad bytes: a line that is not UTF-8, or longer
//! than the bound, is refused with a warning and the channel goes on taking commands.

use crate::common;

use common::process::Proc;
use std::time::Duration;

#[test]
fn a_bad_line_on_stdin_is_refused_and_the_next_command_is_taken() {
    let mut sim = Proc::start(&["sim", "--no-mqtt", "--commands-stdin"]);
    sim.wait_log(Duration::from_secs(10), "drive right: running");

    sim.send_bytes(b"cmd_vel {\"linear\":{\"x\":\xff\xfe}}\n");
    sim.wait_log(Duration::from_secs(5), "line refused, not UTF-8");
    sim.send(r#"cmd_vel {"linear":{"x":0.1}}"#);
    sim.wait_log(Duration::from_secs(5), "command accepted");

    // Longer than the 1 MiB bound, sent in pieces as a slow writer would.
    let chunk = vec![b'x'; 256 * 1024];
    for _ in 0..6 {
        sim.send_bytes(&chunk);
    }
    sim.send_bytes(b"\n");
    sim.wait_log(Duration::from_secs(5), "line refused, too long");
    sim.send(r#"cmd_vel {"linear":{"x":0.0}}"#);
    sim.wait_log(Duration::from_secs(5), "command accepted");
    sim.stop();
}
