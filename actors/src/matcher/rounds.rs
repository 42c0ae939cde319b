//! An alignment round (paper §IV-C, §IV-D): object clouds in, object-cloud ICP refines the
//! match, the neighbour keyframes around the matched objects are asked for, and once all are
//! in (or reported unavailable) the round is registered and judged by
//! `model::matching::alignment`: incomplete, refuted, or aligned with inter-robot factors.

use super::*;
use sgm_model::geometry::Brief;

/// A local keyframe as registration sees it.
pub(super) fn local_view(k: &ViewKeyframe) -> LocalView<'_> {
    LocalView { world_from_body: &k.world_from_body, points_in_body: &k.scan.points_in_body }
}

/// A neighbour keyframe as registration sees it.
pub(super) fn remote_view(k: &NeighbourKeyframe) -> RemoteView<'_> {
    RemoteView {
        id: k.id,
        world_from_body: &k.world_from_body,
        covariance: &k.covariance,
        points_in_body: &k.points_in_body,
    }
}

impl Matcher {
    /// Keyframe-to-keyframe ICP: the object-cloud settings at the keyframe voxel size and
    /// iteration cap.
    pub(super) fn keyframe_icp(&self) -> IcpConfig {
        IcpConfig {
            voxel_m: self.config.keyframe_voxel_m,
            max_iterations: self.config.keyframe_max_iterations,
            ..self.config.icp.clone()
        }
    }

    /// How a round's keyframes are registered and checked, with `icp` from [`Self::keyframe_icp`].
    pub(super) fn round_config<'a>(&'a self, icp: &'a IcpConfig) -> RoundConfig<'a> {
        RoundConfig {
            icp,
            structure: &self.config.structure_check,
            min_structure_agreement: self.config.min_structure_agreement,
            sigma_floor: self.config.factor_sigma_floor(),
            workers: &self.workers,
            // Gravity-aligned worlds (as the Optimiser's level anchors), when asked for.
            level: self.config.level_registration && self.config.matching.max_tilt_deg == 0.0,
        }
    }

    pub(super) fn local_object_cloud(&self, object: &GraphObject) -> Vec<Point3<f64>> {
        let observed = self.map.objects.observed_in.get(&object.id).cloned().unwrap_or_default();
        let scans = observed
            .iter()
            .rev()
            .filter_map(|k| self.map.keyframes.get(k))
            .take(MAX_VIEWS)
            .map(|k| (&k.world_from_body, &k.scan.points_in_body[..], &k.scan.labels[..]));
        object_cloud(scans, object.label, &object.centroid, &object.size.unwrap_or_default(), 0.3, 0.1)
    }

    /// Object-cloud ICP of the matched pairs (remote object points, remote world, onto ours,
    /// local world) from `initial`: the refined transform (`initial` when ICP does not
    /// converge or the pairs are fewer than three), and the neighbour keyframes that observed
    /// each matched remote object.
    pub(super) fn object_cloud_icp(
        &self,
        pairs: &[(ObjectId, ObjectId)],
        clouds: &[ObjectCloud],
        initial: &Pose3,
    ) -> (Pose3, BTreeMap<ObjectId, Vec<KeyframeId>>) {
        let remote_of: BTreeMap<ObjectId, ObjectId> = pairs.iter().map(|(l, r)| (*r, *l)).collect();
        let (mut source, mut target) = (Vec::new(), Vec::new());
        let mut observed_in = BTreeMap::new();
        for cloud in clouds {
            let Some(local_id) = remote_of.get(&cloud.id) else { continue };
            observed_in.insert(cloud.id, cloud.keyframes.clone());
            // The envelope held the clouds' declared points within `comms.limits.max_cloud_points`.
            if let Ok(points) = cloud_codec::decode(&cloud.cloud) {
                source.extend(points);
            }
            if let Some(object) = self.map.objects.objects.iter().find(|o| o.id == *local_id) {
                target.extend(self.local_object_cloud(object));
            }
        }
        // Fewer than three objects leave a turn about them free (one object: any turn about its
        // centroid): the first estimate stands, and the keyframes' registrations refine it.
        if pairs.len() < 3 {
            return (*initial, observed_in);
        }
        let icp = &self.config.icp;
        let registered = IcpTarget::new(&target, icp)
            .and_then(|mut t| register_to(&source, &mut t, initial, icp, &self.workers, Freedom::Full));
        let refined = match registered {
            Ok(result) if result.converged => result.target_from_source,
            _ => *initial,
        };
        (refined, observed_in)
    }

    pub(super) fn on_object_clouds(&mut self, msg: NeighbourObjectClouds) {
        let now = self.clock.now();
        let matched = match self.neighbours.get(&msg.robot).and_then(|e| e.protocol.clone()) {
            Some(Protocol::Matched(matched)) => matched,
            Some(Protocol::Aligned(aligned)) => return self.on_closure_clouds(msg, aligned),
            _ => return,
        };
        // Clouds of objects this round did not ask for answer an earlier request (a closure
        // round of an alignment withdrawn since): not this round's; it asks again on time-out.
        let asked: BTreeSet<ObjectId> = matched.state.pairs.iter().map(|(_, r)| *r).collect();
        if let Some(other) = msg.clouds.iter().find(|c| !asked.contains(&c.id)) {
            tracing::debug!(robot = %self.robot, neighbour = %msg.robot, object = other.id.0,
                "object clouds not of this round's request, not used");
            return;
        }
        let (local_from_remote, observed_in) =
            self.object_cloud_icp(&matched.state.pairs, &msg.clouds, &matched.state.local_from_remote);
        // Neighbour keyframes that observed the matched objects, ± the neighbourhood; a round
        // from few pairs (a chained hint's, `relay.min_relayed_pairs`) asks only for those that
        // observed them, as many as twice the registrations it needs (within
        // `max_keyframes_per_alignment`): most such rounds find no
        // overlap, and the bytes are spent before that is known.
        let (spread, cap) = if matched.state.pairs.len() < self.min_hinted_pairs() {
            (0, self.config.min_keyframe_factors.saturating_mul(2).min(self.config.max_keyframes_per_alignment))
        } else {
            (self.config.keyframe_neighbourhood as u32, self.config.max_keyframes_per_alignment)
        };
        let around = neighbourhood(observed_in.values().flatten().copied(), spread);
        let round = evenly(around, cap);
        let retry = self.retry.clone();
        let entry = self.entry(msg.robot);
        entry.observed_in = observed_in;
        let wanted: BTreeSet<KeyframeId> =
            round.iter().filter(|id| !entry.keyframes.contains_key(id)).copied().collect();
        entry.closures.requested.extend(wanted.iter().copied());
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

    pub(super) fn on_keyframe_resolved(&mut self, robot: RobotId, id: KeyframeId) {
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        match &mut entry.protocol {
            Some(Protocol::KeyframesRequested(n)) => {
                n.state.awaiting.remove(&id);
                if n.state.awaiting.is_empty() {
                    self.finish_alignment(robot);
                }
            }
            Some(Protocol::Aligned(n)) => {
                if let Some(Closure { stage: ClosureStage::Keyframes { awaiting, .. }, .. }) = &mut n.state.closure {
                    awaiting.remove(&id);
                    if awaiting.is_empty() {
                        self.finish_closure(robot);
                    }
                }
            }
            _ => {}
        }
    }

    /// Every requested keyframe arrived or was reported unavailable: register them and align
    /// (`model::matching::alignment`).
    pub(super) fn finish_alignment(&mut self, robot: RobotId) {
        let now = self.clock.now();
        let Some(entry) = self.neighbours.get(&robot) else { return };
        let Some(Protocol::KeyframesRequested(n)) = entry.protocol.clone() else { return };
        let mut local_from_remote = n.state.local_from_remote;
        // Local keyframes that observed the matched objects are the registration targets (with
        // Scan Context, those around the round's local keyframe).
        let local_ids: BTreeSet<KeyframeId> = match &entry.place_round {
            Some((_, targets)) => targets.clone(),
            _ => n
                .state
                .pairs
                .iter()
                .filter_map(|(l, _)| self.map.objects.observed_in.get(l))
                .flatten()
                .copied()
                .collect(),
        };
        let keyframe_icp = self.keyframe_icp();
        if let Some((pair, _)) = &entry.place_round {
            let (local, remote) = (self.map.keyframes.get(&pair.local), entry.keyframes.get(&pair.remote));
            let coarse = self.config.scan_context.coarse_correspondence_m;
            if let Some(refined) = local
                .zip(remote)
                .and_then(|(l, r)| coarse_to_fine(&local_view(l), &remote_view(r), pair.yaw, coarse, &keyframe_icp))
            {
                local_from_remote = refined;
            }
        }
        let targets = local_ids.iter().filter_map(|id| Some((*id, local_view(self.map.keyframes.get(id)?)))).collect();
        let round = entry.keyframes.iter().filter(|(id, _)| entry.round.contains(id)).map(|(_, k)| remote_view(k));
        let registered = register_round(&targets, round, &local_from_remote, &self.round_config(&keyframe_icp));
        let min_factors = self.min_round_factors(robot);
        let few = n.state.pairs.len() < self.min_hinted_pairs();
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        let factors = registered.factors.len();
        match judge_round(&registered, min_factors, entry.round_incomplete, &local_from_remote) {
            RoundVerdict::Incomplete => {
                // Keyframes were lost on the way: too few to judge the match, which is tried again.
                tracing::info!(robot = %self.robot, neighbour = %robot, factors, "alignment round incomplete");
                if let Some(Protocol::KeyframesRequested(n)) = entry.protocol.take() {
                    entry.protocol = Some(n.gave_up(now).into());
                }
                entry.match_again = true;
            }
            RoundVerdict::Refuted => {
                tracing::info!(robot = %self.robot, neighbour = %robot, factors,
                    local_from_remote = %Brief(&n.state.local_from_remote), "object match refuted");
                entry.attempts.rounds_refuted += 1;
                match entry.round_via {
                    None => {
                        // The stronger match that withdrew our alignment did not hold up.
                        if let Some(lifted) =
                            entry.graph_round_refuted(&n.state.local_from_remote, now, &self.config.relay)
                        {
                            match lifted.barred {
                                Some(barred) => {
                                    tracing::info!(robot = %self.robot, neighbour = %robot,
                                        local_from_remote = %Brief(&barred),
                                        "the bar on our withdrawn alignment lifted: the match that withdrew it was refuted");
                                    if let Some(why) = &mut entry.last_withdrawal {
                                        why.push_str(&format!(
                                            "; the bar lifted at {now:.1} s: that match was refuted by keyframe registration"
                                        ));
                                    }
                                }
                                None => tracing::info!(robot = %self.robot, neighbour = %robot,
                                    challenger = %Brief(&lifted.challenger),
                                    "the match that withdrew our alignment was refuted; its bar had already been forgotten among newer ones"),
                            }
                        }
                    }
                    Some(_) => {
                        let list = if few { &mut entry.refuted_few } else { &mut entry.refuted_hints };
                        push_recent(list, n.state.local_from_remote, now);
                    }
                }
                if let Some(Protocol::KeyframesRequested(n)) = entry.protocol.take() {
                    entry.protocol = Some(n.refuted(now).into());
                }
            }
            RoundVerdict::Aligned(local_from_remote) => {
                if let Some(Protocol::KeyframesRequested(n)) = entry.protocol.take() {
                    entry.protocol = Some(n.aligned(local_from_remote, now).into());
                    if entry.first_aligned.is_none() {
                        entry.first_aligned = Some(now);
                    }
                    // Aligned once, or again after a withdrawal: whose alignment this one came from.
                    entry.aligned_via = entry.round_via;
                    // What a match that puts it elsewhere must beat (`relay.rematch`).
                    entry.aligned_significance =
                        if entry.round_via.is_none() { entry.attempts.last_significance } else { None };
                    entry.challenger = None;
                    // A bar on a stronger match's word stands for good now.
                    entry.challenged_bar = None;
                }
                // The first round's ground counts as covered for closure rounds.
                let at: Vec<Point3<f64>> = n
                    .state
                    .pairs
                    .iter()
                    .filter_map(|(l, _)| self.map.objects.objects.iter().find(|o| o.id == *l))
                    .map(|o| o.centroid)
                    .collect();
                if !at.is_empty() {
                    let mean = at.iter().fold(nalgebra::Vector3::zeros(), |s, p| s + p.coords) / at.len() as f64;
                    entry.closures.seeds.push(Point3::from(mean));
                }
                // Aligned: the factors hold what registration learnt; the clouds are let go.
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
                self.share_alignments();
                self.review_contradictions();
            }
        }
    }
}
