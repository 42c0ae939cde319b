//! Keyframe responses waiting to go out, as plain state: at most `max_responses_per_tick` leave
//! per tick (pacing the radio), a retried request does not queue a second copy of one still
//! waiting, and a keyframe sent twice to one neighbour is counted (it should never be).

use crate::messages::Outgoing;
use sgm_model::scene_graph::{KeyframeId, RobotId};
use sgm_model::wire::Message as WireMessage;
use std::collections::{BTreeMap, BTreeSet, VecDeque};

/// Responses may wait at most this many per id a request may carry (`limits.max_ids`): a
/// request that would queue more is refused as busy instead of dropped.
pub const QUEUED_PER_MAX_ID: usize = 4;

#[derive(Clone, Debug, Default)]
pub struct Responses {
    queue: VecDeque<Outgoing>,
    /// Every keyframe sent to each neighbour.
    sent: BTreeMap<RobotId, BTreeSet<KeyframeId>>,
}

impl Responses {
    /// Restored from a snapshot: what each neighbour was sent.
    pub fn with_sent(sent: BTreeMap<RobotId, BTreeSet<KeyframeId>>) -> Self {
        Self { queue: VecDeque::new(), sent }
    }

    pub fn sent(&self) -> &BTreeMap<RobotId, BTreeSet<KeyframeId>> {
        &self.sent
    }

    pub fn len(&self) -> usize {
        self.queue.len()
    }

    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    /// Whether `n` more responses may queue, with requests of at most `max_ids` ids.
    pub fn room_for(&self, n: usize, max_ids: usize) -> bool {
        self.queue.len() + n <= max_ids * QUEUED_PER_MAX_ID
    }

    /// Queues a keyframe response, unless the same one to the same neighbour still waits.
    pub fn push(&mut self, out: Outgoing) {
        let queued = match &out.message {
            WireMessage::KeyframeResponse(r) => self.queue.iter().any(|q| {
                q.to == out.to && matches!(&q.message, WireMessage::KeyframeResponse(x) if x.keyframe == r.keyframe)
            }),
            _ => false,
        };
        if !queued {
            self.queue.push_back(out);
        }
    }

    /// The responses that leave this tick (at most `max`), each with whether that keyframe had
    /// been sent to that neighbour before.
    pub fn take(&mut self, max: usize) -> Vec<(Outgoing, bool)> {
        let mut out = Vec::new();
        for _ in 0..max {
            let Some(next) = self.queue.pop_front() else { break };
            let twice = match &next.message {
                WireMessage::KeyframeResponse(r) => !self.sent.entry(next.to).or_default().insert(r.keyframe),
                _ => false,
            };
            out.push((next, twice));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sgm_model::wire::messages::{KeyframeResponse, WirePose};

    fn response(to: u16, keyframe: u32) -> Outgoing {
        let response = KeyframeResponse {
            keyframe: KeyframeId(keyframe),
            stamp: 0.0,
            world_from_body: WirePose { translation: [0.0; 3], rotation: [0.0, 0.0, 0.0, 1.0] },
            covariance: [0.0; 21],
            cloud: Vec::new(),
        };
        Outgoing { to: RobotId(to), message: WireMessage::KeyframeResponse(response) }
    }

    #[test]
    fn responses_are_paced_deduplicated_and_never_twice_unnoticed() {
        let mut r = Responses::default();
        r.push(response(2, 1));
        r.push(response(2, 1));
        r.push(response(3, 1));
        r.push(response(2, 2));
        assert_eq!(r.len(), 3, "the copy still waiting is not queued again");
        let first = r.take(2);
        assert_eq!(first.iter().map(|(o, twice)| (o.to.0, *twice)).collect::<Vec<_>>(), [(2, false), (3, false)]);
        assert_eq!(r.len(), 1);
        r.push(response(2, 1));
        let next = r.take(5);
        assert_eq!(
            next.iter().map(|(_, twice)| *twice).collect::<Vec<_>>(),
            [false, true],
            "keyframe 1 to robot 2 again"
        );
        assert!(r.is_empty());
    }
}
