//! `[matcher]`: how robots find each other (object graphs, or the Scan Context baseline) and
//! how an alignment is confirmed.

use super::error::{check, positive, ConfigError};
use serde::{Deserialize, Serialize};
use sgm_model::matching::closure::ClosurePlan;
use sgm_model::matching::place_candidates::ScanContextSection;
use sgm_model::matching::MatcherConfig;
use sgm_model::perception::icp::IcpConfig;
use sgm_model::perception::structure_check::StructureCheck;

/// Inter-robot association.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Association {
    /// Object-graph matching, then object-cloud and keyframe ICP (the paper).
    #[default]
    Objects,
    /// None: robots exchange object data but never align (the evaluation's "no inter-robot
    /// association" baseline).
    None,
    /// Scan Context descriptors of every keyframe instead of objects, then coarse-to-fine
    /// keyframe ICP (the evaluation's Swarm-SC baseline, paper §V-B).
    ScanContext,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MatcherSection {
    /// How robots find each other. Default `objects`.
    pub association: Association,
    /// Object-graph matching (paper §IV-C).
    #[serde(flatten)]
    pub matching: MatcherConfig,
    /// The Scan Context baseline (used with `association = "scan_context"` only).
    pub scan_context: ScanContextSection,
    /// Matched objects needed before object clouds are requested. Default 4.
    pub min_matched_objects: usize,
    /// Matching against one neighbour is tried at most this often (on new local objects or
    /// new neighbour data), s. Default 2.
    pub match_interval_s: f64,
    /// Object-cloud ICP (paper §IV-D).
    pub icp: IcpConfig,
    /// Neighbour keyframes around each observing keyframe that are requested (paper: ±5; none
    /// for a round from few pairs, `relay.min_relayed_pairs`). Default 5.
    pub keyframe_neighbourhood: usize,
    /// Neighbour keyframes registered per alignment round, at most (spread evenly over those
    /// the neighbourhood names; a round from few pairs asks for at most twice
    /// `min_keyframe_factors` of them): bounds radio bytes and ICP time. Default 8 (16 cost twice
    /// the bytes for the same alignments: book, evaluation chapter).
    pub max_keyframes_per_alignment: usize,
    /// Voxel size of keyframe-to-keyframe ICP (`icp.voxel_m` is for object clouds), m.
    /// Default 0.3.
    pub keyframe_voxel_m: f64,
    /// Iteration cap of keyframe-to-keyframe ICP (it starts from the object-cloud estimate and
    /// converges in a few; a wrong match is refuted sooner). Default 20.
    pub keyframe_max_iterations: usize,
    /// Verification of keyframe registrations with the ground left out
    /// (`model::perception::structure_check`).
    pub structure_check: StructureCheck,
    /// A keyframe registration counts when this fraction of its structure points agree.
    /// Default 0.3.
    pub min_structure_agreement: f64,
    /// Least standard deviation of an inter-robot factor's rotation, degrees: added to ICP's
    /// own covariance, which counts every point as an independent measurement and so claims
    /// sub-millimetre precision (`model::matching::alignment::with_floor`). Default 0.5.
    pub factor_sigma_floor_deg: f64,
    /// ... and of its translation, m. Default 0.05.
    pub factor_sigma_floor_m: f64,
    /// In gravity-aligned worlds (`max_tilt_deg = 0`), register keyframes in x, y, z and yaw,
    /// keeping the relative tilt the two robots' gravity gives
    /// (`model::perception::level_icp`). Default false: on `handheld_indoor` it fixes the tilt
    /// of the handheld rig's factors but leaves their heights free to pull maps (book:
    /// Optimiser, gravity priors).
    pub level_registration: bool,
    /// Registrations that must count before an alignment is accepted; fewer refute the object
    /// match (the neighbour goes back to waiting for object data). Default 2.
    pub min_keyframe_factors: usize,
    /// Neighbour keyframes (clouds) held per neighbour between rounds, at most: kept so that a
    /// round after a refutation need not ask for them again; the lowest ids outside the current
    /// round go first, and all go once the neighbour is aligned. Default 16 (two rounds; a
    /// keyframe is about 370 KB as held, and a pair refuted again and again fills its cap).
    pub max_held_keyframes: usize,
    /// Inter-robot closures after the first alignment (`[matcher.closures]`).
    pub closures: ClosureSection,
    /// Alignments shared and relayed between neighbours (`[matcher.relay]`).
    pub relay: RelaySection,
}

/// `[matcher.relay]`: our alignments are broadcast (the `Alignments` message); a neighbour's are
/// hints for ours — inverted when it placed us, chained through our alignment with it when it
/// placed a third robot — each checked by our own round before it counts
/// (`model::matching::relay`). Object association only.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RelaySection {
    /// Whether alignments are shared and hints used. Default true.
    pub enabled: bool,
    /// A local and a neighbour object this close through a hint are one, m (a hint chained
    /// through two alignments carries both errors). Default 1.5.
    pub gate_m: f64,
    /// Our registrations a round needs when it started from the neighbour's own alignment of
    /// us (it registered at least `min_keyframe_factors` of our keyframes onto its own: the
    /// same evidence seen from its side); a hint chained through a third robot needs
    /// `min_keyframe_factors`. Default 1.
    pub min_own_factors: usize,
    /// Objects that must pair through a hint chained through a third robot for its round to
    /// start (a direct hint needs `min_matched_objects`). They only choose which keyframes are
    /// asked for: the round's `min_keyframe_factors` registrations are its evidence, so two
    /// robots whose shared ground holds one object still align when a third placed both.
    /// Default 1.
    pub min_relayed_pairs: usize,
    /// A neighbour's alignments contradict ours of a robot when the transform they imply
    /// (`model::matching::relay::contradicting`) places that robot's origin this far from ours,
    /// m (the status and the report then name them: `contradicted_by`); a stronger match
    /// (`rematch`) contradicts ours when it places one of the objects it paired this far from
    /// where ours does (`model::matching::relay::agree_where_matched`). Default 2.0.
    pub contradiction_m: f64,
    /// ... or turns it by this much (the angle of the rotation between the two), degrees.
    /// Default 5.0. Without relaying nothing is heard, so nothing is flagged.
    pub contradiction_deg: f64,
    /// Whether a contradicted cycle is settled by object evidence
    /// (`model::matching::settle`): every alignment on it is scored by the object pairs it
    /// explains against those the product of the others does, and ours that the evidence
    /// names wrong is withdrawn — out of the pose graph, barred for the rest of the mission —
    /// to be aligned again through the others. Off: the cycle is only flagged. Default true.
    pub settle: bool,
    /// The pairs by which the wrong alignment's loss must be below every other alignment's on
    /// the cycle (on a cycle of two: by which it explains fewer pairs than the other's); within
    /// it the cycle stays flagged, unsettled. Default 3.
    pub settle_margin_pairs: usize,
    /// Whether our alignments are matched again as the maps grow (at most every
    /// `match_interval_s`, on new object data) and withdrawn when a stronger match puts the
    /// neighbour elsewhere: settled by evidence, not by which match came first. A wrong
    /// alignment on no cycle is contradicted by nothing else. Default true.
    pub rematch: bool,
    /// How much more significant (−log₁₀ NFA) than the match our alignment came from the other
    /// must be (an alignment from a neighbour's counts as the threshold, −log₁₀ `matching.max_false_alarms`).
    /// Default 1 (ten times fewer false alarms expected).
    pub rematch_margin: f64,
    /// ... and at least this significant. Default 3.
    pub rematch_min_significance: f64,
    /// ... found this many times running (within the contradiction tolerance of each other),
    /// each from changed object graphs (ours or its). Default 1: after a robot's route its map
    /// stops changing, and the last match is all the evidence there will be.
    pub rematch_confirmations: usize,
}

impl Default for RelaySection {
    fn default() -> Self {
        Self {
            enabled: true,
            gate_m: 1.5,
            min_own_factors: 1,
            min_relayed_pairs: 1,
            contradiction_m: 2.0,
            contradiction_deg: 5.0,
            settle: true,
            settle_margin_pairs: 3,
            rematch: true,
            rematch_margin: 1.0,
            rematch_min_significance: 3.0,
            rematch_confirmations: 1,
        }
    }
}

impl RelaySection {
    fn validate(&self) -> Result<(), ConfigError> {
        let g = self.gate_m;
        check(g.is_finite() && g > 0.0 && g <= 10.0, "matcher.relay.gate_m", g, "0 < x ≤ 10 m")?;
        check(self.min_own_factors >= 1, "matcher.relay.min_own_factors", self.min_own_factors, "≥ 1")?;
        check(self.min_relayed_pairs >= 1, "matcher.relay.min_relayed_pairs", self.min_relayed_pairs, "≥ 1")?;
        let (m, deg) = (self.contradiction_m, self.contradiction_deg);
        check(m.is_finite() && m > 0.0, "matcher.relay.contradiction_m", m, "finite and > 0 m")?;
        check(deg.is_finite() && deg > 0.0 && deg <= 180.0, "matcher.relay.contradiction_deg", deg, "0 < x ≤ 180°")?;
        let margin = self.settle_margin_pairs;
        check(margin >= 1, "matcher.relay.settle_margin_pairs", margin, "≥ 1 (0 would settle a tie by edge order)")?;
        let m = self.rematch_margin;
        check(m.is_finite() && m >= 0.0, "matcher.relay.rematch_margin", m, "finite and ≥ 0")?;
        let s = self.rematch_min_significance;
        check(s.is_finite(), "matcher.relay.rematch_min_significance", s, "finite")?;
        let n = self.rematch_confirmations;
        check(n >= 1, "matcher.relay.rematch_confirmations", n, "≥ 1")
    }
}

/// `[matcher.closures]`: once a neighbour is aligned, its objects are associated with ours
/// through the current transform and keyframes around them are registered, over ground no
/// earlier round covered, within a budget of bytes and time (`model::matching::closure`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClosureSection {
    /// Whether closure rounds run at all. Default true.
    pub enabled: bool,
    /// Least time between two rounds with one neighbour (bounds CPU), s. Default 10.
    pub interval_s: f64,
    /// Neighbour keyframes asked for per round, at most. Default 2 (rounds spread over more
    /// ground for the same bytes).
    pub max_keyframes_per_round: usize,
    /// Keyframe-cloud bytes received from one neighbour for closures, at most (a round starts
    /// only while under it). Default 131072 (128 KiB, about four keyframes of a campus).
    pub max_bytes_per_neighbour: u64,
    /// How fast that budget grows once the neighbour is aligned, bytes/s: closures all mission
    /// long at a bounded rate ([`ClosureSection::allowance_bytes`]). 0: a fixed budget.
    /// Default 0.
    pub refill_bytes_per_s: f64,
    /// A local and a neighbour object this close through the current transform are one, m.
    /// Default 1.0.
    pub gate_m: f64,
    /// A round takes the object pairs within this distance of its seed, m. Default 15.
    pub radius_m: f64,
    /// A round's seed is at least this far from every earlier round's, m. Default 10.
    pub spacing_m: f64,
    /// Object pairs a round needs. Default 3.
    pub min_pairs: usize,
}

impl Default for ClosureSection {
    fn default() -> Self {
        let plan = ClosurePlan::default();
        Self {
            enabled: true,
            interval_s: 10.0,
            max_keyframes_per_round: 2,
            max_bytes_per_neighbour: 128 * 1024,
            refill_bytes_per_s: 0.0,
            gate_m: plan.gate_m,
            radius_m: plan.radius_m,
            spacing_m: plan.spacing_m,
            min_pairs: plan.min_pairs,
        }
    }
}

impl ClosureSection {
    pub fn plan(&self) -> ClosurePlan {
        ClosurePlan {
            gate_m: self.gate_m,
            radius_m: self.radius_m,
            spacing_m: self.spacing_m,
            min_pairs: self.min_pairs,
        }
    }

    /// Keyframe-cloud bytes a neighbour aligned `since_aligned_s` ago may have sent us for
    /// closures before no further round starts: the budget, plus its refill since then,
    ///
    /// ```text
    /// B(t) = max_bytes_per_neighbour + refill_bytes_per_s · (t − t_aligned)
    /// ```
    ///
    /// (t_aligned: the neighbour's first alignment, kept through a withdrawal), so that over a
    /// long mission closures go on at no more than refill_bytes_per_s on average. Credit left
    /// unspent while no round was due is spent at the pace rounds run anyway: at most one every
    /// `interval_s`, of at most `max_keyframes_per_round` keyframes. A negative or non-finite
    /// time counts as 0.
    pub fn allowance_bytes(&self, since_aligned_s: f64) -> f64 {
        let since = if since_aligned_s.is_finite() { since_aligned_s.max(0.0) } else { 0.0 };
        self.max_bytes_per_neighbour as f64 + self.refill_bytes_per_s * since
    }

    fn validate(&self) -> Result<(), ConfigError> {
        let c = self;
        let in_range = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;
        check(in_range(c.interval_s, 0.0, 3600.0), "matcher.closures.interval_s", c.interval_s, "0 ≤ x ≤ 3600 s")?;
        check(
            c.refill_bytes_per_s.is_finite() && c.refill_bytes_per_s >= 0.0,
            "matcher.closures.refill_bytes_per_s",
            c.refill_bytes_per_s,
            "≥ 0 bytes/s (0: a fixed budget)",
        )?;
        check(
            (1..=64).contains(&c.max_keyframes_per_round),
            "matcher.closures.max_keyframes_per_round",
            c.max_keyframes_per_round,
            "1–64",
        )?;
        check(c.gate_m > 0.0 && in_range(c.gate_m, 0.0, 10.0), "matcher.closures.gate_m", c.gate_m, "0 < x ≤ 10 m")?;
        check(
            c.radius_m > 0.0 && in_range(c.radius_m, 0.0, 200.0),
            "matcher.closures.radius_m",
            c.radius_m,
            "0 < x ≤ 200 m",
        )?;
        check(in_range(c.spacing_m, 0.0, 1000.0), "matcher.closures.spacing_m", c.spacing_m, "0 ≤ x ≤ 1000 m")?;
        check(c.min_pairs >= 3, "matcher.closures.min_pairs", c.min_pairs, "≥ 3")
    }
}

impl Default for MatcherSection {
    fn default() -> Self {
        Self {
            association: Association::Objects,
            matching: MatcherConfig::default(),
            scan_context: ScanContextSection::default(),
            min_matched_objects: 4,
            match_interval_s: 2.0,
            icp: IcpConfig { max_correspondence_distance_m: 1.0, voxel_m: 0.1, ..IcpConfig::default() },
            keyframe_neighbourhood: 5,
            max_keyframes_per_alignment: 8,
            keyframe_voxel_m: 0.3,
            keyframe_max_iterations: 20,
            structure_check: StructureCheck::default(),
            min_structure_agreement: 0.3,
            factor_sigma_floor_deg: 0.5,
            factor_sigma_floor_m: 0.05,
            level_registration: false,
            min_keyframe_factors: 2,
            max_held_keyframes: 16,
            closures: ClosureSection::default(),
            relay: RelaySection::default(),
        }
    }
}

impl MatcherSection {
    /// (σ_r rad, σ_t m) of `factor_sigma_floor_*`.
    pub fn factor_sigma_floor(&self) -> (f64, f64) {
        (self.factor_sigma_floor_deg.to_radians(), self.factor_sigma_floor_m)
    }

    /// Checks the object-graph matching keys (`matcher.*` of `model::matching::MatcherConfig`).
    pub fn validate_matching(&self) -> Result<(), ConfigError> {
        self.matching.validate().map_err(|e| ConfigError::Invalid {
            key: format!("matcher.{}", e.key),
            value: e.value,
            allowed: e.allowed.into(),
        })
    }

    /// Checks the other `matcher.*` keys against their allowed ranges.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let m = self;
        check(m.min_matched_objects >= 3, "matcher.min_matched_objects", m.min_matched_objects, "≥ 3")?;
        check(
            positive(m.icp.max_correspondence_distance_m),
            "matcher.icp.max_correspondence_distance_m",
            m.icp.max_correspondence_distance_m,
            "> 0",
        )?;
        let sc = &m.scan_context;
        let shape = (1..=255).contains(&sc.descriptor.rings) && (1..=255).contains(&sc.descriptor.sectors);
        check(shape, "matcher.scan_context.rings", sc.descriptor.rings, "rings and sectors 1–255")?;
        check(shape, "matcher.scan_context.sectors", sc.descriptor.sectors, "rings and sectors 1–255")?;
        let r = sc.descriptor.max_range_m;
        check(positive(r), "matcher.scan_context.max_range_m", r, "> 0")?;
        let h = sc.descriptor.height_offset_m;
        check(h.is_finite(), "matcher.scan_context.height_offset_m", h, "finite")?;
        let d = sc.max_distance;
        check(d.is_finite() && (0.0..=1.0).contains(&d), "matcher.scan_context.max_distance", d, "0–1")?;
        let c = sc.ring_key_candidates;
        check(c >= 1, "matcher.scan_context.ring_key_candidates", c, "≥ 1")?;
        let c = sc.coarse_correspondence_m;
        check(positive(c), "matcher.scan_context.coarse_correspondence_m", c, "> 0")?;
        check(sc.max_places >= 2, "matcher.scan_context.max_places", sc.max_places, "≥ 2")?;
        check(m.keyframe_neighbourhood <= 50, "matcher.keyframe_neighbourhood", m.keyframe_neighbourhood, "0–50")?;
        check(
            m.keyframe_voxel_m.is_finite() && (0.0..=5.0).contains(&m.keyframe_voxel_m),
            "matcher.keyframe_voxel_m",
            m.keyframe_voxel_m,
            "0 ≤ x ≤ 5 m",
        )?;
        check(
            (0.0..=1.0).contains(&m.min_structure_agreement),
            "matcher.min_structure_agreement",
            m.min_structure_agreement,
            "0 ≤ x ≤ 1",
        )?;
        check(
            m.match_interval_s.is_finite() && (0.0..=3600.0).contains(&m.match_interval_s),
            "matcher.match_interval_s",
            m.match_interval_s,
            "0 ≤ x ≤ 3600 s",
        )?;
        check(
            (1..=1000).contains(&m.keyframe_max_iterations),
            "matcher.keyframe_max_iterations",
            m.keyframe_max_iterations,
            "1 ≤ x ≤ 1000",
        )?;
        let (deg, m_) = (m.factor_sigma_floor_deg, m.factor_sigma_floor_m);
        check(deg.is_finite() && (0.0..=45.0).contains(&deg), "matcher.factor_sigma_floor_deg", deg, "0 ≤ x ≤ 45°")?;
        check(m_.is_finite() && (0.0..=10.0).contains(&m_), "matcher.factor_sigma_floor_m", m_, "0 ≤ x ≤ 10 m")?;
        check(m.min_keyframe_factors >= 1, "matcher.min_keyframe_factors", m.min_keyframe_factors, "≥ 1")?;
        check(
            m.max_keyframes_per_alignment >= m.min_keyframe_factors,
            "matcher.max_keyframes_per_alignment",
            m.max_keyframes_per_alignment,
            "≥ matcher.min_keyframe_factors",
        )?;
        check(
            m.max_held_keyframes >= m.max_keyframes_per_alignment,
            "matcher.max_held_keyframes",
            m.max_held_keyframes,
            "≥ matcher.max_keyframes_per_alignment",
        )?;
        let sc = &m.structure_check;
        for (key, v) in [
            ("matcher.structure_check.voxel_m", sc.voxel_m),
            ("matcher.structure_check.ground_clearance_m", sc.ground_clearance_m),
            ("matcher.structure_check.inlier_m", sc.inlier_m),
        ] {
            check(v.is_finite() && (0.0..=10.0).contains(&v), key, v, "0 ≤ x ≤ 10 m")?;
        }
        check(
            sc.ground_cell_m.is_finite() && sc.ground_cell_m > 0.0 && sc.ground_cell_m <= 10.0,
            "matcher.structure_check.ground_cell_m",
            sc.ground_cell_m,
            "0 < x ≤ 10 m",
        )?;
        check(
            (0.0..=60.0).contains(&sc.max_ground_slope_deg),
            "matcher.structure_check.max_ground_slope_deg",
            sc.max_ground_slope_deg,
            "0 ≤ x ≤ 60°",
        )?;
        m.closures.validate()?;
        m.relay.validate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn impossible_closure_and_factor_keys_are_refused_with_their_key() {
        let refused = |change: fn(&mut MatcherSection), expected: &str| {
            let mut m = MatcherSection::default();
            change(&mut m);
            let e = m.validate().unwrap_err().to_string();
            assert!(e.starts_with(expected), "{e}");
        };
        MatcherSection::default().validate().unwrap();
        refused(|m| m.closures.interval_s = -1.0, "matcher.closures.interval_s = -1");
        refused(|m| m.closures.max_keyframes_per_round = 0, "matcher.closures.max_keyframes_per_round = 0");
        refused(|m| m.closures.gate_m = 0.0, "matcher.closures.gate_m = 0");
        refused(|m| m.closures.radius_m = f64::NAN, "matcher.closures.radius_m = NaN");
        refused(|m| m.closures.spacing_m = -5.0, "matcher.closures.spacing_m = -5");
        refused(|m| m.closures.min_pairs = 2, "matcher.closures.min_pairs = 2");
        refused(|m| m.closures.refill_bytes_per_s = -1.0, "matcher.closures.refill_bytes_per_s = -1");
        refused(|m| m.closures.refill_bytes_per_s = f64::NAN, "matcher.closures.refill_bytes_per_s = NaN");
        refused(|m| m.relay.gate_m = 0.0, "matcher.relay.gate_m = 0");
        refused(|m| m.relay.gate_m = f64::INFINITY, "matcher.relay.gate_m = inf");
        refused(|m| m.relay.min_own_factors = 0, "matcher.relay.min_own_factors = 0");
        refused(|m| m.relay.contradiction_m = f64::NAN, "matcher.relay.contradiction_m = NaN");
        refused(|m| m.relay.contradiction_m = 0.0, "matcher.relay.contradiction_m = 0");
        refused(|m| m.relay.contradiction_deg = 181.0, "matcher.relay.contradiction_deg = 181");
        refused(|m| m.relay.settle_margin_pairs = 0, "matcher.relay.settle_margin_pairs = 0");
        refused(|m| m.relay.rematch_margin = -1.0, "matcher.relay.rematch_margin = -1");
        refused(|m| m.relay.rematch_min_significance = f64::NAN, "matcher.relay.rematch_min_significance = NaN");
        refused(|m| m.relay.rematch_confirmations = 0, "matcher.relay.rematch_confirmations = 0");
        refused(|m| m.factor_sigma_floor_deg = -0.1, "matcher.factor_sigma_floor_deg = -0.1");
        refused(|m| m.factor_sigma_floor_m = f64::INFINITY, "matcher.factor_sigma_floor_m = inf");
        let plan = MatcherSection::default().closures.plan();
        assert_eq!((plan.gate_m, plan.radius_m, plan.spacing_m, plan.min_pairs), (1.0, 15.0, 10.0, 3));
    }

    #[test]
    fn the_closure_budget_refills_at_its_rate_from_the_alignment() {
        let fixed = ClosureSection::default();
        assert_eq!(fixed.allowance_bytes(0.0), 131_072.0);
        assert_eq!(fixed.allowance_bytes(3600.0), 131_072.0, "no refill: the budget is all there is");
        let refilled = ClosureSection { max_bytes_per_neighbour: 1000, refill_bytes_per_s: 50.0, ..fixed };
        assert_eq!(refilled.allowance_bytes(0.0), 1000.0);
        assert_eq!(refilled.allowance_bytes(120.0), 7000.0);
        // Before the alignment, or with a clock that jumped back: no refill, never less.
        assert_eq!(refilled.allowance_bytes(-30.0), 1000.0);
        assert_eq!(refilled.allowance_bytes(f64::NAN), 1000.0);
    }
}
