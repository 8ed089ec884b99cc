//! What to do when a serial port does not open: the advice follows the reason, so a port
//! another program holds is not blamed on the cable.

use std::io::ErrorKind as Io;

use tokio_serial::{Error, ErrorKind};

/// The next step for a person whose `port` failed to open with `error`.
pub fn advice(port: &str, error: &Error) -> String {
    let held = error.description.contains("lock")
        || (error.kind == ErrorKind::NoDevice && error.description.contains("busy"));
    if held {
        return format!(
            "another program holds {port}, most often a running chassisd: stop it first \
             (`sudo systemctl stop chassisd`), or see who holds it with `fuser -v {port}`"
        );
    }
    match error.kind {
        ErrorKind::Io(Io::PermissionDenied) => format!(
            "this user may not open {port}: add it to the group that owns the port \
             (`ls -l {port}`, most often dialout: `sudo usermod -aG dialout $USER`, then log \
             in again)"
        ),
        ErrorKind::Io(Io::NotFound) | ErrorKind::NoDevice => format!(
            "no device at {port}: check the path (`ls -l /dev/serial/by-id/`) and the cable"
        ),
        _ => format!(
            "check the path of {port} (`ls -l /dev/serial/by-id/`), the cable, and that this \
             user may open it (group dialout)"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_reason_gets_its_own_advice() {
        let lock = Error::new(
            ErrorKind::NoDevice,
            "Unable to acquire exclusive lock on serial port",
        );
        let held = advice("/dev/ttyUSB0", &lock);
        assert!(held.contains("another program holds"), "{held}");
        assert!(!held.contains("cable"), "{held}");
        let denied = Error::new(ErrorKind::Io(Io::PermissionDenied), "Permission denied");
        assert!(advice("/dev/ttyUSB0", &denied).contains("dialout"));
        let missing = Error::new(ErrorKind::Io(Io::NotFound), "No such file or directory");
        assert!(advice("/dev/ttyUSB0", &missing).contains("no device at /dev/ttyUSB0"));
    }
}
