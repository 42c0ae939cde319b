//! Candidate associations (i, m): local object i may be remote object m only if they are
//! compatible, d_v(v_i, v_m) > threshold (paper §IV-B: d_v = 0 removes the association).

use super::vertex::VertexCompare;
use super::ObjectGraph;

/// One candidate association between local object `local` and remote object `remote` (indices
/// into the graphs' object lists), with d_v of their labels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    pub local: u32,
    pub remote: u32,
    pub label_similarity: f64,
}

/// All pairs with d_v ≥ `min_similarity` (and > 0), local-major order.
pub fn candidates(
    local: &ObjectGraph,
    remote: &ObjectGraph,
    vertices: &VertexCompare,
    min_similarity: f64,
) -> Vec<Candidate> {
    let mut out = Vec::new();
    for (i, a) in local.objects().iter().enumerate() {
        for (m, b) in remote.objects().iter().enumerate() {
            let s = vertices.similarity(a, b);
            if s > 0.0 && s >= min_similarity {
                out.push(Candidate { local: i as u32, remote: m as u32, label_similarity: s });
            }
        }
    }
    out
}
