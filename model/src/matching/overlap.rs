//! Negative evidence (beyond the paper): how consistently a transform explains the ground the two
//! graphs share, not only how many objects it explains.
//!
//! Inlier counts reward a transform for what it explains and never charge it for what it
//! contradicts. In a repeated layout (lamp posts on a grid, cars in rows of bays) a transform
//! shifted by a period of the layout, or turned by 180°, can explain *more* objects than the true
//! one, because it lays the two views over each other more widely — while it also puts many
//! objects where the other robot saw none. Under T, with A the inliers (one-to-one pairs), an
//! object of either graph that has no partner but lands where the other robot did map
//! something — within `support_m` of one of its objects — is a disagreement; D counts them over
//! both directions. The agreement index (Birk & Carpin 2006, "Merging occupancy grid maps from
//! multiple robots", Proc. IEEE 94(7), for cells rather than objects)
//!
//!   ω(T) = 2A / (2A + D)
//!
//! is what the true transform keeps high — only missed detections and label changes lower it —
//! and what a shifted copy of a layout cannot (every bay it lays onto an empty one).
//!
//! ω is a proportion of the N = 2A + D objects on shared ground, so it carries sampling noise:
//! read as a binomial proportion, its standard error is
//!
//!   se(ω) = √(ω (1 − ω) / N),
//!
//! and two transforms' indices differ by more than chance only beyond a few
//! √(se₁² + se₂²) ([`Agreement::difference_error`]).

use super::object_grid::Grid;
use super::verification::Evaluation;
use super::ObjectGraph;
use nalgebra::Point3;

/// The agreement index of one transform and the objects it was counted over.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Agreement {
    /// ω = 2A / (2A + D), in [0, 1]; 0 when nothing lands on shared ground.
    pub index: f64,
    /// N = 2A + D: the objects of either graph on shared ground.
    pub on_shared_ground: usize,
}

impl Agreement {
    /// se(ω) = √(ω (1 − ω) / N); 0 when N = 0.
    pub fn standard_error(&self) -> f64 {
        if self.on_shared_ground == 0 {
            return 0.0;
        }
        (self.index * (1.0 - self.index) / self.on_shared_ground as f64).sqrt()
    }

    /// The standard error of ω₁ − ω₂ for two transforms counted apart: √(se₁² + se₂²).
    pub fn difference_error(&self, other: &Agreement) -> f64 {
        self.standard_error().hypot(other.standard_error())
    }
}

/// Agreement of transforms between two graphs.
pub struct Overlap<'a> {
    local: &'a ObjectGraph,
    remote: &'a ObjectGraph,
    local_grid: Grid,
    remote_grid: Grid,
    support_m: f64,
}

impl<'a> Overlap<'a> {
    /// An object lands on mapped ground when it is within `support_m` of one of the other graph's
    /// objects.
    pub fn new(local: &'a ObjectGraph, remote: &'a ObjectGraph, support_m: f64) -> Self {
        Self {
            local,
            remote,
            local_grid: Grid::new(local, support_m),
            remote_grid: Grid::new(remote, support_m),
            support_m,
        }
    }

    /// ω of an evaluated transform, with the number of objects it was counted over.
    pub fn agreement(&self, e: &Evaluation) -> Agreement {
        let mut matched_local = vec![false; self.local.len()];
        let mut matched_remote = vec![false; self.remote.len()];
        for i in &e.inliers {
            matched_local[i.local as usize] = true;
            matched_remote[i.remote as usize] = true;
        }
        let local_from_remote = e.local_from_remote;
        let disagreements_remote =
            self.unmatched_on_ground(self.remote, &matched_remote, &local_from_remote, &self.local_grid, self.local);
        let disagreements_local = self.unmatched_on_ground(
            self.local,
            &matched_local,
            &local_from_remote.inverse(),
            &self.remote_grid,
            self.remote,
        );
        let agreements = 2 * e.inliers.len();
        let total = agreements + disagreements_remote + disagreements_local;
        let index = if total == 0 { 0.0 } else { agreements as f64 / total as f64 };
        Agreement { index, on_shared_ground: total }
    }

    /// Objects of `from` without a partner that `other_from_this` lays within the support radius
    /// of an object of `other` (its mapped ground).
    fn unmatched_on_ground(
        &self,
        from: &ObjectGraph,
        matched: &[bool],
        other_from_this: &crate::geometry::Pose3,
        grid: &Grid,
        other: &ObjectGraph,
    ) -> usize {
        from.objects()
            .iter()
            .zip(matched)
            .filter(|(o, matched)| !**matched && self.near(grid, other, &(other_from_this * o.centroid)))
            .count()
    }

    /// Whether some object of `graph` lies within the support radius of `point`, horizontally.
    fn near(&self, grid: &Grid, graph: &ObjectGraph, point: &Point3<f64>) -> bool {
        let r2 = self.support_m * self.support_m;
        let mut found = false;
        grid.around(point.x, point.y, |k| {
            found |= (graph.objects()[k as usize].centroid - point).xy().norm_squared() <= r2;
        });
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_from_yaw_translation, Pose3};
    use crate::matching::graph::flat_graph;
    use crate::matching::verification::Inlier;
    use nalgebra::Vector3;

    fn graph(points: &[(f64, f64)]) -> ObjectGraph {
        flat_graph(points)
    }

    fn evaluation(pose: Pose3, pairs: &[(u32, u32)]) -> Evaluation {
        let inliers = pairs
            .iter()
            .map(|&(local, remote)| Inlier {
                local,
                remote,
                weight: 1.0,
                residual_m: 0.0,
                residual_xy_m: 0.0,
                same_label: true,
            })
            .collect();
        Evaluation { local_from_remote: pose, inliers, score: pairs.len() as f64 }
    }

    #[test]
    fn a_shift_that_lays_objects_on_empty_ground_is_charged_for_it() {
        // Local and remote: three objects in a row, 6 m apart.
        let local = graph(&[(0.0, 0.0), (6.0, 0.0), (12.0, 0.0)]);
        let remote = graph(&[(0.0, 0.0), (6.0, 0.0), (12.0, 0.0)]);
        let overlap = Overlap::new(&local, &remote, 4.0);
        let truth = evaluation(Pose3::identity(), &[(0, 0), (1, 1), (2, 2)]);
        assert_eq!(overlap.agreement(&truth).index, 1.0);
        // Shifted by one occupied period: two pairs, and one object each side on mapped ground.
        let shifted = evaluation(pose_from_yaw_translation(0.0, Vector3::new(6.0, 0.0, 0.0)), &[(1, 0), (2, 1)]);
        // Remote 2 lands at 18 m: 6 m from local 2, beyond support. Local 0 lands at −6 m: beyond.
        assert_eq!(overlap.agreement(&shifted).index, 1.0);
        let tight = Overlap::new(&local, &remote, 7.0);
        // With a 7 m support both unmatched objects land on mapped ground: ω = 4 / (4 + 2).
        assert!((tight.agreement(&shifted).index - 4.0 / 6.0).abs() < 1e-12);
    }

    #[test]
    fn the_agreement_index_carries_a_binomial_standard_error() {
        // Two pairs and two unmatched objects on mapped ground: ω = 4 / 6 over N = 6 objects.
        let local = graph(&[(0.0, 0.0), (6.0, 0.0), (12.0, 0.0)]);
        let remote = graph(&[(0.0, 0.0), (6.0, 0.0), (12.0, 0.0)]);
        let shifted = evaluation(pose_from_yaw_translation(0.0, Vector3::new(6.0, 0.0, 0.0)), &[(1, 0), (2, 1)]);
        let a = Overlap::new(&local, &remote, 7.0).agreement(&shifted);
        assert_eq!(a.on_shared_ground, 6);
        let se = (4.0 / 6.0 * (2.0 / 6.0) / 6.0_f64).sqrt();
        assert!((a.standard_error() - se).abs() < 1e-12);
        // The difference of two independent indices: √(se₁² + se₂²); perfect agreement has none.
        let perfect = Agreement { index: 1.0, on_shared_ground: 40 };
        assert_eq!(perfect.standard_error(), 0.0);
        assert!((a.difference_error(&a) - se * 2.0_f64.sqrt()).abs() < 1e-12);
        assert!((a.difference_error(&perfect) - se).abs() < 1e-12);
        // Nothing on shared ground: no sampling, no error (and no division by zero).
        assert_eq!(Agreement { index: 0.0, on_shared_ground: 0 }.standard_error(), 0.0);
    }

    #[test]
    fn nothing_on_shared_ground_is_no_agreement() {
        let local = graph(&[(0.0, 0.0)]);
        let remote = graph(&[(100.0, 0.0)]);
        let overlap = Overlap::new(&local, &remote, 5.0);
        assert_eq!(overlap.agreement(&evaluation(Pose3::identity(), &[])).index, 0.0);
    }
}
