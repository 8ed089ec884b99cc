//! Lines to standard error in one write each. `eprintln!` writes a formatted line piece by
//! piece, and the embedded broker's process shares the descriptor: its log lines landed
//! inside a panic's report, which then no longer said where the panic was. One write of up
//! to PIPE_BUF (4096) bytes reaches a pipe whole.

use std::io::Write;

/// Writes `text` and a newline to standard error in one write; an error is dropped (there is
/// nowhere left to report it).
pub fn line(mut text: String) {
    text.push('\n');
    let _ = std::io::stderr().lock().write_all(text.as_bytes());
}
