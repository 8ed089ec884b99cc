//! Reconnect manners shared by a fleet: exponential back-off with full jitter, and the walk
//! over a link's brokers.
//!
//! Each wait is drawn evenly between zero and a bound that starts at the link's
//! `reconnect_min_s` and doubles per failed attempt up to `reconnect_max_s`. Without the
//! draw, every vehicle that lost the same broker node at the same instant would come back
//! at the same instants, each wave as large as the fleet; with it, the returns spread over
//! the bound's window (the "full jitter" of AWS's architecture note on back-off).

use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Waits between connection attempts.
pub struct Backoff {
    first: Duration,
    max: Duration,
    /// Attempts failed since the last session, or since the link started.
    failures: u32,
    rng: ChaCha8Rng,
}

impl Backoff {
    /// Bounds from `first` doubling to `max`, draws seeded by `seed` (each vehicle its own:
    /// [`crate::secret::unguessable`]).
    pub fn new(first: Duration, max: Duration, seed: u64) -> Self {
        Self {
            first,
            max: max.max(first),
            failures: 0,
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// The bound of the next wait: `first × 2^failures`, at most `max`.
    pub fn bound(&self) -> Duration {
        let doublings = self.failures.min(30);
        self.first
            .checked_mul(1 << doublings)
            .map_or(self.max, |b| b.min(self.max))
    }

    /// The wait before the next attempt, drawn evenly from zero to [`Backoff::bound`]; each
    /// call counts one more failure.
    pub fn next_wait(&mut self) -> Duration {
        let bound = self.bound();
        self.failures = self.failures.saturating_add(1);
        bound.mul_f64(self.rng.random::<f64>())
    }

    /// A session was established: the next loss starts from the first bound again.
    pub fn reset(&mut self) {
        self.failures = 0;
    }
}

/// Which of a link's brokers the next attempt goes to: a lost session is tried again on
/// its broker first (a blip, or a node back at once), a failed attempt moves on to the
/// next broker in the list, wrapping round.
#[derive(Debug, Clone)]
pub struct BrokerWalk {
    count: usize,
    current: usize,
}

impl BrokerWalk {
    /// A walk over `count` brokers, starting at the first.
    pub fn new(count: usize) -> Self {
        Self {
            count: count.max(1),
            current: 0,
        }
    }

    /// The broker the next attempt goes to.
    pub fn current(&self) -> usize {
        self.current
    }

    /// An attempt to connect failed: the next goes to the next broker.
    pub fn attempt_failed(&mut self) {
        self.current = (self.current + 1) % self.count;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_double_from_the_first_to_the_largest() {
        let mut b = Backoff::new(Duration::from_millis(100), Duration::from_secs(2), 1);
        let mut bounds = Vec::new();
        for _ in 0..8 {
            bounds.push(b.bound().as_millis());
            b.next_wait();
        }
        assert_eq!(bounds, [100, 200, 400, 800, 1600, 2000, 2000, 2000]);
        b.reset();
        assert_eq!(b.bound(), Duration::from_millis(100));
        // Thousands of failures neither overflow nor pass the largest bound.
        for _ in 0..5000 {
            assert!(b.next_wait() <= Duration::from_secs(2));
        }
    }

    /// A fleet that lost one node at one instant: each vehicle's first wait is spread
    /// evenly over the first bound, so no tenth of the window takes much more than a
    /// tenth of the fleet.
    #[test]
    fn a_fleets_first_waits_spread_evenly_over_the_window() {
        let window = Duration::from_secs(1);
        let fleet = 10_000;
        let mut per_tenth = [0usize; 10];
        for vehicle in 0..fleet {
            let mut b = Backoff::new(window, Duration::from_secs(30), vehicle);
            let wait = b.next_wait();
            assert!(wait <= window);
            per_tenth[((wait.as_secs_f64() / window.as_secs_f64()) * 10.0).min(9.0) as usize] += 1;
        }
        // Evenly: 1000 a tenth; a binomial's spread is about 30.
        for n in per_tenth {
            assert!((850..=1150).contains(&n), "{per_tenth:?}");
        }
    }

    #[test]
    fn a_failed_attempt_moves_to_the_next_broker_and_wraps_round() {
        let mut w = BrokerWalk::new(3);
        let mut seen = vec![w.current()];
        for _ in 0..4 {
            w.attempt_failed();
            seen.push(w.current());
        }
        assert_eq!(seen, [0, 1, 2, 0, 1]);
        let mut one = BrokerWalk::new(1);
        one.attempt_failed();
        assert_eq!(one.current(), 0);
    }
}
