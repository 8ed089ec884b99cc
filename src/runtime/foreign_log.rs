//! The log lines of the libraries that serve network peers themselves (roslibrust, RustDDS
//! and ros2-client: one line per refused connection, per failed accept, per bad header, per
//! participant), held to the per-message budget: a peer that makes such a library log at every connection costs the log a few
//! lines every 5 s and a count, never a line per connection. Warnings and errors are
//! counted (what the log shows of them by default); more verbose levels asked for with
//! `RUST_LOG` are shown as asked.

use std::sync::Mutex;
use std::time::Instant;

use crate::api::log_budget::LogBudget;
use crate::time::Timestamp;

/// Targets whose lines are budgeted.
const BUDGETED: &[&str] = &["roslibrust", "rustdds", "ros2_client"];

static BUDGET: Mutex<LogBudget> = Mutex::new(LogBudget::new());
static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();

/// Whether a log event of `target` may be written now (a filter on the process's log).
pub fn allow(target: &str) -> bool {
    if !BUDGETED.iter().any(|b| target.starts_with(b)) {
        return true;
    }
    let start = *START.get_or_init(Instant::now);
    let now =
        Timestamp::from_micros(u64::try_from(start.elapsed().as_micros()).unwrap_or(u64::MAX));
    let allowed = crate::api::log_budget::allow(&BUDGET, now);
    if let Some(left_out) = allowed.filter(|&n| n > 0) {
        crate::runtime::stderr::line(format!(
            "chassisd: {left_out} log lines of {} left out over the budget of 5 every 5 s",
            BUDGETED.join(", ")
        ));
    }
    allowed.is_some()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_budgeted_libraries_are_held_to_it() {
        let allowed = (0..100)
            .filter(|_| allow("roslibrust_ros1::publisher"))
            .count();
        assert_eq!(allowed, crate::api::log_budget::LINES_PER_PERIOD as usize);
        assert!((0..100).all(|_| allow("chassisd::runtime::links::ros1::child")));
    }
}
