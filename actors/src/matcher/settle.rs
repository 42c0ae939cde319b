//! Contradicted cycles settled by evidence (`matcher.relay.settle`, `model::matching::settle`):
//! every cycle that contradicts one of our alignments is scored by the object graphs we hold —
//! ours and both neighbours' on it — and when the evidence names one of *our* alignments wrong,
//! it is withdrawn: the protocol goes back to waiting for a match, the transform is barred (as a
//! match and as a hint; the latest `MAX_WITHDRAWN` per neighbour), the pose graph drops the neighbour
//! (`KeyframeGraph::withdraw_neighbour`), and the team hears our alignments without it. The
//! other alignments of the cycle then place the neighbour again through the relay
//! (`relay.rs`), with a round of our own registrations as for any hint. An alignment of
//! another robot named wrong is left to that robot, which holds the same evidence.
//!
//! Before any cycle is scored, an alignment of ours that was relayed by a robot whose
//! alignments now put the neighbour beyond twice the contradiction tolerance is withdrawn, one
//! at a time: it was made from that robot's alignments (and ours of that robot, when chained),
//! and they no longer say it. On
//! `handheld_indoor` seed 6 with `world.ceiling` bravo's wrong alignment of alpha, withdrawn
//! on a stronger match (`rematch.rs`), had been chained into alignments of charlie by both.

use super::association::graph_objects;
use super::*;
use sgm_model::geometry::Brief;
use sgm_model::matching::relay::placed_by;
use sgm_model::matching::settle::{settle_cycle, CycleEdge, SettleConfig, Settlement};

/// One of our alignments that a cycle's evidence names wrong.
struct Withdrawal {
    robot: RobotId,
    /// The cycle's robots, from us.
    cycle: Vec<RobotId>,
    settlement: Settlement,
}

impl Matcher {
    /// Settles the contradicted cycles the evidence decides (with `relay.settle`), one
    /// withdrawal at a time (each changes the cycles), then logs the contradictions left.
    pub(super) fn review_contradictions(&mut self) {
        let mut contradicted = self.contradicted_now();
        if self.config.relay.settle {
            // An alignment relayed by a robot whose alignments now put the neighbour elsewhere
            // has lost the ground it stood on (that robot's, or ours it was chained through, was
            // withdrawn or moved): withdrawn and barred (else the robots it was chained to hand
            // it back to each other), to be placed again by what holds now. Elsewhere means
            // beyond twice the contradiction tolerance: a relayed alignment drifts from its
            // relay's as both are re-estimated, and near the tolerance a contradiction can come
            // and go at each solve. One at a time: each withdrawal changes the cycles.
            for _ in 0..self.neighbours.len() {
                let Some((robot, via)) = self.next_lost_basis(&contradicted) else { break };
                self.withdraw(robot, format!("relayed by {via}, whose alignments now put it elsewhere"), true);
                contradicted = self.contradicted_now();
            }
            // Each withdrawal leaves one alignment fewer: at most one per neighbour.
            for _ in 0..self.neighbours.len() {
                let Some(w) = self.next_withdrawal(&contradicted) else { break };
                let (support, losses) = (&w.settlement.support, w.settlement.losses());
                let cycle = w.cycle.iter().map(ToString::to_string).collect::<Vec<_>>().join(" → ");
                let why = format!(
                    "the object evidence of the contradicted cycle {cycle} names it wrong (pairs per edge, own \
                     and the others' product: {support:?}; losses: {losses:?})"
                );
                self.withdraw(w.robot, why, true);
                contradicted = self.contradicted_now();
            }
        }
        self.log_contradictions(&contradicted);
    }

    /// The first of our alignments (neighbour order; `contradicted`: [`Self::contradicted_now`])
    /// relayed by a robot whose alignments now put the neighbour beyond twice the contradiction
    /// tolerance, and that robot.
    fn next_lost_basis(&self, contradicted: &BTreeMap<RobotId, Vec<RobotId>>) -> Option<(RobotId, RobotId)> {
        contradicted.iter().find_map(|(robot, by)| {
            let via = self.neighbours.get(robot)?.aligned_via?;
            (by.contains(&via) && self.contradicted_beyond(*robot, 2.0).contains(&via)).then_some((*robot, via))
        })
    }

    /// The first of our alignments (in neighbour order, then the contradicting robots' order;
    /// `contradicted`: [`Self::contradicted_now`]) that a contradicted cycle's evidence names
    /// wrong.
    fn next_withdrawal(&self, contradicted: &BTreeMap<RobotId, Vec<RobotId>>) -> Option<Withdrawal> {
        // Nothing contradicted (almost always): the object graphs are not looked at.
        if contradicted.is_empty() {
            return None;
        }
        let ours: BTreeMap<RobotId, Pose3> = self.aligned().into_iter().collect();
        let remote: BTreeMap<RobotId, Vec<GraphObject>> = self
            .neighbours
            .iter()
            .filter_map(|(robot, e)| Some((*robot, graph_objects(e.objects.as_ref()?))))
            .collect();
        let mut objects: BTreeMap<RobotId, &[GraphObject]> = remote.iter().map(|(r, o)| (*r, &o[..])).collect();
        objects.insert(self.robot, &self.map.objects.objects[..]);
        let config = SettleConfig {
            labels: &self.labels,
            gate_m: self.config.relay.gate_m,
            margin_pairs: self.config.relay.settle_margin_pairs,
        };
        for (&robot, &through) in contradicted.iter().flat_map(|(r, by)| by.iter().map(move |t| (r, t))) {
            let Some((robots, edges)) = ours.get(&robot).and_then(|own| self.cycle(robot, own, through, &ours)) else {
                continue;
            };
            let Some(settlement) = settle_cycle(&robots, &edges, &objects, &config) else { continue };
            let Some(wrong) = settlement.wrong.and_then(|k| edges.get(k).copied()) else { continue };
            if wrong.placer == self.robot && ours.contains_key(&wrong.placed) {
                return Some(Withdrawal { robot: wrong.placed, cycle: robots, settlement });
            }
        }
        None
    }

    /// The cycle that `through`'s alignments close with ours of `robot` (`own`): on a cycle of
    /// two (`through` = `robot`), its alignment of us; else its alignment of `robot` and the
    /// link between it and us — ours of it, or else its own of us.
    fn cycle(
        &self,
        robot: RobotId,
        own: &Pose3,
        through: RobotId,
        ours: &BTreeMap<RobotId, Pose3>,
    ) -> Option<(Vec<RobotId>, Vec<CycleEdge>)> {
        let placed_by = |placer: RobotId, placed: RobotId| {
            let t = placed_by(&self.hints, placer, placed)?;
            Some(CycleEdge { placer, placed, placer_from_placed: t })
        };
        let me = self.robot;
        let ours_of = |placed: RobotId, t: Pose3| CycleEdge { placer: me, placed, placer_from_placed: t };
        if through == robot {
            return Some((vec![me, robot], vec![ours_of(robot, *own), placed_by(robot, me)?]));
        }
        let link = ours.get(&through).map(|t| ours_of(through, *t)).or_else(|| placed_by(through, me))?;
        Some((vec![me, robot, through], vec![ours_of(robot, *own), placed_by(through, robot)?, link]))
    }

    /// Withdraws our alignment of `robot` for the reason `why`: back to waiting for a match with
    /// its objects held, the transform barred (if `bar`), any round's keyframes let go, the pose
    /// graph told, the team told.
    pub(super) fn withdraw(&mut self, robot: RobotId, why: String, bar: bool) {
        let now = self.clock.now();
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        if !matches!(entry.protocol, Some(Protocol::Aligned(_))) {
            return;
        }
        let Some(Protocol::Aligned(aligned)) = entry.protocol.take() else { return };
        let transform = aligned.state.local_from_remote;
        entry.protocol = Some(aligned.withdrawn(now).into());
        if bar {
            entry.bar(transform);
        }
        entry.withdrawals += 1;
        entry.aligned_via = None;
        entry.aligned_significance = None;
        entry.challenger = None;
        // A bar still on a challenger's word stays: we were aligned again since.
        entry.challenged_bar = None;
        // Closure rounds of a wrong alignment covered nothing, and its factors are gone: the new
        // alignment's rounds start afresh and may ask for those keyframes again (the bytes they
        // cost stay counted, against `closures.max_bytes_per_neighbour` too).
        entry.closures.seeds.clear();
        entry.closures.requested.clear();
        entry.round.clear();
        let released: Vec<KeyframeId> = std::mem::take(&mut entry.keyframes).into_keys().collect();
        // Matched again at once: the other alignments of a cycle place it through the relay, a
        // stronger match places it itself.
        entry.last_attempt = None;
        entry.match_again = true;
        entry.last_withdrawal = Some(format!("at {now:.1} s: {why}"));
        tracing::warn!(robot = %self.robot, neighbour = %robot, local_from_remote = %Brief(&transform), %why,
            "our alignment of the neighbour withdrawn");
        self.release(robot, released);
        if let Some(links) = &self.links {
            links.withdraw.do_send(NeighbourWithdrawn { robot });
        }
        self.share_alignments();
    }
}
