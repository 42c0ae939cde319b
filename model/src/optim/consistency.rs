//! Pairwise consistency maximisation over one neighbour's inter-robot closures (PCM: Mangelson,
//! Dominic, Eustice, Vasudevan, "Pairwise Consistent Measurement Set Maximization for Robust
//! Multi-robot Map Merging", ICRA 2018; as Kimera-Multi and DOOR-SLAM use it before their
//! robust back ends).
//!
//! A closure k ties local keyframe i (pose W_l(i) in our world) to neighbour keyframe j (pose
//! T_r(j) in its world) by the measured relative pose Z_k; it implies where the neighbour's
//! world lies in ours:
//!
//! ```text
//! L_k = W_l(i) · Z_k · T_r(j)⁻¹
//! ```
//!
//! Two closures are consistent when their implied transforms agree *where the closures are*
//! (comparing translations at the origin would multiply a small turn by the distance to it):
//!
//! ```text
//! e_t(a, b) = max over p ∈ {p_a, p_b} of ‖L_a·p − L_b·p‖     (p: neighbour keyframe positions)
//! e_r(a, b) = ∠(L_a⁻¹ · L_b)
//! consistent ⇔ e_t ≤ tolerance_m + drift · ‖p_a − p_b‖  and  e_r ≤ tolerance_deg
//! ```
//!
//! The drift term lets two honest closures far apart disagree as much as two maps drift over
//! that distance. The largest set of mutually consistent closures (a maximum clique of the
//! consistency graph) is kept; the rest are outliers, whatever order they came in.

use crate::geometry::Pose3;
use nalgebra::Point3;

/// How far two closures may disagree and still be consistent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Consistency {
    pub tolerance_m: f64,
    /// Allowed disagreement per metre between the closures (map drift), m/m.
    pub drift: f64,
    pub tolerance_deg: f64,
}

impl Default for Consistency {
    fn default() -> Self {
        Self { tolerance_m: 1.0, drift: 0.02, tolerance_deg: 3.0 }
    }
}

/// One closure as PCM sees it: the transform it implies and where it is (the neighbour
/// keyframe's position in the neighbour's world).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImpliedClosure {
    pub local_from_remote: Pose3,
    pub at_in_remote: Point3<f64>,
}

impl ImpliedClosure {
    /// L = W_l(i) · Z · T_r(j)⁻¹.
    pub fn new(local_pose: &Pose3, measured: &Pose3, remote_pose: &Pose3) -> Self {
        Self {
            local_from_remote: local_pose * measured * remote_pose.inverse(),
            at_in_remote: Point3::from(remote_pose.translation.vector),
        }
    }
}

/// Whether closures `a` and `b` agree (module documentation).
pub fn consistent(a: &ImpliedClosure, b: &ImpliedClosure, c: &Consistency) -> bool {
    let (la, lb) = (&a.local_from_remote, &b.local_from_remote);
    let e_t = [a.at_in_remote, b.at_in_remote].iter().map(|p| (la * p - lb * p).norm()).fold(0.0, f64::max);
    let e_r = (la.rotation.inverse() * lb.rotation).angle().to_degrees();
    e_t <= c.tolerance_m + c.drift * (a.at_in_remote - b.at_in_remote).norm() && e_r <= c.tolerance_deg
}

/// Most branch-and-bound steps of the clique search; beyond them the best clique found so far
/// is kept (deterministic, never reached with a few hundred closures that mostly agree).
const MAX_STEPS: usize = 200_000;

/// The indices of a largest set of mutually consistent closures, in increasing order. Among
/// sets of equal size the one found first in index order (the earliest closures) wins.
pub fn largest_consistent_set(closures: &[ImpliedClosure], c: &Consistency) -> Vec<usize> {
    let n = closures.len();
    let adjacent: Vec<Vec<bool>> =
        (0..n).map(|a| (0..n).map(|b| a != b && consistent(&closures[a], &closures[b], c)).collect()).collect();
    max_clique(&adjacent)
}

/// A maximum clique of the graph `adjacent` (symmetric, no self loops): branch and bound with
/// a greedy-colouring bound (Tomita & Seki, 2003).
pub fn max_clique(adjacent: &[Vec<bool>]) -> Vec<usize> {
    struct Search<'a> {
        adjacent: &'a [Vec<bool>],
        best: Vec<usize>,
        steps: usize,
    }
    impl Search<'_> {
        /// Colour classes of `candidates` greedily: a clique takes at most one vertex per class.
        fn colour_bound(&self, candidates: &[usize]) -> Vec<(usize, usize)> {
            let mut classes: Vec<Vec<usize>> = Vec::new();
            let mut out = Vec::with_capacity(candidates.len());
            for &v in candidates {
                let k = classes.iter().position(|class| class.iter().all(|&u| !self.adjacent[u][v]));
                let k = match k {
                    Some(k) => k,
                    None => {
                        classes.push(Vec::new());
                        classes.len() - 1
                    }
                };
                classes[k].push(v);
                out.push((v, k + 1));
            }
            // Expanded from the end: highest colour last.
            out.sort_by_key(|&(v, colour)| (colour, std::cmp::Reverse(v)));
            out
        }

        fn expand(&mut self, clique: &mut Vec<usize>, candidates: Vec<usize>) {
            self.steps += 1;
            if self.steps > MAX_STEPS {
                return;
            }
            let mut coloured = self.colour_bound(&candidates);
            let mut remaining = candidates;
            while let Some((v, colour)) = coloured.pop() {
                if clique.len() + colour <= self.best.len() {
                    return;
                }
                clique.push(v);
                let next: Vec<usize> = remaining.iter().copied().filter(|&u| self.adjacent[v][u]).collect();
                if next.is_empty() {
                    if clique.len() > self.best.len() {
                        self.best = clique.clone();
                    }
                } else {
                    self.expand(clique, next);
                }
                clique.pop();
                remaining.retain(|&u| u != v);
            }
        }
    }
    let n = adjacent.len();
    let mut search = Search { adjacent, best: Vec::new(), steps: 0 };
    search.expand(&mut Vec::new(), (0..n).collect());
    search.best.sort_unstable();
    search.best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_yaw_translation;
    use nalgebra::Vector3;
    use proptest::prelude::*;

    /// Brute force over every subset (small n only).
    fn largest_by_brute_force(adjacent: &[Vec<bool>]) -> usize {
        let n = adjacent.len();
        (0u32..1 << n)
            .filter(|mask| {
                (0..n).all(|a| (0..n).all(|b| a == b || mask & (1 << a) == 0 || mask & (1 << b) == 0 || adjacent[a][b]))
            })
            .map(|mask| mask.count_ones() as usize)
            .max()
            .unwrap_or(0)
    }

    proptest! {
        #[test]
        fn the_clique_is_a_clique_and_as_large_as_any(edges in prop::collection::vec(any::<bool>(), 0..120), n in 0usize..13) {
            let mut adjacent = vec![vec![false; n]; n];
            let pairs = (0..n).flat_map(|a| (a + 1..n).map(move |b| (a, b)));
            for (k, (a, b)) in pairs.enumerate() {
                let e = edges.get(k).copied().unwrap_or(false);
                adjacent[a][b] = e;
                adjacent[b][a] = e;
            }
            let clique = max_clique(&adjacent);
            for &a in &clique {
                for &b in &clique {
                    prop_assert!(a == b || adjacent[a][b]);
                }
            }
            prop_assert_eq!(clique.len(), largest_by_brute_force(&adjacent));
        }
    }

    #[test]
    fn honest_closures_outvote_a_consistent_lie_that_came_first() {
        let truth = pose_from_yaw_translation(0.4, Vector3::new(30.0, -10.0, 0.0));
        let lie = pose_from_yaw_translation(0.4 + 0.3, Vector3::new(25.0, -4.0, 0.0));
        let closure = |l: &Pose3, x: f64, y: f64| {
            let remote_pose = pose_from_yaw_translation(0.0, Vector3::new(x, y, 0.0));
            let local_pose = l * remote_pose * pose_from_yaw_translation(0.0, Vector3::new(0.0, 1.0, 0.0));
            ImpliedClosure::new(
                &local_pose,
                &pose_from_yaw_translation(0.0, Vector3::new(0.0, -1.0, 0.0)),
                &remote_pose,
            )
        };
        // Three mutually consistent lies first, then five honest closures spread over 80 m.
        let mut closures: Vec<ImpliedClosure> = (0..3).map(|k| closure(&lie, 5.0 * k as f64, 0.0)).collect();
        closures.extend((0..5).map(|k| closure(&truth, 20.0 * k as f64, 10.0)));
        let kept = largest_consistent_set(&closures, &Consistency::default());
        assert_eq!(kept, vec![3, 4, 5, 6, 7]);
        // Exact closures imply the transform exactly.
        let e = crate::geometry::pose_error(&closures[3].local_from_remote, &truth);
        assert!(e.translation_m < 1e-9);
    }

    #[test]
    fn far_apart_closures_may_disagree_as_maps_drift() {
        let c = Consistency::default();
        let at = |x: f64| Point3::new(x, 0.0, 0.0);
        let a = ImpliedClosure { local_from_remote: Pose3::identity(), at_in_remote: at(0.0) };
        // 1.5 m apart in implied translation: too much for neighbours 10 m apart ...
        let shifted = Pose3::translation(1.5, 0.0, 0.0);
        assert!(!consistent(&a, &ImpliedClosure { local_from_remote: shifted, at_in_remote: at(10.0) }, &c));
        // ... but within what 50 m of drift allows (1 + 0.02 × 50 = 2 m).
        assert!(consistent(&a, &ImpliedClosure { local_from_remote: shifted, at_in_remote: at(50.0) }, &c));
    }
}
