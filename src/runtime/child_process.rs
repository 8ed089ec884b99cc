//! What chassisd's own helper processes (the embedded broker, the ROS1 node) share: the
//! program they run, how their end is told, and the memory they hold. Each runs a part that
//! network clients reach, so that its faults (a panic, memory or descriptors taken by a
//! client) end that process, never the one that holds the drives and the control loop.

use std::path::{Path, PathBuf};
use std::process::Stdio;

use crate::runtime::error::{RuntimeError, io};

/// The program a helper process runs: chassisd itself, through /proc/self/exe, the very
/// file this process runs, even after a package upgrade replaced the one at its path (a
/// restart then starts the same version, not the new one).
pub fn self_exe(what: &str) -> Result<PathBuf, RuntimeError> {
    let this = PathBuf::from("/proc/self/exe");
    if this.exists() {
        return Ok(this);
    }
    std::env::current_exe().map_err(io(format!("{what}: finding chassisd's program")))
}

/// The command that starts helper process `subcommand` of `exe`: its settings go in on
/// standard input, its reports come out on standard output, its log goes to chassisd's.
/// Its environment has no backtraces: a client can make a helper end on purpose (an
/// allocation over its memory limit), and a backtrace would then read the program's debug
/// information (measured: 291 MB and seconds for the ROS1 node) and write a hundred lines
/// for each end, where chassisd logs one saying why.
pub fn helper_command(exe: &Path, subcommand: &str) -> std::process::Command {
    let mut command = std::process::Command::new(exe);
    command
        .arg(subcommand)
        .env("RUST_BACKTRACE", "0")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    command
}

/// Makes any panic end this helper process (exit status 101) after `what`'s line, so that
/// chassisd starts a whole one rather than keep one a panic left half-dead.
pub fn end_on_panic(what: &'static str) {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        report(info);
        crate::runtime::stderr::line(format!(
            "chassisd {what}: panic; the process ends and chassisd restarts it"
        ));
        std::process::exit(101);
    }));
}

/// A process's end in words: its exit status (with the meaning of those in `known`), or
/// the signal that ended it.
pub fn describe_exit(status: std::process::ExitStatus, known: &[(i32, &str)]) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(101), _) => "it panicked (exit status 101)".into(),
        (Some(code), _) => match known.iter().find(|(c, _)| *c == code) {
            Some((_, meaning)) => format!("{meaning} (exit status {code})"),
            None => format!("exit status {code}"),
        },
        (None, Some(libc::SIGABRT)) => {
            "it aborted (signal 6: an allocation over its memory limit, or a fault)".into()
        }
        (None, Some(signal)) => format!("killed by signal {signal}"),
        (None, None) => "ended".into(),
    }
}

/// The resident memory of process `pid`, MB; `None` when it cannot be read (gone).
pub fn rss_mb(pid: u32) -> Option<u64> {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|status| {
            status
                .lines()
                .find(|l| l.starts_with("VmRSS:"))?
                .split_whitespace()
                .nth(1)?
                .parse::<u64>()
                .ok()
        })
        .map(|kib| kib / 1024)
}

/// Sets a resource limit of this process, soft and hard (lowering it for good).
pub fn limit(resource: libc::__rlimit_resource_t, value: u64) -> std::io::Result<()> {
    let limit = libc::rlimit {
        rlim_cur: value,
        rlim_max: value,
    };
    // SAFETY: setrlimit reads the struct it is given and nothing else.
    if unsafe { libc::setrlimit(resource, &limit) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::process::ExitStatusExt;

    #[test]
    fn exits_are_told_by_their_meaning() {
        let known = [(75, "it stopped answering its probe")];
        let exit = |code: i32| std::process::ExitStatus::from_raw(code << 8);
        assert_eq!(
            describe_exit(exit(101), &known),
            "it panicked (exit status 101)"
        );
        assert_eq!(
            describe_exit(exit(75), &known),
            "it stopped answering its probe (exit status 75)"
        );
        assert_eq!(describe_exit(exit(3), &known), "exit status 3");
        let signalled = std::process::ExitStatus::from_raw(libc::SIGKILL);
        assert_eq!(describe_exit(signalled, &known), "killed by signal 9");
    }

    #[test]
    fn this_process_memory_is_read() {
        assert!(rss_mb(std::process::id()).is_some());
        assert_eq!(rss_mb(u32::MAX), None);
    }
}
