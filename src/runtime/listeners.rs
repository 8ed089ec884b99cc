//! The ports chassisd's own servers listen on, so the ROS1 node's socket filter
//! (`links::ros1::bind`), which finds roslibrust's listeners among the process's sockets,
//! leaves them alone.

use std::sync::Mutex;

static OWN: Mutex<Vec<u16>> = Mutex::new(Vec::new());

/// Notes that a server of chassisd's own listens on `port`.
pub fn own(port: u16) {
    lock().push(port);
}

/// Whether `port` is one of chassisd's own servers'.
pub fn is_own(port: u16) -> bool {
    lock().contains(&port)
}

fn lock() -> std::sync::MutexGuard<'static, Vec<u16>> {
    // A plain list: a panic elsewhere cannot leave it half-written.
    OWN.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}
