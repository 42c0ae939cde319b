//! The affinity matrix U_2D over candidate associations (paper eqs. 5–7), built sparse.
//!
//! u_{(i,m),(j,n)} = d_v(v_i, v_m) · d_v(v_j, v_n) · d_e(e_ij, e_mn),
//! d_e = exp(−μ |w_ij − w_mn|), w = ‖p_i − p_j‖₂.
//!
//! Only candidate rows and columns exist (a pair with d_v = 0 has u = 0 everywhere), conflicting
//! pairs (i = j or m = n, which no one-to-one assignment can hold together) are 0 as in Leordeanu
//! & Hebert 2005, and entries with |w_ij − w_mn| > `edge_tolerance_m` (where d_e is negligible)
//! edges longer than `max_edge_length_m`, and local edges beyond each object's `max_neighbours`
//! nearest are left out. The diagonal holds d_v². Per row, the
//! compatible remote edges are found by a sliding window over distance-sorted neighbour lists, so
//! the cost is proportional to the entries kept, never to (n·m)².

use super::candidates::Candidate;
use super::ObjectGraph;

/// A symmetric sparse matrix in compressed-row form.
#[derive(Clone, Debug, Default)]
pub struct SparseAffinity {
    pub row_start: Vec<usize>,
    pub cols: Vec<u32>,
    pub values: Vec<f64>,
}

impl SparseAffinity {
    pub fn dim(&self) -> usize {
        self.row_start.len().saturating_sub(1)
    }

    pub fn nonzeros(&self) -> usize {
        self.values.len()
    }

    /// y = U x.
    pub fn multiply(&self, x: &[f64], y: &mut [f64]) {
        for (r, out) in y.iter_mut().enumerate() {
            let (a, b) = (self.row_start[r], self.row_start[r + 1]);
            *out = self.cols[a..b].iter().zip(&self.values[a..b]).map(|(&c, &v)| v * x[c as usize]).sum();
        }
    }
}

/// Parameters of the affinity (from `MatcherConfig`).
#[derive(Clone, Copy, Debug)]
pub struct AffinityParams {
    pub edge_sharpness: f64,
    pub edge_tolerance_m: f64,
    pub max_edge_length_m: f64,
    pub max_neighbours: usize,
}

/// Builds U over `candidates`.
pub fn build(
    local: &ObjectGraph,
    remote: &ObjectGraph,
    candidates: &[Candidate],
    params: AffinityParams,
) -> SparseAffinity {
    const NONE: u32 = u32::MAX;
    let (nl, nr) = (local.len(), remote.len());
    let mut index = vec![NONE; nl * nr];
    // Remote objects that some local object of each label may be: only their edges can count.
    let mut candidate_remote = vec![false; nr];
    for (k, c) in candidates.iter().enumerate() {
        index[c.local as usize * nr + c.remote as usize] = k as u32;
        candidate_remote[c.remote as usize] = true;
    }
    let local_neighbours =
        nearest_symmetric(neighbour_lists(local, params.max_edge_length_m, |_| true), params.max_neighbours);
    let remote_neighbours =
        neighbour_lists(remote, params.max_edge_length_m + params.edge_tolerance_m, |n| candidate_remote[n]);

    let mut out = SparseAffinity { row_start: Vec::with_capacity(candidates.len() + 1), ..Default::default() };
    out.row_start.push(0);
    for a in candidates {
        out.cols.push(out.row_start.len() as u32 - 1);
        out.values.push(a.label_similarity * a.label_similarity);
        let sorted = &remote_neighbours[a.remote as usize];
        let mut lo = 0;
        // Local neighbours come by increasing w_ij, so the window start only moves forward.
        for &(w_ij, j) in &local_neighbours[a.local as usize] {
            let row = &index[j as usize * nr..(j as usize + 1) * nr];
            while lo < sorted.len() && sorted[lo].0 < w_ij - params.edge_tolerance_m {
                lo += 1;
            }
            for &(w_mn, n) in &sorted[lo..] {
                if w_mn > w_ij + params.edge_tolerance_m {
                    break;
                }
                let b = row[n as usize];
                if b != NONE {
                    let c = &candidates[b as usize];
                    let d_e = (-params.edge_sharpness * (w_ij - w_mn).abs()).exp();
                    out.cols.push(b);
                    out.values.push(a.label_similarity * c.label_similarity * d_e);
                }
            }
        }
        out.row_start.push(out.cols.len());
    }
    out
}

/// For each object, the other objects (accepted by `keep`) within `max_length` as
/// (distance, index), by distance.
fn neighbour_lists(graph: &ObjectGraph, max_length: f64, keep: impl Fn(usize) -> bool) -> Vec<Vec<(f64, u32)>> {
    let objects = graph.objects();
    let mut lists = vec![Vec::new(); objects.len()];
    for i in 0..objects.len() {
        for j in (i + 1)..objects.len() {
            let w = (objects[i].centroid - objects[j].centroid).norm();
            if w <= max_length {
                if keep(j) {
                    lists[i].push((w, j as u32));
                }
                if keep(i) {
                    lists[j].push((w, i as u32));
                }
            }
        }
    }
    for list in &mut lists {
        list.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    }
    lists
}

/// Keeps edge (i, j) when j is among i's `k` nearest or i among j's, so U stays symmetric.
fn nearest_symmetric(full: Vec<Vec<(f64, u32)>>, k: usize) -> Vec<Vec<(f64, u32)>> {
    let mut kept: Vec<Vec<(f64, u32)>> = full.iter().map(|l| l[..l.len().min(k)].to_vec()).collect();
    for (i, list) in full.iter().enumerate() {
        for &(w, j) in list.iter().take(k) {
            let back = &mut kept[j as usize];
            if back.len() >= k && !back.iter().any(|&(_, x)| x == i as u32) {
                back.push((w, i as u32));
            }
        }
    }
    for list in &mut kept {
        list.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    }
    kept
}
