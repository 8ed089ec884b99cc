//! The process's file descriptors, shared out so that no network client can take the last
//! ones: the CAN sockets, serial ports, recordings and trajectory files the vehicle needs
//! must open whatever clients do. At start the soft `RLIMIT_NOFILE` is raised to the hard
//! one (at most [`MOST`]); client sockets may then hold all but [`RESERVED`] of it. Every
//! server takes a permit for each connection it accepts, or closes the connection at once.

use std::sync::{Arc, OnceLock};

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// Descriptors kept for devices, files, pipes, the runtime and the children's standard
/// streams: a vehicle opens a few dozen; the rest is margin for reconnects that open the
/// new socket before the old one is closed.
pub const RESERVED: u64 = 256;
/// The soft limit is raised no further than this: enough for every server's caps many
/// times over, and small enough for the kernel's default `nr_open` (1,048,576).
pub const MOST: u64 = 1 << 16;

/// The process's soft limit and the client sockets' permits.
struct Budget {
    limit: u64,
    sockets: Arc<Semaphore>,
}

static BUDGET: OnceLock<Budget> = OnceLock::new();

fn budget() -> &'static Budget {
    BUDGET.get_or_init(|| {
        let limit = raise_limit();
        Budget {
            limit,
            sockets: Arc::new(Semaphore::new(client_budget(limit))),
        }
    })
}

/// Raises the limit (once) and sets the budget; called at start so that everything the
/// process opens sees the raised limit. Returns the soft limit.
pub fn init() -> u64 {
    budget().limit
}

/// The permits of client sockets: one per accepted connection, given back when it closes.
pub fn client_sockets() -> Arc<Semaphore> {
    budget().sockets.clone()
}

/// A permit for one more client socket, or `None` when the budget is spent (the caller
/// closes the connection at once and counts it).
pub fn try_acquire() -> Option<OwnedSemaphorePermit> {
    client_sockets().try_acquire_owned().ok()
}

/// Client sockets allowed under a soft limit of `limit` descriptors.
pub fn client_budget(limit: u64) -> usize {
    usize::try_from(limit.saturating_sub(RESERVED))
        .unwrap_or(usize::MAX)
        .min(Semaphore::MAX_PERMITS)
}

/// Sets the soft `RLIMIT_NOFILE` to the hard limit (at most [`MOST`]) when it is lower;
/// returns the soft limit in force.
fn raise_limit() -> u64 {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes the struct it is given and nothing else.
    if unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) } != 0 {
        // Unknown: the common default, so the budget errs small.
        return 1024;
    }
    let want = limit.rlim_max.min(MOST);
    if limit.rlim_cur < want {
        let raised = libc::rlimit {
            rlim_cur: want,
            rlim_max: limit.rlim_max,
        };
        // SAFETY: setrlimit reads the struct it is given; raising the soft limit up to the
        // hard one needs no privilege.
        if unsafe { libc::setrlimit(libc::RLIMIT_NOFILE, &raised) } == 0 {
            return want;
        }
    }
    limit.rlim_cur
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_budget_keeps_the_reserve_and_the_limit_is_raised() {
        assert_eq!(client_budget(1024), 768);
        assert_eq!(client_budget(100), 0);
        let limit = init();
        let mut now = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: as in raise_limit.
        assert_eq!(unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut now) }, 0);
        assert_eq!(now.rlim_cur, limit);
        assert_eq!(limit, now.rlim_max.min(MOST).max(limit));
        assert_eq!(client_sockets().available_permits(), client_budget(limit));
    }
}
