//! Running the real binary in tests: a child process whose output lines can be awaited with
//! a timeout, stopped with SIGTERM, and killed when the test ends.

use std::ffi::OsStr;
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// Lines of a child's pipe, delivered through a channel so waits can time out.
pub fn lines_of(pipe: impl std::io::Read + Send + 'static) -> Receiver<String> {
    let (tx, rx) = channel();
    std::thread::spawn(move || {
        for line in BufReader::new(pipe).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

/// Waits up to `wait` for a line matching `want`, keeping every line seen in `seen`.
pub fn wait_for(
    rx: &Receiver<String>,
    seen: &mut Vec<String>,
    wait: Duration,
    what: &str,
    want: impl Fn(&str) -> bool,
) {
    let deadline = Instant::now() + wait;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match rx.recv_timeout(left) {
            Ok(line) => {
                let hit = want(&line);
                seen.push(line);
                if hit {
                    return;
                }
            }
            Err(_) => break,
        }
    }
    panic!(
        "timed out after {wait:?} waiting for {what}; last lines: {:#?}",
        seen.iter().rev().take(8).collect::<Vec<_>>()
    );
}

/// A running `chassisd` with its stdin, stdout lines and stderr lines.
pub struct Proc {
    /// The process.
    pub child: Child,
    /// Its standard input.
    pub stdin: Option<ChildStdin>,
    /// Its standard output, line by line.
    pub stdout: Receiver<String>,
    /// Its standard error, line by line.
    pub stderr: Receiver<String>,
    /// Every stdout line seen so far.
    pub out: Vec<String>,
    /// Every stderr line seen so far.
    pub log: Vec<String>,
}

impl Proc {
    /// Starts `chassisd ARGS`.
    pub fn start<S: AsRef<OsStr>>(args: &[S]) -> Proc {
        Self::start_under(&[], args)
    }

    /// Starts `chassisd ARGS` with `env` added to its environment.
    pub fn start_with_env<S: AsRef<OsStr>>(args: &[S], env: &[(&str, &str)]) -> Proc {
        Self::spawn(&[], args, env)
    }

    /// Starts `WRAPPER... chassisd ARGS` (e.g. under strace).
    pub fn start_under<S: AsRef<OsStr>>(wrapper: &[&str], args: &[S]) -> Proc {
        Self::spawn(wrapper, args, &[])
    }

    fn spawn<S: AsRef<OsStr>>(wrapper: &[&str], args: &[S], env: &[(&str, &str)]) -> Proc {
        let mut command = match wrapper.split_first() {
            Some((program, rest)) => {
                let mut c = Command::new(program);
                c.args(rest).arg(super::chassisd());
                c
            }
            None => Command::new(super::chassisd()),
        };
        let mut child = command
            .args(args)
            .env("RUST_LOG", "info")
            .envs(env.iter().copied())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("chassisd starts");
        Proc {
            stdin: child.stdin.take(),
            stdout: lines_of(child.stdout.take().expect("piped stdout")),
            stderr: lines_of(child.stderr.take().expect("piped stderr")),
            child,
            out: Vec::new(),
            log: Vec::new(),
        }
    }

    /// Writes one line to its standard input.
    pub fn send(&mut self, line: &str) {
        if let Some(stdin) = &mut self.stdin {
            writeln!(stdin, "{line}").expect("write to stdin");
            stdin.flush().expect("flush stdin");
        }
    }

    /// Writes raw bytes to its standard input.
    pub fn send_bytes(&mut self, bytes: &[u8]) {
        if let Some(stdin) = &mut self.stdin {
            stdin.write_all(bytes).expect("write to stdin");
            stdin.flush().expect("flush stdin");
        }
    }

    /// Waits for a stdout line matching `want`.
    pub fn wait_out(&mut self, wait: Duration, what: &str, want: impl Fn(&str) -> bool) {
        wait_for(&self.stdout, &mut self.out, wait, what, want);
    }

    /// Waits for a stderr line containing `text`.
    pub fn wait_log(&mut self, wait: Duration, text: &str) {
        wait_for(&self.stderr, &mut self.log, wait, text, |l| {
            l.contains(text)
        });
    }

    /// As [`Proc::wait_log`], satisfied too by a line seen before.
    pub fn wait_log_seen(&mut self, wait: Duration, text: &str) {
        if !self.log.iter().any(|l| l.contains(text)) {
            self.wait_log(wait, text);
        }
    }

    /// Takes every stdout line that has arrived, without waiting.
    pub fn drain_out(&mut self) -> &[String] {
        let before = self.out.len();
        self.out.extend(self.stdout.try_iter());
        &self.out[before..]
    }

    /// Waits for the process to exit by itself within `wait` (`what` names the wait in the
    /// failure), and returns its status.
    pub fn wait_exit(&mut self, wait: Duration, what: &str) -> std::process::ExitStatus {
        let deadline = Instant::now() + wait;
        loop {
            if let Some(exit) = self.child.try_wait().expect("process status") {
                return exit;
            }
            assert!(Instant::now() < deadline, "{what}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// How many stderr lines so far contain `text` (those arrived are taken first).
    pub fn log_count(&mut self, text: &str) -> usize {
        self.log.extend(self.stderr.try_iter());
        self.log.iter().filter(|l| l.contains(text)).count()
    }

    /// Stops it with SIGTERM, checks it exits cleanly within ten seconds, and returns every
    /// stdout line.
    pub fn stop(mut self) -> Vec<String> {
        kill(Pid::from_raw(self.child.id() as i32), Signal::SIGTERM).expect("signal");
        let exit = self.wait_exit(Duration::from_secs(10), "no exit within 10 s of SIGTERM");
        assert!(exit.success(), "exit status {exit}");
        let mut out = std::mem::take(&mut self.out);
        out.extend(self.stdout.iter());
        out
    }

    /// [`Proc::stop`], returning every stderr (log) line instead.
    pub fn stop_log(mut self) -> Vec<String> {
        kill(Pid::from_raw(self.child.id() as i32), Signal::SIGTERM).expect("signal");
        let exit = self.wait_exit(Duration::from_secs(10), "no exit within 10 s of SIGTERM");
        assert!(exit.success(), "exit status {exit}");
        let mut log = std::mem::take(&mut self.log);
        log.extend(self.stderr.iter());
        log
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Resident memory of process `pid`, MB.
pub fn rss_mb(pid: u32) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))?
                .split_whitespace()
                .nth(1)?
                .parse::<f64>()
                .ok()
        })
        .map_or(0.0, |kib| kib / 1024.0)
}

/// Open descriptors of process `pid`.
pub fn descriptors(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count())
}

/// The processes `pid` started (any of its threads).
pub fn children_of(pid: u32) -> Vec<u32> {
    std::fs::read_dir(format!("/proc/{pid}/task"))
        .map(|tasks| {
            tasks
                .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("children")).ok())
                .flat_map(|c| {
                    c.split_whitespace()
                        .filter_map(|p| p.parse().ok())
                        .collect::<Vec<u32>>()
                })
                .collect()
        })
        .unwrap_or_default()
}
