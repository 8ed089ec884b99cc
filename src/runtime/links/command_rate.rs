//! A per-topic rate limit on incoming MQTT commands, so a flooding client costs chassisd a
//! map lookup per message instead of a decode, an engine step and a reply each.
//!
//! Each topic has a token bucket (`rate` per second, up to `burst` at once). A command
//! without a token is refused before anything else sees it: no reply (a reply per refused
//! message would be a flood of its own), no record. The log says so once when refusing
//! starts on a topic, then sums up every [`SUMMARY_EVERY`] while it goes on.
//!
//! The wildcard subscriptions let a client invent topic names. Where the topics that mean
//! something are known (the MQTT dialects'), every other name shares one slow bucket
//! ([`UNKNOWN_RATE_HZ`]), so inventing names buys nothing. Otherwise the buckets are
//! bounded: when [`MAX_TOPICS`] are tracked, full buckets (idle topics) are forgotten, and
//! if none is idle, new topics share one bucket.

use std::collections::{BTreeMap, HashMap};
use std::time::{Duration, Instant};

/// Topics tracked at most.
pub const MAX_TOPICS: usize = 256;
/// How often a flood is summed up in the log.
pub const SUMMARY_EVERY: Duration = Duration::from_secs(5);
/// The bucket new topics share when [`MAX_TOPICS`] are busy.
const SHARED: &str = "(other topics)";
/// The bucket every name outside the known topics shares.
const UNKNOWN: &str = "(unknown topics)";
/// Messages per second on unknown topics altogether: enough to answer a mistyped topic,
/// too few to be worth a flood.
pub const UNKNOWN_RATE_HZ: f64 = 1.0;
/// Messages at once on unknown topics before [`UNKNOWN_RATE_HZ`] applies.
pub const UNKNOWN_BURST: f64 = 5.0;

#[derive(Debug, Clone, Copy)]
struct Bucket {
    tokens: f64,
    at: Instant,
}

/// The limiter of one MQTT link.
#[derive(Debug)]
pub struct CommandRate {
    rate_hz: f64,
    burst: f64,
    buckets: HashMap<String, Bucket>,
    /// Refused since the last summary, by topic (sorted for a stable log line).
    refused: BTreeMap<String, u64>,
    last_summary: Option<Instant>,
    /// The topics that mean something, when known: others share [`UNKNOWN`].
    known: Option<std::collections::HashSet<String>>,
}

/// What the log should say now.
#[derive(Debug, Clone, PartialEq)]
pub enum RateReport {
    /// Refusing started on this topic.
    Started(String),
    /// Refused per topic over the last period.
    Summary(Vec<(String, u64)>),
}

impl CommandRate {
    /// `rate_hz` commands per second per topic, `burst` at once (both positive).
    pub fn new(rate_hz: f64, burst: u32) -> Self {
        Self {
            rate_hz,
            burst: f64::from(burst.max(1)),
            buckets: HashMap::new(),
            refused: BTreeMap::new(),
            last_summary: None,
            known: None,
        }
    }

    /// Only `topics` get buckets of their own; every other name shares one slow bucket.
    pub fn with_known_topics(mut self, topics: impl IntoIterator<Item = String>) -> Self {
        self.known = Some(topics.into_iter().collect());
        self
    }

    /// Whether a command on `topic` arriving at `now` may pass; takes its token. The second
    /// value is what to log, if anything.
    pub fn admit(&mut self, topic: &str, now: Instant) -> (bool, Option<RateReport>) {
        let unknown = self.known.as_ref().is_some_and(|k| !k.contains(topic));
        let (rate, burst) = if unknown {
            (UNKNOWN_RATE_HZ, UNKNOWN_BURST)
        } else {
            (self.rate_hz, self.burst)
        };
        let key = if unknown {
            UNKNOWN
        } else if self.buckets.contains_key(topic) || self.make_room(now) {
            topic
        } else {
            SHARED
        };
        let bucket = self.buckets.entry(key.to_owned()).or_insert(Bucket {
            tokens: burst,
            at: now,
        });
        refill(bucket, now, rate, burst);
        if bucket.tokens >= 1.0 {
            bucket.tokens -= 1.0;
            return (true, None);
        }
        let count = self.refused.entry(key.to_owned()).or_insert(0);
        *count += 1;
        let report = if *count == 1 && self.last_summary.is_none() {
            self.last_summary = Some(now);
            Some(RateReport::Started(key.to_owned()))
        } else {
            None
        };
        (false, report)
    }

    /// The summary due at `now`, if refusing went on over the last period. Cheap when not.
    pub fn due_summary(&mut self, now: Instant) -> Option<RateReport> {
        let since = self.last_summary?;
        if now.saturating_duration_since(since) < SUMMARY_EVERY {
            return None;
        }
        if self.refused.is_empty() {
            // The flood is over: the next refusal starts a new one.
            self.last_summary = None;
            return None;
        }
        self.last_summary = Some(now);
        let counts = std::mem::take(&mut self.refused).into_iter().collect();
        Some(RateReport::Summary(counts))
    }

    /// Whether a new topic may have a bucket of its own; forgets idle ones to make room.
    fn make_room(&mut self, now: Instant) -> bool {
        if self.buckets.len() < MAX_TOPICS {
            return true;
        }
        let (rate, burst) = (self.rate_hz, self.burst);
        self.buckets.retain(|topic, bucket| {
            refill(bucket, now, rate, burst);
            topic == SHARED || bucket.tokens < burst
        });
        self.buckets.len() < MAX_TOPICS
    }
}

fn refill(bucket: &mut Bucket, now: Instant, rate: f64, burst: f64) {
    let dt = now.saturating_duration_since(bucket.at).as_secs_f64();
    bucket.tokens = (bucket.tokens + dt * rate).min(burst);
    bucket.at = now;
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn admitted(limiter: &mut CommandRate, topic: &str, now: Instant, n: usize) -> usize {
        (0..n).filter(|_| limiter.admit(topic, now).0).count()
    }

    #[test]
    fn invented_topic_names_share_one_slow_bucket() {
        let t0 = Instant::now();
        let mut limiter = CommandRate::new(50.0, 50).with_known_topics(["mqtt_control".to_owned()]);
        let invented = (0..10_000)
            .filter(|i| limiter.admit(&format!("device/SIM0001/x{i}"), t0).0)
            .count();
        assert_eq!(invented, UNKNOWN_BURST as usize);
        // The known topic keeps its own, full budget.
        assert_eq!(admitted(&mut limiter, "mqtt_control", t0, 100), 50);
        // Ten seconds later, ten more (and the burst is not refilled beyond its size).
        let later = t0 + Duration::from_secs(10);
        let more = (0..10_000)
            .filter(|i| limiter.admit(&format!("x/{i}"), later).0)
            .count();
        assert_eq!(more, UNKNOWN_BURST as usize);
        // The summary names the shared bucket, not each invented name.
        let Some(RateReport::Summary(counts)) = limiter.due_summary(later) else {
            panic!("a summary");
        };
        let names: Vec<&str> = counts.iter().map(|(t, _)| t.as_str()).collect();
        assert_eq!(names, [UNKNOWN, "mqtt_control"]);
    }

    #[test]
    fn a_burst_passes_then_the_rate_and_other_topics_keep_their_own_budget() {
        let t0 = Instant::now();
        let mut limiter = CommandRate::new(10.0, 5);
        assert_eq!(admitted(&mut limiter, "a", t0, 100), 5);
        assert_eq!(
            admitted(&mut limiter, "b", t0, 3),
            3,
            "b has its own bucket"
        );
        let t1 = t0 + Duration::from_millis(500);
        assert_eq!(admitted(&mut limiter, "a", t1, 100), 5, "10/s for 0.5 s");
        assert_eq!(limiter.refused["a"], 190);
    }

    #[test]
    fn a_flood_logs_once_at_its_start_then_a_summary_per_period_then_nothing() {
        let t0 = Instant::now();
        let mut limiter = CommandRate::new(1.0, 1);
        let mut reports = Vec::new();
        for ms in 0..12_000 {
            let now = t0 + Duration::from_millis(ms);
            if ms < 7_000 {
                reports.extend(limiter.admit("flood", now).1);
            }
            reports.extend(limiter.due_summary(now));
        }
        assert_eq!(reports.len(), 3, "{reports:?}");
        assert_eq!(reports[0], RateReport::Started("flood".into()));
        let RateReport::Summary(first) = &reports[1] else {
            panic!("{reports:?}")
        };
        assert_eq!(first.len(), 1);
        assert!(first[0].1 > 4_900, "{first:?}");
        // The flood ended at 7 s: the summary at 10 s holds its last 2 s, then silence.
        assert!(matches!(&reports[2], RateReport::Summary(s) if s[0].1 > 1_900 && s[0].1 < 2_000));
        assert_eq!(limiter.due_summary(t0 + Duration::from_secs(16)), None);
        let later = t0 + Duration::from_secs(60);
        limiter.admit("flood", later);
        assert!(matches!(
            limiter.admit("flood", later).1,
            Some(RateReport::Started(_))
        ));
    }

    #[test]
    fn invented_topic_names_cannot_grow_the_limiter() {
        let t0 = Instant::now();
        let mut limiter = CommandRate::new(10.0, 2);
        // Every topic stays busy (its bucket not yet refilled): new ones share a bucket.
        for i in 0..10_000 {
            limiter.admit(&format!("device/x/t{i}"), t0);
            limiter.admit(&format!("device/x/t{i}"), t0);
        }
        assert!(limiter.buckets.len() <= MAX_TOPICS + 1);
        // Once they are idle, new topics take their places.
        let later = t0 + Duration::from_secs(10);
        assert!(limiter.admit("device/x/new", later).0);
        assert!(limiter.buckets.len() <= MAX_TOPICS + 1);
        assert!(limiter.buckets.contains_key("device/x/new"));
    }

    proptest! {
        /// Over any arrival pattern, no topic gets more than burst + rate × elapsed commands.
        #[test]
        fn no_topic_exceeds_its_budget(
            rate in 0.5f64..200.0,
            burst in 1u32..50,
            arrivals in proptest::collection::vec((0u8..4, 0u64..50), 1..400),
        ) {
            let t0 = Instant::now();
            let mut limiter = CommandRate::new(rate, burst);
            let mut now = t0;
            let mut passed = [0u64; 4];
            for (topic, gap_ms) in arrivals {
                now += Duration::from_millis(gap_ms);
                if limiter.admit(&format!("t{topic}"), now).0 {
                    passed[topic as usize] += 1;
                }
            }
            let budget = f64::from(burst) + rate * (now - t0).as_secs_f64() + 1e-9;
            for p in passed {
                prop_assert!(p as f64 <= budget, "{p} > {budget}");
            }
        }
    }
}
