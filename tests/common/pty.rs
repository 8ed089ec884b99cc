//! A pseudo-terminal standing in for a serial device.

use std::fs::File;
use std::io::Write;
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::Path;

use nix::fcntl::{FcntlArg, FdFlag, fcntl};
use nix::pty::openpty;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
use nix::unistd::ttyname;

/// A pty whose slave is reachable at `link`, like `/dev/serial/by-id/...`.
pub struct Port {
    /// The side the test writes to.
    pub master: File,
}

impl Port {
    pub fn open_at(link: &Path) -> Port {
        let pty = openpty(None, None).expect("openpty");
        // Children must not inherit the master, or closing it here would not hang up the
        // line. (Tests in this file hold SERIAL while they open ptys and spawn, so no other
        // thread forks in between.)
        for fd in [pty.master.as_fd(), pty.slave.as_fd()] {
            fcntl(fd.as_raw_fd(), FcntlArg::F_SETFD(FdFlag::FD_CLOEXEC)).expect("cloexec");
        }
        let mut termios = tcgetattr(pty.slave.as_fd()).expect("tcgetattr");
        cfmakeraw(&mut termios);
        tcsetattr(pty.slave.as_fd(), SetArg::TCSANOW, &termios).expect("tcsetattr");
        let path = ttyname(pty.slave.as_fd()).expect("ttyname");
        let _ = std::fs::remove_file(link);
        std::os::unix::fs::symlink(&path, link).expect("symlink");
        // The daemon opens the slave by path; the test keeps only the master.
        drop::<OwnedFd>(pty.slave);
        Port {
            master: File::from(pty.master),
        }
    }

    pub fn send(&mut self, sentence_body: &str) {
        send_on(&mut self.master, sentence_body);
    }
}

/// Writes `sentence_body` as a whole NMEA sentence (checksum and line end) to a pty master.
pub fn send_on(master: &mut File, sentence_body: &str) {
    let checksum = sentence_body.bytes().fold(0u8, |a, b| a ^ b);
    let line = format!("${sentence_body}*{checksum:02X}\r\n");
    master.write_all(line.as_bytes()).expect("write to pty");
}

/// A receiver on a pty: GGA (RTK fixed) and RMC at 10 Hz until dropped.
pub struct Talker {
    running: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

impl Talker {
    pub fn start(mut port: Port) -> Talker {
        use std::sync::atomic::Ordering;
        let running = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
        let flag = running.clone();
        std::thread::spawn(move || {
            while flag.load(Ordering::Relaxed) {
                for body in [
                    "GNGGA,120000.00,2301.5,N,11301.17918515,E,4,20,0.6,12.3,M,-6.1,M,1.0,0123",
                    "GNRMC,120000.00,A,2301.5,N,11301.17918515,E,0.0,0.0,241126,,,R",
                ] {
                    let sum = body.bytes().fold(0u8, |a, b| a ^ b);
                    let _ = port
                        .master
                        .write_all(format!("${body}*{sum:02X}\r\n").as_bytes());
                }
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
        });
        Talker { running }
    }
}

impl Drop for Talker {
    fn drop(&mut self) {
        self.running
            .store(false, std::sync::atomic::Ordering::Relaxed);
    }
}
