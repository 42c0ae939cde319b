//! Traffic accounting per message type (count, bytes total / mean / max) and refused messages
//! per reason: what the reports' message table (paper Table 4) reads.

use super::envelope::WireError;
use super::messages::MessageKind;
use super::replay::ReplayError;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Sizes of the messages of one type.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TrafficStats {
    pub count: u64,
    pub bytes_total: u64,
    pub bytes_max: u64,
}

impl TrafficStats {
    pub fn bytes_mean(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.bytes_total as f64 / self.count as f64
        }
    }

    pub fn merge(&mut self, other: &TrafficStats) {
        self.count += other.count;
        self.bytes_total += other.bytes_total;
        self.bytes_max = self.bytes_max.max(other.bytes_max);
    }
}

/// Messages sent or received, per type.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TrafficAccount {
    pub by_kind: BTreeMap<MessageKind, TrafficStats>,
}

impl TrafficAccount {
    pub fn record(&mut self, kind: MessageKind, bytes: usize) {
        let s = self.by_kind.entry(kind).or_default();
        s.count += 1;
        s.bytes_total += bytes as u64;
        s.bytes_max = s.bytes_max.max(bytes as u64);
    }

    pub fn get(&self, kind: MessageKind) -> TrafficStats {
        self.by_kind.get(&kind).copied().unwrap_or_default()
    }

    pub fn bytes_total(&self) -> u64 {
        self.by_kind.values().map(|s| s.bytes_total).sum()
    }

    pub fn merge(&mut self, other: &TrafficAccount) {
        for (kind, s) in &other.by_kind {
            self.by_kind.entry(*kind).or_default().merge(s);
        }
    }
}

/// Received envelopes refused, per reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RejectionCounts {
    /// Wrong team key or altered in flight.
    pub bad_mac: u64,
    pub replayed: u64,
    pub oversized: u64,
    pub truncated: u64,
    pub wrong_version: u64,
    /// Authenticated but not decodable, or beyond a per-message limit.
    pub malformed: u64,
}

impl RejectionCounts {
    pub fn record_wire(&mut self, e: &WireError) {
        match e {
            WireError::TooShort(_) => self.truncated += 1,
            WireError::TooLarge { .. } => self.oversized += 1,
            WireError::BadMac => self.bad_mac += 1,
            WireError::Version { .. } => self.wrong_version += 1,
            WireError::Malformed(_) | WireError::Limit { .. } => self.malformed += 1,
        }
    }

    pub fn record_replay(&mut self, _: &ReplayError) {
        self.replayed += 1;
    }

    pub fn total(&self) -> u64 {
        self.bad_mac + self.replayed + self.oversized + self.truncated + self.wrong_version + self.malformed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_means_and_maxima() {
        let mut a = TrafficAccount::default();
        a.record(MessageKind::ObjectData, 100);
        a.record(MessageKind::ObjectData, 300);
        a.record(MessageKind::KeyframeRequest, 25);
        let s = a.get(MessageKind::ObjectData);
        assert_eq!((s.count, s.bytes_total, s.bytes_max, s.bytes_mean()), (2, 400, 300, 200.0));
        assert_eq!(a.get(MessageKind::KeyframeResponse), TrafficStats::default());
        let mut b = TrafficAccount::default();
        b.record(MessageKind::ObjectData, 500);
        b.merge(&a);
        assert_eq!(b.get(MessageKind::ObjectData).bytes_max, 500);
        assert_eq!(b.bytes_total(), 925);
    }
}
