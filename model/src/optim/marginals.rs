//! Marginal covariances of selected poses, from the sparse Cholesky factorisation of the
//! information matrix H = Jᵀ J at the current estimate (Gauss–Newton approximation, as GTSAM's
//! `Marginals`): the covariance of pose k is the k-th diagonal D × D block of H⁻¹, never a
//! dense inverse. With the factor P H Pᵀ = L Lᵀ (P the fill-reducing permutation),
//!
//! ```text
//! E_kᵀ H⁻¹ E_k = (L⁻¹ P E_k)ᵀ (L⁻¹ P E_k) = Y_kᵀ Y_k,
//! ```
//!
//! so one forward solve L Y_k = P E_k per block (its D unit columns; the columns of 32 poses
//! at once) and a D × D Gram product give it: half the triangular solves of solving
//! H X = E_k. A simplicial factor (tiny graphs) solves H X = E_k in full. Covariances are in
//! the tangent space of the pose's right perturbation (x ⊕ δ = x · Exp(δ)), the chart of the
//! factors. Sent with keyframe responses.

use super::graph::PoseGraph;
use super::manifold::Manifold;
use super::solver::{assemble, least_squares, Kernel, SolveError, Structure};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
use faer::{get_global_parallelism, Accum, MatMut, MatRef};
use nalgebra::SMatrix;

/// Variables whose columns are solved for in one pass over the factor. Fewer columns in flight
/// leave more supernodes all zero, which [`forward_solve_sparse`] skips; more keep the dense
/// kernels busy. `cargo bench -p sgm-model --bench marginals` (sphere2500, newest 200): 4
/// variables (24 columns) 107 ms, 1: 117 ms, 8: 125 ms, 16: 169 ms, 32: 224 ms. The buffer is
/// n × 24 values (2.3 MB for 2 000 poses).
const SOLVED_TOGETHER: usize = 4;

/// Covariances of `variables` (indices into `graph.values`); a fixed variable has zero
/// covariance. `structure` must fit `graph` (see [`Structure::fits`]).
pub fn marginal_covariances<G: Manifold<D>, const D: usize>(
    graph: &PoseGraph<G, D>,
    structure: &Structure<D>,
    variables: &[usize],
) -> Result<Vec<SMatrix<f64, D, D>>, SolveError> {
    marginal_covariances_with(graph, structure, variables, &least_squares)
}

/// As [`marginal_covariances`], each between factor's information scaled by its kernel weight
/// (a factor that robust estimation rejected, weight 0, adds none).
pub fn marginal_covariances_with<G: Manifold<D>, const D: usize>(
    graph: &PoseGraph<G, D>,
    structure: &Structure<D>,
    variables: &[usize],
    kernel: Kernel,
) -> Result<Vec<SMatrix<f64, D, D>>, SolveError> {
    let (mut h, mut g) = (Vec::new(), Vec::new());
    assemble(graph, &graph.values, structure, kernel, &mut h, &mut g);
    let n = g.len();
    let symbolic = structure.symbolic();
    let par = get_global_parallelism();
    let mut factor = structure.numeric_factor(SOLVED_TOGETHER.min(variables.len().max(1)) * D)?;
    structure.factorize(&h, &mut factor)?;
    // Row of P E_k's unit entry for unknown i: P moves row fwd[r] of H to row r.
    let permuted = |i: usize| symbolic.perm().map_or(i, |p| p.arrays().1[i]);

    let mut out = vec![SMatrix::zeros(); variables.len()];
    // (output slot, block) of each free variable; a fixed one keeps its zero covariance.
    let free: Vec<(usize, usize)> = variables
        .iter()
        .enumerate()
        .filter_map(|(i, &v)| structure.block_of.get(v).copied().flatten().map(|block| (i, block)))
        .collect();
    let mut rhs = Vec::new();
    let mut below = Vec::new();
    for chunk in free.chunks(SOLVED_TOGETHER) {
        // D right-hand sides per variable, the unit columns of its block, all in one solve.
        let width = chunk.len() * D;
        rhs.clear();
        rhs.resize(n * width, 0.0);
        match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(supernodal) => {
                for (j, &(_, block)) in chunk.iter().enumerate() {
                    for k in 0..D {
                        rhs[(j * D + k) * n + permuted(block * D + k)] = 1.0;
                    }
                }
                let factor = SupernodalLltRef::new(supernodal, &factor.values);
                forward_solve_sparse(factor, MatMut::from_column_major_slice_mut(&mut rhs, n, width), &mut below, par);
                for (j, &(i, _)) in chunk.iter().enumerate() {
                    // Σ = Yᵀ Y over the block's D columns of Y (one blocked pass over them).
                    let y = MatRef::from_column_major_slice(&rhs[j * D * n..(j + 1) * D * n], n, D);
                    let gram = y.transpose() * y;
                    out[i] = SMatrix::<f64, D, D>::from_fn(|r, c| gram[(r, c)]);
                }
            }
            SymbolicCholeskyRaw::Simplicial(_) => {
                for (j, &(_, block)) in chunk.iter().enumerate() {
                    for k in 0..D {
                        rhs[(j * D + k) * n + block * D + k] = 1.0;
                    }
                }
                let x = MatMut::from_column_major_slice_mut(&mut rhs, n, width);
                structure.solve_in_place(&mut factor, x);
                for (j, &(i, block)) in chunk.iter().enumerate() {
                    out[i] = SMatrix::<f64, D, D>::from_fn(|r, c| rhs[(j * D + c) * n + block * D + r]);
                }
            }
        }
    }
    Ok(out)
}

/// Solves L Y = B in place for the supernodal factor L, skipping every supernode whose rows of
/// Y are still zero there: with unit right-hand sides only the supernodes on the paths from
/// their rows to the root of the elimination tree are touched. Otherwise as faer's
/// `l_solve_with_conj`: per supernode, its diagonal block solves its rows, and the rows below
/// (its pattern) take away L_below · Y_rows. `below` is scratch.
fn forward_solve_sparse(
    factor: SupernodalLltRef<'_, usize, f64>,
    mut y: MatMut<'_, f64>,
    below: &mut Vec<f64>,
    par: faer::Par,
) {
    let width = y.ncols();
    for s in 0..factor.symbolic().n_supernodes() {
        let supernode = factor.supernode(s);
        let l = supernode.val();
        let size = l.ncols();
        let (l_top, l_bottom) = l.split_at_row(size);
        let start = supernode.start();
        let mut rows = y.as_mut().subrows_mut(start, size);
        if (0..width).all(|j| rows.as_ref().col(j).iter().all(|v| *v == 0.0)) {
            continue;
        }
        solve_lower_triangular_in_place(l_top, rows.as_mut(), par);
        let pattern = supernode.pattern();
        below.clear();
        below.resize(pattern.len() * width, 0.0);
        let mut product = MatMut::from_column_major_slice_mut(below, pattern.len(), width);
        matmul(product.as_mut(), Accum::Replace, l_bottom, rows.as_ref(), 1.0, par);
        for j in 0..width {
            for (k, &i) in pattern.iter().enumerate() {
                y[(i, j)] -= product[(k, j)];
            }
        }
    }
}
