//! `chassisd-bench`: the benchmarks that print figures. A binary of its own, so the daemon
//! does not carry them; `chassisd bench …` hands over to it.

mod bench;
#[path = "../../cli/common.rs"]
mod common;

use std::process::ExitCode;

use clap::Parser;

/// Benchmarks of chassisd that print figures (also run as `chassisd bench`).
#[derive(Parser)]
#[command(version)]
struct Cli {
    #[command(flatten)]
    bench: bench::Args,
}

fn main() -> ExitCode {
    // As the daemon's main does, before any thread or descriptor exists: the benchmarks run
    // its links and engine.
    chassisd::runtime::heap::tune_allocator();
    chassisd::runtime::descriptors::init();
    let _log_guard = chassisd::runtime::logging::init();
    // The benchmarks run the links, whose helper processes (the embedded broker, the ROS1
    // node) are this program started again with their hidden subcommand.
    #[cfg(feature = "ros2")]
    if std::env::args().nth(1).as_deref() == Some(chassisd::bench::ros2::LISTEN_COMMAND) {
        let args: Vec<String> = std::env::args().skip(2).collect();
        return match chassisd::bench::ros2::listen_main(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("chassisd-bench: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if let Some(helper) = helper(std::env::args().nth(1).as_deref()) {
        return match helper {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("chassisd-bench: {e}");
                ExitCode::FAILURE
            }
        };
    }
    match bench::execute(Cli::parse().bench) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("chassisd-bench: {}", common::describe(&e));
            ExitCode::FAILURE
        }
    }
}

/// Runs the helper process `subcommand` names, if it names one.
fn helper(subcommand: Option<&str>) -> Option<Result<(), chassisd::runtime::error::RuntimeError>> {
    match subcommand? {
        chassisd::runtime::links::broker::CHILD_COMMAND => {
            Some(chassisd::runtime::links::broker::child::main())
        }
        #[cfg(feature = "ros1")]
        chassisd::runtime::links::ros1::CHILD_COMMAND => {
            Some(chassisd::runtime::links::ros1::child::main())
        }
        #[cfg(feature = "ros2")]
        chassisd::runtime::links::ros2::CHILD_COMMAND => {
            Some(chassisd::runtime::links::ros2::child::main())
        }
        _ => None,
    }
}
