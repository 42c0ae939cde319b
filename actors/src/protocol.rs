//! The per-neighbour protocol (paper §IV-C..F) as typestates: `Neighbour<Discovered>` →
//! `Neighbour<ObjectsReceived>` → `Neighbour<Matched>` → `Neighbour<KeyframesRequested>` →
//! `Neighbour<Aligned>`. Each transition consumes the old state, so an illegal one does not
//! compile:
//!
//! ```compile_fail
//! use sgm_actors::protocol::{Neighbour, Discovered};
//! use sgm_model::scene_graph::RobotId;
//! let n = Neighbour::<Discovered>::discovered(RobotId(2), 0.0);
//! n.aligned(sgm_model::geometry::Pose3::identity(), 1.0); // no such transition from Discovered
//! ```
//!
//! [`Protocol`] holds any state for storage in an actor; it changes only through these
//! transitions. Waiting states carry a [`Wait`] (deadline, attempts) for timeouts, retries with
//! exponential back-off, and giving up back to `ObjectsReceived`.
//!
//! Once aligned, a neighbour stays `Aligned` for good (only a silent link sends it back to
//! `Discovered`): its later encounters are *closure rounds* inside that state ([`Closure`]:
//! object clouds, then keyframes), each adding inter-robot factors; one that fails or times out
//! ends without touching the alignment.

use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::{KeyframeId, ObjectId, RobotId, Stamp};
use std::collections::BTreeSet;

/// Timeouts and retries of waiting states.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RetryConfig {
    /// First wait for a response, s. Default 5.
    pub timeout_s: f64,
    /// Each retry waits this factor longer. Default 2.
    pub backoff: f64,
    /// Retries before giving up. Default 4.
    pub max_retries: u32,
}

impl Default for RetryConfig {
    fn default() -> Self {
        Self { timeout_s: 5.0, backoff: 2.0, max_retries: 4 }
    }
}

/// A pending request: when it was last sent, when that attempt expires, and how often it was
/// sent.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Wait {
    pub sent: Stamp,
    pub deadline: Stamp,
    pub attempts: u32,
}

impl Wait {
    pub fn new(now: Stamp, config: &RetryConfig) -> Self {
        Self { sent: now, deadline: now + config.timeout_s, attempts: 1 }
    }

    pub fn expired(&self, now: Stamp) -> bool {
        now >= self.deadline
    }

    /// The next attempt, or `None` when retries are exhausted. `heard_since_sent`: the
    /// neighbour was heard after the last attempt went out. Then the link works and the answer
    /// was lost at random: the next attempt waits `timeout_s` again. Otherwise the neighbour
    /// may be gone or swamped, and each attempt waits `backoff` times longer than the last.
    pub fn retry(&self, now: Stamp, config: &RetryConfig, heard_since_sent: bool) -> Option<Wait> {
        let growth = if heard_since_sent { 1.0 } else { config.backoff.powi(self.attempts as i32) };
        (self.attempts <= config.max_retries).then(|| Wait {
            sent: now,
            deadline: now + config.timeout_s * growth,
            attempts: self.attempts + 1,
        })
    }
}

/// A neighbour in state `S`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Neighbour<S> {
    pub robot: RobotId,
    /// When the current state was entered.
    pub since: Stamp,
    pub state: S,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Discovered;

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObjectsReceived {
    pub revision: u32,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Matched {
    pub revision: u32,
    pub local_from_remote: Pose3,
    /// (local, remote) object pairs of the match.
    pub pairs: Vec<(ObjectId, ObjectId)>,
    /// The object-cloud request.
    pub wait: Wait,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct KeyframesRequested {
    pub revision: u32,
    pub local_from_remote: Pose3,
    pub pairs: Vec<(ObjectId, ObjectId)>,
    pub awaiting: BTreeSet<KeyframeId>,
    pub wait: Wait,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Aligned {
    pub revision: u32,
    /// The current estimate: the first round's, then the pose graph's (its anchor).
    pub local_from_remote: Pose3,
    pub pairs: Vec<(ObjectId, ObjectId)>,
    /// The closure round in progress, if any.
    pub closure: Option<Closure>,
}

/// A closure round of an aligned neighbour: the object pairs it was started from (matched
/// through the current transform), and where it stands.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Closure {
    pub pairs: Vec<(ObjectId, ObjectId)>,
    pub stage: ClosureStage,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum ClosureStage {
    /// The object clouds of the pairs were asked for.
    Clouds { wait: Wait },
    /// The keyframes in `awaiting` were asked for; `guess` is the round's transform after
    /// object-cloud ICP.
    Keyframes { guess: Pose3, awaiting: BTreeSet<KeyframeId>, wait: Wait },
}

impl<S> Neighbour<S> {
    fn to<T>(self, now: Stamp, state: T) -> Neighbour<T> {
        Neighbour { robot: self.robot, since: now, state }
    }

    /// The link went silent: start over (what was learnt about the neighbour is kept elsewhere).
    pub fn lost(self, now: Stamp) -> Neighbour<Discovered> {
        self.to(now, Discovered)
    }
}

impl Neighbour<Discovered> {
    pub fn discovered(robot: RobotId, now: Stamp) -> Self {
        Neighbour { robot, since: now, state: Discovered }
    }

    pub fn objects_received(self, revision: u32, now: Stamp) -> Neighbour<ObjectsReceived> {
        self.to(now, ObjectsReceived { revision })
    }
}

impl Neighbour<ObjectsReceived> {
    pub fn objects_received(self, revision: u32, now: Stamp) -> Neighbour<ObjectsReceived> {
        let revision = revision.max(self.state.revision);
        self.to(now, ObjectsReceived { revision })
    }

    pub fn matched(
        self,
        local_from_remote: Pose3,
        pairs: Vec<(ObjectId, ObjectId)>,
        now: Stamp,
        retry: &RetryConfig,
    ) -> Neighbour<Matched> {
        let revision = self.state.revision;
        self.to(now, Matched { revision, local_from_remote, pairs, wait: Wait::new(now, retry) })
    }
}

impl Neighbour<Matched> {
    /// Object clouds arrived; the keyframes in `awaiting` were requested.
    pub fn keyframes_requested(
        self,
        local_from_remote: Pose3,
        awaiting: BTreeSet<KeyframeId>,
        now: Stamp,
        retry: &RetryConfig,
    ) -> Neighbour<KeyframesRequested> {
        let Matched { revision, pairs, .. } = self.state.clone();
        let wait = Wait::new(now, retry);
        self.to(now, KeyframesRequested { revision, local_from_remote, pairs, awaiting, wait })
    }

    /// No answer after every retry: back to waiting for object data.
    pub fn gave_up(self, now: Stamp) -> Neighbour<ObjectsReceived> {
        let revision = self.state.revision;
        self.to(now, ObjectsReceived { revision })
    }
}

impl Neighbour<KeyframesRequested> {
    /// Registration of the received keyframes succeeded.
    pub fn aligned(self, local_from_remote: Pose3, now: Stamp) -> Neighbour<Aligned> {
        let KeyframesRequested { revision, pairs, .. } = self.state.clone();
        self.to(now, Aligned { revision, local_from_remote, pairs, closure: None })
    }

    pub fn gave_up(self, now: Stamp) -> Neighbour<ObjectsReceived> {
        let revision = self.state.revision;
        self.to(now, ObjectsReceived { revision })
    }

    /// The keyframes arrived but too few registrations confirm the object match: it was wrong.
    pub fn refuted(self, now: Stamp) -> Neighbour<ObjectsReceived> {
        let revision = self.state.revision;
        self.to(now, ObjectsReceived { revision })
    }
}

impl Neighbour<Aligned> {
    /// Newer object data: keep the alignment, refine it when a new match asks for keyframes.
    pub fn objects_received(mut self, revision: u32) -> Neighbour<Aligned> {
        self.state.revision = self.state.revision.max(revision);
        self
    }

    /// A closure round starts: the object clouds of `pairs` were asked for.
    pub fn closure_started(mut self, pairs: Vec<(ObjectId, ObjectId)>, now: Stamp, retry: &RetryConfig) -> Self {
        self.state.closure = Some(Closure { pairs, stage: ClosureStage::Clouds { wait: Wait::new(now, retry) } });
        self
    }

    /// The round's object clouds arrived; the keyframes in `awaiting` were asked for.
    pub fn closure_keyframes(
        mut self,
        guess: Pose3,
        awaiting: BTreeSet<KeyframeId>,
        now: Stamp,
        retry: &RetryConfig,
    ) -> Self {
        if let Some(closure) = &mut self.state.closure {
            closure.stage = ClosureStage::Keyframes { guess, awaiting, wait: Wait::new(now, retry) };
        }
        self
    }

    /// The round is over, whatever it gave; the alignment stands.
    pub fn closure_ended(mut self) -> Self {
        self.state.closure = None;
        self
    }

    /// The alignment was found wrong (a contradicted cycle settled against it, a stronger
    /// match elsewhere, the relay it came from gone): back to
    /// waiting for a match, with the object data held (any closure round in progress ends).
    pub fn withdrawn(self, now: Stamp) -> Neighbour<ObjectsReceived> {
        let revision = self.state.revision;
        self.to(now, ObjectsReceived { revision })
    }

    /// The pose graph's estimate of the transform.
    pub fn reestimated(mut self, local_from_remote: Pose3) -> Self {
        self.state.local_from_remote = local_from_remote;
        self
    }
}

/// Any protocol state, for storage in an actor.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Protocol {
    Discovered(Neighbour<Discovered>),
    ObjectsReceived(Neighbour<ObjectsReceived>),
    Matched(Neighbour<Matched>),
    KeyframesRequested(Neighbour<KeyframesRequested>),
    Aligned(Neighbour<Aligned>),
}

macro_rules! into_protocol {
    ($($s:ident),*) => {$(
        impl From<Neighbour<$s>> for Protocol {
            fn from(n: Neighbour<$s>) -> Self {
                Protocol::$s(n)
            }
        }
    )*};
}
into_protocol!(Discovered, ObjectsReceived, Matched, KeyframesRequested, Aligned);

/// Where a neighbour's protocol stands: the state's name, without its data.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize)]
pub enum ProtocolStage {
    Discovered,
    ObjectsReceived,
    Matched,
    KeyframesRequested,
    Aligned,
}

impl ProtocolStage {
    pub fn name(self) -> &'static str {
        match self {
            ProtocolStage::Discovered => "Discovered",
            ProtocolStage::ObjectsReceived => "ObjectsReceived",
            ProtocolStage::Matched => "Matched",
            ProtocolStage::KeyframesRequested => "KeyframesRequested",
            ProtocolStage::Aligned => "Aligned",
        }
    }
}

impl std::fmt::Display for ProtocolStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Protocol {
    pub fn stage(&self) -> ProtocolStage {
        match self {
            Protocol::Discovered(_) => ProtocolStage::Discovered,
            Protocol::ObjectsReceived(_) => ProtocolStage::ObjectsReceived,
            Protocol::Matched(_) => ProtocolStage::Matched,
            Protocol::KeyframesRequested(_) => ProtocolStage::KeyframesRequested,
            Protocol::Aligned(_) => ProtocolStage::Aligned,
        }
    }

    /// The current estimate of `local_from_remote`, if any.
    pub fn local_from_remote(&self) -> Option<&Pose3> {
        match self {
            Protocol::Matched(n) => Some(&n.state.local_from_remote),
            Protocol::KeyframesRequested(n) => Some(&n.state.local_from_remote),
            Protocol::Aligned(n) => Some(&n.state.local_from_remote),
            _ => None,
        }
    }

    pub fn is_aligned(&self) -> bool {
        matches!(self, Protocol::Aligned(_))
    }

    /// After a thaw: a request that was in flight died with the robot; a waiting state goes
    /// back to waiting for a match (its objects are still held), any other stays.
    pub fn settled(self, now: Stamp) -> Protocol {
        match self {
            Protocol::Matched(n) => n.gave_up(now).into(),
            Protocol::KeyframesRequested(n) => n.gave_up(now).into(),
            Protocol::Aligned(n) => n.closure_ended().into(),
            other => other,
        }
    }

    /// Object data arrived with `revision`.
    pub fn on_objects(self, revision: u32, now: Stamp) -> Protocol {
        match self {
            Protocol::Discovered(n) => n.objects_received(revision, now).into(),
            Protocol::ObjectsReceived(n) => n.objects_received(revision, now).into(),
            Protocol::Aligned(n) => n.objects_received(revision).into(),
            waiting => waiting, // a request is in flight: the match it serves stands
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_happy_path_and_giving_up() {
        let retry = RetryConfig::default();
        let n = Neighbour::discovered(RobotId(2), 0.0).objects_received(3, 1.0);
        let m = n.matched(Pose3::identity(), vec![(ObjectId(1), ObjectId(7))], 1.5, &retry);
        assert_eq!(m.state.wait, Wait { sent: 1.5, deadline: 6.5, attempts: 1 });
        let k = m.keyframes_requested(Pose3::identity(), [KeyframeId(4)].into(), 2.0, &retry);
        let a = k.aligned(Pose3::identity(), 3.0);
        assert_eq!((a.since, a.state.revision), (3.0, 3));
        let p: Protocol = a.objects_received(5).into();
        assert!(p.is_aligned());
        assert_eq!(
            p.clone().on_objects(9, 4.0),
            Protocol::Aligned(Neighbour {
                robot: RobotId(2),
                since: 3.0,
                state: Aligned {
                    revision: 9,
                    local_from_remote: Pose3::identity(),
                    pairs: vec![(ObjectId(1), ObjectId(7))],
                    closure: None,
                }
            })
        );
        let again = Neighbour::discovered(RobotId(2), 0.0).objects_received(1, 0.0).matched(
            Pose3::identity(),
            vec![],
            0.0,
            &retry,
        );
        assert_eq!(again.gave_up(9.0).state.revision, 1);
    }

    #[test]
    fn closure_rounds_never_leave_aligned() {
        let retry = RetryConfig::default();
        let a = Neighbour::discovered(RobotId(2), 0.0)
            .objects_received(1, 0.0)
            .matched(Pose3::identity(), vec![], 0.0, &retry)
            .keyframes_requested(Pose3::identity(), BTreeSet::new(), 0.0, &retry)
            .aligned(Pose3::identity(), 1.0);
        let started = a.closure_started(vec![(ObjectId(3), ObjectId(4))], 5.0, &retry);
        assert!(matches!(started.state.closure, Some(Closure { stage: ClosureStage::Clouds { .. }, .. })));
        let moved = Pose3::translation(0.1, 0.0, 0.0);
        let asked = started.closure_keyframes(moved, [KeyframeId(9)].into(), 6.0, &retry).reestimated(moved);
        let Some(Closure { stage: ClosureStage::Keyframes { awaiting, .. }, .. }) = &asked.state.closure else {
            panic!("keyframes stage expected")
        };
        assert_eq!(awaiting.len(), 1);
        // A thaw drops a round in flight and keeps the alignment.
        let p: Protocol = asked.into();
        let Protocol::Aligned(settled) = p.settled(7.0) else { panic!("still aligned") };
        assert_eq!((settled.state.closure.clone(), settled.state.local_from_remote), (None, moved));
        assert_eq!(settled.since, 1.0);
        // Only a withdrawal leaves it, round and all, back to waiting with the objects held.
        let withdrawn = settled.objects_received(4).closure_started(vec![], 8.0, &retry).withdrawn(9.0);
        assert_eq!(withdrawn, Neighbour { robot: RobotId(2), since: 9.0, state: ObjectsReceived { revision: 4 } });
    }

    #[test]
    fn retries_back_off_then_stop() {
        let retry = RetryConfig { timeout_s: 1.0, backoff: 2.0, max_retries: 2 };
        let w = Wait::new(0.0, &retry);
        assert!(!w.expired(0.5) && w.expired(1.0));
        let w2 = w.retry(1.0, &retry, false).unwrap();
        assert_eq!(w2, Wait { sent: 1.0, deadline: 3.0, attempts: 2 });
        let w3 = w2.retry(3.0, &retry, false).unwrap();
        assert_eq!(w3, Wait { sent: 3.0, deadline: 7.0, attempts: 3 });
        assert_eq!(w3.retry(7.0, &retry, false), None);
        // A neighbour heard since the last attempt: no back-off, but the same retry budget.
        let w2 = w.retry(1.0, &retry, true).unwrap();
        assert_eq!(w2, Wait { sent: 1.0, deadline: 2.0, attempts: 2 });
        let w3 = w2.retry(2.0, &retry, true).unwrap();
        assert_eq!(w3, Wait { sent: 2.0, deadline: 3.0, attempts: 3 });
        assert_eq!(w3.retry(3.0, &retry, true), None);
    }
}
