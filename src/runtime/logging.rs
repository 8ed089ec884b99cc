//! The process's log: lines leave through a bounded, lossy queue to their own thread (a
//! stalled stderr never holds up the control loop), to the journal's format under systemd,
//! and libraries that log per connection are held to a budget ([`super::foreign_log`]).

use std::io::IsTerminal;

use tracing_appender::non_blocking::WorkerGuard;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

/// Log lines waiting for stderr before new ones are dropped.
const LOG_QUEUE: usize = 4096;

/// Starts the log (`RUST_LOG` filters it); what is queued is written when the guard drops.
pub fn init() -> WorkerGuard {
    let (log_writer, guard) = tracing_appender::non_blocking::NonBlockingBuilder::default()
        .lossy(true)
        .buffered_lines_limit(LOG_QUEUE)
        .thread_name("log-out")
        .finish(std::io::stderr());
    let mut filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        tracing_subscriber::EnvFilter::new("info,rumqttd=off,roslibrust_ros1=warn")
    });
    // RustDDS logs every participant it discovers at INFO: a peer announcing hundreds would
    // write hundreds of lines. Its warnings still show (budgeted), unless RUST_LOG names it.
    let named = std::env::var("RUST_LOG").is_ok_and(|v| v.contains("rustdds"));
    if !named {
        // ros2-client warns at every start that ROS_DISTRO is not set: on a vehicle without
        // ROS it never is. A distribution that does not match is still an error, shown.
        let directives = [
            "rustdds=warn",
            "ros2_client=warn",
            "ros2_client::distributions=error",
        ];
        for directive in directives {
            if let Ok(d) = directive.parse() {
                filter = filter.add_directive(d);
            }
        }
    }
    let logs = tracing_subscriber::fmt()
        .with_writer(log_writer)
        .with_env_filter(filter);
    // Asked before the level filter, so only the levels shown by default are counted.
    let budget = tracing_subscriber::filter::filter_fn(|meta| {
        !meta.is_event()
            || *meta.level() > tracing::Level::WARN
            || super::foreign_log::allow(meta.target())
    });
    if super::journal::to_journal() {
        logs.event_format(super::journal::JournalFormat::default())
            .finish()
            .with(budget)
            .init();
    } else {
        logs.with_ansi(std::io::stderr().is_terminal())
            .finish()
            .with(budget)
            .init();
    }
    guard
}
