//! The envelope door, as plain state: our sequence numbers (never repeated under one team
//! key: `incarnation ‖ counter`, `sgm_model::wire::replay`), and the replay windows of what
//! we accept. Sealing numbers and MACs an envelope; opening checks the MAC, the size limits,
//! the addressee and the replay window, per sender and incarnation.
//!
//! A neighbour heard under a new incarnation has restarted, perhaps from a snapshot: its
//! replay windows then refuse our counters up to its journal's reservation, at most `RESERVE`
//! above the highest it accepted. Our counter skips `RESERVE` (skipping is allowed; repeating
//! is not) so that what we send next is heard at once.

use sgm_model::scene_graph::RobotId;
use sgm_model::wire::{
    open, seal, Accepted, Destination, Envelope, Message as WireMessage, RejectionCounts, ReplayGuard, Sequence,
    TeamKey, WireError, WireLimits, PROTOCOL_VERSION,
};
use std::collections::BTreeMap;

/// An envelope let in.
#[derive(Debug)]
pub struct Admitted {
    pub from: RobotId,
    pub message: WireMessage,
    /// The replay reservations grew: the journal (if any) should record them.
    pub reservations_grew: bool,
    /// The sender was heard before under another incarnation (it restarted).
    pub sender_restarted: bool,
}

#[derive(Clone, Debug)]
pub struct Door {
    robot: RobotId,
    sequence: u64,
    replay: ReplayGuard,
    /// Each neighbour's incarnation when last heard.
    incarnations: BTreeMap<RobotId, u32>,
}

impl Door {
    pub fn new(robot: RobotId, sequence_start: u64) -> Self {
        Self { robot, sequence: sequence_start, replay: ReplayGuard::default(), incarnations: BTreeMap::new() }
    }

    pub fn sequence(&self) -> u64 {
        self.sequence
    }

    pub fn replay(&self) -> &ReplayGuard {
        &self.replay
    }

    /// Continues from a snapshot: the counter goes on above the snapshot's when this start
    /// keeps its incarnation (simulation); otherwise it starts afresh in the new one (a ROS
    /// node: what it sent after the snapshot stays unique). The replay windows are restored.
    pub fn thaw(&mut self, sequence: u64, replay: ReplayGuard) {
        let incarnation = |s: u64| Sequence::from_bits(s).incarnation;
        if incarnation(sequence) == incarnation(self.sequence) {
            self.sequence = self.sequence.max(sequence);
        }
        self.replay = replay;
    }

    /// `message` to `to`, numbered and sealed.
    pub fn seal(
        &mut self,
        to: Destination,
        message: WireMessage,
        key: &TeamKey,
        limits: &WireLimits,
    ) -> Result<Vec<u8>, WireError> {
        self.sequence += 1;
        let envelope = Envelope { version: PROTOCOL_VERSION, from: self.robot, to, sequence: self.sequence, message };
        seal(&envelope, key, limits)
    }

    /// `bytes` opened, or why not (counted in `rejected`; `None` also for our own broadcasts
    /// and envelopes for others).
    pub fn open(
        &mut self,
        bytes: &[u8],
        key: &TeamKey,
        limits: &WireLimits,
        rejected: &mut RejectionCounts,
    ) -> Option<Admitted> {
        let envelope = match open(bytes, key, limits) {
            Ok(e) => e,
            Err(e) => {
                rejected.record_wire(&e);
                tracing::debug!(robot = %self.robot, "refused envelope: {e}");
                return None;
            }
        };
        if envelope.from == self.robot || !envelope.to.includes(self.robot) {
            return None;
        }
        let reservations_grew = match self.replay.accept(envelope.from.0, envelope.sequence) {
            Err(e) => {
                rejected.record_replay(&e);
                return None;
            }
            Ok(Accepted::ReservationGrew) => true,
            Ok(Accepted::Reserved) => false,
        };
        let incarnation = Sequence::from_bits(envelope.sequence).incarnation;
        let sender_restarted =
            self.incarnations.insert(envelope.from, incarnation).is_some_and(|before| before != incarnation);
        if sender_restarted {
            self.sequence += sgm_model::wire::replay::RESERVE;
            tracing::info!(robot = %self.robot, neighbour = %envelope.from,
                "neighbour restarted (new incarnation): our counter skips past its replay reservation");
        }
        Some(Admitted { from: envelope.from, message: envelope.message, reservations_grew, sender_restarted })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sgm_model::wire::messages::KeyframeRequest;

    fn request() -> WireMessage {
        WireMessage::KeyframeRequest(KeyframeRequest { keyframes: vec![] })
    }

    /// Sealed by one door, opened by another once; a replay refused and counted; a sender's new
    /// incarnation makes our counter skip its reservation.
    #[test]
    fn envelopes_are_numbered_opened_once_and_restarts_noticed() {
        let (key, limits) = (TeamKey::from_bytes([1; 32]), WireLimits::default());
        let (mut a, mut b) = (Door::new(RobotId(1), 10), Door::new(RobotId(2), 0));
        let bytes = a.seal(Destination::Robot(RobotId(2)), request(), &key, &limits).unwrap();
        assert_eq!(a.sequence(), 11);
        let mut rejected = RejectionCounts::default();
        let admitted = b.open(&bytes, &key, &limits, &mut rejected).unwrap();
        assert_eq!((admitted.from, admitted.sender_restarted), (RobotId(1), false));
        assert!(b.open(&bytes, &key, &limits, &mut rejected).is_none(), "a replay");
        assert_eq!(rejected.replayed, 1);
        assert!(a.open(&bytes, &key, &limits, &mut rejected).is_none(), "our own");
        let other = TeamKey::from_bytes([2; 32]);
        assert!(b.open(&bytes, &other, &limits, &mut rejected).is_none());
        assert_eq!(rejected.bad_mac, 1);
        // Robot 1 restarts in incarnation 5.
        let mut a2 = Door::new(RobotId(1), Sequence { incarnation: 5, counter: 0 }.to_bits());
        let bytes = a2.seal(Destination::Broadcast, request(), &key, &limits).unwrap();
        let before = b.sequence();
        assert!(b.open(&bytes, &key, &limits, &mut rejected).unwrap().sender_restarted);
        assert_eq!(b.sequence(), before + sgm_model::wire::replay::RESERVE);
    }
}
