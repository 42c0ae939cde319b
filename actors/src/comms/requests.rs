//! Keyframe requests, per neighbour: plain state that takes what happened and `now`, and says
//! what to send. Keyframes are coalesced over `request_window_s`, at most
//! `max_keyframes_in_flight` are asked for at once, and one held, in flight or already waiting
//! is never asked for again; beyond `max_keyframes_waiting` a keyframe is refused locally. A
//! request that times out is retried with back-off (at once when the neighbour was heard since:
//! the answer was lost), then given up. Towards a neighbour whose link is down nothing is
//! retried or given up: it is probed once per `link_timeout_s`, and when it is heard again its
//! unanswered requests are asked afresh.
//!
//! Every keyframe wanted is accounted in exactly one way: `wanted = received + refused +
//! given_up + pending` ([`KeyframeLedger`]).

use super::status::KeyframeLedger;
use crate::config::CommsConfig;
use crate::protocol::Wait;
use sgm_model::scene_graph::{KeyframeId, RobotId, Stamp};
use std::collections::{BTreeMap, BTreeSet};

/// Keyframe requests to one neighbour.
#[derive(Clone, Debug, Default)]
pub struct KeyframeRequests {
    /// Wanted, not yet asked for (coalescing).
    wanted: BTreeSet<KeyframeId>,
    in_flight: BTreeMap<KeyframeId, Wait>,
    /// Received and still held by the Matcher (it reports those it lets go).
    held: BTreeSet<KeyframeId>,
    /// Answered "not here" (or undecodable), and not wanted since.
    refused: BTreeSet<KeyframeId>,
    /// Every retry timed out, or too many were waiting; not wanted since.
    given_up: BTreeSet<KeyframeId>,
    window_opened: Option<Stamp>,
    /// Since when requests have been in flight without a break (for the link timeout).
    owed_since: Option<Stamp>,
    /// While the link is down: when it was last probed.
    last_probe: Option<Stamp>,
}

/// What one flush asks Comms to do towards one neighbour.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Flush {
    /// Keyframe requests to send, each at most `max_keyframes_per_request` ids.
    pub requests: Vec<Vec<KeyframeId>>,
    /// Keyframes given up on now (to report to the Matcher).
    pub given_up: Vec<KeyframeId>,
    /// Keyframes in flight after the flush.
    pub in_flight: usize,
}

/// What a keyframe response means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResponseFate {
    /// A late duplicate of a retried request: ignore it.
    Duplicate,
    /// Take it (decode it, and say whether it was good with [`KeyframeRequests::decoded`]).
    Take,
}

impl KeyframeRequests {
    pub fn ledger(&self) -> KeyframeLedger {
        let pending = (self.wanted.len() + self.in_flight.len()) as u64;
        let (received, refused, given_up) =
            (self.held.len() as u64, self.refused.len() as u64, self.given_up.len() as u64);
        KeyframeLedger { wanted: received + refused + given_up + pending, received, refused, given_up, pending }
    }

    /// Queues `ids` for the next request window: never one held, in flight or already queued;
    /// beyond `max_keyframes_waiting`, refused locally (returned, counted as given up).
    pub fn want(
        &mut self,
        ids: impl IntoIterator<Item = KeyframeId>,
        now: Stamp,
        config: &CommsConfig,
    ) -> Vec<KeyframeId> {
        let mut overflow = Vec::new();
        for id in ids {
            if self.held.contains(&id) || self.in_flight.contains_key(&id) || self.wanted.contains(&id) {
                continue;
            }
            if self.wanted.len() < config.max_keyframes_waiting {
                self.wanted.insert(id);
                self.given_up.remove(&id);
                self.refused.remove(&id);
            } else {
                overflow.push(id);
                self.given_up.insert(id);
            }
        }
        if !self.wanted.is_empty() && self.window_opened.is_none() {
            self.window_opened = Some(now);
        }
        overflow
    }

    /// What to send now. Link down (`link_up` false): only a probe, once per `link_timeout_s`; otherwise
    /// timeouts retried (`heard_at`: when the neighbour was last heard) or given up, and the
    /// waiting keyframes asked once the coalescing window has passed, within the bound.
    pub fn flush(&mut self, now: Stamp, link_up: bool, heard_at: Option<Stamp>, config: &CommsConfig) -> Flush {
        if !link_up {
            let mut flush = Flush { in_flight: self.in_flight.len(), ..Flush::default() };
            if self.last_probe.is_none_or(|t| now - t >= config.link_timeout_s) {
                self.last_probe = Some(now);
                flush.requests.push(self.in_flight.keys().take(config.max_keyframes_per_request).copied().collect());
            }
            return flush;
        }
        let expired: Vec<(KeyframeId, Wait)> =
            self.in_flight.iter().filter(|(_, w)| w.expired(now)).map(|(k, w)| (*k, *w)).collect();
        let (mut retry, mut given_up) = (Vec::new(), Vec::new());
        for (id, wait) in expired {
            let heard = heard_at.is_some_and(|t| t >= wait.sent);
            match wait.retry(now, &config.retry, heard) {
                Some(next) => {
                    self.in_flight.insert(id, next);
                    retry.push(id);
                }
                None => {
                    self.in_flight.remove(&id);
                    self.given_up.insert(id);
                    given_up.push(id);
                }
            }
        }
        let window_passed = self.window_opened.is_some_and(|t| now - t >= config.request_window_s);
        let mut fresh = Vec::new();
        if window_passed {
            let room = config.max_keyframes_in_flight.saturating_sub(self.in_flight.len());
            fresh = self.wanted.iter().copied().take(room).collect();
            for id in &fresh {
                self.wanted.remove(id);
                self.in_flight.insert(*id, Wait::new(now, &config.retry));
            }
            self.window_opened = if self.wanted.is_empty() { None } else { Some(now) };
        }
        self.owed_since = if self.in_flight.is_empty() { None } else { self.owed_since.or(Some(now)) };
        let mut ids = retry;
        ids.extend(fresh);
        let requests = ids.chunks(config.max_keyframes_per_request).map(<[KeyframeId]>::to_vec).collect();
        Flush { requests, given_up, in_flight: self.in_flight.len() }
    }

    /// Since when requests have been in flight without a break.
    pub fn owed_since(&self) -> Option<Stamp> {
        self.owed_since
    }

    /// The neighbour is heard again after its link was down: its unanswered requests are asked
    /// afresh in the next window.
    pub fn link_back(&mut self, now: Stamp) {
        let unanswered: Vec<KeyframeId> = self.in_flight.keys().copied().collect();
        self.in_flight.clear();
        self.owed_since = None;
        self.last_probe = None;
        self.wanted.extend(unanswered);
        if !self.wanted.is_empty() {
            self.window_opened = Some(now);
        }
    }

    /// A response for `id` arrived.
    pub fn response(&mut self, id: KeyframeId) -> ResponseFate {
        let asked = self.in_flight.remove(&id).is_some() | self.wanted.remove(&id);
        if !asked && self.held.contains(&id) {
            return ResponseFate::Duplicate;
        }
        // One given up on that arrives late after all is received.
        self.given_up.remove(&id);
        ResponseFate::Take
    }

    /// The response for `id` decoded (`true`: held now) or did not (refused).
    pub fn decoded(&mut self, id: KeyframeId, ok: bool) {
        if ok {
            self.held.insert(id);
        } else {
            self.refused.insert(id);
        }
    }

    /// The neighbour answered that it has none of `ids` (those in flight are refused).
    pub fn refused(&mut self, ids: &[KeyframeId]) {
        for id in ids {
            if self.in_flight.remove(id).is_some() {
                self.refused.insert(*id);
            }
        }
    }

    /// The Matcher let `ids` go.
    pub fn released(&mut self, ids: &[KeyframeId]) {
        for id in ids {
            self.held.remove(id);
        }
    }

    pub fn held(&self) -> &BTreeSet<KeyframeId> {
        &self.held
    }

    /// Restored from a snapshot: the keyframes held.
    pub fn with_held(held: BTreeSet<KeyframeId>) -> Self {
        Self { held, ..Self::default() }
    }
}

/// Every neighbour's requests.
pub type RequestBook = BTreeMap<RobotId, KeyframeRequests>;

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> CommsConfig {
        CommsConfig {
            request_window_s: 0.5,
            max_keyframes_in_flight: 3,
            max_keyframes_waiting: 5,
            max_keyframes_per_request: 2,
            link_timeout_s: 10.0,
            ..CommsConfig::default()
        }
    }

    fn ids(v: &[u32]) -> Vec<KeyframeId> {
        v.iter().map(|&k| KeyframeId(k)).collect()
    }

    /// Coalesced over the window, bounded in flight, chunked, never asked twice, refused
    /// locally beyond the waiting bound; the ledger adds up.
    #[test]
    fn requests_coalesce_and_stay_bounded() {
        let c = config();
        let mut q = KeyframeRequests::default();
        assert!(q.want(ids(&[1, 2]), 0.0, &c).is_empty());
        assert_eq!(q.flush(0.2, true, None, &c).requests, Vec::<Vec<KeyframeId>>::new(), "the window is open");
        assert!(q.want(ids(&[2, 3, 4, 5]), 0.3, &c).is_empty());
        let f = q.flush(0.5, true, None, &c);
        assert_eq!(f.requests, vec![ids(&[1, 2]), ids(&[3])], "three in flight, two per request");
        assert_eq!(f.in_flight, 3);
        assert_eq!(q.want(ids(&[1, 6, 7, 8, 9]), 0.6, &c), ids(&[9]), "1 is in flight; 9 is one too many");
        let ledger = q.ledger();
        assert_eq!((ledger.wanted, ledger.pending, ledger.given_up), (9, 8, 1));
        assert_eq!(q.response(KeyframeId(1)), ResponseFate::Take);
        q.decoded(KeyframeId(1), true);
        assert_eq!(q.response(KeyframeId(1)), ResponseFate::Duplicate, "a late duplicate");
        assert!(q.want(ids(&[1]), 0.7, &c).is_empty(), "held: never asked again");
        assert_eq!(q.ledger().received, 1);
    }

    /// Timeouts retry with back-off, at once when the neighbour was heard since, then give up;
    /// a given-up keyframe that arrives late is received after all.
    #[test]
    fn timeouts_retry_then_give_up() {
        let c = CommsConfig {
            retry: crate::protocol::RetryConfig { timeout_s: 1.0, backoff: 2.0, max_retries: 1 },
            ..config()
        };
        let mut q = KeyframeRequests::default();
        q.want(ids(&[7]), 0.0, &c);
        q.flush(0.5, true, None, &c);
        assert_eq!(q.flush(1.4, true, None, &c).requests, Vec::<Vec<KeyframeId>>::new(), "not yet expired");
        assert_eq!(q.flush(1.5, true, None, &c).requests, vec![ids(&[7])], "retried");
        let f = q.flush(3.6, true, None, &c);
        assert_eq!((f.requests.len(), f.given_up.clone()), (0, ids(&[7])), "given up after the retries");
        assert_eq!(q.ledger().given_up, 1);
        assert_eq!(q.response(KeyframeId(7)), ResponseFate::Take);
        q.decoded(KeyframeId(7), true);
        assert_eq!((q.ledger().given_up, q.ledger().received), (0, 1));
    }

    /// A link down: only probes, once per link timeout; back up: the unanswered asked afresh.
    #[test]
    fn a_link_down_is_probed_and_its_requests_asked_again_when_back() {
        let c = config();
        let mut q = KeyframeRequests::default();
        q.want(ids(&[1, 2, 3]), 0.0, &c);
        q.flush(0.5, true, None, &c);
        assert_eq!(q.owed_since(), Some(0.5));
        assert_eq!(q.flush(100.0, false, None, &c).requests, vec![ids(&[1, 2])], "a probe");
        assert!(q.flush(105.0, false, None, &c).requests.is_empty(), "once per link timeout");
        assert!(q.flush(1000.0, false, None, &c).given_up.is_empty(), "nothing given up while down");
        q.link_back(1001.0);
        assert_eq!(q.owed_since(), None);
        assert_eq!(q.flush(1001.5, true, Some(1001.0), &c).requests, vec![ids(&[1, 2]), ids(&[3])]);
        q.refused(&ids(&[2]));
        assert_eq!(q.ledger().refused, 1);
    }
}
