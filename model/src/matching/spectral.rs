//! Spectral relaxation of the QAP (paper eq. 8, Leordeanu & Hebert 2005): with a ∈ [0, 1], the
//! maximiser of vec(A)ᵀ U vec(A) / ‖vec(A)‖² is the principal eigenvector of U, positive because
//! U is non-negative (Perron–Frobenius).
//!
//! Small U: power iteration. Large U: restarted Lanczos: from the uniform vector, K = `KRYLOV` steps build an orthonormal
//! basis V of the Krylov space (re-orthogonalised against all previous vectors) and the tridiagonal T = Vᵀ U V; the top
//! eigenpair (θ, s) of T gives the Ritz vector x = V s with residual ‖U x − θ x‖ = |β_K s_K|.
//! Stop when that residual is below `tolerance` · θ; otherwise restart from x. Large graphs have
//! a small spectral gap (separate spatial clusters), where plain power iteration needs hundreds
//! of products; Lanczos needs a few dozen.

use super::affinity::SparseAffinity;
use nalgebra::DMatrix;

/// Krylov steps per restart.
const KRYLOV: usize = 32;
/// Below this dimension power iteration is cheaper (the gap is large and it needs no basis).
const LANCZOS_FROM_DIM: usize = 1024;

/// Principal eigenvector of U: power iteration for small U, restarted Lanczos for large.
/// `max_iterations` bounds the matrix–vector products; `tolerance` is relative.
pub fn principal_eigenvector(u: &SparseAffinity, tolerance: f64, max_iterations: usize) -> Eigen {
    if u.dim() < LANCZOS_FROM_DIM {
        power_iteration(u, tolerance, max_iterations)
    } else {
        lanczos(u, tolerance, max_iterations)
    }
}

/// The principal eigenvector and how the iteration went.
#[derive(Clone, Debug, PartialEq)]
pub struct Eigen {
    pub vector: Vec<f64>,
    pub eigenvalue: f64,
    /// Matrix–vector products used.
    pub iterations: usize,
    pub converged: bool,
}

/// w ← w − Σ_k c_k v_k, each entry updated in the order k = 0, 1, … (the bits of one pass per
/// v_k), a block of w at a time so that it stays in cache while every v_k streams past.
fn subtract_combination(w: &mut [f64], basis: &[Vec<f64>], coefficients: &[f64]) {
    const BLOCK: usize = 512;
    for (b, block) in w.chunks_mut(BLOCK).enumerate() {
        let range = b * BLOCK..b * BLOCK + block.len();
        for (v, &c) in basis.iter().zip(coefficients) {
            block.iter_mut().zip(&v[range.clone()]).for_each(|(wi, vi)| *wi -= c * vi);
        }
    }
}

/// [dot(w, v) for v in basis], four at a time: each coefficient is summed in index order as
/// [`dot`] sums it (the same bits), but four independent sums share one pass over `w`, so the
/// adds no longer wait on one another.
fn dots(w: &[f64], basis: &[Vec<f64>]) -> Vec<f64> {
    let mut out = Vec::with_capacity(basis.len());
    let mut quads = basis.chunks_exact(4);
    for quad in quads.by_ref() {
        let (v0, v1, v2, v3) = (&quad[0][..w.len()], &quad[1][..w.len()], &quad[2][..w.len()], &quad[3][..w.len()]);
        let mut acc = [0.0f64; 4];
        for i in 0..w.len() {
            acc[0] += w[i] * v0[i];
            acc[1] += w[i] * v1[i];
            acc[2] += w[i] * v2[i];
            acc[3] += w[i] * v3[i];
        }
        out.extend(acc);
    }
    out.extend(quads.remainder().iter().map(|v| dot(w, v)));
    out
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Restarted Lanczos; `max_iterations` bounds the matrix–vector products.
fn lanczos(u: &SparseAffinity, tolerance: f64, max_iterations: usize) -> Eigen {
    let n = u.dim();
    if n == 0 {
        return Eigen { vector: Vec::new(), eigenvalue: 0.0, iterations: 0, converged: true };
    }
    let mut x = vec![1.0 / (n as f64).sqrt(); n];
    let (mut products, mut eigenvalue) = (0usize, 0.0);
    while products < max_iterations {
        let steps = KRYLOV.min(n).min(max_iterations - products);
        let mut basis: Vec<Vec<f64>> = vec![x.clone()];
        let (mut alphas, mut betas) = (Vec::with_capacity(steps), Vec::with_capacity(steps));
        let mut w = vec![0.0; n];
        let mut last_beta = 0.0;
        for j in 0..steps {
            u.multiply(&basis[j], &mut w);
            products += 1;
            let alpha = dot(&w, &basis[j]);
            alphas.push(alpha);
            // Full re-orthogonalisation, one classical Gram–Schmidt pass (enough for the top
            // eigenpair; the residual test below catches a loss of accuracy).
            let coefficients = dots(&w, &basis);
            subtract_combination(&mut w, &basis, &coefficients);
            let beta = dot(&w, &w).sqrt();
            last_beta = beta;
            if !beta.is_finite() || beta <= 1e-13 * alpha.abs().max(1e-300) || j + 1 == steps {
                break;
            }
            betas.push(beta);
            basis.push(w.iter().map(|v| v / beta).collect());
        }
        let m = alphas.len();
        let mut t = DMatrix::zeros(m, m);
        for k in 0..m {
            t[(k, k)] = alphas[k];
            if k + 1 < m {
                t[(k, k + 1)] = betas[k];
                t[(k + 1, k)] = betas[k];
            }
        }
        let eig = t.symmetric_eigen();
        let Some((top, &theta)) = eig.eigenvalues.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) else {
            break;
        };
        let s = eig.eigenvectors.column(top);
        let mut ritz = vec![0.0; n];
        let weights: Vec<f64> = (0..m).map(|k| -s[k]).collect();
        subtract_combination(&mut ritz, &basis[..m], &weights);
        let norm = dot(&ritz, &ritz).sqrt();
        if !norm.is_finite() || norm <= 0.0 || !theta.is_finite() {
            return Eigen { vector: x, eigenvalue, iterations: products, converged: false };
        }
        let sign = if ritz.iter().sum::<f64>() < 0.0 { -1.0 } else { 1.0 };
        ritz.iter_mut().for_each(|r| *r *= sign / norm);
        x = ritz;
        eigenvalue = theta;
        let residual = (last_beta * s[m - 1]).abs();
        if residual <= tolerance * theta.abs() {
            return Eigen { vector: x, eigenvalue, iterations: products, converged: true };
        }
    }
    Eigen { vector: x, eigenvalue, iterations: products, converged: false }
}

/// Power iteration x ← U x / ‖U x‖ from the uniform vector until no entry changes by more than
/// `tolerance` × the largest entry.
fn power_iteration(u: &SparseAffinity, tolerance: f64, max_iterations: usize) -> Eigen {
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

    #[test]
    fn four_dots_at_a_time_give_the_bits_of_one_at_a_time() {
        let w: Vec<f64> = (0..1000).map(|i| ((i * 7919) % 1013) as f64 / 97.0 - 5.0).collect();
        let basis: Vec<Vec<f64>> =
            (0..11).map(|k| (0..1000).map(|i| (((i + 31 * k) * 104_729) % 1009) as f64 / 1e3).collect()).collect();
        let one_at_a_time: Vec<u64> = basis.iter().map(|v| dot(&w, v).to_bits()).collect();
        assert_eq!(dots(&w, &basis).iter().map(|c| c.to_bits()).collect::<Vec<_>>(), one_at_a_time);
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
            for got in [power_iteration(&sparse_from_dense(&m), 1e-12, 100_000), lanczos(&sparse_from_dense(&m), 1e-12, 100_000)] {
                prop_assert!(got.converged);
                prop_assert!((got.eigenvalue - lambda).abs() < 1e-8 * lambda.max(1.0));
                for (a, b) in got.vector.iter().zip(&reference) {
                    prop_assert!((a - b).abs() < 1e-6, "{a} vs {b}");
                }
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
        // Capped products report non-convergence; enough of them converge exactly.
        let m = DMatrix::from_row_slice(3, 3, &[1.0, 0.9, 0.0, 0.9, 1.0, 0.5, 0.0, 0.5, 1.0]);
        let e = lanczos(&sparse_from_dense(&m), 1e-12, 1);
        assert!(!e.converged && e.iterations == 1);
        let e = lanczos(&sparse_from_dense(&m), 1e-12, 10);
        assert!(e.converged && e.iterations <= 4, "{e:?}");
        let e = power_iteration(&sparse_from_dense(&m), 1e-15, 2);
        assert!(!e.converged && e.iterations == 2);
    }
}
