//! Gives freed heap memory back to the operating system on a schedule.
//!
//! glibc's allocator keeps the freed pages of its per-thread arenas for reuse, so a burst (a
//! command flood through the embedded broker, a large trajectory) leaves resident memory at
//! the burst's high-water mark, and each new peak raises it a little more. The soak saw the
//! live heap flat at about 7 MB for eight minutes while resident memory crept up 1.4 MB.
//! `malloc_trim` hands back every whole free page, in the middle of the arenas too.
//!
//! glibc also raises its mmap threshold each time a large block it had mapped is freed, so
//! later blocks of that size come from the arenas, where they stay resident after use: the
//! soak saw 800 KB mapped blocks move into the arenas one by one over ten minutes, which a
//! resident-memory slope reads as growth. A fixed threshold keeps large blocks mapped and
//! returned to the system the moment they are freed. And each of glibc's arenas (up to
//! eight per core, one per thread that allocates at once) keeps partly used pages of its
//! own; two arenas stop the creep that remained after trims.

use std::time::{Duration, Instant};

/// How often freed memory is handed back: often enough that a burst's pages go back within
/// seconds. A trim takes 20–160 µs in `chassisd sim` on the embedded broker, and holds only
/// the arena it is trimming, so the control loop's allocations wait at most that long.
const PERIOD: Duration = Duration::from_secs(10);

/// Blocks of this size and larger are mapped on their own and unmapped when freed: glibc's
/// default starting threshold, held fixed.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MMAP_THRESHOLD: libc::c_int = 128 * 1024;

/// Heap arenas at most. glibc gives threads up to eight arenas per core; each keeps its own
/// partly used pages, which no trim can hand back. chassisd allocates little outside bursts,
/// so two arenas cost no measurable contention, and the soak's resident memory stops
/// creeping after a few fault cycles (with the default it crept 4.8 MB/h after trims).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const ARENA_MAX: libc::c_int = 2;

/// Sets the allocator up for a process that runs for months: a fixed mmap threshold
/// (setting it turns glibc's dynamic raise off) and at most [`ARENA_MAX`] arenas. Call it
/// first in `main`, before any thread starts, so every thread shares those arenas. Returns
/// whether the allocator took both; without glibc its own policy stands.
pub fn tune_allocator() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; it has no preconditions.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
            && libc::mallopt(libc::M_ARENA_MAX, ARENA_MAX) == 1
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    false
}

/// Hands freed heap pages back now; what it took. Without glibc, the allocator's own
/// policy stands and this does nothing.
pub fn release_free_memory() -> Duration {
    let start = Instant::now();
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim takes the allocator's own locks and only releases pages that hold
    // no live allocation; it has no preconditions.
    unsafe {
        libc::malloc_trim(0);
    }
    start.elapsed()
}

/// Starts the periodic release on a blocking thread of the runtime (the trim walks every
/// arena under its lock); it stops with the runtime.
pub fn spawn() {
    tokio::spawn(crate::runtime::panics::restarting(
        "heap release",
        || async {
            let mut interval = tokio::time::interval(PERIOD);
            interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                interval.tick().await;
                match tokio::task::spawn_blocking(release_free_memory).await {
                    Ok(took) => tracing::trace!(?took, "freed heap pages handed back"),
                    Err(_) => return,
                }
            }
        },
    ));
}
