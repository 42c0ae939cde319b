//! The affinity matrix U_2D over candidate associations (paper eqs. 5–7), built sparse.
//!
//! u_{(i,m),(j,n)} = d_v(v_i, v_m) · d_v(v_j, v_n) · d_e(e_ij, e_mn),
//! d_e = exp(−μ |w_ij − w_mn|), w = ‖p_i − p_j‖₂.
//!
//! Only candidate rows and columns exist (a pair with d_v = 0 has u = 0 everywhere), conflicting
//! pairs (i = j or m = n, which no one-to-one assignment can hold together) are 0 as in Leordeanu
//! & Hebert 2005, and entries with |w_ij − w_mn| > `edge_tolerance_m` (where d_e is negligible)
//! edges longer than `max_edge_length_m`, and local edges beyond each object's `max_neighbours`
//! nearest are left out, and of the remote edges agreeing with one local edge only the
//! `MAX_EDGE_MATCHES` closest in length are kept. The diagonal holds d_v². Per row, the
//! compatible remote edges are found by a sliding window over distance-sorted neighbour lists, so
//! the cost is proportional to the entries kept, never to (n·m)².

use super::candidates::Candidate;

/// Per candidate and local neighbour, at most about this many remote edges enter U: those whose
/// lengths agree best (a dense layout of identical objects — a lecture hall's seats — otherwise
/// puts hundreds in every row). Kept only when both ends keep it, so U stays symmetric.
const MAX_EDGE_MATCHES: usize = 8;
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

/// One object's neighbours, split by label bit: (bit, [(distance, index)] by distance).
type LabelGroups = Vec<(u32, Vec<(f64, u32)>)>;

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
    // A cheap pre-test before `index`: bit (label mod 64) of each remote object, and per local
    // object the bits of the remote objects it may be.
    let label_bit = |o: &super::GraphObject| 1u64 << (o.label.0 % 64);
    let remote_bits: Vec<u64> = remote.objects().iter().map(label_bit).collect();
    let mut local_masks = vec![0u64; nl];
    for (k, c) in candidates.iter().enumerate() {
        index[c.local as usize * nr + c.remote as usize] = k as u32;
        candidate_remote[c.remote as usize] = true;
        local_masks[c.local as usize] |= remote_bits[c.remote as usize];
    }
    let local_neighbours = nearest_symmetric(
        neighbour_lists(local, params.max_edge_length_m, Some(params.max_neighbours), |_| true),
        params.max_neighbours,
    );
    // Each remote object's neighbours split by label bit, each part by distance: a window only
    // visits the labels its local neighbour may be (found through `group_of`, in group order).
    let remote_neighbours: Vec<LabelGroups> =
        neighbour_lists(remote, params.max_edge_length_m + params.edge_tolerance_m, None, |n| candidate_remote[n])
            .into_iter()
            .map(|list| {
                let mut groups: LabelGroups = Vec::new();
                for (w, n) in list {
                    let bit = remote_bits[n as usize].trailing_zeros();
                    match groups.iter_mut().find(|g| g.0 == bit) {
                        Some(g) => g.1.push((w, n)),
                        None => groups.push((bit, vec![(w, n)])),
                    }
                }
                groups
            })
            .collect();

    // Per remote object, its groups' label bits and bit → group index.
    let group_bits: Vec<u64> =
        remote_neighbours.iter().map(|groups| groups.iter().fold(0u64, |m, g| m | (1u64 << g.0))).collect();
    let mut group_of = [0u8; 64];
    let mut visit: Vec<usize> = Vec::new();

    // Per candidate a and local neighbour j, the remote edges (j, n) in the window are kept up
    // to the K-th smallest gap |w_ij − w_mn| (all of them when there are at most K)...
    let mut out = SparseAffinity { row_start: Vec::with_capacity(candidates.len() + 1), ..Default::default() };
    out.row_start.push(0);
    let mut gaps: Vec<f64> = Vec::new();
    let mut thresholds: Vec<f64> = Vec::new();
    let mut threshold_start: Vec<usize> = Vec::with_capacity(candidates.len() + 1);
    let mut capped = vec![false; candidates.len()];
    let mut window: Vec<(u32, f64)> = Vec::new();
    let mut selected: Vec<f64> = Vec::new();
    let mut starts: Vec<usize> = Vec::new();
    for (k, a) in candidates.iter().enumerate() {
        threshold_start.push(thresholds.len());
        out.cols.push(k as u32);
        out.values.push(a.label_similarity * a.label_similarity);
        gaps.push(0.0);
        let groups = &remote_neighbours[a.remote as usize];
        for (g, (bit, _)) in groups.iter().enumerate() {
            group_of[*bit as usize] = g as u8;
        }
        // Local neighbours come by increasing w_ij, so each window start only moves forward.
        starts.clear();
        starts.resize(groups.len(), 0);
        for &(w_ij, j) in &local_neighbours[a.local as usize] {
            let row = &index[j as usize * nr..(j as usize + 1) * nr];
            let mask = local_masks[j as usize];
            window.clear();
            visit.clear();
            let mut wanted = mask & group_bits[a.remote as usize];
            while wanted != 0 {
                visit.push(usize::from(group_of[wanted.trailing_zeros() as usize]));
                wanted &= wanted - 1;
            }
            visit.sort_unstable();
            for &g in &visit {
                let (sorted, lo) = (&groups[g].1, &mut starts[g]);
                while *lo < sorted.len() && sorted[*lo].0 < w_ij - params.edge_tolerance_m {
                    *lo += 1;
                }
                for &(w_mn, n) in &sorted[*lo..] {
                    if w_mn > w_ij + params.edge_tolerance_m {
                        break;
                    }
                    let b = row[n as usize];
                    if b != NONE {
                        window.push((b, (w_ij - w_mn).abs()));
                    }
                }
            }
            let limit = if window.len() <= MAX_EDGE_MATCHES {
                f64::INFINITY
            } else {
                capped[k] = true;
                selected.clear();
                selected.extend(window.iter().map(|w| w.1));
                *selected.select_nth_unstable_by(MAX_EDGE_MATCHES - 1, f64::total_cmp).1
            };
            thresholds.push(limit);
            for &(b, gap) in window.iter().filter(|w| w.1 <= limit) {
                out.cols.push(b);
                out.values.push(
                    a.label_similarity * candidates[b as usize].label_similarity * (-params.edge_sharpness * gap).exp(),
                );
                gaps.push(gap);
            }
        }
        out.row_start.push(out.cols.len());
    }
    threshold_start.push(thresholds.len());
    if capped.iter().any(|&c| c) {
        // ... and an entry stays only when the other end keeps it too, so U stays symmetric.
        let threshold = |b: usize, i: u32| {
            let list = &local_neighbours[candidates[b].local as usize];
            list.iter().position(|&(_, x)| x == i).map_or(f64::INFINITY, |slot| thresholds[threshold_start[b] + slot])
        };
        let mut kept = SparseAffinity { row_start: vec![0], ..Default::default() };
        for (k, a) in candidates.iter().enumerate() {
            let range = out.row_start[k]..out.row_start[k + 1];
            let entries = out.cols[range.clone()].iter().zip(&out.values[range.clone()]).zip(&gaps[range]);
            for ((&b, &value), &gap) in entries {
                if b as usize == k || !capped[b as usize] || gap <= threshold(b as usize, a.local) {
                    kept.cols.push(b);
                    kept.values.push(value);
                }
            }
            kept.row_start.push(kept.cols.len());
        }
        out = kept;
    }
    out
}

/// For each object, the other objects (accepted by `keep`) within `max_length` as
/// (distance, index), by distance; only the `nearest` first when given.
fn neighbour_lists(
    graph: &ObjectGraph,
    max_length: f64,
    nearest: Option<usize>,
    keep: impl Fn(usize) -> bool,
) -> Vec<Vec<(f64, u32)>> {
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
    let order = |a: &(f64, u32), b: &(f64, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
    for list in &mut lists {
        // Only the first `nearest` of the sorted list are ever read: select them, sort those.
        if let Some(k) = nearest.filter(|&k| k > 0 && k < list.len()) {
            list.select_nth_unstable_by(k - 1, order);
            list.truncate(k);
        }
        list.sort_by(order);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::matching::candidates::candidates;
    use crate::matching::{GraphObject, LabelSimilarity, MatcherConfig, VertexCompare};
    use crate::scene_graph::{LabelId, ObjectId};
    use nalgebra::Point3;

    /// Seats 0.6 m apart in rows 1 m apart, one label: every row of U would hold hundreds.
    fn seats(nx: usize, ny: usize, dx: f64) -> ObjectGraph {
        let objects = (0..nx * ny)
            .map(|k| GraphObject {
                id: ObjectId(k as u32),
                label: LabelId(0),
                centroid: Point3::new(dx + 0.6 * (k % nx) as f64, (k / nx) as f64, 0.45),
                size: None,
            })
            .collect();
        ObjectGraph::new(objects, usize::MAX).unwrap()
    }

    #[test]
    fn a_dense_layout_is_capped_and_u_stays_symmetric() {
        let (local, remote) = (seats(12, 8, 0.0), seats(12, 8, 0.3));
        let config = MatcherConfig::default();
        let labels = LabelSimilarity::hard(1);
        let vertices = VertexCompare::new(&labels, &config);
        let cands = candidates(&local, &remote, &vertices, 0.5);
        let params = AffinityParams {
            edge_sharpness: config.edge_sharpness,
            edge_tolerance_m: config.edge_tolerance_m,
            max_edge_length_m: config.max_edge_length_m,
            max_neighbours: config.max_neighbours,
        };
        let u = build(&local, &remote, &cands, params);
        let entry = |r: usize, c: u32| {
            let (a, b) = (u.row_start[r], u.row_start[r + 1]);
            u.cols[a..b].iter().position(|&x| x == c).map(|k| u.values[a + k])
        };
        let mut widest = 0;
        for r in 0..u.dim() {
            let (a, b) = (u.row_start[r], u.row_start[r + 1]);
            widest = widest.max(b - a);
            for k in a..b {
                let back = entry(u.cols[k] as usize, r as u32);
                assert_eq!(back, Some(u.values[k]), "U[{r}][{}] has no mirror", u.cols[k]);
            }
        }
        // At most K per local neighbour (ties at the K-th gap may add a few), plus the diagonal.
        let neighbours = 2 * config.max_neighbours;
        assert!(widest <= 1 + neighbours * (MAX_EDGE_MATCHES + 4), "a row holds {widest} entries");
    }
}
