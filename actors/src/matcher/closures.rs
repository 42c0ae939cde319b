//! Closure rounds (`matcher.closures`): once a neighbour is aligned, its objects are associated
//! with ours through the current transform (`model::matching::closure`), a round is planned
//! over ground no earlier round covered, the object clouds of its pairs refine the transform
//! locally, and the neighbour keyframes that observed them — never one asked for before — are
//! registered onto ours. Each registration that converges and agrees with the scans becomes an
//! inter-robot factor; the Optimiser keeps the largest mutually consistent set of them (PCM,
//! `model::optim::consistency`) and re-estimates the transform from it
//! ([`NeighbourTransforms`]). A round that fails or times out ends; the alignment stands.

use super::association::graph_objects;
use super::rounds::{local_view, remote_view};
use super::*;
use crate::protocol::{Aligned, Closure, ClosureStage};
use sgm_model::matching::closure::{next_round, pairs_through};

impl Matcher {
    /// Starts a closure round with `robot` when one is due: aligned, no round in flight, the
    /// link up, under the byte budget, `interval_s` since the last look, and ground with
    /// enough object pairs that no earlier round covered.
    pub(super) fn try_close(&mut self, robot: RobotId) {
        let now = self.clock.now();
        let config = &self.config.closures;
        if !config.enabled || self.config.association != Association::Objects {
            return;
        }
        let Some(entry) = self.neighbours.get(&robot) else { return };
        let Some(Protocol::Aligned(n)) = &entry.protocol else { return };
        let memory = &entry.closures;
        let due = memory.last_considered.is_none_or(|t| now - t >= config.interval_s);
        let since_aligned = entry.first_aligned.map_or(0.0, |t| now - t);
        let spent = memory.counts.bytes as f64 >= config.allowance_bytes(since_aligned);
        if n.state.closure.is_some() || !entry.link_up || !due || spent {
            return;
        }
        let Some(data) = &entry.objects else { return };
        let pairs = pairs_through(
            &self.map.objects.objects,
            &graph_objects(data),
            &n.state.local_from_remote,
            &self.labels,
            config.gate_m,
        );
        let next = next_round(&pairs, &memory.seeds, &config.plan());
        let retry = self.retry.clone();
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        entry.closures.last_considered = Some(now);
        let Some((seed, round)) = next else { return };
        entry.closures.seeds.push(seed);
        entry.closures.counts.rounds += 1;
        let pairs: Vec<(ObjectId, ObjectId)> = round.iter().map(|p| (p.local, p.remote)).collect();
        let objects: Vec<ObjectId> = pairs.iter().map(|p| p.1).collect();
        if let Some(Protocol::Aligned(n)) = entry.protocol.take() {
            entry.protocol = Some(n.closure_started(pairs, now, &retry).into());
        }
        tracing::debug!(robot = %self.robot, neighbour = %robot, pairs = objects.len(), "closure round started");
        if let Some(links) = &self.links {
            links.request_clouds.do_send(RequestObjectClouds { robot, objects });
        }
    }

    /// The round's object clouds: refine the transform on them, then ask for the neighbour
    /// keyframes that observed its objects and were never asked for (at most
    /// `max_keyframes_per_round`, spread evenly).
    pub(super) fn on_closure_clouds(&mut self, msg: NeighbourObjectClouds, aligned: Neighbour<Aligned>) {
        let now = self.clock.now();
        let Some(Closure { pairs, stage: ClosureStage::Clouds { .. } }) = &aligned.state.closure else { return };
        let (guess, observed_in) = self.object_cloud_icp(pairs, &msg.clouds, &aligned.state.local_from_remote);
        let retry = self.retry.clone();
        let per_round = self.config.closures.max_keyframes_per_round;
        let Some(entry) = self.neighbours.get_mut(&msg.robot) else { return };
        let fresh: BTreeSet<KeyframeId> = observed_in
            .values()
            .flatten()
            .filter(|k| !entry.closures.requested.contains(k) && !entry.keyframes.contains_key(k))
            .copied()
            .collect();
        let wanted = evenly(fresh, per_round);
        if wanted.is_empty() {
            entry.protocol = Some(aligned.closure_ended().into());
            return;
        }
        entry.closures.requested.extend(wanted.iter().copied());
        entry.round = wanted.clone();
        entry.round_incomplete = false;
        entry.protocol = Some(aligned.closure_keyframes(guess, wanted.clone(), now, &retry).into());
        if let Some(links) = &self.links {
            links
                .request_keyframes
                .do_send(RequestKeyframes { robot: msg.robot, keyframes: wanted.into_iter().collect() });
        }
    }

    /// Every keyframe of the round arrived or will not: register those held onto the local
    /// keyframes that observed the round's objects and hand what registered to the Optimiser.
    pub(super) fn finish_closure(&mut self, robot: RobotId) {
        let Some(entry) = self.neighbours.get(&robot) else { return };
        let Some(Protocol::Aligned(n)) = entry.protocol.clone() else { return };
        let Some(Closure { pairs, stage: ClosureStage::Keyframes { guess, .. } }) = &n.state.closure else { return };
        let current = n.state.local_from_remote;
        let local_ids: BTreeSet<KeyframeId> =
            pairs.iter().filter_map(|(l, _)| self.map.objects.observed_in.get(l)).flatten().copied().collect();
        let keyframe_icp = self.keyframe_icp();
        let targets = local_ids.iter().filter_map(|id| Some((*id, local_view(self.map.keyframes.get(id)?)))).collect();
        let round = entry.keyframes.iter().filter(|(id, _)| entry.round.contains(id)).map(|(_, k)| remote_view(k));
        let registered = register_round(&targets, round, guess, &self.round_config(&keyframe_icp));
        let constraints = InterRobotConstraints {
            robot,
            local_from_remote: current,
            neighbour_keyframes: registered.neighbour_keyframes,
            factors: registered.factors,
        };
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        let added = constraints.factors.len();
        entry.closures.counts.factors += added as u32;
        // The factors hold what registration learnt: the clouds are let go.
        let released: Vec<KeyframeId> = std::mem::take(&mut entry.keyframes).into_keys().collect();
        entry.round.clear();
        if let Some(Protocol::Aligned(n)) = entry.protocol.take() {
            entry.protocol = Some(n.closure_ended().into());
        }
        self.release(robot, released);
        tracing::debug!(robot = %self.robot, neighbour = %robot, added, "closure round done");
        if let (Some(links), true) = (&self.links, added > 0) {
            links.optimiser.do_send(constraints);
        }
    }

    /// A closure round whose answer is overdue: its object clouds are asked for again with
    /// back-off, then given up; its keyframes (Comms retries those) are waited for as long,
    /// then the round is finished with what came.
    pub(super) fn closure_timeouts(&mut self, robot: RobotId, now: Stamp) {
        let retry = self.retry.clone();
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        let Some(Protocol::Aligned(mut n)) = entry.protocol.clone() else { return };
        let link_up = entry.link_up;
        let Some(closure) = &mut n.state.closure else { return };
        let (wait, clouds) = match &mut closure.stage {
            ClosureStage::Clouds { wait } => (wait, true),
            ClosureStage::Keyframes { wait, .. } => (wait, false),
        };
        if !link_up || !wait.expired(now) {
            return;
        }
        match wait.retry(now, &retry, link_up) {
            Some(next) => {
                *wait = next;
                let objects: Vec<ObjectId> = closure.pairs.iter().map(|p| p.1).collect();
                entry.protocol = Some(n.into());
                if let (true, Some(links)) = (clouds, &self.links) {
                    links.request_clouds.do_send(RequestObjectClouds { robot, objects });
                }
            }
            None if clouds => entry.protocol = Some(n.closure_ended().into()),
            None => self.finish_closure(robot),
        }
    }
}

impl Handler<NeighbourTransforms> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: NeighbourTransforms, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            for (robot, local_from_remote, withdrawals) in msg.0 {
                let Some(entry) = self.neighbours.get_mut(&robot) else { continue };
                // Solved before the graph heard of our last withdrawal: the withdrawn alignment's.
                if withdrawals != entry.withdrawals {
                    continue;
                }
                entry.protocol = match entry.protocol.take() {
                    Some(Protocol::Aligned(n)) => Some(n.reestimated(local_from_remote).into()),
                    other => other,
                };
            }
            self.share_alignments();
            self.review_contradictions();
        });
    }
}
