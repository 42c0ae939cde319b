//! Linear assignment (paper eq. 2–4 and the final step of §IV-B): minimise Σ c_ij a_ij over
//! one-to-one assignments of a rectangular cost matrix, every row of the smaller side assigned.
//!
//! Shortest augmenting paths with dual variables (Jonker & Volgenant 1987, in the rectangular
//! form of Crouse 2016, the algorithm behind scipy's `linear_sum_assignment`): for each free row,
//! a Dijkstra search on reduced costs c_ij − u_i − v_j finds the cheapest augmenting path; the
//! duals are then updated so reduced costs stay non-negative. O(n² m) worst case.

/// A dense row-major cost matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct CostMatrix {
    rows: usize,
    cols: usize,
    costs: Vec<f64>,
}

/// Why a cost matrix cannot be built or solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LapError {
    #[error("cost matrix has {len} entries, expected {rows}×{cols}")]
    Shape { rows: usize, cols: usize, len: usize },
    #[error("cost ({row}, {col}) is not finite")]
    NonFinite { row: usize, col: usize },
}

impl CostMatrix {
    pub fn new(rows: usize, cols: usize, costs: Vec<f64>) -> Result<Self, LapError> {
        if costs.len() != rows * cols {
            return Err(LapError::Shape { rows, cols, len: costs.len() });
        }
        if let Some(k) = costs.iter().position(|c| !c.is_finite()) {
            return Err(LapError::NonFinite { row: k / cols.max(1), col: k % cols.max(1) });
        }
        Ok(Self { rows, cols, costs })
    }

    /// An all-`value` matrix.
    pub fn filled(rows: usize, cols: usize, value: f64) -> Self {
        Self { rows, cols, costs: vec![value; rows * cols] }
    }

    pub fn set(&mut self, row: usize, col: usize, cost: f64) {
        if row < self.rows && col < self.cols && cost.is_finite() {
            self.costs[row * self.cols + col] = cost;
        }
    }

    pub fn get(&self, row: usize, col: usize) -> f64 {
        self.costs[row * self.cols + col]
    }

    pub fn rows(&self) -> usize {
        self.rows
    }

    pub fn cols(&self) -> usize {
        self.cols
    }

    fn transposed(&self) -> Self {
        let mut costs = Vec::with_capacity(self.costs.len());
        for c in 0..self.cols {
            for r in 0..self.rows {
                costs.push(self.costs[r * self.cols + c]);
            }
        }
        Self { rows: self.cols, cols: self.rows, costs }
    }
}

/// Optimal assignment: `row_to_col[r]` is the column of row r (`None` for rows left over when
/// there are more rows than columns).
pub fn solve(costs: &CostMatrix) -> Vec<Option<usize>> {
    if costs.rows == 0 || costs.cols == 0 {
        return vec![None; costs.rows];
    }
    if costs.rows > costs.cols {
        let col_to_row = solve_wide(&costs.transposed());
        let mut row_to_col = vec![None; costs.rows];
        for (c, r) in col_to_row.into_iter().enumerate() {
            row_to_col[r] = Some(c);
        }
        return row_to_col;
    }
    solve_wide(costs).into_iter().map(Some).collect()
}

/// rows ≤ cols: every row gets a column.
fn solve_wide(c: &CostMatrix) -> Vec<usize> {
    const NONE: usize = usize::MAX;
    let (nr, nc) = (c.rows, c.cols);
    let mut u = vec![0.0; nr];
    let mut v = vec![0.0; nc];
    let mut shortest = vec![f64::INFINITY; nc];
    let mut path = vec![NONE; nc];
    let mut col4row = vec![NONE; nr];
    let mut row4col = vec![NONE; nc];
    let mut visited_row = vec![false; nr];
    let mut visited_col = vec![false; nc];
    let mut remaining = vec![0usize; nc];

    for cur_row in 0..nr {
        // Dijkstra over reduced costs from `cur_row` until a free column is reached.
        let mut min_val = 0.0;
        let mut num_remaining = nc;
        for (k, r) in remaining.iter_mut().enumerate() {
            *r = nc - k - 1;
        }
        visited_row.fill(false);
        visited_col.fill(false);
        shortest.fill(f64::INFINITY);
        let mut i = cur_row;
        let sink = loop {
            visited_row[i] = true;
            let row = &c.costs[i * nc..(i + 1) * nc];
            let mut lowest = f64::INFINITY;
            let mut index = 0;
            for (k, &j) in remaining[..num_remaining].iter().enumerate() {
                let reduced = min_val + row[j] - u[i] - v[j];
                if reduced < shortest[j] {
                    path[j] = i;
                    shortest[j] = reduced;
                }
                if shortest[j] < lowest || (shortest[j] == lowest && row4col[j] == NONE) {
                    lowest = shortest[j];
                    index = k;
                }
            }
            min_val = lowest;
            let j = remaining[index];
            visited_col[j] = true;
            num_remaining -= 1;
            remaining[index] = remaining[num_remaining];
            if row4col[j] == NONE {
                break j;
            }
            i = row4col[j];
        };
        // Dual update.
        u[cur_row] += min_val;
        for r in 0..nr {
            if visited_row[r] && r != cur_row {
                u[r] += min_val - shortest[col4row[r]];
            }
        }
        for j in 0..nc {
            if visited_col[j] {
                v[j] -= min_val - shortest[j];
            }
        }
        // Augment along the path back to `cur_row`.
        let mut j = sink;
        loop {
            let r = path[j];
            row4col[j] = r;
            std::mem::swap(&mut col4row[r], &mut j);
            if r == cur_row {
                break;
            }
        }
    }
    col4row
}

/// Total cost of an assignment.
pub fn assignment_cost(costs: &CostMatrix, row_to_col: &[Option<usize>]) -> f64 {
    row_to_col.iter().enumerate().filter_map(|(r, c)| c.map(|c| costs.get(r, c))).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Minimum over all injective maps from the smaller side, by enumeration.
    fn brute_force(c: &CostMatrix) -> f64 {
        fn rec(c: &CostMatrix, row: usize, used: &mut Vec<bool>, transposed: bool) -> f64 {
            let (rows, cols) = if transposed { (c.cols, c.rows) } else { (c.rows, c.cols) };
            if row == rows {
                return 0.0;
            }
            let mut best = f64::INFINITY;
            for col in 0..cols {
                if !used[col] {
                    used[col] = true;
                    let cost = if transposed { c.get(col, row) } else { c.get(row, col) };
                    best = best.min(cost + rec(c, row + 1, used, transposed));
                    used[col] = false;
                }
            }
            best
        }
        let transposed = c.rows > c.cols;
        let n = if transposed { c.rows } else { c.cols };
        rec(c, 0, &mut vec![false; n], transposed)
    }

    proptest! {
        #[test]
        fn matches_brute_force_on_random_rectangular_matrices(
            rows in 1usize..7, cols in 1usize..7, seed in prop::collection::vec(-100.0f64..100.0, 49),
        ) {
            let costs = CostMatrix::new(rows, cols, seed[..rows * cols].to_vec()).unwrap();
            let assignment = solve(&costs);
            prop_assert_eq!(assignment.iter().filter(|c| c.is_some()).count(), rows.min(cols));
            let mut seen = vec![false; cols];
            for c in assignment.iter().flatten() {
                prop_assert!(!seen[*c]);
                seen[*c] = true;
            }
            let got = assignment_cost(&costs, &assignment);
            let want = brute_force(&costs);
            prop_assert!((got - want).abs() < 1e-9, "got {got}, want {want}");
        }

        #[test]
        fn handles_ties_and_integer_costs(rows in 1usize..6, cols in 1usize..6, seed in prop::collection::vec(0u8..3, 36)) {
            let costs = CostMatrix::new(rows, cols, seed[..rows * cols].iter().map(|&v| v as f64).collect()).unwrap();
            let got = assignment_cost(&costs, &solve(&costs));
            prop_assert!((got - brute_force(&costs)).abs() < 1e-9);
        }
    }

    #[test]
    fn known_case_and_degenerate_shapes() {
        let c = CostMatrix::new(3, 3, vec![4.0, 1.0, 3.0, 2.0, 0.0, 5.0, 3.0, 2.0, 2.0]).unwrap();
        assert_eq!(solve(&c), vec![Some(1), Some(0), Some(2)]);
        assert_eq!(solve(&CostMatrix::filled(0, 4, 0.0)), Vec::<Option<usize>>::new());
        assert_eq!(solve(&CostMatrix::filled(2, 0, 0.0)), vec![None, None]);
        assert!(matches!(CostMatrix::new(2, 2, vec![0.0; 3]), Err(LapError::Shape { .. })));
        assert_eq!(CostMatrix::new(1, 2, vec![0.0, f64::NAN]), Err(LapError::NonFinite { row: 0, col: 1 }));
    }
}
