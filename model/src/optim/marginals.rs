//! Marginal covariances of selected poses, from the sparse Cholesky factorisation of the
//! information matrix H = Jᵀ J at the current estimate (Gauss–Newton approximation, as GTSAM's
//! `Marginals`): the covariance of pose k is the k-th diagonal D × D block of H⁻¹, obtained by
//! solving H X = E_k for the D unit columns E_k of that block — a pair of sparse triangular
//! solves per column, the columns of 32 poses at once, never a dense inverse. Covariances are in
//! the tangent space of the pose's right perturbation (x ⊕ δ = x · Exp(δ)), the chart of the
//! factors. Sent with keyframe responses.

use super::graph::PoseGraph;
use super::manifold::Manifold;
use super::solver::{assemble, least_squares, Kernel, SolveError, Structure};
use faer::linalg::solvers::SolveCore;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::SparseColMatRef;
use faer::{Conj, MatMut, Side};
use nalgebra::SMatrix;

/// Variables whose columns are solved for in one pass over the factor. Six columns at a time
/// leave the supernodes' dense kernels mostly idle; 32 variables (192 columns) keep the buffer
/// at n × 192 values (37 MB for 4 000 poses) and are measured by `cargo bench -p sgm-model
/// --bench marginals`.
const SOLVED_TOGETHER: usize = 32;

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
    let matrix = SparseColMatRef::new(structure.symbolic_matrix().as_ref(), &h);
    let llt = Llt::try_new_with_symbolic(structure.symbolic_llt().clone(), matrix, Side::Upper)
        .map_err(|_| SolveError::Singular)?;
    let n = g.len();
    let mut out = vec![SMatrix::zeros(); variables.len()];
    // (output slot, block) of each free variable; a fixed one keeps its zero covariance.
    let free: Vec<(usize, usize)> = variables
        .iter()
        .enumerate()
        .filter_map(|(i, &v)| structure.block_of.get(v).copied().flatten().map(|block| (i, block)))
        .collect();
    let mut rhs = Vec::new();
    for chunk in free.chunks(SOLVED_TOGETHER) {
        // D right-hand sides per variable, the unit columns of its block, all in one solve.
        let width = chunk.len() * D;
        rhs.clear();
        rhs.resize(n * width, 0.0);
        for (j, &(_, block)) in chunk.iter().enumerate() {
            for k in 0..D {
                rhs[(j * D + k) * n + block * D + k] = 1.0;
            }
        }
        llt.solve_in_place_with_conj(Conj::No, MatMut::from_column_major_slice_mut(&mut rhs, n, width));
        for (j, &(i, block)) in chunk.iter().enumerate() {
            out[i] = SMatrix::<f64, D, D>::from_fn(|r, c| rhs[(j * D + c) * n + block * D + r]);
        }
    }
    Ok(out)
}
