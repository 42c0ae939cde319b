//! Association: which neighbour's map overlaps ours, and the first estimate of the transform
//! between them. By object-graph matching (`model::matching`, the paper) or, with
//! `matcher.association = "scan_context"`, by Scan Context descriptors (the evaluation's
//! Swarm-SC baseline).

use super::relay::RoundStart;
use super::*;
use sgm_model::geometry::Brief;

/// A neighbour's object data as graph objects (its world).
pub(super) fn graph_objects(data: &ObjectData) -> Vec<GraphObject> {
    data.objects
        .iter()
        .map(|o| GraphObject {
            id: o.id,
            label: o.label,
            centroid: o.centroid_m(data.resolution_mm),
            size: Some(o.size_m()),
        })
        .collect()
}

/// Whether two object lists are the same to the bit (graph matching gives the same outcome).
pub(super) fn same_objects(a: &[GraphObject], b: &[GraphObject]) -> bool {
    let bits = |p: &Point3<f64>| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    let size_bits = |s: &Option<nalgebra::Vector3<f64>>| s.map(|s| [s.x.to_bits(), s.y.to_bits(), s.z.to_bits()]);
    a.len() == b.len()
        && a.iter().zip(b).all(|(a, b)| {
            a.id == b.id
                && a.label == b.label
                && bits(&a.centroid) == bits(&b.centroid)
                && size_bits(&a.size) == size_bits(&b.size)
        })
}

impl Matcher {
    /// Matches the neighbour's latest object data against ours; asks for object clouds on success.
    /// Unchanged inputs since the last attempt reuse its outcome.
    pub(super) fn try_match(&mut self, robot: RobotId) {
        let now = self.clock.now();
        let min_matched = self.config.min_matched_objects;
        let Some(entry) = self.neighbours.get(&robot) else { return };
        let Some(data) = &entry.objects else { return };
        let waiting = matches!(entry.protocol, Some(Protocol::ObjectsReceived(_)));
        let due = entry.last_attempt.is_none_or(|t| now - t >= self.config.match_interval_s);
        if !waiting || !due || !entry.link_up || self.config.association != Association::Objects {
            return;
        }
        let remote_objects = graph_objects(data);
        let (Ok(local), Ok(remote)) = (
            ObjectGraph::new(self.map.objects.objects.clone(), usize::MAX),
            ObjectGraph::new(remote_objects, usize::MAX),
        ) else {
            return;
        };
        let refuted = entry.refuted.clone();
        let (local_objects, remote_revision) = (self.local_objects_revision, data.revision);
        let reused = entry
            .last_match
            .as_ref()
            .filter(|last| last.local_objects == local_objects && last.remote_revision == remote_revision)
            .map(|last| last.outcome.clone());
        if let Some(entry) = self.neighbours.get_mut(&robot) {
            entry.last_attempt = Some(now);
            entry.match_again = false;
        }
        let outcome = match reused {
            Some(outcome) => outcome,
            None => {
                let outcome = match_graphs(&local, &remote, &self.labels, &self.config.matching).outcome;
                if let Some(entry) = self.neighbours.get_mut(&robot) {
                    entry.last_match = Some(LastMatch { local_objects, remote_revision, outcome: outcome.clone() });
                }
                outcome
            }
        };
        // Refusals before any hypothesis was scored (too few objects, no candidates) carry none.
        let significance = match &outcome {
            MatchOutcome::Aligned(a) => Some(a.significance),
            MatchOutcome::Refused(r) => r.best_guess.is_some().then_some(r.significance),
        };
        let (matched, refusal) = match outcome {
            MatchOutcome::Aligned(alignment) if alignment.matches.len() < min_matched => {
                let n = alignment.matches.len();
                (None, Some(format!("{n} objects matched, fewer than matcher.min_matched_objects ({min_matched})")))
            }
            MatchOutcome::Aligned(alignment) if self.withdrawn_near(robot, &alignment.local_from_remote) => {
                (None, Some("the match lands on an alignment withdrawn by a contradicted cycle".to_string()))
            }
            MatchOutcome::Aligned(alignment) if refuted_recently(&refuted, &alignment.local_from_remote, now) => (
                None,
                Some(format!("the match lands on a transform keyframe registration refuted within {REFUTED_FOR_S} s")),
            ),
            MatchOutcome::Aligned(alignment) => {
                let pairs: Vec<(ObjectId, ObjectId)> = alignment.matches.iter().map(|m| (m.local, m.remote)).collect();
                (Some(RoundStart { local_from_remote: alignment.local_from_remote, pairs, via: None }), None)
            }
            MatchOutcome::Refused(refusal) => {
                tracing::debug!(robot = %self.robot, neighbour = %robot, reason = %refusal.reason, "object graphs not matched");
                (None, Some(refusal.reason.to_string()))
            }
        };
        if let Some(entry) = self.neighbours.get_mut(&robot) {
            entry.attempts.record(now, significance, refusal);
        }
        // Graph matching found nothing to pursue: a neighbour's alignment may still place it.
        let Some(RoundStart { local_from_remote, pairs, via }) =
            matched.or_else(|| self.hinted(robot, local.objects(), remote.objects(), now))
        else {
            return;
        };
        let remote_ids: Vec<ObjectId> = pairs.iter().map(|p| p.1).collect();
        let retry = self.retry.clone();
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        if let Some(Protocol::ObjectsReceived(n)) = entry.protocol.take() {
            entry.protocol = Some(n.matched(local_from_remote, pairs, now, &retry).into());
        }
        entry.round_via = via;
        let at = Brief(&local_from_remote);
        match via {
            None => {
                tracing::info!(robot = %self.robot, neighbour = %robot, matches = remote_ids.len(), local_from_remote = %at, "object graphs matched")
            }
            Some(via) => {
                tracing::info!(robot = %self.robot, neighbour = %robot, %via, pairs = remote_ids.len(), local_from_remote = %at, "round from a relayed alignment")
            }
        }
        if let Some(links) = &self.links {
            links.request_clouds.do_send(RequestObjectClouds { robot, objects: remote_ids });
        }
    }

    /// Matches by the configured association (objects, or Scan Context descriptors).
    pub(super) fn try_associate(&mut self, robot: RobotId) {
        match self.config.association {
            Association::ScanContext => self.try_match_places(robot),
            _ => self.try_match(robot),
        }
    }

    /// Sends the object-cloud request of a match again.
    pub(super) fn ask_clouds_again(&self, robot: RobotId, matched: &Neighbour<Matched>) {
        if let Some(links) = &self.links {
            let objects = matched.state.pairs.iter().map(|p| p.1).collect();
            links.request_clouds.do_send(RequestObjectClouds { robot, objects });
        }
    }

    /// Scan Context association: our descriptors of `dropped` are gone; no neighbour's
    /// candidates may name them.
    pub(super) fn forget_places(&mut self, dropped: &[KeyframeId]) {
        if dropped.is_empty() {
            return;
        }
        for entry in self.neighbours.values_mut() {
            entry.places.forget_local(dropped);
        }
    }

    /// Scan Context association: compares the descriptors not yet compared and starts an
    /// alignment round from the best candidate pair not refuted recently.
    pub(super) fn try_match_places(&mut self, robot: RobotId) {
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
            let (Some(local), Some(remote)) = (self.map.keyframes.get(&c.local), entry.places.remote_pose(c.remote))
            else {
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
            neighbourhood([c.local], k).into_iter().filter(|id| self.map.keyframes.contains_key(id)).collect();
        let wanted: BTreeSet<KeyframeId> =
            round.iter().filter(|id| !entry.keyframes.contains_key(id)).copied().collect();
        entry.closures.requested.extend(wanted.iter().copied());
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use sgm_model::scene_graph::LabelId;

    fn objects() -> Vec<GraphObject> {
        (0..4)
            .map(|k| GraphObject {
                id: ObjectId(k),
                label: LabelId(k as u16 % 2),
                centroid: Point3::new(k as f64, 2.0 * k as f64, 0.5),
                size: Some(nalgebra::Vector3::new(0.5, 0.5, 1.0)),
            })
            .collect()
    }

    #[test]
    fn objects_are_the_same_only_to_the_bit() {
        let a = objects();
        assert!(same_objects(&a, &a.clone()));
        let mut moved = a.clone();
        moved[2].centroid.x = f64::from_bits(moved[2].centroid.x.to_bits() + 1);
        assert!(!same_objects(&a, &moved), "one ulp apart");
        let mut signed = a.clone();
        signed[0].centroid.x = -0.0;
        assert!(!same_objects(&a, &signed), "0 and −0 compare equal but are different bits");
        let mut relabelled = a.clone();
        relabelled[1].label = LabelId(7);
        assert!(!same_objects(&a, &relabelled));
        let mut resized = a.clone();
        resized[3].size = None;
        assert!(!same_objects(&a, &resized));
        assert!(!same_objects(&a, &a[..3]));
    }
}
