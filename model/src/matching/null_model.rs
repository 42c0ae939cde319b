//! The chance model of the significance test (`significance`): how likely a remote object is to
//! land within r of a local object it may match, were the transform wrong.
//!
//! Two estimates of the density of eligible local objects around the landing point p̂ of remote
//! object m under a hypothesis; the larger (the more cautious) is used:
//!
//! * **spread**: the c(l) eligible local objects spread uniformly over the local graph's
//!   horizontal bounding box (area A, expanded by r): density c(l) / A;
//! * **crowd**: the eligible local objects actually within D = 2r of p̂, not counting the one the
//!   hypothesis pairs m with (its own partner is what is being tested): density k_m / (π D²).
//!
//! so p_m(r) = min(1, π r² · max(c(l) / A, k_m / (π D²))). The spread estimate alone treats a
//! layout whose objects crowd into a few strips (furniture along the walls of a row of rooms) as if
//! they filled the box: every remote object then lands near some local object by chance, and a
//! wrong transform that maps one row of rooms onto another gathers as many loose inliers as the
//! box model calls significant (`handheld_indoor`, seed 2: `model/tests/matching_crowded.rs`).
//! Counting the crowd where the object lands charges that chance to the hypothesis; where objects
//! stand farther apart than D the two estimates agree.
//!
//! The trials are the n remote objects landing inside the box; the significance test takes the
//! mean p̄(r) = (1/n) Σ p_m(r), which bounds the tail of the heterogeneous (Poisson-binomial)
//! count from above for counts beyond the mean (Hoeffding 1956).
//!
//! The search and the runner-up rules (`matcher`) compare hypotheses under the spread estimate,
//! as before this model; only the claim must also pass under the crowd estimate, which is then
//! the significance reported. A claim made now was made before it: the crowd adds refusals only.

use super::object_grid::Grid;
use super::significance::log10_nfa_adaptive;
use super::verification::Evaluation;
use super::vertex::VertexCompare;
use super::ObjectGraph;
use nalgebra::Point3;

/// Radius of the crowd estimate, in inlier distances.
const CROWD_RADII: f64 = 2.0;

/// The chance model: per remote object, how many local objects it may match, and where they are.
pub(super) struct NullModel<'a> {
    local: &'a ObjectGraph,
    remote: &'a ObjectGraph,
    vertices: &'a VertexCompare<'a>,
    area_m2: f64,
    /// Residuals below this count as this (centroids are never exact).
    min_radius_m: f64,
    crowd_radius_m: f64,
    crowd_grid: Grid,
    min: Point3<f64>,
    max: Point3<f64>,
    same_label: Vec<f64>,
    any_label: Vec<f64>,
    soft: bool,
}

impl<'a> NullModel<'a> {
    /// `radius`: the inlier distance r; `min_radius_m`: the smallest residual counted.
    pub(super) fn new(
        local: &'a ObjectGraph,
        remote: &'a ObjectGraph,
        vertices: &'a VertexCompare<'a>,
        radius: f64,
        min_radius_m: f64,
    ) -> Self {
        let (mut min, mut max) = (Point3::new(f64::MAX, f64::MAX, 0.0), Point3::new(f64::MIN, f64::MIN, 0.0));
        for o in local.objects() {
            min.x = min.x.min(o.centroid.x - radius);
            min.y = min.y.min(o.centroid.y - radius);
            max.x = max.x.max(o.centroid.x + radius);
            max.y = max.y.max(o.centroid.y + radius);
        }
        let count = |q: &super::GraphObject, same: bool| {
            local.objects().iter().filter(|p| vertices.similarity(p, q) > 0.0 && (!same || p.label == q.label)).count()
                as f64
        };
        let crowd_radius_m = CROWD_RADII * radius;
        Self {
            local,
            remote,
            vertices,
            area_m2: ((max.x - min.x) * (max.y - min.y)).max(1e-9),
            min_radius_m,
            crowd_radius_m,
            crowd_grid: Grid::new(local, crowd_radius_m),
            min,
            max,
            same_label: remote.objects().iter().map(|q| count(q, true)).collect(),
            any_label: remote.objects().iter().map(|q| count(q, false)).collect(),
            soft: vertices.labels.is_soft(),
        }
    }

    /// −log10 NFA of an evaluation over `tests` hypotheses under the spread estimate (with soft
    /// labels: the better of the same-label and any-label tests, Bonferroni-corrected by 2): what
    /// the search and the runner-up rules compare.
    pub(super) fn spread_significance(&self, e: &Evaluation, tests: usize) -> f64 {
        self.significance(e, tests, false)
    }

    /// The same under the more cautious of the spread and crowd estimates (≤ the spread
    /// significance): what a claim must also pass.
    pub(super) fn crowd_significance(&self, e: &Evaluation, tests: usize) -> f64 {
        self.significance(e, tests, true)
    }

    fn significance(&self, e: &Evaluation, tests: usize, crowd: bool) -> f64 {
        // The local object each remote one is paired with (only the crowd estimate needs it).
        let mut partner: Vec<Option<u32>> = Vec::new();
        if crowd {
            partner.resize(self.remote.len(), None);
            for i in &e.inliers {
                partner[i.remote as usize] = Some(i.local);
            }
        }
        let local = self.local.objects();
        let crowd_area = std::f64::consts::PI * self.crowd_radius_m.powi(2);
        let d2 = self.crowd_radius_m.powi(2);
        // Sums over the trials, same label and any label: the counts c (the spread estimate's
        // density is c / A, summed in the order it always was, so its bits are the box model's)
        // and the crowd estimate's density per m².
        let (mut trials, mut counted, mut crowded) = (0usize, [0.0; 2], [0.0; 2]);
        for (m, q) in self.remote.objects().iter().enumerate() {
            let p = e.local_from_remote * q.centroid;
            if !(p.x >= self.min.x && p.x <= self.max.x && p.y >= self.min.y && p.y <= self.max.y) {
                continue;
            }
            trials += 1;
            let mut near = [0usize; 2];
            if crowd {
                let own = partner[m];
                self.crowd_grid.around(p.x, p.y, |i| {
                    let o = &local[i as usize];
                    let far = (o.centroid - p).xy().norm_squared() > d2;
                    if Some(i) == own || far || self.vertices.similarity(o, q) <= 0.0 {
                        return;
                    }
                    near[0] += usize::from(o.label == q.label);
                    near[1] += 1;
                });
            }
            for (k, counts) in [&self.same_label, &self.any_label].into_iter().enumerate() {
                counted[k] += counts[m];
                crowded[k] += (counts[m] / self.area_m2).max(near[k] as f64 / crowd_area);
            }
        }
        if trials == 0 {
            return 0.0;
        }
        let floor = self.min_radius_m;
        // Mean density of the trials' eligible objects, per m².
        let per_m2 = |k: usize| {
            if crowd {
                crowded[k] / trials as f64
            } else {
                counted[k] / trials as f64 / self.area_m2
            }
        };
        let chance = |per_m2: f64| move |r: f64| (per_m2 * std::f64::consts::PI * r.max(floor).powi(2)).min(1.0);
        let mut same: Vec<f64> = e.inliers.iter().filter(|i| i.same_label).map(|i| i.residual_xy_m).collect();
        let mut nfa = log10_nfa_adaptive(tests, trials, &mut same, chance(per_m2(0)));
        if self.soft {
            let mut all: Vec<f64> = e.inliers.iter().map(|i| i.residual_xy_m).collect();
            nfa = nfa.min(log10_nfa_adaptive(tests, trials, &mut all, chance(per_m2(1)))) + 2f64.log10();
        }
        (-nfa).clamp(-1e3, 1e3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_from_yaw_translation, Pose3};
    use crate::matching::graph::flat_graph;
    use crate::matching::verification::Scorer;
    use crate::matching::{LabelSimilarity, MatcherConfig};
    use nalgebra::Vector3;
    use proptest::prelude::*;

    const R: f64 = 1.0;

    /// (spread, crowd) significance of `local_from_remote` between `local` and `remote`.
    fn both(local: &ObjectGraph, remote: &ObjectGraph, local_from_remote: &Pose3) -> (f64, f64) {
        let labels = LabelSimilarity::uniform(1, 0.0);
        let config = MatcherConfig::default();
        let vertices = VertexCompare::new(&labels, &config);
        let scorer = Scorer::new(local, remote, &vertices, R, config.inlier_height_m);
        let null = NullModel::new(local, remote, &vertices, R, 0.1 * R);
        let e = scorer.evaluate(local_from_remote);
        (null.spread_significance(&e, 100), null.crowd_significance(&e, 100))
    }

    /// `n` points on a jittered grid of pitch `pitch` in [0, width] × [y0, y0 + height].
    fn jittered(n: usize, width: f64, y0: f64, height: f64, seed: u64) -> Vec<(f64, f64)> {
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let columns = ((n as f64 * width / height).sqrt().ceil() as usize).max(1);
        let rows = n.div_ceil(columns);
        let (dx, dy) = (width / columns as f64, height / rows as f64);
        (0..n)
            .map(|k| {
                let (i, j) = (k % columns, k / columns);
                ((i as f64 + 0.2 + 0.6 * next()) * dx, y0 + (j as f64 + 0.2 + 0.6 * next()) * dy)
            })
            .collect()
    }

    #[test]
    fn a_crowded_strip_is_charged_its_crowd_and_a_sparse_box_is_not() {
        // 60 objects spread over a 40 m × 40 m box (about 5 m apart, farther than D = 2 m), and
        // 60 objects crowded into a 40 m × 3 m strip of the same box (two far corners keep the
        // box). Each graph against itself under a 0.45 m shift: every object lands 0.45 m from
        // its copy. In the strip it also lands within D of several others, which the spread
        // estimate ignores; in the sparse box there are none, and the estimates agree.
        let sparse = jittered(60, 40.0, 0.0, 40.0, 7);
        let mut strip = jittered(58, 40.0, 18.5, 3.0, 7);
        strip.extend([(0.0, 0.0), (40.0, 40.0)]);
        for (points, crowded) in [(sparse, false), (strip, true)] {
            let local = flat_graph(&points);
            let remote = flat_graph(&points);
            let shift = pose_from_yaw_translation(0.0, Vector3::new(0.45, 0.0, 0.0));
            let (spread, crowd) = both(&local, &remote, &shift);
            assert!(crowd <= spread + 1e-12, "{crowd} > {spread}");
            if crowded {
                assert!(crowd < spread - 3.0, "crowded strip: spread {spread}, crowd {crowd}");
            } else {
                assert!((crowd - spread).abs() < 1e-9, "sparse box: spread {spread}, crowd {crowd}");
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The crowd estimate is never less cautious than the spread one.
        #[test]
        fn crowd_significance_never_exceeds_spread(
            points in proptest::collection::vec((0.0..30.0f64, 0.0..30.0f64), 3..40),
            yaw in -3.2..3.2f64,
            tx in -5.0..5.0f64,
            ty in -5.0..5.0f64,
        ) {
            let graph = flat_graph(&points);
            let pose = pose_from_yaw_translation(yaw, Vector3::new(tx, ty, 0.0));
            let (spread, crowd) = both(&graph, &graph, &pose);
            prop_assert!(crowd <= spread + 1e-12, "{} > {}", crowd, spread);
        }
    }
}
