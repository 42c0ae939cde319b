//! `Matcher` (paper §IV-C, §IV-D): per neighbour, the protocol of `crate::protocol`. Object data
//! in → object-graph matching (`model::matching`) → with enough matched objects, the neighbour's
//! object clouds → ICP of its object clouds onto ours (refines `local_from_remote`) → the
//! neighbour keyframes that observed the matched objects, ± `keyframe_neighbourhood` → each
//! registered by ICP to the nearest local keyframe that observed a matched object → inter-robot
//! factors and the neighbour keyframes (with their marginal covariances) to the Optimiser.
//! A round from a chained hint with fewer pairs than that (`matcher.relay.min_relayed_pairs`)
//! skips object-cloud ICP below three pairs and asks only for the observing keyframes
//! (`relay.rs`).
//!
//! With `association = "scan_context"` (the evaluation's Swarm-SC baseline) the first two
//! steps differ: every local keyframe's Scan Context descriptor goes to Comms for broadcast;
//! a local and a neighbour keyframe whose descriptors agree give the first estimate,
//! local_from_remote = W_l(k_l) · Rz(−yaw) · W_r(k_r)⁻¹ (same place, turned by the descriptor's
//! yaw); the neighbour keyframes around k_r are requested, k_r is registered onto k_l coarse
//! to fine, and the rest is as above with the local keyframes around k_l as targets.

mod association;
mod closures;
mod neighbour;
mod relay;
mod rematch;
mod rounds;
mod settle;

pub use neighbour::{
    ChallengedBar, ClosureCounts, ClosureMemory, GetNeighbours, MatchAttempts, MatcherState, NeighbourMemory,
    NeighbourStatus,
};

use crate::clock::Clock;
use crate::config::{Association, MatcherSection};
use crate::containment::contained;
use crate::map_view::{MapView, ViewKeyframe};
use crate::messages::*;
use crate::protocol::{Closure, ClosureStage, Matched, Neighbour, Protocol, ProtocolStage, RetryConfig, Wait};
use actix::{Actor, Context, Handler, Message, MessageResult, Recipient, Supervised};
use nalgebra::Point3;
use sgm_model::geometry::Pose3;
use sgm_model::matching::alignment::{
    coarse_to_fine, evenly, judge_round, neighbourhood, refuted_recently, register_round, yaw_turn, LocalView,
    RemoteView, RoundConfig, RoundVerdict, REFUTED_FOR_S,
};
use sgm_model::matching::place_candidates::{EvenPlaces, PlaceCandidate, PlaceCandidates};
use sgm_model::matching::scan_context::{Place, ScanContext};
use sgm_model::matching::{match_graphs, GraphObject, LabelSimilarity, MatchOutcome, ObjectGraph};
use sgm_model::perception::icp::{register_to, Freedom, IcpConfig, IcpTarget};
use sgm_model::perception::object_cloud::{object_cloud, MAX_VIEWS};
use sgm_model::scene_graph::{KeyframeId, ObjectId, RobotId, Stamp};
use sgm_model::wire::cloud_codec;
use sgm_model::wire::messages::{KeyframeRefusalReason, ObjectCloud, ObjectData};
use sgm_model::workers::Workers;
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use association::same_objects;
use neighbour::{hold_at_most, push_recent, LastMatch, NeighbourEntry};

/// Where the Matcher sends what it produces.
#[derive(Clone)]
pub struct MatcherLinks {
    pub request_clouds: Recipient<RequestObjectClouds>,
    pub request_keyframes: Recipient<RequestKeyframes>,
    pub release_keyframes: Recipient<KeyframesReleased>,
    pub share_descriptors: Recipient<ShareDescriptor>,
    pub share_alignments: Recipient<ShareAlignments>,
    pub optimiser: Recipient<InterRobotConstraints>,
    pub withdraw: Recipient<NeighbourWithdrawn>,
}

pub struct Matcher {
    robot: RobotId,
    config: MatcherSection,
    retry: RetryConfig,
    clock: Clock,
    labels: LabelSimilarity,
    links: Option<MatcherLinks>,
    /// The map as the Tracker last shared it (keyframe poses, held scans, confirmed objects).
    map: Arc<MapView>,
    /// Scan Context association only: our keyframes' descriptors, at most
    /// `scan_context.max_places`, spread over the run.
    places: EvenPlaces,
    neighbours: BTreeMap<RobotId, NeighbourEntry>,
    /// Each neighbour's latest alignments (`[matcher.relay]`): hints, not kept in snapshots (they
    /// come again within `comms.alignments_refresh_s`).
    hints: BTreeMap<RobotId, Vec<(RobotId, Pose3)>>,
    /// The robots last logged as contradicting our alignment of each neighbour (a warning when
    /// this changes; not kept in snapshots, so a restarted robot warns again).
    contradictions: BTreeMap<RobotId, relay::LoggedContradiction>,
    /// Threads a registration may split its work over (the same answers for any number).
    workers: Workers,
    /// Counts the changes of the map's matchable objects (`LastMatch`).
    local_objects_revision: u64,
}

impl Matcher {
    pub fn new(
        robot: RobotId,
        config: MatcherSection,
        retry: RetryConfig,
        clock: Clock,
        labels: LabelSimilarity,
    ) -> Self {
        Self {
            robot,
            config,
            retry,
            clock,
            labels,
            links: None,
            map: Arc::default(),
            places: EvenPlaces::default(),
            neighbours: BTreeMap::new(),
            hints: BTreeMap::new(),
            contradictions: BTreeMap::new(),
            workers: Workers::sequential(),
            local_objects_revision: 0,
        }
    }

    /// Lets registrations split their work over `workers` (the same answers for any number).
    pub fn with_workers(mut self, workers: Workers) -> Self {
        self.workers = workers;
        self
    }

    pub fn freeze(&self) -> MatcherState {
        let neighbours = self
            .neighbours
            .iter()
            .map(|(robot, e)| NeighbourMemory {
                robot: *robot,
                protocol: e.protocol.clone(),
                objects: e.objects.clone(),
                keyframes: e.keyframes.values().cloned().collect(),
                first_aligned: e.first_aligned,
                refuted: e.refuted.clone(),
                closures: e.closures.clone(),
                aligned_via: e.aligned_via,
                withdrawn: e.withdrawn.clone(),
                withdrawals: e.withdrawals,
                last_withdrawal: e.last_withdrawal.clone(),
                aligned_significance: e.aligned_significance,
                challenged_bar: e.challenged_bar,
                discredited: e.discredited.clone(),
                graph_rounds_refuted: e.graph_rounds_refuted,
            })
            .collect();
        MatcherState { neighbours }
    }

    pub fn thawed(mut self, state: MatcherState) -> Self {
        let now = self.clock.now();
        for memory in state.neighbours {
            let entry = self.entry(memory.robot);
            entry.protocol = memory.protocol.map(|p| p.settled(now)).or(entry.protocol.take());
            entry.objects = memory.objects;
            entry.last_match = None;
            entry.keyframes = memory.keyframes.into_iter().map(|k| (k.id, k)).collect();
            entry.first_aligned = memory.first_aligned;
            entry.refuted = memory.refuted;
            entry.closures = memory.closures;
            entry.aligned_via = memory.aligned_via;
            entry.withdrawn = memory.withdrawn;
            entry.withdrawals = memory.withdrawals;
            entry.last_withdrawal = memory.last_withdrawal;
            entry.aligned_significance = memory.aligned_significance;
            entry.challenged_bar = memory.challenged_bar;
            entry.discredited = memory.discredited;
            entry.graph_rounds_refuted = memory.graph_rounds_refuted;
            entry.match_again = true;
        }
        self
    }

    fn entry(&mut self, robot: RobotId) -> &mut NeighbourEntry {
        let now = self.clock.now();
        self.neighbours.entry(robot).or_insert_with(|| NeighbourEntry::discovered(robot, now))
    }

    /// Scan Context association: the descriptor of a new local keyframe, shared with the
    /// neighbours through Comms, kept among our places and tried against theirs.
    fn describe(&mut self, id: KeyframeId) {
        let Some(keyframe) = self.map.keyframes.get(&id) else { return };
        let points: Vec<Point3<f64>> = keyframe.scan.points_in_body.iter().map(|p| p.cast::<f64>()).collect();
        let descriptor = ScanContext::new(&points, &self.config.scan_context.descriptor);
        if let Some(links) = &self.links {
            let world_from_body = keyframe.world_from_body;
            links.share_descriptors.do_send(ShareDescriptor {
                keyframe: id,
                world_from_body,
                descriptor: descriptor.clone(),
            });
        }
        let dropped = self.places.insert(id, Place::new(descriptor), self.config.scan_context.max_places);
        self.forget_places(&dropped);
        let robots: Vec<RobotId> = self.neighbours.keys().copied().collect();
        for robot in robots {
            self.try_match_places(robot);
        }
    }

    /// Tells Comms that these neighbour keyframes are no longer held.
    fn release(&self, robot: RobotId, keyframes: Vec<KeyframeId>) {
        if let (Some(links), false) = (&self.links, keyframes.is_empty()) {
            links.release_keyframes.do_send(KeyframesReleased { robot, keyframes });
        }
    }
}

impl Actor for Matcher {
    type Context = Context<Self>;
}

impl Supervised for Matcher {
    fn restarting(&mut self, _: &mut Context<Self>) {
        tracing::warn!(robot = %self.robot, "matcher restarting with its neighbour states");
        // A handler that panicked between taking a protocol state and putting the next one back
        // left none: that neighbour starts over (its objects and keyframes are kept).
        let now = self.clock.now();
        for (robot, entry) in &mut self.neighbours {
            if entry.protocol.is_none() {
                entry.protocol = Some(Neighbour::discovered(*robot, now).into());
            }
        }
    }
}

impl Handler<MapChanged> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: MapChanged, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            let changes = msg.0.changes_since(&self.map);
            if !same_objects(&msg.0.objects.objects, &self.map.objects.objects) {
                self.local_objects_revision += 1;
            }
            self.map = msg.0;
            if self.config.association == Association::ScanContext {
                for id in changes.added {
                    self.describe(id);
                }
                // An evicted keyframe's descriptor could only lead to one we cannot register.
                for id in changes.removed {
                    if self.places.remove(id) {
                        self.forget_places(&[id]);
                    }
                }
            }
            let robots: Vec<RobotId> = self.neighbours.keys().copied().collect();
            for robot in robots {
                self.rematch(robot);
                self.try_match(robot);
            }
        });
    }
}

impl Handler<NeighbourDescriptors> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: NeighbourDescriptors, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            if self.config.association != Association::ScanContext {
                return;
            }
            let now = self.clock.now();
            let shape = (self.config.scan_context.descriptor.rings, self.config.scan_context.descriptor.sectors);
            let max_places = self.config.scan_context.max_places;
            let entry = self.entry(msg.robot);
            // A descriptor of another shape can never match ours: not kept.
            for (id, world_from_body, descriptor) in msg.descriptors {
                if (descriptor.rings, descriptor.sectors) == shape {
                    entry.places.add_remote(id, world_from_body, Place::new(descriptor), max_places);
                }
            }
            // The number of keyframes the neighbour shared stands in for an object-data revision.
            let revision = u32::try_from(entry.places.remote_count()).unwrap_or(u32::MAX);
            entry.protocol = entry.protocol.take().map(|p| p.on_objects(revision, now));
            self.try_match_places(msg.robot);
        });
    }
}

impl Handler<NeighbourObjects> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: NeighbourObjects, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            let now = self.clock.now();
            let entry = self.entry(msg.robot);
            if entry.objects.as_ref().is_some_and(|d| d.revision >= msg.data.revision) {
                return;
            }
            let revision = msg.data.revision;
            entry.objects = Some(msg.data);
            entry.protocol = entry.protocol.take().map(|p| p.on_objects(revision, now));
            self.rematch(msg.robot);
            self.try_match(msg.robot);
        });
    }
}

impl Handler<NeighbourObjectClouds> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: NeighbourObjectClouds, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            self.on_object_clouds(msg);
        });
    }
}

impl Handler<NeighbourKeyframe> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: NeighbourKeyframe, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            let (robot, id) = (msg.robot, msg.id);
            let cap = self.config.max_held_keyframes;
            let entry = self.entry(robot);
            // Only a keyframe of the current round is kept (a late or duplicated one is not).
            if !entry.round.contains(&id) {
                tracing::debug!(neighbour = %robot, keyframe = id.0, "keyframe outside the round, not kept");
                self.release(robot, vec![id]);
                return;
            }
            if matches!(entry.protocol, Some(Protocol::Aligned(_))) {
                entry.closures.counts.bytes += msg.cloud_bytes;
            }
            entry.keyframes.insert(id, msg);
            let released = hold_at_most(&mut entry.keyframes, &entry.round, cap);
            self.release(robot, released);
            self.on_keyframe_resolved(robot, id);
        });
    }
}

impl Handler<KeyframesUnavailable> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: KeyframesUnavailable, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            // Busy: given up after every retry, or refused for load; the keyframe was not
            // shown to be absent.
            if msg.reason == KeyframeRefusalReason::Busy {
                self.entry(msg.robot).round_incomplete = true;
            }
            for id in msg.keyframes {
                self.on_keyframe_resolved(msg.robot, id);
            }
        });
    }
}

impl Handler<Tick> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: Tick, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            // Object clouds that never came: ask again with back-off, then start over.
            let robots: Vec<RobotId> = self.neighbours.keys().copied().collect();
            for robot in robots.clone() {
                let Some(entry) = self.neighbours.get_mut(&robot) else { continue };
                let Some(Protocol::Matched(mut n)) = entry.protocol.clone() else { continue };
                if !entry.link_up || !n.state.wait.expired(msg.now) {
                    continue;
                }
                // Comms reports the link down after `link_timeout_s` of silence; until then the
                // neighbour counts as heard, and a lost cloud response is asked for again at
                // the same pace. (While it is down nothing is retried: see above.)
                match n.state.wait.retry(msg.now, &self.retry, entry.link_up) {
                    Some(next) => {
                        n.state.wait = next;
                        entry.protocol = Some(n.clone().into());
                        self.ask_clouds_again(robot, &n);
                    }
                    None => {
                        entry.protocol = Some(n.gave_up(msg.now).into());
                        entry.match_again = true;
                    }
                }
            }
            // Rounds cut short by losses: try again (the neighbour may have stopped changing).
            let again: Vec<RobotId> = self.neighbours.iter().filter(|(_, e)| e.match_again).map(|(r, _)| *r).collect();
            for robot in again {
                self.try_associate(robot);
            }
            // Aligned neighbours: overdue closure rounds, and new ones.
            for robot in robots {
                self.closure_timeouts(robot, msg.now);
                self.try_close(robot);
            }
        });
    }
}

impl Handler<LinkChanged> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: LinkChanged, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            let now = self.clock.now();
            let retry = self.retry.clone();
            let entry = self.entry(msg.robot);
            entry.link_up = msg.up;
            if !msg.up {
                return;
            }
            // Back: a pending object-cloud request is sent again at once (its retries were
            // paused); a neighbour waiting to be matched is matched now.
            entry.last_attempt = None;
            if let Some(Protocol::Matched(mut n)) = entry.protocol.clone() {
                n.state.wait = Wait::new(now, &retry);
                entry.protocol = Some(n.clone().into());
                self.ask_clouds_again(msg.robot, &n);
            }
            self.try_associate(msg.robot);
        });
    }
}

impl Handler<GetNeighbours> for Matcher {
    type Result = MessageResult<GetNeighbours>;
    fn handle(&mut self, _: GetNeighbours, _: &mut Context<Self>) -> Self::Result {
        MessageResult(
            self.neighbours
                .iter()
                .map(|(robot, e)| NeighbourStatus {
                    contradicted_by: self.contradicted_by(*robot),
                    robot: *robot,
                    state: e.protocol.as_ref().map(Protocol::stage),
                    local_from_remote: e.protocol.as_ref().and_then(|p| p.local_from_remote().copied()),
                    first_aligned: e.first_aligned,
                    closures: e.closures.counts,
                    aligned_via: e.aligned_via,
                    keyframes_held: e.keyframes.len(),
                    objects_revision: e.objects.as_ref().map(|d| d.revision),
                    match_attempts: e.attempts.clone(),
                    graph_rounds_refuted: e.graph_rounds_refuted as usize,
                    withdrawals: e.withdrawals,
                    last_withdrawal: e.last_withdrawal.clone(),
                })
                .collect(),
        )
    }
}

connects!(Matcher => MatcherLinks);
freezes!(Matcher => MatcherState);
stops_on_injected_failure!(Matcher => "matcher");

#[cfg(test)]
mod tests {
    use super::*;

    fn matcher() -> Matcher {
        let labels = LabelSimilarity::hard(4);
        Matcher::new(RobotId(1), MatcherSection::default(), RetryConfig::default(), Clock::starting_at(5.0), labels)
    }

    /// Our alignment of `robot` at `local_from_remote`, as a round leaves it.
    fn aligned_at(robot: RobotId, local_from_remote: Pose3) -> Protocol {
        let retry = RetryConfig::default();
        Neighbour::discovered(robot, 0.0)
            .objects_received(1, 0.0)
            .matched(local_from_remote, Vec::new(), 0.0, &retry)
            .keyframes_requested(local_from_remote, BTreeSet::new(), 0.0, &retry)
            .aligned(local_from_remote, 0.0)
            .into()
    }

    /// Robot 1 holds robot 2 through robot 3's alignment of it (relayed); robot 3's alignment
    /// of 2 now puts it `off_m` from ours. Whether ours is withdrawn.
    fn relayed_alignment_withdrawn(off_m: f64) -> bool {
        let (two, three) = (RobotId(2), RobotId(3));
        let ours_of_two = Pose3::translation(10.0, 0.0, 0.0);
        let ours_of_three = Pose3::translation(0.0, 10.0, 0.0);
        let mut matcher = matcher();
        matcher.entry(two).protocol = Some(aligned_at(two, ours_of_two));
        matcher.entry(two).aligned_via = Some(three);
        matcher.entry(three).protocol = Some(aligned_at(three, ours_of_three));
        let threes_of_two = ours_of_three.inverse() * ours_of_two * Pose3::translation(off_m, 0.0, 0.0);
        matcher.hints.insert(three, vec![(two, threes_of_two)]);
        matcher.review_contradictions();
        let entry = &matcher.neighbours[&two];
        let withdrawn = !matches!(entry.protocol, Some(Protocol::Aligned(_)));
        assert_eq!(withdrawn, entry.withdrawn == [ours_of_two], "withdrawn and barred go together");
        assert_eq!(withdrawn, entry.last_withdrawal.as_deref().is_some_and(|w| w.contains("relayed by")));
        withdrawn
    }

    /// A relayed alignment is withdrawn when its relay puts the neighbour beyond twice the
    /// contradiction tolerance (2 m by default), not when the two drift apart within it.
    #[test]
    fn a_relayed_alignment_is_withdrawn_only_when_its_relay_puts_the_neighbour_far_elsewhere() {
        assert!(!relayed_alignment_withdrawn(1.0), "agreeing");
        assert!(!relayed_alignment_withdrawn(3.0), "contradicted, but within twice the tolerance");
        assert!(relayed_alignment_withdrawn(5.0));
        assert!(relayed_alignment_withdrawn(32.0));
    }

    /// What a rematch needs after a crash survives the snapshot: the significance to beat, why
    /// the alignment was last withdrawn, and a bar that stands on a challenger's word.
    #[test]
    fn a_withdrawal_and_what_a_rematch_must_beat_survive_freeze_and_thaw() {
        let mut before = matcher();
        let barred = Pose3::translation(32.0, 0.0, 0.0);
        let entry = before.entry(RobotId(2));
        entry.bar(barred);
        entry.withdrawals = 1;
        entry.challenged_bar = Some(ChallengedBar { barred, challenger: Pose3::identity() });
        entry.discredited = vec![Pose3::translation(0.0, 40.0, 0.0)];
        entry.last_withdrawal = Some("at 57.5 s: a match of significance 3.41".into());
        entry.aligned_significance = Some(1.23);
        let state = before.freeze();
        let after = matcher().thawed(state.clone());
        let entry = &after.neighbours[&RobotId(2)];
        assert_eq!(entry.withdrawn, [barred]);
        assert_eq!(entry.challenged_bar, Some(ChallengedBar { barred, challenger: Pose3::identity() }));
        assert_eq!(entry.discredited, [Pose3::translation(0.0, 40.0, 0.0)]);
        assert_eq!(entry.aligned_significance, Some(1.23));
        assert_eq!(entry.last_withdrawal.as_deref(), Some("at 57.5 s: a match of significance 3.41"));
        assert_eq!(after.freeze(), state);
    }
}
