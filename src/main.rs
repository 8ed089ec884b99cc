//! The `chassisd` command line: the argument schema's entry and the dispatch. Each
//! subcommand is a file of [`cli`].

mod cli;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(version, about = "Chassis daemon for RTK ground robots")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The subcommands, in the order `--help` lists them; each one's help is its arguments'
/// doc comment in its file.
#[derive(Subcommand)]
enum Command {
    Replay(cli::replay::Args),
    Export(cli::export::Args),
    Import(cli::import::Args),
    Run(cli::run::Args),
    Record(cli::record::Args),
    Sim(cli::sim::Args),
    Calibrate(cli::calibrate::Args),
    Bench(cli::bench::Args),
    Check(cli::check::Args),
    CanSim(cli::can_sim::Args),
    Ntrip(cli::ntrip::Args),
    /// The embedded broker's own process, started and watched by chassisd (settings on
    /// standard input); not for use by hand.
    #[command(name = "broker-child", hide = true)]
    BrokerChild,
    /// The ROS1 node's own process, started and watched by chassisd (settings on standard
    /// input); not for use by hand.
    #[cfg(feature = "ros1")]
    #[command(name = "ros1-child", hide = true)]
    Ros1Child,
    /// The ROS 2 node's own process, started and watched by chassisd (settings on standard
    /// input); not for use by hand.
    #[cfg(feature = "ros2")]
    #[command(name = "ros2-child", hide = true)]
    Ros2Child,
}

/// Exit status of a configuration error (sysexits' EX_CONFIG).
const EX_CONFIG: u8 = 78;

fn main() -> ExitCode {
    // Before any thread exists: see runtime::heap.
    chassisd::runtime::heap::tune_allocator();
    // Before anything opens a descriptor: see runtime::descriptors.
    chassisd::runtime::descriptors::init();
    // Errors travel to network clients (a ROS1 service's refusal carries its text), so they
    // carry no backtrace unless asked for by RUST_LIB_BACKTRACE itself; RUST_BACKTRACE still
    // gives panics theirs.
    if std::env::var_os("RUST_LIB_BACKTRACE").is_none() {
        // SAFETY: no other thread exists yet to read the environment concurrently.
        unsafe { std::env::set_var("RUST_LIB_BACKTRACE", "0") };
    }
    // The guard writes what is queued when main returns.
    let _log_guard = chassisd::runtime::logging::init();
    match run(Cli::parse()) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("chassisd: {}", cli::describe(&e));
            // A configuration error does not mend itself: 78 (EX_CONFIG) tells systemd not to
            // restart (the unit's RestartPreventExitStatus).
            if e.chain()
                .any(|c| c.downcast_ref::<chassisd::config::ConfigError>().is_some())
            {
                ExitCode::from(EX_CONFIG)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// Runs the command; `Ok(false)` when it ran but its verdict is negative (a benchmark missed
/// a target, a probe failed).
fn run(cli: Cli) -> anyhow::Result<bool> {
    match cli.command {
        Command::Replay(args) => cli::replay::execute(args),
        Command::Export(args) => cli::export::execute(args),
        Command::Import(args) => cli::import::execute(args),
        Command::Run(args) => cli::run::execute(args),
        Command::Record(args) => cli::record::execute(args),
        Command::Sim(args) => cli::sim::execute(args),
        Command::Calibrate(args) => cli::calibrate::execute(args),
        Command::Bench(args) => cli::bench::execute(args),
        Command::Check(args) => cli::check::execute(args),
        Command::CanSim(args) => cli::can_sim::execute(args),
        Command::Ntrip(args) => cli::ntrip::execute(args),
        Command::BrokerChild => {
            chassisd::runtime::links::broker::child::main()?;
            Ok(true)
        }
        #[cfg(feature = "ros1")]
        Command::Ros1Child => {
            chassisd::runtime::links::ros1::child::main()?;
            Ok(true)
        }
        #[cfg(feature = "ros2")]
        Command::Ros2Child => {
            chassisd::runtime::links::ros2::child::main()?;
            Ok(true)
        }
    }
}
