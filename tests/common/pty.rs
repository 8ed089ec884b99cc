//! A pseudo-terminal standing in for a serial device.

use std::fs::File;
use std::io::Write;
use std::os::fd::{AsFd, FromRawFd, IntoRawFd, OwnedFd};
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;

use nix::fcntl::OFlag;
use nix::pty::{grantpt, posix_openpt, ptsname_r, unlockpt};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

/// A pty whose slave is reachable at `link`, like `/dev/serial/by-id/...`.
pub struct Port {
    /// The side the test writes to.
    pub master: File,
}

impl Port {
    pub fn open_at(link: &Path) -> Port {
        // Both ends open close-on-exec at once: tests of other modules spawn children from
        // other threads of the same binary at any moment, and a child that inherited the
        // master would keep the line from hanging up when the test closes it.
        let master =
            posix_openpt(OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_CLOEXEC).expect("posix_openpt");
        grantpt(&master).expect("grantpt");
        unlockpt(&master).expect("unlockpt");
        let path = ptsname_r(&master).expect("ptsname");
        // std opens with O_CLOEXEC.
        let slave = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            // Not the test process's controlling terminal.
            .custom_flags(OFlag::O_NOCTTY.bits())
            .open(&path)
            .expect("open the pty's slave");
        let mut termios = tcgetattr(slave.as_fd()).expect("tcgetattr");
        cfmakeraw(&mut termios);
        tcsetattr(slave.as_fd(), SetArg::TCSANOW, &termios).expect("tcsetattr");
        let _ = std::fs::remove_file(link);
        std::os::unix::fs::symlink(&path, link).expect("symlink");
        // The daemon opens the slave by path; the test keeps only the master.
        drop(slave);
        Port {
            // SAFETY: the descriptor was just taken out of `master`, which owned it alone.
            master: File::from(unsafe { OwnedFd::from_raw_fd(master.into_raw_fd()) }),
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
