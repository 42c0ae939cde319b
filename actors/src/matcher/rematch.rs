//! Our alignments matched again as the maps grow (`matcher.relay.rematch`; beyond the paper).
//! An alignment starts from one match and one round of keyframe registrations, and in a
//! building of identical rooms both can be fooled: a match just over the significance threshold
//! and walls that agree in every room (`handheld_indoor` seed 6 under a ceiling: bravo placed
//! alpha half a turn off, 32 m, from a match of −log₁₀ NFA 1.23). On no closed cycle nothing
//! contradicts it, and robots that take it as a hint pass it on. The maps keep growing, and so
//! does the evidence: at new object data, ours or its (at most every `match_interval_s`), the graphs are
//! matched again, and a match that puts the neighbour elsewhere (one of the objects it paired
//! beyond `relay.contradiction_m` from where ours places it, or turned beyond
//! `contradiction_deg`: `relay::agree_where_matched`, not at the neighbour's origin, which a
//! tilt within the tolerance moves by metres)
//!
//! ```text
//! s' ≥ max(s + rematch_margin, rematch_min_significance)
//! ```
//!
//! (s: the significance of the match our alignment came from; the threshold itself for
//! one from a neighbour's alignment, −log₁₀ `matching.max_false_alarms`), found
//! `rematch_confirmations` times running (from changed inputs: the same graphs give the same
//! match, which is not made again), withdraws
//! ours, and it is aligned again from the stronger match, through a round of keyframe
//! registrations as any. In that run the graphs, matched again at 57.5 s, put alpha where it
//! was (significance 3.41).
//!
//! The withdrawn transform is barred (as a match and as a hint: else the robots it was chained
//! to hand it back), but on the challenger's word only: once another alignment stands the bar
//! stays for good, and if the challenger's own round is refuted first, the bar is lifted and
//! the challenger withdraws nothing again. So a stronger match that does not hold up on the
//! scans cannot bar a right alignment here for good (a neighbour that withdrew an alignment
//! relayed through ours meanwhile keeps its own bar: `settle.rs`).

use super::association::graph_objects;
use super::*;
use sgm_model::geometry::Brief;
use sgm_model::matching::relay::{agree, agree_where_matched};
use sgm_model::matching::{GraphObject, VerifiedMatch};

impl Matcher {
    /// Matches `robot`'s latest object data against ours again while we are aligned with it;
    /// withdraws our alignment when a stronger match puts it elsewhere (module notes).
    pub(super) fn rematch(&mut self, robot: RobotId) {
        let now = self.clock.now();
        let relay = &self.config.relay;
        if !relay.rematch || self.config.association != Association::Objects {
            return;
        }
        let Some(entry) = self.neighbours.get(&robot) else { return };
        let (Some(Protocol::Aligned(aligned)), Some(data)) = (&entry.protocol, &entry.objects) else { return };
        // While the link is down nothing would place it again.
        if !entry.link_up {
            return;
        }
        let inputs = (self.local_objects_revision, data.revision);
        let (due, changed) = match entry.last_rematch {
            None => (true, true),
            Some((t, local, remote)) => (now - t >= self.config.match_interval_s, (local, remote) != inputs),
        };
        if !due || !changed {
            return;
        }
        let current = aligned.state.local_from_remote;
        let standing = entry.aligned_significance.unwrap_or(-self.config.matching.max_false_alarms.log10());
        let (Ok(local), Ok(remote)) = (
            ObjectGraph::new(self.map.objects.objects.clone(), usize::MAX),
            ObjectGraph::new(graph_objects(data), usize::MAX),
        ) else {
            return;
        };
        let (tolerance_m, tolerance_deg) = (relay.contradiction_m, relay.contradiction_deg);
        let needed = (standing + relay.rematch_margin).max(relay.rematch_min_significance);
        let outcome = match_graphs(&local, &remote, &self.labels, &self.config.matching).outcome;
        // Kept as the last match: after a withdrawal `try_match` takes it, not making it again.
        let last = LastMatch { local_objects: inputs.0, remote_revision: inputs.1, outcome: outcome.clone() };
        let challenger = match outcome {
            // A match landing on a transform barred or lately refuted by keyframe registration is
            // no challenger: `try_match` would not pursue it either.
            MatchOutcome::Aligned(a)
                if a.significance >= needed
                    && a.matches.len() >= self.config.min_matched_objects
                    && !agree_where_matched(
                        &current,
                        &a.local_from_remote,
                        matched_centroids(&remote, &a.matches),
                        tolerance_m,
                        tolerance_deg,
                    )
                    && !entry.withdrawn_near(&a.local_from_remote, relay)
                    && !entry.discredited_near(&a.local_from_remote, relay)
                    && !refuted_recently(&entry.refuted, &a.local_from_remote, now) =>
            {
                Some((a.local_from_remote, a.significance))
            }
            _ => None,
        };
        let confirmations = relay.rematch_confirmations;
        let Some(entry) = self.neighbours.get_mut(&robot) else { return };
        entry.last_rematch = Some((now, inputs.0, inputs.1));
        entry.last_match = Some(last);
        let Some((transform, significance)) = challenger else {
            entry.challenger = None;
            return;
        };
        let times = match entry.challenger {
            Some((before, n)) if agree(&before, &transform, tolerance_m, tolerance_deg) => n + 1,
            _ => 1,
        };
        entry.challenger = Some((transform, times));
        if times < confirmations {
            return;
        }
        let found = if times == 1 { "found once".to_string() } else { format!("found {times} times running") };
        let why = format!(
            "a match of significance {significance:.2} (ours {standing:.2}), {found}, puts it at {}",
            Brief(&transform)
        );
        self.withdraw(robot, why, true);
        // Barred on the challenger's word: until another alignment stands, a refuted round of a
        // graph match lifts it (`rounds.rs`).
        if let Some(entry) = self.neighbours.get_mut(&robot) {
            if entry.withdrawn.last() == Some(&current) {
                entry.challenged_bar = Some(ChallengedBar { barred: current, challenger: transform });
            }
        }
    }
}

/// The remote centroids of a match's pairs, as the remote graph holds them.
fn matched_centroids<'a>(
    remote: &'a ObjectGraph,
    matches: &'a [VerifiedMatch],
) -> impl Iterator<Item = nalgebra::Point3<f64>> + 'a {
    let centroid = |id| remote.objects().iter().find(|o: &&GraphObject| o.id == id).map(|o| o.centroid);
    matches.iter().filter_map(move |m| centroid(m.remote))
}
