//! What the Matcher keeps per neighbour: its protocol, object data, held keyframes, the round
//! in progress and the refuted transforms; what a snapshot keeps of it; what status reports.

use super::*;
use sgm_model::matching::suspect::Evidence;
use sgm_model::optim::keyframe_graph::InterRobotCounts;

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
    /// Closure rounds since: how many, what they gave.
    pub closures: ClosureCounts,
    /// When the alignment (the first, or the one after a withdrawal) came from a relayed one
    /// (`[matcher.relay]`): whose.
    pub aligned_via: Option<RobotId>,
    pub keyframes_held: usize,
    /// Revision of the neighbour's object data held (`None`: none received).
    pub objects_revision: Option<u32>,
    /// While aligned: the robots whose relayed alignments put this neighbour elsewhere (around a
    /// cycle of alignments, beyond `matcher.relay.contradiction_m` / `_deg`): one of the cycle's
    /// alignments is wrong (`model::matching::relay::contradicting`).
    pub contradicted_by: Vec<RobotId>,
    /// Times our alignment of it was withdrawn: a contradicted cycle settled against it by
    /// object evidence (`matcher.relay.settle`), or a stronger match that put it elsewhere
    /// (`matcher.relay.rematch`).
    pub withdrawals: u32,
    /// Why the latest withdrawal was made.
    pub last_withdrawal: Option<String>,
    /// What object-graph matching with this neighbour has concluded so far: why a pair that
    /// holds each other's object graphs is not aligned.
    pub match_attempts: MatchAttempts,
    /// Rounds of its keyframes that refuted one of our own matches with it (not those of
    /// relayed hints), over the mission (kept in snapshots).
    pub graph_rounds_refuted: usize,
}

impl NeighbourStatus {
    /// What this robot holds against the neighbour (`model::matching::suspect`), with `held`
    /// the pose graph's counts of its inter-robot factors: one source for the report and the
    /// ROS status.
    pub fn suspect_evidence(&self, held: Option<&InterRobotCounts>) -> Evidence {
        Evidence {
            factors: held.map_or(0, |h| h.factors),
            inconsistent: held.map_or(0, |h| h.inconsistent),
            rounds_refuted: self.graph_rounds_refuted,
        }
    }
}

/// The object-graph matches made against one neighbour, and why the latest started no
/// alignment round. Status only: a snapshot does not keep it (a restarted robot matches again).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MatchAttempts {
    /// Matches made (one whose inputs had not changed since the last counts too: its outcome is
    /// reused).
    pub attempts: u32,
    /// When the latest was made, s.
    pub last_at_s: Option<f64>,
    /// Why the latest started no round (the matcher's refusal, too few matched objects, or a
    /// transform keyframe registration refuted lately); `None` when it started one.
    pub last_refusal: Option<String>,
    /// The latest match's significance, −log₁₀ NFA (`matcher.matching.min_significance` is
    /// what a claim needs); `None` when it had no hypothesis to score.
    pub last_significance: Option<f64>,
    /// The highest significance any match reached: how close the pair came.
    pub best_significance: Option<f64>,
    /// Alignment rounds whose keyframe registration refuted their transform: rounds from a
    /// graph match, from a neighbour's relayed alignment (a hint) or, with Scan Context
    /// association, from a place candidate.
    pub rounds_refuted: u32,
}

impl MatchAttempts {
    /// One line: how many matches, the latest's verdict and the best significance.
    pub fn summary(&self) -> String {
        let refuted = match self.rounds_refuted {
            0 => String::new(),
            n => format!("; {n} round(s) refuted by keyframe registration"),
        };
        let Some(at) = self.last_at_s else { return format!("no object-graph match made{refuted}") };
        let verdict = self.last_refusal.as_deref().unwrap_or("started a round");
        let best = self.best_significance.map_or(String::new(), |b| format!("; best significance {b:.2}"));
        format!("{} matches; the latest, at {at:.1} s: {verdict}{best}{refuted}", self.attempts)
    }

    /// Records a match made at `at_s`: its significance and why it started no round.
    pub(super) fn record(&mut self, at_s: f64, significance: Option<f64>, refusal: Option<String>) {
        self.attempts += 1;
        self.last_at_s = Some(at_s);
        self.last_refusal = refusal;
        self.last_significance = significance.filter(|s| s.is_finite());
        if let Some(s) = self.last_significance {
            self.best_significance = Some(self.best_significance.map_or(s, |b| b.max(s)));
        }
    }
}

pub(super) struct NeighbourEntry {
    pub(super) protocol: Option<Protocol>,
    pub(super) objects: Option<ObjectData>,
    pub(super) keyframes: BTreeMap<KeyframeId, NeighbourKeyframe>,
    pub(super) first_aligned: Option<f64>,
    /// Remote object → keyframes that observed it (from the object-cloud response).
    pub(super) observed_in: BTreeMap<ObjectId, Vec<KeyframeId>>,
    /// Transforms refuted by keyframe registration, and when: a match landing near one of them
    /// within [`REFUTED_FOR_S`] is not pursued again. Only those of that window are kept, at
    /// most [`MAX_REFUTED`] ([`push_recent`]).
    pub(super) refuted: Vec<(Pose3, Stamp)>,
    /// Rounds of our own graph matches refuted by keyframe registration, over the mission
    /// (the suspect rule's count; `refuted` forgets).
    pub(super) graph_rounds_refuted: u32,
    /// The neighbour keyframes of the current alignment round (requested or already held).
    pub(super) round: BTreeSet<KeyframeId>,
    /// When matching against this neighbour was last tried.
    pub(super) last_attempt: Option<Stamp>,
    /// Scan Context association only: the neighbour's descriptors and the candidate pairs.
    pub(super) places: PlaceCandidates,
    /// Scan Context association only (never set otherwise): the pair of the current round and
    /// the local keyframes around its local one (object association derives its targets from
    /// the object pairs).
    pub(super) place_round: Option<(PlaceCandidate, BTreeSet<KeyframeId>)>,
    /// Comms reported the link down: nothing is matched, requested or retried until it is back.
    pub(super) link_up: bool,
    /// A keyframe of the current round was given up on (lost, not refused): too few factors
    /// then say nothing against the match.
    pub(super) round_incomplete: bool,
    /// The last round was cut short by losses, not refuted: match again once
    /// `match_interval_s` has passed, even if no new object data comes.
    pub(super) match_again: bool,
    /// What closure rounds have done with this neighbour.
    pub(super) closures: ClosureMemory,
    /// The current alignment round started from a neighbour's alignment: whose.
    pub(super) round_via: Option<RobotId>,
    /// The current alignment came from a neighbour's: whose.
    pub(super) aligned_via: Option<RobotId>,
    /// Hints whose rounds (with as many pairs as a graph match) were refuted, and when: not
    /// tried again within `REFUTED_FOR_S`; those of rounds from fewer are in `refuted_few`. (A
    /// refuted graph match does not bar a hint: a neighbour that registered the same transform
    /// from its side is new evidence.)
    pub(super) refuted_hints: Vec<(Pose3, Stamp)>,
    /// Hints whose rounds from fewer pairs than a graph match needs were refuted, and when: such
    /// a round is not tried again within `REFUTED_FOR_S`, while one with enough pairs still is.
    pub(super) refuted_few: Vec<(Pose3, Stamp)>,
    /// What graph matching has concluded (status only).
    pub(super) attempts: MatchAttempts,
    /// Our alignments of it withdrawn (a contradicted cycle settled against them, a stronger
    /// match elsewhere, or the relay they came from gone), at most [`MAX_WITHDRAWN`], oldest
    /// first: barred as a match and as a hint, for good (one on a stronger match's word until
    /// that match is tested: [`Self::challenged_bar`]).
    pub(super) withdrawn: Vec<Pose3>,
    /// Times an alignment of it was withdrawn.
    pub(super) withdrawals: u32,
    /// Why the latest was (status only).
    pub(super) last_withdrawal: Option<String>,
    /// The significance of the match our alignment came from (`None`: it came from a
    /// neighbour's alignment): what a contradicting match must beat (`relay.rematch`).
    pub(super) aligned_significance: Option<f64>,
    /// A match that contradicts our alignment, and how many times running it was found.
    pub(super) challenger: Option<(Pose3, usize)>,
    /// Our alignment withdrawn on a stronger match's word (`relay.rematch`), barred until that
    /// word is tested: the bar stays once another alignment stands, and is lifted if the
    /// challenger's own round is refuted first (it did not hold up on the scans).
    pub(super) challenged_bar: Option<ChallengedBar>,
    /// Challengers whose rounds were refuted, at most [`MAX_WITHDRAWN`], oldest first: they
    /// withdraw nothing again (else a refuted challenger and a restored alignment could take
    /// turns for the rest of the mission).
    pub(super) discredited: Vec<Pose3>,
    /// When our alignment was last matched again, and with what: the revisions of our objects
    /// and of its object data (the same inputs give the same match, which is not made again).
    pub(super) last_rematch: Option<(Stamp, u64, u32)>,
    /// The last graph match and what it was made from: the same local objects against the same
    /// object data give the same outcome (`match_graphs` is a pure function), so it is reused.
    pub(super) last_match: Option<LastMatch>,
}

impl NeighbourEntry {
    /// A neighbour just heard of, at `now`: nothing known of it yet.
    pub(super) fn discovered(robot: RobotId, now: Stamp) -> Self {
        Self {
            protocol: Some(Neighbour::discovered(robot, now).into()),
            objects: None,
            keyframes: BTreeMap::new(),
            first_aligned: None,
            observed_in: BTreeMap::new(),
            refuted: Vec::new(),
            graph_rounds_refuted: 0,
            round: BTreeSet::new(),
            last_attempt: None,
            places: PlaceCandidates::default(),
            place_round: None,
            link_up: true,
            round_incomplete: false,
            match_again: false,
            closures: ClosureMemory::default(),
            round_via: None,
            aligned_via: None,
            refuted_hints: Vec::new(),
            refuted_few: Vec::new(),
            attempts: MatchAttempts::default(),
            withdrawn: Vec::new(),
            withdrawals: 0,
            last_withdrawal: None,
            aligned_significance: None,
            challenger: None,
            challenged_bar: None,
            discredited: Vec::new(),
            last_rematch: None,
            last_match: None,
        }
    }

    /// Bars `transform` as a match and as a hint (the oldest bar forgotten beyond
    /// [`MAX_WITHDRAWN`]).
    pub(super) fn bar(&mut self, transform: Pose3) {
        push_capped(&mut self.withdrawn, transform);
    }

    /// A round of our own graph match at `transform` was refuted at `now`: remembered for
    /// [`REFUTED_FOR_S`] and counted; if it was the challenger's round that barred our withdrawn
    /// alignment ([`Self::challenged_bar`], within the contradiction tolerance of `relay`), the
    /// challenger is discredited and its bar lifted. What was lifted, if anything.
    pub(super) fn graph_round_refuted(
        &mut self,
        transform: &Pose3,
        now: Stamp,
        relay: &crate::config::RelaySection,
    ) -> Option<Lifted> {
        push_recent(&mut self.refuted, *transform, now);
        self.graph_rounds_refuted = self.graph_rounds_refuted.saturating_add(1);
        let bar = self.challenged_bar?;
        if !sgm_model::matching::relay::agree(
            &bar.challenger,
            transform,
            relay.contradiction_m,
            relay.contradiction_deg,
        ) {
            return None;
        }
        self.challenged_bar = None;
        push_capped(&mut self.discredited, bar.challenger);
        let barred = self.withdrawn.iter().rposition(|t| *t == bar.barred).map(|at| self.withdrawn.remove(at));
        Some(Lifted { challenger: bar.challenger, barred })
    }

    /// Whether `transform` agrees with a challenger whose round was refuted.
    pub(super) fn discredited_near(&self, transform: &Pose3, relay: &crate::config::RelaySection) -> bool {
        sgm_model::matching::relay::barred(&self.discredited, transform, relay.contradiction_m, relay.contradiction_deg)
    }

    /// Whether `transform` agrees with one of our alignments withdrawn (within the
    /// contradiction tolerance of `relay`): barred as a match and as a hint.
    pub(super) fn withdrawn_near(&self, transform: &Pose3, relay: &crate::config::RelaySection) -> bool {
        sgm_model::matching::relay::barred(&self.withdrawn, transform, relay.contradiction_m, relay.contradiction_deg)
    }
}

/// A graph match's outcome, and its inputs: the revision of the Matcher's local objects
/// (`Matcher::local_objects_revision`) and the neighbour's object-data revision.
pub(super) struct LastMatch {
    pub(super) local_objects: u64,
    pub(super) remote_revision: u32,
    pub(super) outcome: MatchOutcome,
}

/// Closure rounds with one aligned neighbour so far (`matcher.closures`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ClosureCounts {
    /// Rounds started.
    pub rounds: u32,
    /// Inter-robot factors they added (the Optimiser's status says how many it keeps).
    pub factors: u32,
    /// Keyframe-cloud bytes received for them.
    pub bytes: u64,
}

/// What a robot remembers of its closure rounds with a neighbour (kept in snapshots).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClosureMemory {
    pub counts: ClosureCounts,
    /// Every neighbour keyframe ever asked for: never asked for twice (until an alignment is
    /// withdrawn: its factors went with it, and the next alignment's rounds may ask again).
    pub requested: BTreeSet<KeyframeId>,
    /// Each round's seed (local world): later rounds keep `spacing_m` from them.
    pub seeds: Vec<Point3<f64>>,
    /// When the last round was considered.
    pub last_considered: Option<Stamp>,
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
    pub closures: ClosureMemory,
    pub aligned_via: Option<RobotId>,
    /// Alignments withdrawn and barred, and how many times one was.
    pub withdrawn: Vec<Pose3>,
    pub withdrawals: u32,
    /// Why the latest was.
    pub last_withdrawal: Option<String>,
    /// What a match that puts the neighbour elsewhere must beat (`relay.rematch`).
    pub aligned_significance: Option<f64>,
    /// A bar that stands on a stronger match's word, until its round is judged.
    pub challenged_bar: Option<ChallengedBar>,
    /// Challengers whose rounds were refuted.
    pub discredited: Vec<Pose3>,
    /// Rounds of our own graph matches refuted, over the mission.
    pub graph_rounds_refuted: u32,
}

/// A challenger discredited by its refuted round, and the bar on our withdrawn alignment it
/// lifted (`None`: that bar had already been forgotten, beyond [`MAX_WITHDRAWN`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Lifted {
    pub(super) challenger: Pose3,
    pub(super) barred: Option<Pose3>,
}

/// Our alignment withdrawn on a stronger match's word, and that match.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ChallengedBar {
    /// Our withdrawn alignment.
    pub barred: Pose3,
    /// The stronger match's transform.
    pub challenger: Pose3,
}

/// Withdrawn alignments barred per neighbour, at most (the oldest is forgotten beyond it). A
/// pair is withdrawn when a cycle names it wrong, a stronger match puts the neighbour
/// elsewhere, or the robot it was relayed by contradicts it; once per wrong transform.
pub(super) const MAX_WITHDRAWN: usize = 8;

/// Refuted transforms kept per neighbour and list, at most: rounds fetch keyframes, so a few a
/// minute is what a busy pair makes; a neighbour sending graph after graph that our matches
/// find and its scans refute cannot grow the lists beyond this.
pub(super) const MAX_REFUTED: usize = 32;

/// Appends `transform`, refuted at `now`, to `list`, after forgetting those refuted
/// [`REFUTED_FOR_S`] or longer ago, and the oldest beyond [`MAX_REFUTED`].
pub(super) fn push_recent(list: &mut Vec<(Pose3, Stamp)>, transform: Pose3, now: Stamp) {
    list.retain(|(_, t)| now - t < REFUTED_FOR_S);
    list.push((transform, now));
    if list.len() > MAX_REFUTED {
        list.drain(..list.len() - MAX_REFUTED);
    }
}

/// Appends `transform` to a list of at most [`MAX_WITHDRAWN`], forgetting the oldest beyond it.
fn push_capped(list: &mut Vec<Pose3>, transform: Pose3) {
    list.push(transform);
    if list.len() > MAX_WITHDRAWN {
        list.remove(0);
    }
}

/// Drops held neighbour keyframes outside `round`, lowest ids first, until at most `cap` are
/// held; the ids dropped.
pub(super) fn hold_at_most(
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix6;

    #[test]
    fn a_bar_on_a_challengers_word_is_lifted_by_the_challengers_refutation_alone() {
        let at = |x: f64| Pose3::translation(x, 0.0, 0.0);
        let relay = crate::config::RelaySection::default();
        let challenged = |barred, challenger| Some(ChallengedBar { barred, challenger });
        let lifted = |challenger, barred| Some(Lifted { challenger, barred });
        let mut entry = NeighbourEntry::discovered(RobotId(2), 0.0);
        // Nothing on a challenger's word: nothing to lift.
        entry.bar(at(1.0));
        assert_eq!(entry.graph_round_refuted(&at(40.0), 1.0, &relay), None);
        assert_eq!(entry.withdrawn, [at(1.0)]);
        // A cycle's bar, then one on a challenger's word (at 40 m).
        entry.bar(at(2.0));
        entry.challenged_bar = challenged(at(2.0), at(40.0));
        // Another match's refuted round lifts nothing: the challenger is still untested.
        assert_eq!(entry.graph_round_refuted(&at(70.0), 2.0, &relay), None);
        assert_eq!(entry.withdrawn, [at(1.0), at(2.0)]);
        // The challenger's round, refuted (within the tolerance of it): only its bar is lifted,
        // and the challenger is discredited.
        assert_eq!(entry.graph_round_refuted(&at(40.5), 3.0, &relay), lifted(at(40.0), Some(at(2.0))));
        assert_eq!(entry.withdrawn, [at(1.0)]);
        assert!(entry.discredited_near(&at(40.2), &relay) && !entry.discredited_near(&at(2.0), &relay));
        assert_eq!(entry.graph_round_refuted(&at(40.0), 4.0, &relay), None);
        // The oldest bar goes beyond the cap; a challenged bar forgotten that way lifts nothing,
        // but its challenger is still discredited (and the caller says so).
        entry.challenged_bar = challenged(at(1.0), at(50.0));
        for k in 0..MAX_WITHDRAWN {
            entry.bar(at(10.0 + k as f64));
        }
        assert_eq!(entry.withdrawn.len(), MAX_WITHDRAWN);
        assert!(!entry.withdrawn.contains(&at(1.0)));
        assert_eq!(entry.graph_round_refuted(&at(50.0), 5.0, &relay), lifted(at(50.0), None));
        assert_eq!(entry.withdrawn.len(), MAX_WITHDRAWN);
        assert!(entry.discredited_near(&at(50.0), &relay));
        // Every refuted round is counted.
        assert_eq!(entry.graph_rounds_refuted, 5);
    }

    #[test]
    fn refuted_rounds_are_counted_for_good_but_kept_only_while_they_bar() {
        let relay = crate::config::RelaySection::default();
        let mut entry = NeighbourEntry::discovered(RobotId(2), 0.0);
        // A neighbour whose every graph our matches find and its scans refute, one a second for
        // ten minutes: the list stays within its window and its cap, the count is whole.
        for k in 0..600 {
            entry.graph_round_refuted(&Pose3::translation(k as f64 * 7.0, 0.0, 0.0), k as f64, &relay);
            assert!(entry.refuted.len() <= MAX_REFUTED);
        }
        assert_eq!(entry.graph_rounds_refuted, 600);
        assert_eq!(entry.refuted.len(), MAX_REFUTED);
        // The newest are kept, oldest first, and still bar a match near them.
        assert_eq!(entry.refuted.first().map(|(_, t)| *t), Some(600.0 - MAX_REFUTED as f64));
        assert!(refuted_recently(&entry.refuted, &Pose3::translation(599.0 * 7.0, 0.0, 0.0), 600.0));
        // Beyond the window they are forgotten at the next push; the count stays.
        let mut list = vec![(Pose3::identity(), 0.0), (Pose3::identity(), 100.0)];
        push_recent(&mut list, Pose3::identity(), REFUTED_FOR_S + 50.0);
        assert_eq!(list.iter().map(|(_, t)| *t).collect::<Vec<_>>(), [100.0, REFUTED_FOR_S + 50.0]);
    }

    #[test]
    fn held_neighbour_keyframes_beyond_the_cap_go_lowest_first_sparing_the_round() {
        let keyframe = |id: u32| NeighbourKeyframe {
            robot: RobotId(2),
            id: KeyframeId(id),
            world_from_body: Pose3::identity(),
            covariance: Matrix6::identity(),
            points_in_body: Vec::new(),
            cloud_bytes: 0,
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
