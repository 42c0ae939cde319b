//! Geometric verification (beyond the paper): rigid hypotheses from pairs of candidate
//! associations, scored by the inliers they explain.
//!
//! A pair of associations (i, m), (j, n) whose horizontal edge lengths agree, |h_ij − h_mn| ≤ 2r,
//! fixes a planar transform (yaw from the edge directions, translation from the midpoints, z from
//! the mean offset). Under a transform T, remote object m is an inlier of local object i when
//! ‖(p_i − T q_m)_xy‖ ≤ r and |(p_i − T q_m)_z| ≤ r_z; its weight is the truncated quadratic
//! (MSAC) d_v(l_i, l_m) · (1 − ρ²), ρ² = (d_xy / r)² + (d_z / r_z)². Each object is used once
//! (the heavier claim wins). The score is the sum of weights.

use super::object_grid::Grid;
use super::vertex::VertexCompare;
use super::ObjectGraph;
use crate::geometry::{fit_rigid, Correspondence, Pose3, RigidModel};
use nalgebra::Point3;
use std::cell::RefCell;

/// An inlier association under a hypothesis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inlier {
    pub local: u32,
    pub remote: u32,
    pub weight: f64,
    pub residual_m: f64,
    /// Horizontal part of the residual, m.
    pub residual_xy_m: f64,
    pub same_label: bool,
}

/// A transform with the inliers it explains.
#[derive(Clone, Debug)]
pub struct Evaluation {
    pub local_from_remote: Pose3,
    pub inliers: Vec<Inlier>,
    pub score: f64,
}

/// Scores transforms against the local graph through a dense horizontal grid (CSR) whose cells
/// are at least r wide, so an inlier is always in the 3 × 3 cells around a prediction.
pub struct Scorer<'a> {
    local: &'a ObjectGraph,
    remote: &'a ObjectGraph,
    vertices: &'a VertexCompare<'a>,
    radius: f64,
    height: f64,
    grid: Grid,
    /// Best claim per local object, reused between evaluations.
    claims: RefCell<Vec<Option<Inlier>>>,
}

impl<'a> Scorer<'a> {
    pub fn new(
        local: &'a ObjectGraph,
        remote: &'a ObjectGraph,
        vertices: &'a VertexCompare<'a>,
        radius: f64,
        height: f64,
    ) -> Self {
        Self {
            local,
            remote,
            vertices,
            radius,
            height,
            grid: Grid::new(local, radius),
            claims: RefCell::new(vec![None; local.len()]),
        }
    }

    /// Inliers and score of `local_from_remote`.
    pub fn evaluate(&self, local_from_remote: &Pose3) -> Evaluation {
        self.evaluate_gated(local_from_remote, |_| self.height)
    }

    /// Inliers and score of `local_from_remote` under a vertical gate r_z + s·‖(p̂ − c)_xy‖ that
    /// grows with the horizontal distance of the prediction p̂ from `pivot` c at slope s (a tilt
    /// of up to atan s about c moves a centroid that far vertically): see `tilt`.
    pub fn evaluate_relaxed(&self, local_from_remote: &Pose3, pivot: Point3<f64>, slope: f64) -> Evaluation {
        self.evaluate_gated(local_from_remote, |p: &Point3<f64>| self.height + slope * (p - pivot).xy().norm())
    }

    /// Inliers and score of `local_from_remote` with the vertical gate `height(p̂)` at prediction p̂.
    fn evaluate_gated(&self, local_from_remote: &Pose3, height: impl Fn(&Point3<f64>) -> f64) -> Evaluation {
        let local = self.local.objects();
        let mut claims = self.claims.borrow_mut();
        let r2 = self.radius * self.radius;
        // p = R q + t with the rotation as a matrix (cheaper than a quaternion per point).
        let rotation = local_from_remote.rotation.to_rotation_matrix();
        let translation = local_from_remote.translation.vector;
        for (m, q) in self.remote.objects().iter().enumerate() {
            let predicted = Point3::from(rotation * q.centroid.coords + translation);
            let h = height(&predicted);
            let mut best: Option<Inlier> = None;
            self.grid.around(predicted.x, predicted.y, |i| {
                let p = &local[i as usize];
                let d = p.centroid - predicted;
                let dxy2 = d.x * d.x + d.y * d.y;
                if dxy2 > r2 || d.z.abs() > h {
                    return;
                }
                let similarity = self.vertices.similarity(p, q);
                if similarity <= 0.0 {
                    return;
                }
                let weight = similarity * (1.0 - dxy2 / r2 - (d.z / h).powi(2)).max(0.0);
                if best.is_none_or(|b| weight > b.weight) {
                    best = Some(Inlier {
                        local: i,
                        remote: m as u32,
                        weight,
                        residual_m: d.norm(),
                        residual_xy_m: dxy2.sqrt(),
                        same_label: p.label == q.label,
                    });
                }
            });
            if let Some(b) = best {
                let slot = &mut claims[b.local as usize];
                if slot.is_none_or(|s| b.weight > s.weight) {
                    *slot = Some(b);
                }
            }
        }
        let inliers: Vec<Inlier> = claims.iter_mut().filter_map(Option::take).filter(|i| i.weight > 0.0).collect();
        let score = inliers.iter().map(|i| i.weight).sum();
        Evaluation { local_from_remote: *local_from_remote, inliers, score }
    }

    /// Re-fits the transform to the inliers (weighted least squares under `model`) and re-scores,
    /// until the inlier set stops changing (at most `rounds` times). Returns the best evaluation.
    pub fn refine(&self, start: Evaluation, model: RigidModel, rounds: usize) -> Evaluation {
        let mut best = start;
        for _ in 0..rounds {
            let pairs: Vec<Correspondence> = best
                .inliers
                .iter()
                .map(|i| Correspondence {
                    in_local: self.local.objects()[i.local as usize].centroid,
                    in_remote: self.remote.objects()[i.remote as usize].centroid,
                    weight: i.weight,
                })
                .collect();
            if pairs.len() < 2 {
                break;
            }
            let Some(pose) = fit_rigid(&pairs, model) else { break };
            let next = self.evaluate(&pose);
            let same_set =
                next.inliers.iter().map(|i| (i.local, i.remote)).eq(best.inliers.iter().map(|i| (i.local, i.remote)));
            if next.score + 1e-12 < best.score && !same_set {
                break;
            }
            best = next;
            if same_set {
                break;
            }
        }
        best
    }
}

/// Largest horizontal displacement, over `points`, between two transforms of them.
pub fn max_displacement(a: &Pose3, b: &Pose3, points: impl Iterator<Item = Point3<f64>>) -> f64 {
    points.map(|q| ((a * q) - (b * q)).xy().norm()).fold(0.0, f64::max)
}
