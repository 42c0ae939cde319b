//! Alignments shared and relayed (`[matcher.relay]`, `model::matching::relay`): every time an
//! alignment is made or re-estimated, the Matcher hands all of them to Comms, which broadcasts
//! them when they changed significantly; a neighbour's alignments are kept (the latest per
//! neighbour) and give hints for a neighbour graph matching could not place. A hint only starts
//! a round: the round's own registration decides, as it does for a graph match.

use super::*;
use sgm_model::geometry::Brief;
use sgm_model::matching::closure::{pairs_through, ClosurePlan};
use sgm_model::matching::relay::{contradicting, hinted_round, hints_for, Hint, Reach};

/// Least time between two log lines about the robots contradicting one alignment, s.
const CONTRADICTION_LOG_INTERVAL_S: f64 = 60.0;

/// What was last logged of the robots contradicting our alignment of a neighbour, and when.
pub(super) struct LoggedContradiction {
    robots: Vec<RobotId>,
    at_s: f64,
}

/// Where an alignment round starts: the first estimate, the object pairs whose clouds are asked
/// for, and whose alignment it came from (`None`: object-graph matching).
pub(super) struct RoundStart {
    pub(super) local_from_remote: Pose3,
    pub(super) pairs: Vec<(ObjectId, ObjectId)>,
    pub(super) via: Option<RobotId>,
}

impl Matcher {
    pub(super) fn relaying(&self) -> bool {
        self.config.relay.enabled && self.config.association == Association::Objects
    }

    /// Our alignments now (neighbour's world in ours), to Comms.
    pub(super) fn share_alignments(&self) {
        if !self.relaying() {
            return;
        }
        if let Some(links) = &self.links {
            links.share_alignments.do_send(ShareAlignments(self.aligned()));
        }
    }

    /// The robots whose relayed alignments contradict ours of `robot` (none while it is not
    /// aligned, or without relaying).
    pub(super) fn contradicted_by(&self, robot: RobotId) -> Vec<RobotId> {
        self.contradicted_beyond(robot, 1.0)
    }

    /// [`Self::contradicted_by`] with the contradiction tolerance times `scale`.
    pub(super) fn contradicted_beyond(&self, robot: RobotId, scale: f64) -> Vec<RobotId> {
        let own = self.neighbours.get(&robot).and_then(|e| match &e.protocol {
            Some(p @ Protocol::Aligned(_)) => p.local_from_remote().copied(),
            _ => None,
        });
        let Some(own) = own.filter(|_| self.relaying()) else { return Vec::new() };
        let ours: BTreeMap<RobotId, Pose3> = self.aligned().into_iter().collect();
        let relay = &self.config.relay;
        let (tolerance_m, tolerance_deg) = (scale * relay.contradiction_m, scale * relay.contradiction_deg);
        contradicting(self.robot, robot, &own, &ours, &self.hints, tolerance_m, tolerance_deg)
    }

    /// Whether `transform` agrees with one of our withdrawn alignments of `robot`.
    pub(super) fn withdrawn_near(&self, robot: RobotId, transform: &Pose3) -> bool {
        self.neighbours.get(&robot).is_some_and(|e| e.withdrawn_near(transform, &self.config.relay))
    }

    /// Each aligned neighbour whose alignment is contradicted, and by whom (neighbour order).
    pub(super) fn contradicted_now(&self) -> BTreeMap<RobotId, Vec<RobotId>> {
        self.neighbours
            .keys()
            .map(|robot| (*robot, self.contradicted_by(*robot)))
            .filter(|(_, by)| !by.is_empty())
            .collect()
    }

    /// Logs where the robots contradicting our alignment of a neighbour changed: a warning
    /// naming them when the set grows or moves, a note when it empties. The status and the
    /// report hold the set at all times; the log says when it changed, at most once per
    /// neighbour every `CONTRADICTION_LOG_INTERVAL_S` (a hint near the tolerance may flip the
    /// set at every solve): a change within it is logged at the first event after it, if it
    /// still holds. A neighbour no longer aligned is forgotten without a line (its alignment
    /// went, nothing was settled). `contradicted`: [`Self::contradicted_now`]. Which alignment
    /// of such a cycle is wrong is settled in `settle.rs`, before this.
    pub(super) fn log_contradictions(&mut self, contradicted: &BTreeMap<RobotId, Vec<RobotId>>) {
        let now_s = self.clock.now();
        let robots: Vec<RobotId> = self.neighbours.keys().copied().collect();
        for robot in robots {
            let aligned =
                matches!(self.neighbours.get(&robot).and_then(|e| e.protocol.as_ref()), Some(Protocol::Aligned(_)));
            if !aligned {
                self.contradictions.remove(&robot);
                continue;
            }
            let now = contradicted.get(&robot).cloned().unwrap_or_default();
            let logged = self.contradictions.get(&robot);
            if logged.map_or(now.is_empty(), |l| l.robots == now) {
                continue;
            }
            if logged.is_some_and(|l| now_s - l.at_s < CONTRADICTION_LOG_INTERVAL_S) {
                continue;
            }
            if now.is_empty() {
                tracing::info!(robot = %self.robot, neighbour = %robot, "our alignment of the neighbour is no longer contradicted");
            } else {
                let through = now.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ");
                tracing::warn!(robot = %self.robot, neighbour = %robot, %through, "our alignment of the neighbour is contradicted by the alignments of the robots named: one of them is wrong");
            }
            self.contradictions.insert(robot, LoggedContradiction { robots: now, at_s: now_s });
        }
    }

    pub(super) fn aligned(&self) -> Vec<(RobotId, Pose3)> {
        self.neighbours
            .iter()
            .filter_map(|(robot, e)| match &e.protocol {
                Some(p @ Protocol::Aligned(_)) => Some((*robot, *p.local_from_remote()?)),
                _ => None,
            })
            .collect()
    }

    /// The pairs a hint's round needs when they are evidence, as a graph match's are; a round
    /// from fewer (a chained hint's, `relay.min_relayed_pairs`) only looks for registrations.
    pub(super) fn min_hinted_pairs(&self) -> usize {
        self.config.min_matched_objects.max(3)
    }

    /// Our registrations the current round with `robot` needs to align.
    pub(super) fn min_round_factors(&self, robot: RobotId) -> usize {
        match self.neighbours.get(&robot).and_then(|e| e.round_via) {
            Some(via) if via == robot => self.config.relay.min_own_factors,
            _ => self.config.min_keyframe_factors,
        }
    }

    /// The first hint for `robot` (not near a hint whose round was refuted recently; a round
    /// from few pairs is also barred by one from few pairs refuted recently) that pairs at least
    /// `min_matched_objects` objects: on one patch for a direct hint, whose round one
    /// registration of ours settles (`min_round_factors`); on one patch or else over the whole
    /// map for a relayed one, settled by as many registrations as a graph match, or else its
    /// best patch of at least `relay.min_relayed_pairs`. Its transform, the pairs, and whose
    /// alignment it came from.
    pub(super) fn hinted(
        &self,
        robot: RobotId,
        local: &[GraphObject],
        remote: &[GraphObject],
        now: Stamp,
    ) -> Option<RoundStart> {
        if !self.relaying() {
            return None;
        }
        let entry = self.neighbours.get(&robot)?;
        let (refuted, refuted_few) = (&entry.refuted_hints, &entry.refuted_few);
        let ours: BTreeMap<RobotId, Pose3> = self.aligned().into_iter().collect();
        let plan = ClosurePlan {
            gate_m: self.config.relay.gate_m,
            radius_m: self.config.closures.radius_m,
            spacing_m: 0.0,
            min_pairs: self.min_hinted_pairs(),
        };
        // A chained hint's last resort: the patch with the most of at least `min_relayed_pairs`,
        // which only say where the keyframes to register are.
        let few = ClosurePlan { min_pairs: self.config.relay.min_relayed_pairs, ..plan.clone() };
        let hints = hints_for(self.robot, robot, &ours, &self.hints);
        let withdrawn = |t: &Pose3| entry.withdrawn_near(t, &self.config.relay);
        let open = |hint: &&Hint| {
            !refuted_recently(refuted, &hint.local_from_remote, now) && !withdrawn(&hint.local_from_remote)
        };
        let start = hints.iter().filter(open).find_map(|hint| {
            let round = if hint.via == robot {
                hinted_round(local, remote, hint, &self.labels, &plan, Reach::Patch)
            } else {
                // As many pairs as a graph match, on a patch or over the whole map; else few.
                hinted_round(local, remote, hint, &self.labels, &plan, Reach::WholeMap).or_else(|| {
                    if refuted_recently(refuted_few, &hint.local_from_remote, now) {
                        None
                    } else {
                        hinted_round(local, remote, hint, &self.labels, &few, Reach::Patch)
                    }
                })
            }?;
            let pairs = round.iter().map(|p| (p.local, p.remote)).collect();
            Some(RoundStart { local_from_remote: hint.local_from_remote, pairs, via: Some(hint.via) })
        });
        if start.is_none() && !hints.is_empty() && tracing::enabled!(tracing::Level::DEBUG) {
            // Per hint: through whom, whether refuted recently, and how many objects pair through it.
            let tried: Vec<String> = hints
                .iter()
                .map(|hint| {
                    let pairs = pairs_through(local, remote, &hint.local_from_remote, &self.labels, plan.gate_m).len();
                    let barred = if withdrawn(&hint.local_from_remote) {
                        " withdrawn"
                    } else if refuted_recently(refuted, &hint.local_from_remote, now) {
                        " refuted"
                    } else if refuted_recently(refuted_few, &hint.local_from_remote, now) {
                        " refuted from few pairs"
                    } else {
                        ""
                    };
                    format!("{} [{}]: {pairs} pairs{barred}", hint.via, Brief(&hint.local_from_remote))
                })
                .collect();
            tracing::debug!(robot = %self.robot, neighbour = %robot, hints = %tried.join(", "), need = plan.min_pairs,
                need_chained = self.config.relay.min_relayed_pairs,
                "relayed alignments start no round (too few objects pair through them, or refuted recently)");
        }
        start
    }
}

impl Handler<NeighbourAlignments> for Matcher {
    type Result = ();
    fn handle(&mut self, msg: NeighbourAlignments, ctx: &mut Context<Self>) {
        contained(ctx, "matcher", || {
            if !self.relaying() {
                return;
            }
            // The latest per neighbour: what it holds now replaces what it held (bounded by the
            // envelope's `limits.max_ids`).
            self.hints.insert(msg.robot, msg.alignments);
            self.review_contradictions();
            let robots: Vec<RobotId> = self.neighbours.keys().copied().collect();
            for robot in robots {
                self.try_match(robot);
            }
        });
    }
}
