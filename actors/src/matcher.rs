//! `Matcher` (paper §IV-C, §IV-D): per neighbour, the protocol of `crate::protocol`. Object data
//! in → object-graph matching (`model::matching`) → with enough matched objects, the neighbour's
//! object clouds → ICP of its object clouds onto ours (refines `local_from_remote`) → the
//! neighbour keyframes that observed the matched objects, ± `keyframe_neighbourhood` → each
//! registered by ICP to the nearest local keyframe that observed a matched object → inter-robot
//! factors and the neighbour keyframes (with their marginal covariances) to the Optimiser.
//!
//! With `association = "scan_context"` (the evaluation's Swarm-SC baseline) the first two
//! steps differ: every local keyframe's Scan Context descriptor goes to Comms for broadcast;
//! a local and a neighbour keyframe whose descriptors agree give the first estimate,
//! local_from_remote = W_l(k_l) · Rz(−yaw) · W_r(k_r)⁻¹ (same place, turned by the descriptor's
//! yaw); the neighbour keyframes around k_r are requested, k_r is registered onto k_l coarse
//! to fine, and the rest is as above with the local keyframes around k_l as targets.

use crate::clock::Clock;
use crate::config::{Association, MatcherSection};
use crate::containment::contained;
use crate::messages::*;
use crate::protocol::{Matched, Neighbour, Protocol, ProtocolStage, RetryConfig, Wait};
use actix::{Actor, Context, Handler, Message, MessageResult, Recipient, Supervised};
use nalgebra::Point3;
use sgm_model::geometry::Pose3;
use sgm_model::matching::alignment::{
    coarse_to_fine, evenly, judge_round, neighbourhood, refuted_recently, register_round, yaw_turn, LocalView,
    RemoteView, RoundConfig, RoundVerdict,
};
use sgm_model::matching::place_candidates::{EvenPlaces, PlaceCandidate, PlaceCandidates};
use sgm_model::matching::scan_context::{Place, ScanContext};
use sgm_model::matching::{match_graphs, GraphObject, LabelSimilarity, MatchOutcome, ObjectGraph};
use sgm_model::perception::icp::{register, IcpConfig};
use sgm_model::perception::object_cloud::{object_cloud, MAX_VIEWS};
use sgm_model::scene_graph::{KeyframeId, ObjectId, RobotId, SemanticScan, Stamp};
use sgm_model::wire::cloud_codec;
use sgm_model::wire::messages::{KeyframeRefusalReason, ObjectData};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

/// Where the Matcher sends what it produces.
#[derive(Clone)]
pub struct MatcherLinks {
    pub request_clouds: Recipient<RequestObjectClouds>,
    pub request_keyframes: Recipient<RequestKeyframes>,
    pub release_keyframes: Recipient<KeyframesReleased>,
    pub share_descriptors: Recipient<ShareDescriptor>,
    pub optimiser: Recipient<InterRobotConstraints>,
}

/// The protocol state and alignment of every neighbour.
#[derive(Message)]
#[rtype(result = "Vec<NeighbourStatus>")]
pub struct GetNeighbours;

#[derive(Clone, Debug, PartialEq)]
pub struct NeighbourStatus {
    pub robot: RobotId,
    /// Where its protocol stands (none only while a handler that failed is being restarted).
    pub state: Option<ProtocolStage>,
    pub local_from_remote: Option<Pose3>,
    /// When it first reached `Aligned`.
    pub first_aligned: Option<f64>,
    pub keyframes_held: usize,
    /// Revision of the neighbour's object data held (`None`: none received).
    pub objects_revision: Option<u32>,
}

/// A local keyframe: its latest pose and the map's scan (shared, not copied).
struct LocalKeyframeData {
    world_from_body: Pose3,
    scan: Arc<SemanticScan>,
}

/// A local keyframe as registration sees it.
fn local_view(k: &LocalKeyframeData) -> LocalView<'_> {
    LocalView { world_from_body: &k.world_from_body, points_in_body: &k.scan.points_in_body }
}

/// A neighbour keyframe as registration sees it.
fn remote_view(k: &NeighbourKeyframe) -> RemoteView<'_> {
    RemoteView {
        id: k.id,
        world_from_body: &k.world_from_body,
        covariance: &k.covariance,
        points_in_body: &k.points_in_body,
    }
}

struct NeighbourEntry {
    protocol: Option<Protocol>,
    objects: Option<ObjectData>,
    keyframes: BTreeMap<KeyframeId, NeighbourKeyframe>,
    first_aligned: Option<f64>,
    /// Remote object → keyframes that observed it (from the object-cloud response).
    observed_in: BTreeMap<ObjectId, Vec<KeyframeId>>,
    /// Transforms refuted by keyframe registration, and when: a match landing near one of them
    /// within [`REFUTED_FOR_S`] is not pursued again.
    refuted: Vec<(Pose3, Stamp)>,
    /// The neighbour keyframes of the current alignment round (requested or already held).
    round: BTreeSet<KeyframeId>,
    /// When matching against this neighbour was last tried.
    last_attempt: Option<Stamp>,
    /// Scan Context association only: the neighbour's descriptors and the candidate pairs.
    places: PlaceCandidates,
    /// Scan Context association only (never set otherwise): the pair of the current round and
    /// the local keyframes around its local one (object association derives its targets from
    /// the object pairs).
    place_round: Option<(PlaceCandidate, BTreeSet<KeyframeId>)>,
    /// Comms reported the link down: nothing is matched, requested or retried until it is back.
    link_up: bool,
    /// A keyframe of the current round was given up on (lost, not refused): too few factors
    /// then say nothing against the match.
    round_incomplete: bool,
    /// The last round was cut short by losses, not refuted: match again once
    /// `match_interval_s` has passed, even if no new object data comes.
    match_again: bool,
}

/// What of the Matcher a snapshot keeps, per neighbour: its protocol state (a request in flight
/// is not kept: see [`Protocol::settled`]), its latest object data, every keyframe received
/// (never asked for twice, also across a crash), and the refuted transforms. Local keyframes
/// and objects are not kept here: the Tracker hands them over again after a thaw.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MatcherState {
    pub neighbours: Vec<NeighbourMemory>,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NeighbourMemory {
    pub robot: RobotId,
    pub protocol: Option<Protocol>,
    pub objects: Option<ObjectData>,
    pub keyframes: Vec<NeighbourKeyframe>,
    pub first_aligned: Option<f64>,
    pub refuted: Vec<(Pose3, Stamp)>,
}

/// Drops held neighbour keyframes outside `round`, lowest ids first, until at most `cap` are
/// held; the ids dropped.
fn hold_at_most(
    held: &mut BTreeMap<KeyframeId, NeighbourKeyframe>,
    round: &BTreeSet<KeyframeId>,
    cap: usize,
) -> Vec<KeyframeId> {
    let excess = held.len().saturating_sub(cap);
    let victims: Vec<KeyframeId> = held.keys().filter(|k| !round.contains(k)).take(excess).copied().collect();
    for k in &victims {
        held.remove(k);
    }
    victims
}

pub struct Matcher {
    robot: RobotId,
    config: MatcherSection,
    retry: RetryConfig,
    clock: Clock,
    labels: LabelSimilarity,
    links: Option<MatcherLinks>,
    local: LocalObjects,
    keyframes: BTreeMap<KeyframeId, LocalKeyframeData>,
    /// Scan Context association only: our keyframes' descriptors, at most
    /// `scan_context.max_places`, spread over the run.
    places: EvenPlaces,
    neighbours: BTreeMap<RobotId, NeighbourEntry>,
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
            local: LocalObjects::default(),
            keyframes: BTreeMap::new(),
            places: EvenPlaces::default(),
            neighbours: BTreeMap::new(),
        }
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
            entry.keyframes = memory.keyframes.into_iter().map(|k| (k.id, k)).collect();
            entry.first_aligned = memory.first_aligned;
            entry.refuted = memory.refuted;
            entry.match_again = true;
        }
        self
    }

    fn entry(&mut self, robot: RobotId) -> &mut NeighbourEntry {
        let now = self.clock.now();
        self.neighbours.entry(robot).or_insert_with(|| NeighbourEntry {
            protocol: Some(Neighbour::discovered(robot, now).into()),
            objects: None,
            keyframes: BTreeMap::new(),
            first_aligned: None,
            observed_in: BTreeMap::new(),
            refuted: Vec::new(),
            round: BTreeSet::new(),
            last_attempt: None,
            places: PlaceCandidates::default(),
            place_round: None,
            link_up: true,
            round_incomplete: false,
            match_again: false,
        })
    }

    /// Tells Comms that these neighbour keyframes are no longer held.
    fn release(&self, robot: RobotId, keyframes: Vec<KeyframeId>) {
        if let (Some(links), false) = (&self.links, keyframes.is_empty()) {
            links.release_keyframes.do_send(KeyframesReleased { robot, keyframes });
        }
    }

    fn local_object_cloud(&self, object: &GraphObject) -> Vec<Point3<f64>> {
        let observed = self.local.observed_in.get(&object.id).cloned().unwrap_or_default();
        let scans = observed
            .iter()
            .rev()
            .filter_map(|k| self.keyframes.get(k))
            .take(MAX_VIEWS)
            .map(|k| (&k.world_from_body, &k.scan.points_in_body[..], &k.scan.labels[..]));
        object_cloud(scans, object.label, &object.centroid, &object.size.unwrap_or_default(), 0.3, 0.1)
    }

    /// Matches the neighbour's latest object data against ours; asks for object clouds on success.
    fn try_match(&mut self, robot: RobotId) {
        let now = self.clock.now();
        let min_matched = self.config.min_matched_objects;
        let Some(entry) = self.neighbours.get(&robot) else { return };
        let Some(data) = &entry.objects else { return };
        let waiting = matches!(entry.protocol, Some(Protocol::ObjectsReceived(_)));
        let due = entry.last_attempt.is_none_or(|t| now - t >= self.config.match_interval_s);
        if !waiting || !due || !entry.link_up || self.config.association != Association::Objects {
            return;
        }
        let remote_objects: Vec<GraphObject> = data
            .objects
            .iter()
            .map(|o| GraphObject {
                id: o.id,
                label: o.label,
                centroid: o.centroid_m(data.resolution_mm),
                size: Some(o.size_m()),
            })
            .collect();
        let (Ok(local), Ok(remote)) =
            (ObjectGraph::new(self.local.objects.clone(), usize::MAX), ObjectGraph::new(remote_objects, usize::MAX))
        else {
            return;
        };
        let refuted = entry.refuted.clone();
        if let Some(entry) = self.neighbours.get_mut(&robot) {
            entry.last_attempt = Some(now);
            entry.match_again = false;
        }
        let report = match_graphs(&local, &remote, &self.labels, &self.config.matching);
        let alignment = match report.outcome {
            MatchOutcome::Aligned(alignment) => alignment,
            MatchOutcome::Refused(refusal) => {
                tracing::debug!(robot = %self.robot, neighbour = %robot, reason = %refusal.reason, "object graphs not matched");
                return;
            }
        };
        if alignment.matches.len() < min_matched {
            return;
        }
        if refuted_recently(&refuted, &alignment.local_from_remote, now) {
            return;
        }
        let pairs: Vec<(ObjectId, ObjectId)> = alignment.matches.iter().map(|m| (m.local, m.remote)).collect();
        let remote_ids: Vec<ObjectId> = pairs.iter().map(|p| p.1).collect();
        let retry = self.retry.clone();
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        if let Some(Protocol::ObjectsReceived(n)) = entry.protocol.take() {
            entry.protocol = Some(n.matched(alignment.local_from_remote, pairs, now, &retry).into());
        }
        tracing::info!(robot = %self.robot, neighbour = %robot, matches = remote_ids.len(), "object graphs matched");
        if let Some(links) = &self.links {
            links.request_clouds.do_send(RequestObjectClouds { robot, objects: remote_ids });
        }
    }

    /// Matches by the configured association (objects, or Scan Context descriptors).
    fn try_associate(&mut self, robot: RobotId) {
        match self.config.association {
            Association::ScanContext => self.try_match_places(robot),
            _ => self.try_match(robot),
        }
    }

    /// Sends the object-cloud request of a match again.
    fn ask_clouds_again(&self, robot: RobotId, matched: &Neighbour<Matched>) {
        if let Some(links) = &self.links {
            let objects = matched.state.pairs.iter().map(|p| p.1).collect();
            links.request_clouds.do_send(RequestObjectClouds { robot, objects });
        }
    }

    /// Scan Context association: our descriptors of `dropped` are gone; no neighbour's
    /// candidates may name them.
    fn forget_places(&mut self, dropped: &[KeyframeId]) {
        if dropped.is_empty() {
            return;
        }
        for entry in self.neighbours.values_mut() {
            entry.places.forget_local(dropped);
        }
    }

    /// Scan Context association: compares the descriptors not yet compared and starts an
    /// alignment round from the best candidate pair not refuted recently.
    fn try_match_places(&mut self, robot: RobotId) {
        let now = self.clock.now();
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        let waiting = matches!(entry.protocol, Some(Protocol::ObjectsReceived(_)));
        let due = entry.last_attempt.is_none_or(|t| now - t >= self.config.match_interval_s);
        if !waiting || !due || !entry.link_up {
            return;
        }
        entry.last_attempt = Some(now);
        entry.match_again = false;
        entry.places.update(self.places.held(), &self.config.scan_context);
        let candidate = loop {
            let Some(c) = entry.places.take_best() else { return };
            let (Some(local), Some(remote)) = (self.keyframes.get(&c.local), entry.places.remote_pose(c.remote)) else {
                continue;
            };
            let guess = local.world_from_body * yaw_turn(-c.yaw) * remote.inverse();
            if !refuted_recently(&entry.refuted, &guess, now) {
                break (c, guess);
            }
        };
        let (c, guess) = candidate;
        let k = self.config.keyframe_neighbourhood as u32;
        let remote_ids: BTreeSet<KeyframeId> =
            neighbourhood([c.remote], k).into_iter().filter(|id| entry.places.knows_remote(*id)).collect();
        let mut round = evenly(remote_ids, self.config.max_keyframes_per_alignment.max(1));
        round.insert(c.remote);
        let local_targets: BTreeSet<KeyframeId> =
            neighbourhood([c.local], k).into_iter().filter(|id| self.keyframes.contains_key(id)).collect();
        let wanted: BTreeSet<KeyframeId> =
            round.iter().filter(|id| !entry.keyframes.contains_key(id)).copied().collect();
        let retry = self.retry.clone();
        if let Some(Protocol::ObjectsReceived(n)) = entry.protocol.take() {
            let matched = n.matched(guess, Vec::new(), now, &retry);
            entry.protocol = Some(matched.keyframes_requested(guess, wanted.clone(), now, &retry).into());
        }
        entry.round = round;
        entry.round_incomplete = false;
        entry.place_round = Some((c, local_targets));
        tracing::info!(robot = %self.robot, neighbour = %robot, local = c.local.0, remote = c.remote.0,
            distance = c.distance, "scan contexts matched");
        if wanted.is_empty() {
            self.finish_alignment(robot);
        } else if let Some(links) = &self.links {
            links.request_keyframes.do_send(RequestKeyframes { robot, keyframes: wanted.into_iter().collect() });
        }
    }

    fn on_object_clouds(&mut self, msg: NeighbourObjectClouds) {
        let now = self.clock.now();
        let Some(Protocol::Matched(matched)) = self.neighbours.get(&msg.robot).and_then(|e| e.protocol.clone()) else {
            return;
        };
        // Object-cloud ICP: remote object points (remote world) onto ours (local world).
        let remote_of: BTreeMap<ObjectId, ObjectId> = matched.state.pairs.iter().map(|(l, r)| (*r, *l)).collect();
        let (mut source, mut target) = (Vec::new(), Vec::new());
        let mut observed_in = BTreeMap::new();
        for cloud in &msg.clouds {
            let Some(local_id) = remote_of.get(&cloud.id) else { continue };
            observed_in.insert(cloud.id, cloud.keyframes.clone());
            // The envelope held the clouds' declared points within `comms.limits.max_cloud_points`.
            if let Ok(points) = cloud_codec::decode(&cloud.cloud) {
                source.extend(points);
            }
            if let Some(object) = self.local.objects.iter().find(|o| o.id == *local_id) {
                target.extend(self.local_object_cloud(object));
            }
        }
        let mut local_from_remote = matched.state.local_from_remote;
        if let Ok(result) = register(&source, &target, &local_from_remote, &self.config.icp) {
            if result.converged {
                local_from_remote = result.target_from_source;
            }
        }
        // Neighbour keyframes that observed the matched objects, ± the neighbourhood.
        let around = neighbourhood(observed_in.values().flatten().copied(), self.config.keyframe_neighbourhood as u32);
        let round = evenly(around, self.config.max_keyframes_per_alignment);
        let retry = self.retry.clone();
        let entry = self.entry(msg.robot);
        entry.observed_in = observed_in;
        let wanted: BTreeSet<KeyframeId> =
            round.iter().filter(|id| !entry.keyframes.contains_key(id)).copied().collect();
        entry.round = round;
        entry.round_incomplete = false;
        entry.protocol = Some(matched.keyframes_requested(local_from_remote, wanted.clone(), now, &retry).into());
        tracing::debug!(robot = %self.robot, neighbour = %msg.robot, wanted = wanted.len(), "object clouds in, keyframes wanted");
        if wanted.is_empty() {
            self.finish_alignment(msg.robot);
        } else if let Some(links) = &self.links {
            links
                .request_keyframes
                .do_send(RequestKeyframes { robot: msg.robot, keyframes: wanted.into_iter().collect() });
        }
    }

    fn on_keyframe_resolved(&mut self, robot: RobotId, id: KeyframeId) {
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        if let Some(Protocol::KeyframesRequested(n)) = &mut entry.protocol {
            n.state.awaiting.remove(&id);
            if n.state.awaiting.is_empty() {
                self.finish_alignment(robot);
            }
        }
    }

    /// Every requested keyframe arrived or was reported unavailable: register them and align
    /// (`model::matching::alignment`).
    fn finish_alignment(&mut self, robot: RobotId) {
        let now = self.clock.now();
        let Some(entry) = self.neighbours.get(&robot) else { return };
        let Some(Protocol::KeyframesRequested(n)) = entry.protocol.clone() else { return };
        let mut local_from_remote = n.state.local_from_remote;
        // Local keyframes that observed the matched objects are the registration targets (with
        // Scan Context, those around the round's local keyframe).
        let local_ids: BTreeSet<KeyframeId> = match &entry.place_round {
            Some((_, targets)) => targets.clone(),
            _ => n.state.pairs.iter().filter_map(|(l, _)| self.local.observed_in.get(l)).flatten().copied().collect(),
        };
        let keyframe_icp = IcpConfig {
            voxel_m: self.config.keyframe_voxel_m,
            max_iterations: self.config.keyframe_max_iterations,
            ..self.config.icp.clone()
        };
        if let Some((pair, _)) = &entry.place_round {
            let (local, remote) = (self.keyframes.get(&pair.local), entry.keyframes.get(&pair.remote));
            let coarse = self.config.scan_context.coarse_correspondence_m;
            if let Some(refined) = local
                .zip(remote)
                .and_then(|(l, r)| coarse_to_fine(&local_view(l), &remote_view(r), pair.yaw, coarse, &keyframe_icp))
            {
                local_from_remote = refined;
            }
        }
        let targets = local_ids.iter().filter_map(|id| Some((*id, local_view(self.keyframes.get(id)?)))).collect();
        let round = entry.keyframes.iter().filter(|(id, _)| entry.round.contains(id)).map(|(_, k)| remote_view(k));
        let config = RoundConfig {
            icp: &keyframe_icp,
            structure: &self.config.structure_check,
            min_structure_agreement: self.config.min_structure_agreement,
        };
        let registered = register_round(&targets, round, &local_from_remote, &config);
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        let factors = registered.factors.len();
        match judge_round(&registered, self.config.min_keyframe_factors, entry.round_incomplete, &local_from_remote) {
            RoundVerdict::Incomplete => {
                // Keyframes were lost on the way: too few to judge the match, which is tried again.
                tracing::info!(robot = %self.robot, neighbour = %robot, factors, "alignment round incomplete");
                if let Some(Protocol::KeyframesRequested(n)) = entry.protocol.take() {
                    entry.protocol = Some(n.gave_up(now).into());
                }
                entry.match_again = true;
            }
            RoundVerdict::Refuted => {
                tracing::info!(robot = %self.robot, neighbour = %robot, factors, "object match refuted");
                entry.refuted.push((n.state.local_from_remote, now));
                if let Some(Protocol::KeyframesRequested(n)) = entry.protocol.take() {
                    entry.protocol = Some(n.refuted(now).into());
                }
            }
            RoundVerdict::Aligned(local_from_remote) => {
                if let Some(Protocol::KeyframesRequested(n)) = entry.protocol.take() {
                    entry.protocol = Some(n.aligned(local_from_remote, now).into());
                    entry.first_aligned.get_or_insert(now);
                }
                // Aligned is final: no later round reads the neighbour's clouds.
                let released: Vec<KeyframeId> = std::mem::take(&mut entry.keyframes).into_keys().collect();
                entry.round.clear();
                self.release(robot, released);
                tracing::info!(robot = %self.robot, neighbour = %robot, factors, "aligned");
                if let (Some(links), false) = (&self.links, registered.factors.is_empty()) {
                    links.optimiser.do_send(InterRobotConstraints {
                        robot,
                        local_from_remote,
                        neighbour_keyframes: registered.neighbour_keyframes,
                        factors: registered.factors,
                    });
                }
            }
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

impl Handler<LocalObjects> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: LocalObjects, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            self.local = msg;
            let robots: Vec<RobotId> = self.neighbours.keys().copied().collect();
            for robot in robots {
                self.try_match(robot);
            }
        });
    }
}

impl Handler<LocalKeyframe> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: LocalKeyframe, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            let data = LocalKeyframeData { world_from_body: msg.world_from_body, scan: msg.scan.clone() };
            self.keyframes.insert(msg.id, data);
            if self.config.association == Association::ScanContext {
                let points: Vec<Point3<f64>> = msg.scan.points_in_body.iter().map(|p| p.cast::<f64>()).collect();
                let descriptor = ScanContext::new(&points, &self.config.scan_context.descriptor);
                if let Some(links) = &self.links {
                    let (keyframe, world_from_body) = (msg.id, msg.world_from_body);
                    let share = ShareDescriptor { keyframe, world_from_body, descriptor: descriptor.clone() };
                    links.share_descriptors.do_send(share);
                }
                let dropped = self.places.insert(msg.id, Place::new(descriptor), self.config.scan_context.max_places);
                self.forget_places(&dropped);
                let robots: Vec<RobotId> = self.neighbours.keys().copied().collect();
                for robot in robots {
                    self.try_match_places(robot);
                }
            }
        });
    }
}

impl Handler<LocalScansChanged> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: LocalScansChanged, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            for (id, change) in msg.changes {
                match change {
                    Some(scan) => {
                        if let Some(k) = self.keyframes.get_mut(&id) {
                            k.scan = scan;
                        }
                    }
                    None => {
                        self.keyframes.remove(&id);
                        // Its descriptor could only lead to a keyframe we cannot register.
                        if self.places.remove(id) {
                            self.forget_places(&[id]);
                        }
                    }
                }
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

impl Handler<PosesOptimised> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: PosesOptimised, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            for (id, pose) in msg.poses {
                if let Some(k) = self.keyframes.get_mut(&id) {
                    k.world_from_body = pose;
                }
            }
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
            for robot in robots {
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
                    robot: *robot,
                    state: e.protocol.as_ref().map(Protocol::stage),
                    local_from_remote: e.protocol.as_ref().and_then(|p| p.local_from_remote().copied()),
                    first_aligned: e.first_aligned,
                    keyframes_held: e.keyframes.len(),
                    objects_revision: e.objects.as_ref().map(|d| d.revision),
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
    use nalgebra::Matrix6;

    #[test]
    fn held_neighbour_keyframes_beyond_the_cap_go_lowest_first_sparing_the_round() {
        let keyframe = |id: u32| NeighbourKeyframe {
            robot: RobotId(2),
            id: KeyframeId(id),
            world_from_body: Pose3::identity(),
            covariance: Matrix6::identity(),
            points_in_body: Vec::new(),
        };
        let mut held: BTreeMap<KeyframeId, NeighbourKeyframe> = (0..10).map(|k| (KeyframeId(k), keyframe(k))).collect();
        let round: BTreeSet<KeyframeId> = [KeyframeId(1), KeyframeId(2)].into();
        let released = hold_at_most(&mut held, &round, 5);
        assert_eq!(released, [0, 3, 4, 5, 6].map(KeyframeId));
        assert_eq!(held.keys().copied().collect::<Vec<_>>(), [1, 2, 7, 8, 9].map(KeyframeId));
        // The round itself is never dropped, even over the cap.
        let everything: BTreeSet<KeyframeId> = held.keys().copied().collect();
        assert!(hold_at_most(&mut held, &everything, 2).is_empty());
        assert_eq!(held.len(), 5);
    }
}
