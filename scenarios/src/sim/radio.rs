//! The radio model plugged into the in-process transport: each robot transmits through one
//! channel of `bandwidth_kbps` (a packet waits for the ones before it; one that would wait
//! behind more than `queue_bytes` is dropped), then `latency_ms` of propagation; a packet is
//! lost with probability `loss`, and robots farther apart than `range_m` (true positions, set
//! by the runner every step) cannot hear each other. Seeded: the same run drops the same packets.

use crate::scenario::RadioSpec;
use nalgebra::Point3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use sgm_actors::transport::RadioModel;
use sgm_model::scene_graph::{RobotId, Stamp};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, PoisonError};

/// What happened to the packets.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RadioStats {
    pub delivered: u64,
    pub lost: u64,
    pub out_of_range: u64,
    pub queue_full: u64,
}

/// True positions (set by the runner) and what happened to the packets.
type Medium = (BTreeMap<RobotId, Point3<f64>>, RadioStats);

/// State the runner shares with the model: true positions in, statistics out.
#[derive(Clone, Default)]
pub struct RadioShared {
    inner: Arc<Mutex<Medium>>,
}

impl RadioShared {
    fn lock(&self) -> std::sync::MutexGuard<'_, Medium> {
        self.inner.lock().unwrap_or_else(PoisonError::into_inner)
    }

    pub fn set_position(&self, robot: RobotId, position: Point3<f64>) {
        self.lock().0.insert(robot, position);
    }

    pub fn stats(&self) -> RadioStats {
        self.lock().1.clone()
    }
}

pub struct SimulatedRadio {
    spec: RadioSpec,
    rng: ChaCha8Rng,
    channel_free: BTreeMap<RobotId, Stamp>,
    shared: RadioShared,
}

impl SimulatedRadio {
    pub fn new(spec: &RadioSpec, seed: u64, shared: RadioShared) -> Self {
        Self {
            spec: spec.clone(),
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x0052_4144_494f),
            channel_free: BTreeMap::new(),
            shared,
        }
    }

    fn bytes_per_s(&self) -> f64 {
        self.spec.bandwidth_kbps * 125.0
    }
}

impl RadioModel for SimulatedRadio {
    fn arrival(&mut self, from: RobotId, to: RobotId, bytes: usize, now: Stamp) -> Option<Stamp> {
        let rate = self.bytes_per_s();
        let mut shared = self.shared.lock();
        let (positions, stats) = &mut *shared;
        if self.spec.range_m > 0.0 {
            let distance = match (positions.get(&from), positions.get(&to)) {
                (Some(a), Some(b)) => (a - b).norm(),
                _ => f64::INFINITY,
            };
            if distance > self.spec.range_m {
                stats.out_of_range += 1;
                return None;
            }
        }
        let start = self.channel_free.get(&from).copied().unwrap_or(now).max(now);
        if (start - now) * rate > self.spec.queue_bytes as f64 {
            stats.queue_full += 1;
            return None;
        }
        let done = start + bytes as f64 / rate;
        self.channel_free.insert(from, done);
        // A lost packet still used the channel.
        if self.spec.loss > 0.0 && self.rng.random_bool(self.spec.loss) {
            stats.lost += 1;
            return None;
        }
        stats.delivered += 1;
        Some(done + self.spec.latency_ms / 1000.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bandwidth_queues_latency_delays_range_cuts() {
        let spec = RadioSpec {
            bandwidth_kbps: 8.0,
            latency_ms: 100.0,
            range_m: 50.0,
            queue_bytes: 2000,
            ..RadioSpec::default()
        };
        let shared = RadioShared::default();
        let mut radio = SimulatedRadio::new(&spec, 1, shared.clone());
        let (a, b) = (RobotId(1), RobotId(2));
        shared.set_position(a, Point3::origin());
        shared.set_position(b, Point3::new(30.0, 0.0, 0.0));
        // 1000 bytes/s: a 500-byte packet takes 0.5 s, then 0.1 s of latency.
        assert!((radio.arrival(a, b, 500, 10.0).unwrap() - 10.6).abs() < 1e-9);
        // The next one waits for the first.
        assert!((radio.arrival(a, b, 500, 10.0).unwrap() - 11.1).abs() < 1e-9);
        // 1000 bytes already queued: fine; then 2001 → the one after is dropped.
        assert!(radio.arrival(a, b, 1001, 10.0).is_some());
        assert!(radio.arrival(a, b, 10, 10.0).is_none());
        shared.set_position(b, Point3::new(60.0, 0.0, 0.0));
        assert!(radio.arrival(a, b, 10, 100.0).is_none());
        let stats = shared.stats();
        assert_eq!((stats.delivered, stats.queue_full, stats.out_of_range), (3, 1, 1));
    }

    #[test]
    fn loss_is_seeded_and_near_its_rate() {
        let spec = RadioSpec { loss: 0.3, ..RadioSpec::default() };
        let run = || {
            let mut radio = SimulatedRadio::new(&spec, 7, RadioShared::default());
            (0..2000).map(|k| radio.arrival(RobotId(1), RobotId(2), 10, k as f64).is_some()).collect::<Vec<_>>()
        };
        let (a, b) = (run(), run());
        assert_eq!(a, b);
        let lost = a.iter().filter(|d| !**d).count() as f64 / 2000.0;
        assert!((lost - 0.3).abs() < 0.04, "{lost}");
    }
}
