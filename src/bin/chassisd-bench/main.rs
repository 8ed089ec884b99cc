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
    match bench::execute(Cli::parse().bench) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("chassisd-bench: {}", common::describe(&e));
            ExitCode::FAILURE
        }
    }
}
