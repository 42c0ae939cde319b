//! The matching pipeline: composition only (kiss-icp style). Each stage is its own module.
//!
//! 1. candidates (§IV-B, d_v > 0, `vertex`)  → `candidates`
//! 2. sparse affinity U (eqs. 5–7)           → `affinity`
//! 3. principal eigenvector x (eq. 8)        → `spectral`
//! 4. LAP on −x, minimum score (§IV-B)       → `lap`
//! 5. rigid hypotheses from pairs of the best associations (then, if none is significant, from
//!    pairs sampled along the affinity rows), inlier scoring, refinement (beyond the paper):
//!    `verification`
//!    A hypothesis whose vertical residuals show a significant tilt of the frames is refitted in
//!    6-DoF: `tilt`
//! 6. refusal: too few, collinear, not significant (NFA, `null_model`), ambiguous → `significance`
//! 7. weighted least-squares transform (§IV-C) → `geometry::fit_rigid` (inside refinement)

use super::affinity::{self, AffinityParams};
use super::candidates::{candidates, Candidate};
use super::labels::LabelSimilarity;
use super::null_model::NullModel;
use super::outcome::*;
use super::overlap::Overlap;
use super::spectral::principal_eigenvector;
use super::symmetry::{self, PeriodSearch};
use super::tilt::{self, TiltSearch};
use super::verification::{max_displacement, Evaluation, Scorer};
use super::vertex::VertexCompare;
use super::{MatcherConfig, ObjectGraph};
use crate::geometry::{fit_rigid, minor_axis_spread, Correspondence, RigidModel};
use crate::spatial::lap::{self, CostMatrix};
use nalgebra::{Point3, Translation3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashSet;

/// Minimum d_v for an association to enter the spectral stage; weaker (confused-label)
/// associations only count as verification evidence.
const SPECTRAL_MIN_LABEL_SIMILARITY: f64 = 0.5;
/// Refinement rounds of a hypothesis.
const REFINE_ROUNDS: usize = 5;
/// Smallest radius of the significance test, as a fraction of the inlier distance.
const MIN_RADIUS_FRACTION: f64 = 0.1;
/// Seed of the generator that samples stage-2 hypotheses (fixed: same input, same output).
const SAMPLING_SEED: u64 = 0x5347_4d5f_7365_6564;
/// Number of distinct top hypotheses (more than 2 r from the best) examined for a runner-up.
const RUNNER_UP_CANDIDATES: usize = 64;
/// A runner-up counts when its −log10 NFA is within this of the best's, even below the
/// threshold (three orders of magnitude).
const RUNNER_UP_SIGNIFICANCE_SLACK: f64 = 3.0;
/// A runner-up as consistent as the best refuses only when it scores at least this fraction of
/// the best.
const MIN_RUNNER_UP_SUPPORT: f64 = 0.6;
/// Graphs with at least this many objects each are large: see `RUNNER_UP_SIGNIFICANCE_SLACK`.
const LARGE_GRAPH: usize = 100;
/// Periods of a repeated layout are sought up to this many inlier distances (`symmetry`).
const MAX_PERIOD_RADII: f64 = 5.0;
/// ... and from this many (shorter periods are within the noise of a centroid).
const MIN_PERIOD_RADII: f64 = 0.5;
/// At most this many periods are tried as runner-ups.
const MAX_PERIODS: usize = 8;
/// Objects within this many inlier distances of the other graph's objects land on its mapped
/// ground (`overlap`).
const SUPPORT_RADII: f64 = 2.0;
/// A significant runner-up whose agreement index ω comes within this of the best's makes a
/// repeated layout: refused.
const AGREEMENT_MARGIN: f64 = 0.05;
/// In a repeated layout, a runner-up whose ω is within this many standard errors of the
/// difference below the best's is as consistent (when that is wider than `AGREEMENT_MARGIN`):
/// the best was picked among many period copies of nearly equal ω, and between two different
/// parking lots of one layout it won by 0.05–0.11 (11 of 1000 pairs), within two standard
/// errors (`overlap::Agreement`).
const AGREEMENT_STANDARD_ERRORS: f64 = 2.0;

/// Matches `remote`'s object graph against `local`'s. Never panics on any valid graphs.
pub fn match_graphs(
    local: &ObjectGraph,
    remote: &ObjectGraph,
    labels: &LabelSimilarity,
    config: &MatcherConfig,
) -> MatchReport {
    let mut stats = MatchStats::default();
    let refused = |reason, stats, spectral_matches| MatchReport {
        outcome: MatchOutcome::Refused(Refusal { reason, best_guess: None, significance: 0.0 }),
        spectral_matches,
        stats,
    };
    if local.len() < config.min_matches || remote.len() < config.min_matches {
        let reason =
            RefusalReason::TooFewObjects { local: local.len(), remote: remote.len(), required: config.min_matches };
        return refused(reason, stats, Vec::new());
    }

    // 1–3: spectral relaxation over label-compatible candidates.
    let vertices = VertexCompare::new(labels, config);
    let strong = candidates(local, remote, &vertices, SPECTRAL_MIN_LABEL_SIMILARITY);
    stats.candidates = strong.len();
    if strong.is_empty() {
        return refused(RefusalReason::NoCandidates, stats, Vec::new());
    }
    let params = AffinityParams {
        edge_sharpness: config.edge_sharpness,
        edge_tolerance_m: config.edge_tolerance_m,
        max_edge_length_m: config.max_edge_length_m,
        max_neighbours: config.max_neighbours,
    };
    let u = affinity::build(local, remote, &strong, params);
    stats.affinity_nonzeros = u.nonzeros();
    let eigen = principal_eigenvector(&u, config.power_tolerance, config.max_power_iterations);
    stats.power_iterations = eigen.iterations;
    stats.power_converged = eigen.converged;

    // 4: the paper's assignment.
    let spectral = spectral_assignment(local.len(), remote.len(), &strong, &eigen.vector, config.min_assignment_score);
    let spectral_matches = spectral
        .iter()
        .map(|&k| (local.objects()[strong[k].local as usize].id, remote.objects()[strong[k].remote as usize].id))
        .collect();

    // 5: hypotheses from pairs of the strongest associations.
    // The pool: the LAP's assignments first, then the other candidates, each by eigenvector value.
    let mut in_assignment = vec![false; strong.len()];
    for &k in &spectral {
        in_assignment[k] = true;
    }
    let mut pool: Vec<usize> = (0..strong.len()).collect();
    pool.sort_by(|&a, &b| {
        in_assignment[b].cmp(&in_assignment[a]).then(eigen.vector[b].total_cmp(&eigen.vector[a])).then(a.cmp(&b))
    });
    pool.truncate(config.hypothesis_pool);
    // Stage 1: every pair of the pool. Stage 2, only when stage 1 found nothing significant (large
    // graphs, where spurious associations collect as much affinity as true ones and the
    // eigenvector ranks poorly): seed pairs sampled from the affinity rows — a candidate and one
    // of its consistent partners — with a fixed-seed generator.
    let scorer = Scorer::new(local, remote, &vertices, config.inlier_distance_m, config.inlier_height_m);
    let null = NullModel::new(
        local,
        remote,
        &vertices,
        config.inlier_distance_m,
        MIN_RADIUS_FRACTION * config.inlier_distance_m,
    );
    let required = -config.max_false_alarms.log10();
    let mut search = Search::new(local.len());
    for (x, &a) in pool.iter().enumerate() {
        for &b in &pool[x + 1..] {
            search.try_seed(local, remote, &strong, (a, b), config, &scorer);
        }
    }
    let settle = |e: &Evaluation| settle(&scorer, local, remote, e, config);
    let stage_one_significant =
        search.best().map(|b| null.spread_significance(&settle(b).0, search.tests) >= required).unwrap_or(false);
    if !stage_one_significant && config.hypothesis_samples > 0 {
        let mut rng = ChaCha8Rng::seed_from_u64(SAMPLING_SEED);
        for _ in 0..config.hypothesis_samples {
            let a = rng.random_range(0..strong.len());
            let row = &u.cols[u.row_start[a]..u.row_start[a + 1]];
            if row.len() < 2 {
                continue;
            }
            let b = row[rng.random_range(0..row.len())] as usize;
            if b != a {
                search.try_seed(local, remote, &strong, (a, b), config, &scorer);
            }
        }
    }
    let (mut hypotheses, tests) = (search.hypotheses, search.tests);
    stats.hypotheses = tests;
    if hypotheses.is_empty() {
        return refused(RefusalReason::NoConsistentPair, stats, spectral_matches);
    }
    hypotheses.sort_by(|a, b| b.score.total_cmp(&a.score));
    let (best, model) = settle(&hypotheses[0]);

    // 6: refusals.
    // The search and the runner-up rules compare significances under the spread estimate; a
    // claim must also pass under the crowd estimate (`null_model`), which is what is reported.
    let significance = null.spread_significance(&best, tests);
    let claimed = null.crowd_significance(&best, tests);
    let refuse = |reason| MatchReport {
        outcome: MatchOutcome::Refused(Refusal {
            reason,
            best_guess: Some(best.local_from_remote),
            significance: claimed,
        }),
        spectral_matches: Vec::new(),
        stats: stats.clone(),
    };
    if best.inliers.len() < config.min_matches {
        let reason = RefusalReason::TooFewVerified { verified: best.inliers.len(), required: config.min_matches };
        return MatchReport { spectral_matches, ..refuse(reason) };
    }
    let matched_local: Vec<Point3<f64>> =
        best.inliers.iter().map(|i| local.objects()[i.local as usize].centroid).collect();
    let spread_m = minor_axis_spread(&matched_local, config.model);
    if spread_m < config.min_spread_m {
        let reason = RefusalReason::Collinear { spread_m, required_m: config.min_spread_m };
        return MatchReport { spectral_matches, ..refuse(reason) };
    }
    if claimed < required {
        let reason = RefusalReason::NotSignificant { significance: claimed, required };
        return MatchReport { spectral_matches, ..refuse(reason) };
    }
    let remote_points = || best.inliers.iter().map(|i| remote.objects()[i.remote as usize].centroid);
    // Refinement at most doubles a hypothesis' score in practice, so weaker ones cannot be
    // a runner-up within the ambiguity ratio.
    let floor = 0.5 * config.ambiguity_ratio * best.score;
    let overlap = Overlap::new(local, remote, SUPPORT_RADII * config.inlier_distance_m);
    let agreement = overlap.agreement(&best);
    let distinct = |h: &&Evaluation| {
        max_displacement(&best.local_from_remote, &h.local_from_remote, remote_points())
            > 2.0 * config.inlier_distance_m
    };
    // The best transform shifted by each period of a repeated layout around its matches, then
    // the distinct hypotheses of the search.
    let anchors: Vec<u32> = best.inliers.iter().map(|i| i.local).collect();
    let search = PeriodSearch {
        min_shift_m: MIN_PERIOD_RADII * config.inlier_distance_m,
        max_shift_m: MAX_PERIOD_RADII * config.inlier_distance_m,
        bin_m: config.inlier_distance_m,
        min_votes: config.min_matches.max(anchors.len() / 4),
        max_periods: MAX_PERIODS,
    };
    let shifted: Vec<Evaluation> = symmetry::periods(local, &anchors, search)
        .into_iter()
        .map(|shift| scorer.evaluate(&(Translation3::from(shift) * best.local_from_remote)))
        .collect();
    let searched = hypotheses.iter().take_while(|h| h.score >= floor).filter(distinct).take(RUNNER_UP_CANDIDATES);
    // A runner-up must be significant — or, in a repeated layout (periods found around the
    // matches) or between large graphs, where the best itself barely is, nearly as significant
    // as the best: near-equal transforms straddling the threshold are a tie there. (Between
    // 150- and 400-object graphs that share nothing, 4–7% of pairs had a best barely above the
    // threshold and a runner-up scoring as much just below it.)
    let crowded = !shifted.is_empty() || local.len().min(remote.len()) >= LARGE_GRAPH;
    let runner_up_required = if crowded { required.min(significance - RUNNER_UP_SIGNIFICANCE_SLACK) } else { required };
    let best_pairs: HashSet<(u32, u32)> = best.inliers.iter().map(|i| (i.local, i.remote)).collect();
    let candidates = shifted.iter().map(|e| (e, true)).chain(searched.map(|e| (e, false)));
    for (other, period) in candidates {
        let (runner_up, _) = settle(other);
        let displacement = max_displacement(&best.local_from_remote, &runner_up.local_from_remote, remote_points());
        // A period of the layout may be shorter than 2 r: its copy counts as different when it
        // pairs the objects differently; a searched hypothesis when it moves them beyond 2 r.
        let distinct = if period {
            let shared = runner_up.inliers.iter().filter(|i| best_pairs.contains(&(i.local, i.remote))).count();
            2 * shared < runner_up.inliers.len() && displacement > MIN_PERIOD_RADII * config.inlier_distance_m
        } else {
            displacement > 2.0 * config.inlier_distance_m
        };
        if !distinct {
            continue;
        }
        let score_ratio = runner_up.score / best.score;
        let runner_up_agreement = overlap.agreement(&runner_up);
        let as_good = score_ratio >= config.ambiguity_ratio;
        // As consistent, on comparable support: a runner-up laying a corner of one map on a
        // corner of the other is trivially consistent (nothing lands on mapped ground). In a
        // repeated layout, "as consistent" is "not worse beyond the sampling noise of ω".
        let margin = if shifted.is_empty() {
            AGREEMENT_MARGIN
        } else {
            AGREEMENT_MARGIN.max(AGREEMENT_STANDARD_ERRORS * agreement.difference_error(&runner_up_agreement))
        };
        let as_consistent =
            runner_up_agreement.index + margin >= agreement.index && score_ratio >= MIN_RUNNER_UP_SUPPORT;
        if !(as_good || as_consistent) {
            continue;
        }
        // A tie on score may straddle the threshold; consistency alone must be significant.
        let runner_up_significance = null.spread_significance(&runner_up, tests);
        if runner_up_significance < if as_good { runner_up_required } else { required } {
            continue;
        }
        let reason = if as_good && !period {
            RefusalReason::Ambiguous { runner_up_displacement_m: displacement, score_ratio }
        } else {
            RefusalReason::Repeated {
                runner_up_displacement_m: displacement,
                agreement: agreement.index,
                runner_up_agreement: runner_up_agreement.index,
            }
        };
        return MatchReport { spectral_matches, ..refuse(reason) };
    }

    // 7: final estimate from the verified matches: least squares weighted by label similarity
    // only (every verified centroid carries the same noise; MSAC weights served verification).
    let local_from_remote = fit_rigid(
        &best
            .inliers
            .iter()
            .map(|i| Correspondence {
                in_local: local.objects()[i.local as usize].centroid,
                in_remote: remote.objects()[i.remote as usize].centroid,
                weight: vertices.similarity(&local.objects()[i.local as usize], &remote.objects()[i.remote as usize]),
            })
            .collect::<Vec<_>>(),
        model,
    )
    .unwrap_or(best.local_from_remote);
    let mut matches: Vec<VerifiedMatch> = best
        .inliers
        .iter()
        .map(|i| {
            let (p, q) = (&local.objects()[i.local as usize], &remote.objects()[i.remote as usize]);
            VerifiedMatch {
                local: p.id,
                remote: q.id,
                residual_m: (p.centroid - local_from_remote * q.centroid).norm(),
                same_label: i.same_label,
            }
        })
        .collect();
    matches.sort_by_key(|m| (m.local, m.remote));
    let rmse_m = (matches.iter().map(|m| m.residual_m * m.residual_m).sum::<f64>() / matches.len() as f64).sqrt();
    MatchReport {
        outcome: MatchOutcome::Aligned(Alignment { local_from_remote, matches, significance: claimed, rmse_m }),
        spectral_matches,
        stats,
    }
}

/// A hypothesis refined under the configured model, then refitted in 6-DoF when its frames are
/// tilted (`tilt`); with the model of the result.
fn settle(
    scorer: &Scorer,
    local: &ObjectGraph,
    remote: &ObjectGraph,
    hypothesis: &Evaluation,
    config: &MatcherConfig,
) -> (Evaluation, RigidModel) {
    let refined = scorer.refine(hypothesis.clone(), config.model, REFINE_ROUNDS);
    if config.max_tilt_deg <= 0.0 {
        return (refined, config.model);
    }
    let search =
        TiltSearch { max_tilt_deg: config.max_tilt_deg, radius_m: config.inlier_distance_m, rounds: REFINE_ROUNDS };
    match tilt::refit(scorer, local, remote, &refined, search) {
        Some(tilted) => (tilted, RigidModel::Full3d),
        None => (refined, config.model),
    }
}

/// Hypotheses tried so far. A seed pair already explained by the best hypothesis so far would
/// reproduce it: it counts as a test but is not evaluated again.
struct Search {
    hypotheses: Vec<Evaluation>,
    /// Distinct seed pairs tried (N_tests of the significance test).
    tests: usize,
    /// Candidate pairs (smaller index first) already tried.
    tried: HashSet<(u32, u32)>,
    best: Option<usize>,
    /// Remote index explained for each local object by the best hypothesis so far.
    explained: Vec<u32>,
}

impl Search {
    fn new(local_len: usize) -> Self {
        Self {
            hypotheses: Vec::new(),
            tests: 0,
            tried: HashSet::new(),
            best: None,
            explained: vec![u32::MAX; local_len],
        }
    }

    fn best(&self) -> Option<&Evaluation> {
        self.best.map(|k| &self.hypotheses[k])
    }

    /// Tries the seed pair of candidates `ia`, `ib` (indices into `cands`), once.
    fn try_seed(
        &mut self,
        local: &ObjectGraph,
        remote: &ObjectGraph,
        cands: &[Candidate],
        (ia, ib): (usize, usize),
        config: &MatcherConfig,
        scorer: &Scorer,
    ) {
        if !self.tried.insert((ia.min(ib) as u32, ia.max(ib) as u32)) {
            return;
        }
        let (a, b) = (&cands[ia], &cands[ib]);
        let Some(pose) = seed_transform(local, remote, a, b, config) else { return };
        self.tests += 1;
        if self.explained[a.local as usize] == a.remote && self.explained[b.local as usize] == b.remote {
            return;
        }
        let e = scorer.evaluate(&pose);
        if self.best().is_none_or(|best| e.score > best.score) {
            self.best = Some(self.hypotheses.len());
            self.explained.fill(u32::MAX);
            for i in &e.inliers {
                self.explained[i.local as usize] = i.remote;
            }
        }
        self.hypotheses.push(e);
    }
}

/// LAP on −x over the n × m assignment matrix; keeps assignments with x ≥ min_score · max x.
/// Returns candidate indices.
fn spectral_assignment(n_local: usize, n_remote: usize, cands: &[Candidate], x: &[f64], min_score: f64) -> Vec<usize> {
    let max = x.iter().copied().fold(0.0, f64::max);
    if max.is_nan() || max <= 0.0 {
        return Vec::new();
    }
    let mut costs = CostMatrix::filled(n_local, n_remote, 0.0);
    let mut which = vec![usize::MAX; n_local * n_remote];
    for (k, c) in cands.iter().enumerate() {
        costs.set(c.local as usize, c.remote as usize, -x[k]);
        which[c.local as usize * n_remote + c.remote as usize] = k;
    }
    let mut out: Vec<usize> = lap::solve(&costs)
        .into_iter()
        .enumerate()
        .filter_map(|(i, m)| m.map(|m| which[i * n_remote + m]))
        .filter(|&k| k != usize::MAX && x[k] >= min_score * max)
        .collect();
    out.sort_unstable();
    out
}

/// The planar transform fixed by two associations whose horizontal edges agree within the edge
/// tolerance and that are at least r apart (a stable yaw), or `None`.
fn seed_transform(
    local: &ObjectGraph,
    remote: &ObjectGraph,
    a: &Candidate,
    b: &Candidate,
    config: &MatcherConfig,
) -> Option<crate::geometry::Pose3> {
    if a.local == b.local || a.remote == b.remote {
        return None;
    }
    let (pi, pj) = (local.objects()[a.local as usize].centroid, local.objects()[b.local as usize].centroid);
    let (qm, qn) = (remote.objects()[a.remote as usize].centroid, remote.objects()[b.remote as usize].centroid);
    let (h_local, h_remote) = ((pi - pj).xy().norm(), (qm - qn).xy().norm());
    let r = config.inlier_distance_m;
    if h_local < r || h_remote < r || (h_local - h_remote).abs() > config.edge_tolerance_m {
        return None;
    }
    if ((pi.z - pj.z) - (qm.z - qn.z)).abs() > 2.0 * config.inlier_height_m {
        return None;
    }
    let pair = |p, q| Correspondence { in_local: p, in_remote: q, weight: 1.0 };
    fit_rigid(&[pair(pi, qm), pair(pj, qn)], RigidModel::Planar)
}
