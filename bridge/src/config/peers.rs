//! `[ros.peers]`: the queue, call timeout and back-off of each peer's link
//! (`transport::peer`).

use serde::{Deserialize, Serialize};
use std::time::Duration;

/// `[ros.peers]`: how envelopes addressed to one robot are sent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PeerConfig {
    /// Envelopes waiting per peer, at most; beyond it the oldest is dropped (counted).
    /// Default 256.
    pub queue: usize,
    /// One call to a peer's Deliver service — service lookup, connect, request and reply — ends
    /// after this long at most, s. Default 2.
    pub call_timeout_s: f64,
    /// First wait before probing a peer that stopped answering, s; doubled after every failed
    /// probe. Default 1.
    pub backoff_initial_s: f64,
    /// Longest wait between two probes of a peer that does not answer, s. Default 30.
    pub backoff_max_s: f64,
}

impl Default for PeerConfig {
    fn default() -> Self {
        Self { queue: 256, call_timeout_s: 2.0, backoff_initial_s: 1.0, backoff_max_s: 30.0 }
    }
}

impl PeerConfig {
    pub fn call_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.call_timeout_s)
    }
}
