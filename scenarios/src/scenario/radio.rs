//! `[radio]`: the in-process radio's model (`sim::radio`), and its partitions.

use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RadioSpec {
    /// Each robot's transmit rate, kbit/s (shared by everything it sends). Default 2000.
    pub bandwidth_kbps: f64,
    /// Propagation and stack latency, ms. Default 20.
    pub latency_ms: f64,
    /// Probability that a packet is lost (per destination). Default 0.
    pub loss: f64,
    /// Probability that a delivered packet arrives a second time (a link-layer retransmission
    /// whose acknowledgement was lost), `jitter_ms` or up to a latency later. Default 0.
    pub duplicate: f64,
    /// Each copy of a packet is held back by a further uniform delay in [0, jitter_ms), so
    /// packets overtake each other (reordering), ms. Default 0.
    pub jitter_ms: f64,
    /// Robots farther apart cannot hear each other, m (0: unlimited). Default 0.
    pub range_m: f64,
    /// A packet that would wait behind more than this many bytes in the sender's queue is
    /// dropped. Default 4 000 000.
    pub queue_bytes: usize,
    /// Network partitions: while one is in force, the robots it names hear only each other and
    /// the rest hear only the rest. Default none.
    pub partitions: Vec<PartitionSpec>,
}

impl Default for RadioSpec {
    fn default() -> Self {
        Self {
            bandwidth_kbps: 2000.0,
            latency_ms: 20.0,
            loss: 0.0,
            duplicate: 0.0,
            jitter_ms: 0.0,
            range_m: 0.0,
            queue_bytes: 4_000_000,
            partitions: Vec::new(),
        }
    }
}

/// A partition of the team, from `start_s` until it heals at `end_s`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartitionSpec {
    /// When the link between the two sides is cut, s.
    pub start_s: f64,
    /// When it heals, s.
    pub end_s: f64,
    /// The robots (names) on one side; every other robot is on the other.
    pub robots: Vec<String>,
}
