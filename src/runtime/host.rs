//! Samples the host computer's CPU and memory use once a second (from /proc) and hands the
//! figures to the engine as records, so the root dialect can report them and recordings
//! replay them.

use std::time::Duration;

use bytes::Bytes;
use tokio::sync::mpsc;

use crate::engine::HOST_SOURCE;
use crate::record::{Payload, Record};
use crate::runtime::clock::RecordClock;
use crate::vehicle::HostUsage;

/// How often the load is sampled.
const PERIOD: Duration = Duration::from_secs(1);

/// CPU time counters of /proc/stat's first line: (busy, total), in ticks.
fn cpu_ticks(stat: &str) -> Option<(u64, u64)> {
    let line = stat.lines().find(|l| l.starts_with("cpu "))?;
    let fields: Vec<u64> = line
        .split_whitespace()
        .skip(1)
        .map(|f| f.parse().ok())
        .collect::<Option<_>>()?;
    let total: u64 = fields.iter().take(8).sum();
    // idle and iowait are not busy.
    let idle = fields.get(3)? + fields.get(4).copied().unwrap_or(0);
    Some((total.saturating_sub(idle), total))
}

/// The number after `name` in a /proc file of `Name: value kB` lines.
fn proc_field(text: &str, name: &str) -> Option<f64> {
    text.lines()
        .find(|l| l.starts_with(name))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

/// Memory in use from /proc/meminfo, % of the total.
fn memory_percent(meminfo: &str) -> Option<f64> {
    let total = proc_field(meminfo, "MemTotal:")?;
    let available = proc_field(meminfo, "MemAvailable:")?;
    (total > 0.0).then(|| (total - available) / total * 100.0)
}

/// This process's peak resident memory (VmHWM), bytes, where /proc tells it. Unlike
/// `getrusage`, it covers only this program, not the one that spawned it before exec.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    proc_field(&status, "VmHWM:").map(|kib| (kib * 1024.0) as u64)
}

/// This process's resident memory now (VmRSS), bytes, where /proc tells it.
pub fn resident_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    proc_field(&status, "VmRSS:").map(|kib| (kib * 1024.0) as u64)
}

/// This process's children whose command line holds `arg`: (process id, resident memory
/// in bytes), where /proc tells them. The embedded broker's process is one.
pub fn children_running(arg: &str) -> Vec<(u32, u64)> {
    let me = std::process::id();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    entries
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter_map(|pid| {
            let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
            let parent = proc_field(&status, "PPid:")? as u32;
            let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
            let ours = parent == me && cmdline.split(|&b| b == 0).any(|a| a == arg.as_bytes());
            let rss = proc_field(&status, "VmRSS:").map_or(0, |kib| (kib * 1024.0) as u64);
            ours.then_some((pid, rss))
        })
        .collect()
}

/// The CPU time process `pid` has used so far (user and system, every thread), seconds,
/// where /proc tells it.
pub fn process_cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    process_cpu_ticks(&stat).map(|ticks| ticks as f64 / clock_ticks_per_second())
}

/// utime + stime of a /proc/PID/stat line, in clock ticks. The command's name, in
/// parentheses, may hold spaces and parentheses: the fields start after the last `)`.
fn process_cpu_ticks(stat: &str) -> Option<u64> {
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    // After the name: state is field 3, utime 14 and stime 15.
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    Some(utime + stime)
}

/// The kernel's clock ticks per second (USER_HZ), which /proc's CPU times count.
fn clock_ticks_per_second() -> f64 {
    // SAFETY: sysconf has no preconditions.
    match unsafe { libc::sysconf(libc::_SC_CLK_TCK) } {
        n if n > 0 => n as f64,
        _ => 100.0,
    }
}

/// CPU busy between two samples, %.
fn cpu_percent(before: (u64, u64), now: (u64, u64)) -> Option<f64> {
    let total = now.1.checked_sub(before.1)?;
    let busy = now.0.checked_sub(before.0)?;
    (total > 0).then(|| busy as f64 / total as f64 * 100.0)
}

/// Starts the sampler; it stops when the engine goes.
pub fn spawn(clock: RecordClock, tx: mpsc::Sender<Record>) {
    tokio::spawn(crate::runtime::panics::restarting(
        "host sampler",
        move || sample(clock, tx.clone()),
    ));
}

/// Sends the host's CPU and memory use every [`PERIOD`] until the engine goes.
async fn sample(clock: RecordClock, tx: mpsc::Sender<Record>) {
    let mut interval = tokio::time::interval(PERIOD);
    let mut before = None;
    loop {
        interval.tick().await;
        // /proc is served from memory: a plain read does not block the runtime.
        let stat = std::fs::read_to_string("/proc/stat").ok();
        let meminfo = std::fs::read_to_string("/proc/meminfo").ok();
        let now = stat.as_deref().and_then(cpu_ticks);
        let cpu = before.zip(now).and_then(|(b, n)| cpu_percent(b, n));
        before = now;
        let (Some(cpu), Some(memory)) = (cpu, meminfo.as_deref().and_then(memory_percent)) else {
            continue;
        };
        let usage = HostUsage { cpu, memory };
        let Ok(json) = serde_json::to_vec(&usage) else {
            continue;
        };
        let record = Record {
            t: clock.now(),
            source: HOST_SOURCE.into(),
            payload: Payload::Command {
                topic: "usage".into(),
                payload: Bytes::from(json),
            },
        };
        if tx.send(record).await.is_err() {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_process_cpu_time_is_read_past_its_name() {
        let stat = "42 (a) b) (c) S 1 42 42 0 -1 4194560 100 0 0 0 250 75 0 0 20 0 3 0 1000";
        assert_eq!(process_cpu_ticks(stat), Some(325));
        assert_eq!(process_cpu_ticks("42 (cut"), None);
        let me = process_cpu_seconds(std::process::id()).unwrap();
        assert!(me >= 0.0);
    }

    #[test]
    fn proc_figures_are_read() {
        let a = cpu_ticks("cpu  100 0 50 800 50 0 0 0 0 0\ncpu0 1 2 3 4\n").unwrap();
        let b = cpu_ticks("cpu  150 0 100 850 50 0 0 0 0 0\n").unwrap();
        let cpu = cpu_percent(a, b).unwrap();
        assert!((cpu - 200.0 / 3.0).abs() < 1e-9, "{cpu}");
        let m = "MemTotal:       1000 kB\nMemFree: 1 kB\nMemAvailable:    250 kB\n";
        assert_eq!(memory_percent(m), Some(75.0));
        assert_eq!(cpu_ticks("garbage"), None);
        assert_eq!(memory_percent("MemTotal: 0 kB\nMemAvailable: 0 kB"), None);
    }

    #[test]
    fn this_machine_reports_plausible_figures() {
        let stat = std::fs::read_to_string("/proc/stat").unwrap();
        let (busy, total) = cpu_ticks(&stat).unwrap();
        assert!(busy <= total && total > 0);
        let m = memory_percent(&std::fs::read_to_string("/proc/meminfo").unwrap()).unwrap();
        assert!((0.0..=100.0).contains(&m));
    }
}
