//! The radio model plugged into the in-process transport: each robot transmits through one
//! channel of `bandwidth_kbps` (a packet waits for the ones before it; one that would wait
//! behind more than `queue_bytes` is dropped), then `latency_ms` of propagation plus a uniform
//! `jitter_ms` (so packets overtake each other); a packet is lost with probability `loss` and
//! arrives twice with probability `duplicate`; robots farther apart than `range_m` (true
//! positions, set by the runner every step) cannot hear each other, nor robots on two sides of a
//! partition while it lasts. Seeded: the same run drops, doubles and reorders the same packets.

use crate::scenario::{PartitionSpec, RadioSpec};
use nalgebra::Point3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use sgm_actors::transport::RadioModel;
use sgm_model::scene_graph::{RobotId, Stamp};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex, PoisonError};

/// What happened to the packets.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RadioStats {
    pub delivered: u64,
    pub lost: u64,
    pub out_of_range: u64,
    pub queue_full: u64,
    /// Packets delivered a second time.
    pub duplicated: u64,
    /// Packets that could not cross a partition.
    pub partitioned: u64,
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

/// A partition with its robot names resolved to ids.
struct Partition {
    start_s: Stamp,
    end_s: Stamp,
    side: BTreeSet<RobotId>,
}

impl Partition {
    /// `names[k]` is robot `k + 1`; names not in the team are ignored (validation refuses them).
    fn resolve(spec: &PartitionSpec, names: &[String]) -> Self {
        let side = names
            .iter()
            .enumerate()
            .filter(|(_, n)| spec.robots.contains(n))
            .map(|(k, _)| RobotId::from_index(k))
            .collect();
        Self { start_s: spec.start_s, end_s: spec.end_s, side }
    }

    fn separates(&self, a: RobotId, b: RobotId, now: Stamp) -> bool {
        now >= self.start_s && now < self.end_s && self.side.contains(&a) != self.side.contains(&b)
    }
}

pub struct SimulatedRadio {
    spec: RadioSpec,
    partitions: Vec<Partition>,
    rng: ChaCha8Rng,
    channel_free: BTreeMap<RobotId, Stamp>,
    shared: RadioShared,
}

impl SimulatedRadio {
    /// `names`: the team's robot names in id order (robot `k + 1` is `names[k]`), for partitions.
    pub fn new(spec: &RadioSpec, seed: u64, shared: RadioShared, names: &[String]) -> Self {
        Self {
            spec: spec.clone(),
            partitions: spec.partitions.iter().map(|p| Partition::resolve(p, names)).collect(),
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x0052_4144_494f),
            channel_free: BTreeMap::new(),
            shared,
        }
    }

    fn bytes_per_s(&self) -> f64 {
        self.spec.bandwidth_kbps * 125.0
    }

    /// Latency plus this copy's jitter, s.
    fn delay(&mut self) -> f64 {
        let jitter = if self.spec.jitter_ms > 0.0 { self.rng.random_range(0.0..self.spec.jitter_ms) } else { 0.0 };
        (self.spec.latency_ms + jitter) / 1000.0
    }
}

impl RadioModel for SimulatedRadio {
    fn arrivals(&mut self, from: RobotId, to: RobotId, bytes: usize, now: Stamp) -> Vec<Stamp> {
        let rate = self.bytes_per_s();
        let shared = self.shared.clone();
        let mut medium = shared.lock();
        let (positions, stats) = &mut *medium;
        if self.partitions.iter().any(|p| p.separates(from, to, now)) {
            stats.partitioned += 1;
            return Vec::new();
        }
        if self.spec.range_m > 0.0 {
            let distance = match (positions.get(&from), positions.get(&to)) {
                (Some(a), Some(b)) => (a - b).norm(),
                _ => f64::INFINITY,
            };
            if distance > self.spec.range_m {
                stats.out_of_range += 1;
                return Vec::new();
            }
        }
        let start = self.channel_free.get(&from).copied().unwrap_or(now).max(now);
        if (start - now) * rate > self.spec.queue_bytes as f64 {
            stats.queue_full += 1;
            return Vec::new();
        }
        let done = start + bytes as f64 / rate;
        self.channel_free.insert(from, done);
        // A lost packet still used the channel.
        if self.spec.loss > 0.0 && self.rng.random_bool(self.spec.loss) {
            stats.lost += 1;
            return Vec::new();
        }
        stats.delivered += 1;
        let mut arrivals = vec![done + self.delay()];
        if self.spec.duplicate > 0.0 && self.rng.random_bool(self.spec.duplicate) {
            stats.duplicated += 1;
            // The retransmission follows the first copy by one more trip.
            arrivals.push(done + self.delay() + self.delay());
        }
        arrivals
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
        let mut radio = SimulatedRadio::new(&spec, 1, shared.clone(), &[]);
        let (a, b) = (RobotId(1), RobotId(2));
        shared.set_position(a, Point3::origin());
        shared.set_position(b, Point3::new(30.0, 0.0, 0.0));
        // 1000 bytes/s: a 500-byte packet takes 0.5 s, then 0.1 s of latency.
        assert_eq!(radio.arrivals(a, b, 500, 10.0).len(), 1);
        // The next one waits for the first.
        let second = radio.arrivals(a, b, 500, 10.0);
        assert!((second[0] - 11.1).abs() < 1e-9, "{second:?}");
        // 1000 bytes already queued: fine; then 2001 → the one after is dropped.
        assert!(!radio.arrivals(a, b, 1001, 10.0).is_empty());
        assert!(radio.arrivals(a, b, 10, 10.0).is_empty());
        shared.set_position(b, Point3::new(60.0, 0.0, 0.0));
        assert!(radio.arrivals(a, b, 10, 100.0).is_empty());
        let stats = shared.stats();
        assert_eq!((stats.delivered, stats.queue_full, stats.out_of_range), (3, 1, 1));
    }

    #[test]
    fn loss_is_seeded_and_near_its_rate() {
        let spec = RadioSpec { loss: 0.3, ..RadioSpec::default() };
        let run = || {
            let mut radio = SimulatedRadio::new(&spec, 7, RadioShared::default(), &[]);
            (0..2000).map(|k| !radio.arrivals(RobotId(1), RobotId(2), 10, k as f64).is_empty()).collect::<Vec<_>>()
        };
        let (a, b) = (run(), run());
        assert_eq!(a, b);
        let lost = a.iter().filter(|d| !**d).count() as f64 / 2000.0;
        assert!((lost - 0.3).abs() < 0.04, "{lost}");
    }

    #[test]
    fn first_packet_arrives_after_transmission_and_latency() {
        let spec = RadioSpec { bandwidth_kbps: 8.0, latency_ms: 100.0, ..RadioSpec::default() };
        let mut radio = SimulatedRadio::new(&spec, 1, RadioShared::default(), &[]);
        // 1000 bytes/s: a 500-byte packet takes 0.5 s, then 0.1 s of latency.
        let at = radio.arrivals(RobotId(1), RobotId(2), 500, 10.0);
        assert_eq!(at.len(), 1);
        assert!((at[0] - 10.6).abs() < 1e-9, "{at:?}");
    }

    #[test]
    fn duplicates_come_later_and_at_their_rate() {
        let spec = RadioSpec { duplicate: 0.25, latency_ms: 10.0, ..RadioSpec::default() };
        let shared = RadioShared::default();
        let mut radio = SimulatedRadio::new(&spec, 3, shared.clone(), &[]);
        let mut doubled = 0;
        for k in 0..4000 {
            let at = radio.arrivals(RobotId(1), RobotId(2), 10, k as f64);
            assert!(!at.is_empty() && at.len() <= 2);
            if let [first, second] = at[..] {
                assert!(second > first);
                doubled += 1;
            }
        }
        assert!((doubled as f64 / 4000.0 - 0.25).abs() < 0.03, "{doubled}");
        assert_eq!(shared.stats().duplicated, doubled);
    }

    #[test]
    fn jitter_reorders_packets_within_its_bound() {
        let spec = RadioSpec { jitter_ms: 200.0, latency_ms: 20.0, bandwidth_kbps: 1e6, ..RadioSpec::default() };
        let mut radio = SimulatedRadio::new(&spec, 5, RadioShared::default(), &[]);
        let arrivals: Vec<f64> =
            (0..1000).map(|k| radio.arrivals(RobotId(1), RobotId(2), 10, k as f64 * 0.01)[0]).collect();
        let overtaken = arrivals.windows(2).filter(|w| w[1] < w[0]).count();
        assert!(overtaken > 100, "{overtaken} of 999 overtaken");
        for (k, at) in arrivals.iter().enumerate() {
            let delay = at - k as f64 * 0.01;
            assert!((0.02..0.2201).contains(&delay), "{delay}");
        }
    }

    #[test]
    fn a_partition_cuts_across_its_sides_until_it_heals() {
        let names = ["a".to_string(), "b".to_string(), "c".to_string()];
        let partition = PartitionSpec { start_s: 10.0, end_s: 20.0, robots: vec!["a".into(), "b".into()] };
        let spec = RadioSpec { partitions: vec![partition], ..RadioSpec::default() };
        let shared = RadioShared::default();
        let mut radio = SimulatedRadio::new(&spec, 1, shared.clone(), &names);
        let (a, b, c) = (RobotId(1), RobotId(2), RobotId(3));
        let heard = |radio: &mut SimulatedRadio, x, y, t| !radio.arrivals(x, y, 10, t).is_empty();
        assert!(heard(&mut radio, a, c, 9.9));
        assert!(!heard(&mut radio, a, c, 10.0));
        assert!(!heard(&mut radio, c, b, 15.0));
        assert!(heard(&mut radio, a, b, 15.0), "one side hears itself");
        assert!(heard(&mut radio, c, a, 20.0), "healed");
        assert_eq!(shared.stats().partitioned, 2);
    }
}
