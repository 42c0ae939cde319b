//! One peer's outgoing link: a bounded queue of sealed envelopes and whether the peer answers.
//! A plain state machine — time is handed in, nothing here touches the network — driven by the
//! peer's worker thread ([`super::peers`]), so a peer that is dead, out of range or never
//! answers holds up its own queue and nobody else's.
//!
//! ```text
//!        call ok                      call failed (timeout, refused, no such service)
//!   Up ───────────▶ Up           Up ───────────────────────────────▶ Down { retry_at = now + b₀ }
//!   Down ──(now ≥ retry_at, queue not empty: the front envelope is the probe)──▶ call
//!        probe ok ─▶ Up (the queue drains)     probe failed ─▶ Down { b ← min(2b, b_max) }
//! ```
//!
//! While the peer is down nothing is sent but the probe; envelopes wait, at most `queue` of
//! them (the oldest goes first, counted). The envelope of a failed call goes back to the front:
//! a call that timed out may still have been delivered, and a second copy is refused by the
//! receiver's replay window, so nothing is lost and nothing counts twice.

pub use crate::config::PeerConfig;
use serde::Serialize;
use std::collections::VecDeque;
use std::time::Duration;

/// Whether the peer answers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkState {
    Up,
    /// Since `since`; probed again at `retry_at`, after waiting `backoff`.
    Down {
        since: Duration,
        retry_at: Duration,
        backoff: Duration,
    },
}

/// What one peer's link did, for the status topic.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct PeerCounts {
    /// Envelopes the peer's service accepted.
    pub sent: u64,
    /// Calls that failed (each failure of a probe included).
    pub failed: u64,
    /// Envelopes dropped because the queue was full.
    pub dropped: u64,
    /// Times the peer went down.
    pub downs: u64,
    /// Probes sent while it was down.
    pub probes: u64,
}

/// What the worker should do next.
#[derive(Debug, PartialEq, Eq)]
pub enum Next {
    /// Call the peer with this envelope.
    Send(Vec<u8>),
    /// Nothing to do before this long has passed (a down peer's next probe).
    Wait(Duration),
    /// Nothing to do until an envelope is queued.
    Idle,
}

/// One peer's queue and link state; `now` is any monotone time (the worker's `Instant`s since
/// it started).
#[derive(Debug)]
pub struct PeerLink {
    config: PeerConfig,
    queue: VecDeque<Vec<u8>>,
    state: LinkState,
    in_call: bool,
    pub counts: PeerCounts,
}

impl PeerLink {
    pub fn new(config: PeerConfig) -> Self {
        Self { config, queue: VecDeque::new(), state: LinkState::Up, in_call: false, counts: PeerCounts::default() }
    }

    pub fn state(&self) -> LinkState {
        self.state
    }

    pub fn queued(&self) -> usize {
        self.queue.len()
    }

    /// Queues an envelope; when the queue is full the oldest waiting one is dropped.
    pub fn push(&mut self, envelope: Vec<u8>) {
        if self.queue.len() >= self.config.queue.max(1) {
            self.queue.pop_front();
            self.counts.dropped += 1;
        }
        self.queue.push_back(envelope);
    }

    /// The next step at `now`. A [`Next::Send`] must be answered by [`Self::succeeded`] or
    /// [`Self::failed`] before `next` is asked again.
    pub fn next(&mut self, now: Duration) -> Next {
        if self.in_call {
            return Next::Idle;
        }
        if let LinkState::Down { retry_at, .. } = self.state {
            if self.queue.is_empty() {
                return Next::Idle;
            }
            if now < retry_at {
                return Next::Wait(retry_at - now);
            }
            self.counts.probes += 1;
        }
        match self.queue.pop_front() {
            Some(envelope) => {
                self.in_call = true;
                Next::Send(envelope)
            }
            None => Next::Idle,
        }
    }

    /// Something arrived from the peer (it may be back): a down peer is probed at once, its
    /// back-off kept for the probes after.
    pub fn heard(&mut self, now: Duration) {
        if let LinkState::Down { retry_at, .. } = &mut self.state {
            *retry_at = (*retry_at).min(now);
        }
    }

    /// The call with the envelope `next` gave succeeded: the peer is up.
    pub fn succeeded(&mut self) {
        self.in_call = false;
        self.counts.sent += 1;
        self.state = LinkState::Up;
    }

    /// The call with `envelope` failed at `now`: it goes back to the front of the queue (unless
    /// the queue filled meanwhile) and the peer is down, its next probe after the back-off.
    pub fn failed(&mut self, envelope: Vec<u8>, now: Duration) {
        self.in_call = false;
        self.counts.failed += 1;
        if self.queue.len() < self.config.queue.max(1) {
            self.queue.push_front(envelope);
        } else {
            self.counts.dropped += 1;
        }
        let initial = Duration::from_secs_f64(self.config.backoff_initial_s);
        let max = Duration::from_secs_f64(self.config.backoff_max_s).max(initial);
        let (since, backoff) = match self.state {
            LinkState::Up => {
                self.counts.downs += 1;
                (now, initial)
            }
            LinkState::Down { since, backoff, .. } => (since, (backoff * 2).min(max)),
        };
        self.state = LinkState::Down { since, retry_at: now + backoff, backoff };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(secs: f64) -> Duration {
        Duration::from_secs_f64(secs)
    }

    fn link(queue: usize) -> PeerLink {
        PeerLink::new(PeerConfig { queue, call_timeout_s: 2.0, backoff_initial_s: 1.0, backoff_max_s: 5.0 })
    }

    #[test]
    fn an_answering_peer_gets_its_envelopes_in_order() {
        let mut p = link(8);
        assert_eq!(p.next(s(0.0)), Next::Idle);
        p.push(vec![1]);
        p.push(vec![2]);
        assert_eq!(p.next(s(0.0)), Next::Send(vec![1]));
        assert_eq!(p.next(s(0.0)), Next::Idle, "one call at a time");
        p.succeeded();
        assert_eq!(p.next(s(0.1)), Next::Send(vec![2]));
        p.succeeded();
        assert_eq!(p.next(s(0.2)), Next::Idle);
        assert_eq!(p.counts, PeerCounts { sent: 2, ..PeerCounts::default() });
    }

    #[test]
    fn a_failed_peer_is_probed_with_doubling_back_off_and_loses_nothing() {
        let mut p = link(8);
        for k in 0..3 {
            p.push(vec![k]);
        }
        let Next::Send(first) = p.next(s(0.0)) else { panic!("a call") };
        p.failed(first, s(2.0));
        assert_eq!(p.state(), LinkState::Down { since: s(2.0), retry_at: s(3.0), backoff: s(1.0) });
        assert_eq!(p.next(s(2.5)), Next::Wait(s(0.5)), "no call before the back-off");
        // Probes: 1 s, 2 s, 4 s, then capped at 5 s.
        let mut at = 3.0;
        for backoff in [2.0, 4.0, 5.0, 5.0] {
            assert_eq!(p.next(s(at)), Next::Send(vec![0]), "the front envelope is the probe");
            p.failed(vec![0], s(at));
            assert_eq!(p.state(), LinkState::Down { since: s(2.0), retry_at: s(at + backoff), backoff: s(backoff) });
            at += backoff;
        }
        assert_eq!((p.counts.downs, p.counts.probes, p.counts.failed), (1, 4, 5));
        // It answers: up again, and the queue drains in order.
        assert_eq!(p.next(s(at)), Next::Send(vec![0]));
        p.succeeded();
        assert_eq!(p.state(), LinkState::Up);
        assert_eq!(p.next(s(at)), Next::Send(vec![1]));
        p.succeeded();
        assert_eq!(p.next(s(at)), Next::Send(vec![2]));
        p.succeeded();
        assert_eq!((p.counts.sent, p.counts.dropped), (3, 0));
    }

    #[test]
    fn a_peer_heard_from_is_probed_at_once() {
        let mut p = link(8);
        p.push(vec![1]);
        let Next::Send(e) = p.next(s(0.0)) else { panic!("a call") };
        p.failed(e, s(0.0));
        assert_eq!(p.next(s(0.2)), Next::Wait(s(0.8)));
        p.heard(s(0.3));
        assert_eq!(p.next(s(0.3)), Next::Send(vec![1]));
    }

    #[test]
    fn a_down_peer_with_nothing_to_send_is_not_probed() {
        let mut p = link(8);
        p.push(vec![7]);
        let Next::Send(e) = p.next(s(0.0)) else { panic!("a call") };
        p.failed(e, s(0.0));
        let Next::Send(_) = p.next(s(1.0)) else { panic!("a probe") };
        // A probe that got through drains the queue; with an empty queue nothing is probed.
        p.succeeded();
        assert_eq!(p.next(s(100.0)), Next::Idle);
    }

    #[test]
    fn the_queue_is_bounded_and_drops_the_oldest() {
        let mut p = link(3);
        for k in 0..5 {
            p.push(vec![k]);
        }
        assert_eq!((p.queued(), p.counts.dropped), (3, 2));
        assert_eq!(p.next(s(0.0)), Next::Send(vec![2]));
        // Full again while the call is out: the failed envelope does not grow the queue.
        p.push(vec![5]);
        p.failed(vec![2], s(0.0));
        assert_eq!((p.queued(), p.counts.dropped), (3, 3));
    }
}
