//! A private network namespace for tests that multicast (DDS discovery): loopback up with
//! a multicast route on it and no other interface, so no packet can reach any other
//! address. A holder process keeps the namespace; every process of the test enters it.
//! As root the namespace is a network one only; otherwise a user namespace maps the user
//! to root inside it.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

/// The namespace, for as long as this lives.
pub struct NetNs {
    holder: Child,
    as_root: bool,
}

impl NetNs {
    /// A new namespace, set up and ready.
    pub fn new() -> NetNs {
        // SAFETY: geteuid has no preconditions.
        let as_root = unsafe { libc::geteuid() } == 0;
        let unshare = if as_root { "-n" } else { "-rn" };
        let mut holder = Command::new("unshare")
            .args([
                unshare,
                "sh",
                "-c",
                "ip link set lo up && ip link set lo multicast on \
                 && ip route add 224.0.0.0/4 dev lo && echo ready && exec sleep 3600",
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("unshare (util-linux) starts");
        let mut line = String::new();
        BufReader::new(holder.stdout.take().expect("piped"))
            .read_line(&mut line)
            .expect("the namespace's set-up answers");
        assert_eq!(line.trim(), "ready", "the namespace could not be set up");
        NetNs { holder, as_root }
    }

    /// The command prefix that runs a program inside the namespace.
    pub fn wrapper(&self) -> Vec<String> {
        let pid = self.holder.id();
        let mut wrapper = vec!["nsenter".to_owned(), format!("--net=/proc/{pid}/ns/net")];
        if !self.as_root {
            wrapper.push(format!("--user=/proc/{pid}/ns/user"));
            wrapper.push("--preserve-credentials".to_owned());
        }
        wrapper
    }

    /// `program` to be run inside the namespace.
    pub fn command(&self, program: &str) -> Command {
        let wrapper = self.wrapper();
        let mut command = Command::new(&wrapper[0]);
        command.args(&wrapper[1..]).arg(program);
        command
    }
}

impl Drop for NetNs {
    fn drop(&mut self) {
        let _ = self.holder.kill();
        let _ = self.holder.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inside_there_is_loopback_alone() {
        let ns = NetNs::new();
        let out = ns
            .command("ip")
            .args(["-o", "link"])
            .output()
            .expect("ip runs inside");
        let text = String::from_utf8_lossy(&out.stdout);
        let links: Vec<&str> = text.lines().collect();
        assert_eq!(links.len(), 1, "{text}");
        assert!(links[0].contains(": lo:"), "{text}");
    }
}
