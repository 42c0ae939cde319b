//! Geometric verification (beyond the paper): rigid hypotheses from pairs of candidate
//! associations, scored by the inliers they explain.
//!
//! A pair of associations (i, m), (j, n) whose horizontal edge lengths agree, |h_ij − h_mn| ≤ 2r,
//! fixes a planar transform (yaw from the edge directions, translation from the midpoints, z from
//! the mean offset). Under a transform T, remote object m is an inlier of local object i when
//! ‖(p_i − T q_m)_xy‖ ≤ r and |(p_i − T q_m)_z| ≤ r_z; its weight is the truncated quadratic
//! (MSAC) d_v(l_i, l_m) · (1 − ρ²), ρ² = (d_xy / r)² + (d_z / r_z)². Each object is used once
//! (the heavier claim wins). The score is the sum of weights.

use super::labels::LabelSimilarity;
use super::ObjectGraph;
use crate::geometry::{fit_rigid, Correspondence, Pose3, RigidModel};
use nalgebra::Point3;

/// An inlier association under a hypothesis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inlier {
    pub local: u32,
    pub remote: u32,
    pub weight: f64,
    pub residual_m: f64,
    pub same_label: bool,
}

/// A transform with the inliers it explains.
#[derive(Clone, Debug)]
pub struct Evaluation {
    pub local_from_remote: Pose3,
    pub inliers: Vec<Inlier>,
    pub score: f64,
}

impl Evaluation {
    pub fn same_label_inliers(&self) -> usize {
        self.inliers.iter().filter(|i| i.same_label).count()
    }
}

/// Scores transforms against the local graph through a horizontal grid of cell size r.
pub struct Scorer<'a> {
    local: &'a ObjectGraph,
    remote: &'a ObjectGraph,
    labels: &'a LabelSimilarity,
    radius: f64,
    height: f64,
    /// (cell x, cell y, local index), sorted.
    cells: Vec<(i64, i64, u32)>,
}

impl<'a> Scorer<'a> {
    pub fn new(local: &'a ObjectGraph, remote: &'a ObjectGraph, labels: &'a LabelSimilarity, radius: f64, height: f64) -> Self {
        let mut cells: Vec<(i64, i64, u32)> = local
            .objects()
            .iter()
            .enumerate()
            .map(|(k, o)| {
                let (cx, cy) = cell_of(&o.centroid, radius);
                (cx, cy, k as u32)
            })
            .collect();
        cells.sort_unstable();
        Self { local, remote, labels, radius, height, cells }
    }

    /// Inliers and score of `local_from_remote`.
    pub fn evaluate(&self, local_from_remote: &Pose3) -> Evaluation {
        let local = self.local.objects();
        // best claim per local object: (weight, inlier)
        let mut claims: Vec<Option<Inlier>> = vec![None; local.len()];
        for (m, q) in self.remote.objects().iter().enumerate() {
            let predicted = local_from_remote * q.centroid;
            let (cx, cy) = cell_of(&predicted, self.radius);
            let mut best: Option<Inlier> = None;
            for y in cy - 1..=cy + 1 {
                let start = self.cells.partition_point(|&(a, b, _)| (a, b) < (cx - 1, y));
                for &(a, b, i) in &self.cells[start..] {
                    if (a, b) > (cx + 1, y) {
                        break;
                    }
                    let p = &local[i as usize];
                    let d = p.centroid - predicted;
                    let dxy2 = d.x * d.x + d.y * d.y;
                    if dxy2 > self.radius * self.radius || d.z.abs() > self.height {
                        continue;
                    }
                    let similarity = self.labels.get(p.label, q.label);
                    if similarity <= 0.0 {
                        continue;
                    }
                    let rho2 = dxy2 / (self.radius * self.radius) + (d.z / self.height).powi(2);
                    let weight = similarity * (1.0 - rho2).max(0.0);
                    if best.is_none_or(|b| weight > b.weight) {
                        best = Some(Inlier {
                            local: i,
                            remote: m as u32,
                            weight,
                            residual_m: d.norm(),
                            same_label: p.label == q.label,
                        });
                    }
                }
            }
            if let Some(b) = best {
                let slot = &mut claims[b.local as usize];
                if slot.is_none_or(|s| b.weight > s.weight) {
                    *slot = Some(b);
                }
            }
        }
        let inliers: Vec<Inlier> = claims.into_iter().flatten().filter(|i| i.weight > 0.0).collect();
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
            let same_set = next.inliers.iter().map(|i| (i.local, i.remote)).eq(best.inliers.iter().map(|i| (i.local, i.remote)));
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

fn cell_of(p: &Point3<f64>, size: f64) -> (i64, i64) {
    ((p.x / size).floor() as i64, (p.y / size).floor() as i64)
}

/// Largest horizontal displacement, over `points`, between two transforms of them.
pub fn max_displacement(a: &Pose3, b: &Pose3, points: impl Iterator<Item = Point3<f64>>) -> f64 {
    points.map(|q| ((a * q) - (b * q)).xy().norm()).fold(0.0, f64::max)
}
