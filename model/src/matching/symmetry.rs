//! Near-symmetries of a repeated layout (beyond the paper): horizontal translations under which
//! many of the matched objects land on objects of the same label elsewhere in the same graph.
//!
//! The hypothesis search seeds transforms from pairs of the strongest associations, which all
//! agree with the best transform; in a grid of desks or lamp posts the copies of that transform
//! shifted by a period of the grid are then never tried, and a wrong period can be accepted for
//! lack of a runner-up. For matched local objects i and every same-label object j of the local
//! graph with ‖p_j − p_i‖_xy in [min, max], the shift p_j − p_i votes in a horizontal histogram
//! of `bin`-wide cells (each anchor once per cell: a Hough transform over translations); cells
//! with enough votes are the layout's periods, strongest first. The matcher then scores
//! S ∘ T for each period S as a runner-up of T (`matcher`).

use super::ObjectGraph;
use nalgebra::Vector3;
use std::collections::HashMap;

/// Limits of the period search.
#[derive(Clone, Copy, Debug)]
pub struct PeriodSearch {
    /// Shortest and longest horizontal shift considered, m.
    pub min_shift_m: f64,
    pub max_shift_m: f64,
    /// Histogram cell, m.
    pub bin_m: f64,
    /// Fewest anchors that must agree on a shift.
    pub min_votes: usize,
    /// At most this many periods are returned.
    pub max_periods: usize,
}

/// The strongest periods of `graph` seen from the objects `anchors`, as horizontal shifts (the
/// mean of the votes of each cell), most votes first; ties broken by cell, so deterministic.
pub fn periods(graph: &ObjectGraph, anchors: &[u32], search: PeriodSearch) -> Vec<Vector3<f64>> {
    let objects = graph.objects();
    let (min2, max2) = (search.min_shift_m.powi(2), search.max_shift_m.powi(2));
    // cell → (votes, sum of shifts, last anchor that voted)
    let mut cells: HashMap<(i64, i64), (usize, Vector3<f64>, u32)> = HashMap::new();
    for &i in anchors {
        let Some(a) = objects.get(i as usize) else { continue };
        for b in objects {
            if b.label != a.label {
                continue;
            }
            let mut shift = b.centroid - a.centroid;
            shift.z = 0.0;
            let d2 = shift.norm_squared();
            if d2 < min2 || d2 > max2 {
                continue;
            }
            let key = ((shift.x / search.bin_m).floor() as i64, (shift.y / search.bin_m).floor() as i64);
            let cell = cells.entry(key).or_insert((0, Vector3::zeros(), u32::MAX));
            if cell.2 != i {
                cell.0 += 1;
                cell.1 += shift;
                cell.2 = i;
            }
        }
    }
    let mut strong: Vec<((i64, i64), usize, Vector3<f64>)> = cells
        .into_iter()
        .filter(|(_, (votes, _, _))| *votes >= search.min_votes)
        .map(|(key, (votes, sum, _))| (key, votes, sum / votes as f64))
        .collect();
    strong.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    strong.into_iter().take(search.max_periods).map(|(_, _, shift)| shift).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::matching::graph::flat_graph;

    fn grid(nx: usize, ny: usize, dx: f64, dy: f64) -> ObjectGraph {
        let points: Vec<(f64, f64)> =
            (0..nx).flat_map(|i| (0..ny).map(move |j| (dx * i as f64, dy * j as f64))).collect();
        flat_graph(&points)
    }

    const SEARCH: PeriodSearch =
        PeriodSearch { min_shift_m: 6.0, max_shift_m: 15.0, bin_m: 3.0, min_votes: 3, max_periods: 8 };

    #[test]
    fn a_grid_of_posts_has_its_periods_found() {
        let posts = grid(6, 5, 12.0, 10.0);
        let anchors: Vec<u32> = (0..posts.len() as u32).collect();
        let found = periods(&posts, &anchors, SEARCH);
        for expected in [Vector3::new(12.0, 0.0, 0.0), Vector3::new(0.0, 10.0, 0.0), Vector3::new(-12.0, 0.0, 0.0)] {
            assert!(found.iter().any(|s| (s - expected).norm() < 1e-9), "{expected:?} not in {found:?}");
        }
        // The axis periods have the most votes (5 × 5 anchors for ±12 m, 6 × 4 for ±10 m).
        assert!((found[0].norm() - 12.0).abs() < 1e-9, "{found:?}");
    }

    #[test]
    fn scattered_objects_have_no_period() {
        let graph = flat_graph(&[(0.0, 0.0), (7.0, 1.0), (3.0, 9.0), (14.0, 5.0), (9.0, 13.0)]);
        assert!(periods(&graph, &[0, 1, 2, 3, 4], SEARCH).is_empty());
    }
}
