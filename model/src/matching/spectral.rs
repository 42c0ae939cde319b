//! Spectral relaxation of the QAP (paper eq. 8, Leordeanu & Hebert 2005): with a ∈ [0, 1], the
//! maximiser of vec(A)ᵀ U vec(A) / ‖vec(A)‖² is the principal eigenvector of U, positive because
//! U is non-negative (Perron–Frobenius). Found by power iteration x ← U x / ‖U x‖ from the uniform
//! vector until max_k |x_k − x_k^prev| < tolerance · max_k x_k.

use super::affinity::SparseAffinity;

/// The principal eigenvector and how the iteration went.
#[derive(Clone, Debug)]
pub struct Eigen {
    pub vector: Vec<f64>,
    pub eigenvalue: f64,
    pub iterations: usize,
    pub converged: bool,
}

pub fn principal_eigenvector(u: &SparseAffinity, tolerance: f64, max_iterations: usize) -> Eigen {
    let n = u.dim();
    if n == 0 {
        return Eigen { vector: Vec::new(), eigenvalue: 0.0, iterations: 0, converged: true };
    }
    let mut x = vec![1.0 / (n as f64).sqrt(); n];
    let mut y = vec![0.0; n];
    let mut eigenvalue = 0.0;
    for iteration in 1..=max_iterations {
        u.multiply(&x, &mut y);
        let norm = y.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !norm.is_finite() || norm <= 0.0 {
            return Eigen { vector: x, eigenvalue: 0.0, iterations: iteration, converged: false };
        }
        eigenvalue = norm;
        let (mut change, mut largest): (f64, f64) = (0.0, 0.0);
        for (xi, yi) in x.iter_mut().zip(&y) {
            let next = yi / norm;
            change = change.max((next - *xi).abs());
            largest = largest.max(next);
            *xi = next;
        }
        if change < tolerance * largest {
            return Eigen { vector: x, eigenvalue, iterations: iteration, converged: true };
        }
    }
    Eigen { vector: x, eigenvalue, iterations: max_iterations, converged: false }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use proptest::prelude::*;

    fn sparse_from_dense(m: &DMatrix<f64>) -> SparseAffinity {
        let mut s = SparseAffinity { row_start: vec![0], ..Default::default() };
        for r in 0..m.nrows() {
            for c in 0..m.ncols() {
                if m[(r, c)] != 0.0 {
                    s.cols.push(c as u32);
                    s.values.push(m[(r, c)]);
                }
            }
            s.row_start.push(s.cols.len());
        }
        s
    }

    proptest! {
        /// Against nalgebra's dense symmetric eigendecomposition on random non-negative
        /// symmetric matrices with a positive diagonal (the structure of U).
        #[test]
        fn agrees_with_dense_symmetric_eigen(n in 2usize..12, entries in prop::collection::vec(0.0f64..1.0, 144)) {
            let mut m = DMatrix::zeros(n, n);
            for r in 0..n {
                for c in r..n {
                    let v = if r == c { 1.0 } else { entries[r * 12 + c] };
                    m[(r, c)] = v;
                    m[(c, r)] = v;
                }
            }
            let dense = m.clone().symmetric_eigen();
            let (k, &lambda) = dense.eigenvalues.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).unwrap();
            let mut second = dense.eigenvalues.iter().copied().filter(|v| *v != lambda).fold(f64::MIN, f64::max);
            second = second.max(-dense.eigenvalues.min());
            prop_assume!(lambda - second > 0.05 * lambda); // a spectral gap makes the answer unique
            let mut reference: Vec<f64> = dense.eigenvectors.column(k).iter().copied().collect();
            if reference.iter().sum::<f64>() < 0.0 {
                reference.iter_mut().for_each(|v| *v = -*v);
            }
            let got = principal_eigenvector(&sparse_from_dense(&m), 1e-12, 100_000);
            prop_assert!(got.converged);
            prop_assert!((got.eigenvalue - lambda).abs() < 1e-8 * lambda.max(1.0));
            for (a, b) in got.vector.iter().zip(&reference) {
                prop_assert!((a - b).abs() < 1e-6, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn empty_and_nonconvergent() {
        let e = principal_eigenvector(&SparseAffinity { row_start: vec![0], ..Default::default() }, 1e-9, 10);
        assert!(e.converged && e.vector.is_empty());
        // Two equal blocks with no coupling and equal eigenvalues: still converges from uniform.
        let m = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 1.0]);
        let e = principal_eigenvector(&sparse_from_dense(&m), 1e-12, 10);
        assert!(e.converged && (e.vector[0] - e.vector[1]).abs() < 1e-12);
        // Capped iterations report non-convergence.
        let m = DMatrix::from_row_slice(3, 3, &[1.0, 0.9, 0.0, 0.9, 1.0, 0.5, 0.0, 0.5, 1.0]);
        let e = principal_eigenvector(&sparse_from_dense(&m), 1e-15, 2);
        assert!(!e.converged && e.iterations == 2);
    }
}
