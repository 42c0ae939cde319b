//! The paper's formulation as published (§IV-B, §IV-C), dense, for comparison only:
//! the full (n·m) × (n·m) matrix U_2D with u = d_v d_v d_e over *all* assignments (hard labels,
//! conflicting pairs 0), its principal eigenvector by power iteration, Hungarian LAP on −x with
//! the minimum eigenvector value, and a planar least-squares transform from every assignment
//! kept, with no verification. Success needs ≥ 3 assignments.

use super::{LabelSimilarity, ObjectGraph};
use crate::geometry::{fit_rigid, Correspondence, Pose3, RigidModel};
use crate::scene_graph::ObjectId;
use crate::spatial::lap::{self, CostMatrix};

/// Result of the dense paper formulation.
#[derive(Clone, Debug)]
pub struct PaperResult {
    pub local_from_remote: Option<Pose3>,
    pub matches: Vec<(ObjectId, ObjectId)>,
}

pub fn match_dense(
    local: &ObjectGraph,
    remote: &ObjectGraph,
    labels: &LabelSimilarity,
    edge_sharpness: f64,
    min_assignment_score: f64,
) -> PaperResult {
    let (n, m) = (local.len(), remote.len());
    let dim = n * m;
    let (p, q) = (local.objects(), remote.objects());
    let mut u = vec![0.0; dim * dim];
    for i in 0..n {
        for a in 0..m {
            let row = i * m + a;
            let dv_ia = labels.get(p[i].label, q[a].label);
            for j in 0..n {
                for b in 0..m {
                    let col = j * m + b;
                    if (i == j) != (a == b) {
                        continue; // conflicting assignments
                    }
                    let dv_jb = labels.get(p[j].label, q[b].label);
                    let w_ij = (p[i].centroid - p[j].centroid).norm();
                    let w_ab = (q[a].centroid - q[b].centroid).norm();
                    u[row * dim + col] = dv_ia * dv_jb * (-edge_sharpness * (w_ij - w_ab).abs()).exp();
                }
            }
        }
    }
    let mut x = vec![1.0 / (dim as f64).sqrt(); dim];
    let mut y = vec![0.0; dim];
    for _ in 0..1000 {
        for (r, out) in y.iter_mut().enumerate() {
            *out = u[r * dim..(r + 1) * dim].iter().zip(&x).map(|(a, b)| a * b).sum();
        }
        let norm = y.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm.is_nan() || norm <= 0.0 {
            break;
        }
        let mut change: f64 = 0.0;
        for (xi, yi) in x.iter_mut().zip(&y) {
            change = change.max((yi / norm - *xi).abs());
            *xi = yi / norm;
        }
        if change < 1e-7 {
            break;
        }
    }
    let max = x.iter().copied().fold(0.0, f64::max);
    let mut costs = CostMatrix::filled(n, m, 0.0);
    for i in 0..n {
        for a in 0..m {
            costs.set(i, a, -x[i * m + a]);
        }
    }
    let kept: Vec<(usize, usize)> = lap::solve(&costs)
        .into_iter()
        .enumerate()
        .filter_map(|(i, a)| a.map(|a| (i, a)))
        .filter(|&(i, a)| {
            max > 0.0 && x[i * m + a] >= min_assignment_score * max && labels.get(p[i].label, q[a].label) > 0.0
        })
        .collect();
    let matches = kept.iter().map(|&(i, a)| (p[i].id, q[a].id)).collect();
    let local_from_remote = if kept.len() >= 3 {
        let pairs: Vec<Correspondence> = kept
            .iter()
            .map(|&(i, a)| Correspondence { in_local: p[i].centroid, in_remote: q[a].centroid, weight: 1.0 })
            .collect();
        fit_rigid(&pairs, RigidModel::Planar)
    } else {
        None
    };
    PaperResult { local_from_remote, matches }
}
