//! Latency per frame, as the node sees it: from the moment a sensor frame is handed to the robot
//! (assembled from its cloud, odometry and label image) to the moment the Tracker has handled it
//! (its pose decided, the map updated: [`FrameProgress`]). A thread of its own polls the
//! progress every [`POLL`], so a figure is late by at most that. Wall time is read here, never
//! in a handler: the robot decides nothing from it.

use serde::Serialize;
use sgm_actors::progress::FrameProgress;
use sgm_model::scene_graph::Stamp;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, PoisonError, Weak};
use std::time::{Duration, Instant};

/// How often the progress is read.
pub const POLL: Duration = Duration::from_millis(2);
/// Histogram bin, ms; the last bin holds everything from `BINS × BIN_MS` on.
const BIN_MS: f64 = 0.5;
const BINS: usize = 20_000;
/// Frames waiting to be seen handled, at most (the oldest is forgotten).
const MAX_PENDING: usize = 10_000;

/// A summary of the latencies measured so far.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LatencySummary {
    pub frames: u64,
    pub mean_ms: f64,
    pub p50_ms: f64,
    pub p95_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
}

#[derive(Default)]
struct Histogram {
    bins: Vec<u64>,
    count: u64,
    sum_ms: f64,
    max_ms: f64,
}

impl Histogram {
    fn add(&mut self, ms: f64) {
        if self.bins.is_empty() {
            self.bins = vec![0; BINS];
        }
        let bin = ((ms / BIN_MS) as usize).min(BINS - 1);
        self.bins[bin] += 1;
        self.count += 1;
        self.sum_ms += ms;
        self.max_ms = self.max_ms.max(ms);
    }

    /// The upper edge of the bin holding quantile `q`.
    fn quantile(&self, q: f64) -> f64 {
        let rank = ((q * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (k, n) in self.bins.iter().enumerate() {
            seen += n;
            if seen >= rank {
                return ((k + 1) as f64 * BIN_MS).min(self.max_ms);
            }
        }
        self.max_ms
    }

    fn summary(&self) -> LatencySummary {
        if self.count == 0 {
            return LatencySummary::default();
        }
        LatencySummary {
            frames: self.count,
            mean_ms: self.sum_ms / self.count as f64,
            p50_ms: self.quantile(0.5),
            p95_ms: self.quantile(0.95),
            p99_ms: self.quantile(0.99),
            max_ms: self.max_ms,
        }
    }
}

/// Frames handed to the robot and not yet seen handled, and the latencies of those that were.
pub struct Latency {
    pending: Mutex<VecDeque<(Stamp, Instant)>>,
    histogram: Mutex<Histogram>,
}

impl Latency {
    /// Starts measuring against `progress`; the polling thread ends with the last `Arc`.
    pub fn start(progress: FrameProgress) -> Arc<Self> {
        let latency = Arc::new(Self { pending: Mutex::default(), histogram: Mutex::default() });
        let weak: Weak<Self> = Arc::downgrade(&latency);
        let spawned = std::thread::Builder::new().name("sgm-latency".into()).spawn(move || {
            while let Some(latency) = weak.upgrade() {
                latency.poll(progress.latest(), Instant::now());
                drop(latency);
                std::thread::sleep(POLL);
            }
        });
        if let Err(e) = spawned {
            tracing::warn!("latency not measured: no thread: {e}");
        }
        latency
    }

    /// A frame stamped `stamp` was handed to the robot now.
    pub fn handed(&self, stamp: Stamp) {
        let mut pending = self.pending.lock().unwrap_or_else(PoisonError::into_inner);
        if pending.len() >= MAX_PENDING {
            pending.pop_front();
        }
        pending.push_back((stamp, Instant::now()));
    }

    /// Every frame stamped at or before `handled` was handled by `now`.
    fn poll(&self, handled: Stamp, now: Instant) {
        let mut done = Vec::new();
        {
            let mut pending = self.pending.lock().unwrap_or_else(PoisonError::into_inner);
            while pending.front().is_some_and(|(s, _)| *s <= handled) {
                if let Some((_, at)) = pending.pop_front() {
                    done.push(now.saturating_duration_since(at).as_secs_f64() * 1e3);
                }
            }
        }
        let mut histogram = self.histogram.lock().unwrap_or_else(PoisonError::into_inner);
        for ms in done {
            histogram.add(ms);
        }
    }

    pub fn summary(&self) -> LatencySummary {
        self.histogram.lock().unwrap_or_else(PoisonError::into_inner).summary()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_a_known_distribution() {
        let mut h = Histogram::default();
        for k in 1..=100 {
            h.add(f64::from(k)); // 1 … 100 ms
        }
        let s = h.summary();
        assert_eq!(s.frames, 100);
        assert!((s.mean_ms - 50.5).abs() < 1e-9);
        // Upper bin edges, 0.5 ms wide: the 50th value (50 ms) lies in [50, 50.5).
        assert_eq!((s.p50_ms, s.p95_ms, s.p99_ms, s.max_ms), (50.5, 95.5, 99.5, 100.0));
    }

    #[test]
    fn frames_are_timed_from_handed_to_handled() {
        let latency = Arc::new(Latency { pending: Mutex::default(), histogram: Mutex::default() });
        let t0 = Instant::now();
        latency.pending.lock().unwrap().extend([(1.0, t0), (2.0, t0), (3.0, t0)]);
        latency.poll(2.0, t0 + Duration::from_millis(30));
        assert_eq!(latency.summary().frames, 2, "frames 1 and 2 handled, 3 not yet");
        assert!((latency.summary().max_ms - 30.0).abs() < 1e-6);
        latency.poll(f64::NEG_INFINITY, t0 + Duration::from_millis(40));
        assert_eq!(latency.summary().frames, 2);
    }
}
