//! `chassisd bench`: hands over to `chassisd-bench`, the benchmarks' own binary beside this
//! one, so the daemon does not carry the benchmarks.

use std::ffi::OsString;
use std::os::unix::process::CommandExt;

use anyhow::Context;

/// The benchmarks' binary, found beside this one.
const BINARY: &str = "chassisd-bench";

/// Run a benchmark that prints figures (`chassisd bench --help` lists them). The benchmarks
/// are the binary chassisd-bench beside this one (`cargo build --release` builds both).
#[derive(clap::Args)]
#[command(disable_help_flag = true, disable_version_flag = true)]
pub struct Args {
    /// The benchmark and its arguments, as chassisd-bench takes them.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    args: Vec<OsString>,
}

/// Replaces this process with `chassisd-bench ARGS`; returns only when it cannot start.
pub fn execute(args: Args) -> anyhow::Result<bool> {
    let exe = std::env::current_exe().context("cannot find this binary's path")?;
    let bench = exe.with_file_name(BINARY);
    anyhow::ensure!(
        bench.is_file(),
        "the benchmarks are a binary of their own, {BINARY}, and there is none beside {}: \
         build it with `cargo build --release` in the source tree (the .deb does not install it)",
        exe.display()
    );
    let error = std::process::Command::new(&bench).args(&args.args).exec();
    Err(error).with_context(|| format!("cannot start {}", bench.display()))
}
