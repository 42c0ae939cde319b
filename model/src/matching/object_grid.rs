//! A dense horizontal grid (CSR) over a graph's centroids, cells at least a given radius wide,
//! so that every object within that radius of a point is in the 3 × 3 cells around it.

use super::ObjectGraph;

/// The grid. Cells ≥ the radius it was built for, and no more than ~4 per object.
pub(super) struct Grid {
    origin_x: f64,
    origin_y: f64,
    cell: f64,
    nx: i64,
    ny: i64,
    /// Local indices of cell c are `members[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    members: Vec<u32>,
}

impl Grid {
    pub(super) fn new(graph: &ObjectGraph, radius: f64) -> Self {
        let objects = graph.objects();
        let (mut min_x, mut min_y, mut max_x, mut max_y) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for o in objects {
            min_x = min_x.min(o.centroid.x);
            min_y = min_y.min(o.centroid.y);
            max_x = max_x.max(o.centroid.x);
            max_y = max_y.max(o.centroid.y);
        }
        if objects.is_empty() {
            (min_x, min_y, max_x, max_y) = (0.0, 0.0, 0.0, 0.0);
        }
        // Cells ≥ r, and no more than ~4 per object (bounded memory for sparse, wide graphs).
        let budget = (4 * objects.len() + 64) as f64;
        let area = (max_x - min_x + radius) * (max_y - min_y + radius);
        let cell = radius.max((area / budget).sqrt());
        let nx = ((max_x - min_x) / cell).floor() as i64 + 1;
        let ny = ((max_y - min_y) / cell).floor() as i64 + 1;
        let index =
            |x: f64, y: f64| (((y - min_y) / cell).floor() as i64 * nx + ((x - min_x) / cell).floor() as i64) as usize;
        let mut counts = vec![0u32; (nx * ny) as usize + 1];
        for o in objects {
            counts[index(o.centroid.x, o.centroid.y) + 1] += 1;
        }
        for c in 1..counts.len() {
            counts[c] += counts[c - 1];
        }
        let mut fill = counts.clone();
        let mut members = vec![0u32; objects.len()];
        for (k, o) in objects.iter().enumerate() {
            let c = index(o.centroid.x, o.centroid.y);
            members[fill[c] as usize] = k as u32;
            fill[c] += 1;
        }
        Self { origin_x: min_x, origin_y: min_y, cell, nx, ny, start: counts, members }
    }

    /// Calls `f` with every member of the 3 × 3 cells around (x, y).
    pub(super) fn around(&self, x: f64, y: f64, mut f: impl FnMut(u32)) {
        let (u, v) = ((x - self.origin_x) / self.cell, (y - self.origin_y) / self.cell);
        if !(u >= -1.0 && v >= -1.0 && u < (self.nx + 1) as f64 && v < (self.ny + 1) as f64) {
            return;
        }
        // u + 1 ≥ 0 here, so truncation is floor.
        let (cx, cy) = ((u + 1.0) as i64 - 1, (v + 1.0) as i64 - 1);
        for y in (cy - 1).max(0)..=(cy + 1).min(self.ny - 1) {
            let row = y * self.nx;
            let (x0, x1) = ((cx - 1).max(0), (cx + 1).min(self.nx - 1));
            if x0 > x1 {
                continue;
            }
            let (a, b) = (self.start[(row + x0) as usize], self.start[(row + x1) as usize + 1]);
            for &m in &self.members[a as usize..b as usize] {
                f(m);
            }
        }
    }
}
