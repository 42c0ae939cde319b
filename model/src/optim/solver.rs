//! Levenberg–Marquardt (and Gauss–Newton) on faer's sparse Cholesky.
//!
//! Each iteration linearises every factor (`factors`), assembles the normal equations
//! H = Σ Jᵀ J, g = Σ Jᵀ r over the free variables, and solves (H + λ I) δ = −g. H's sparsity
//! (upper triangle, D × D blocks) depends only on which variables the factors join, so the
//! symbolic factorisation (fill-reducing ordering, elimination tree) is computed once per
//! structure and reused for every λ and every iteration; each factor knows where its blocks'
//! values live. A step is kept when it lowers the error; λ is then divided by `lambda_factor`,
//! otherwise multiplied, as GTSAM's `LevenbergMarquardtOptimizer` with default parameters.
//! Stopping, also GTSAM's: the decrease of the error is below `absolute_error_tol` or below
//! `relative_error_tol` times the error, or `max_iterations` linearisations.

use super::graph::PoseGraph;
use super::manifold::Manifold;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, LltRef, SymbolicCholesky};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{get_global_parallelism, Conj, MatMut, Side};
use nalgebra::{SMatrix, SVector};

/// Solver parameters, GTSAM's defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct LmParams {
    pub max_iterations: usize,
    pub lambda_initial: f64,
    pub lambda_factor: f64,
    pub lambda_max: f64,
    pub relative_error_tol: f64,
    pub absolute_error_tol: f64,
    /// Gauss–Newton: λ = 0 and every step accepted.
    pub gauss_newton: bool,
}

impl Default for LmParams {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            lambda_initial: 1e-5,
            lambda_factor: 10.0,
            lambda_max: 1e10,
            relative_error_tol: 1e-5,
            absolute_error_tol: 1e-5,
            gauss_newton: false,
        }
    }
}

/// What an optimisation did.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    pub initial_error: f64,
    pub final_error: f64,
    /// Linearisations (GTSAM's `iterations()`).
    pub iterations: usize,
    pub converged: bool,
}

/// Why the solver could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("the graph has no free variable")]
    NothingToSolve,
    #[error("the normal equations are singular even with damping (is every variable anchored?)")]
    Singular,
    #[error("the initial values are not finite")]
    NonFinite,
    #[error("sparse factorisation failed: {0}")]
    Factorisation(String),
}

/// The numeric Cholesky factor L of a matrix on a [`Structure`]'s pattern, with the scratch to
/// compute it and solve with it: allocated once per optimisation, not per damped solve.
pub(crate) struct NumericFactor {
    pub(crate) values: Vec<f64>,
    scratch: MemBuffer,
}

/// Block sparsity of H and the symbolic factorisation for it: built once per graph shape and
/// shared by every damped solve of the optimisation and by the marginal covariances after it
/// (`cargo bench -p sgm-model --bench marginals`: 8.9 ms to build for sphere2500).
pub struct Structure<const D: usize> {
    /// What the structure was built from: variable count, fixed flags, joined block pairs.
    fingerprint: (usize, Vec<bool>, Vec<(usize, usize)>),
    /// Block column of each variable (`None`: fixed).
    pub(crate) block_of: Vec<Option<usize>>,
    blocks: usize,
    /// Per block column, the sorted block rows above the diagonal.
    upper: Vec<Vec<usize>>,
    col_ptr: Vec<usize>,
    symbolic_matrix: SymbolicSparseColMat<usize>,
    symbolic: SymbolicCholesky<usize>,
}

impl<const D: usize> Structure<D> {
    pub fn new<G: Manifold<D>>(graph: &PoseGraph<G, D>) -> Result<Self, SolveError> {
        let mut block_of = vec![None; graph.values.len()];
        let mut blocks = 0;
        for (k, fixed) in graph.fixed.iter().enumerate() {
            if !fixed {
                block_of[k] = Some(blocks);
                blocks += 1;
            }
        }
        if blocks == 0 {
            return Err(SolveError::NothingToSolve);
        }
        let mut upper = vec![Vec::new(); blocks];
        for f in &graph.betweens {
            if let (Some(a), Some(b)) = (block_of[f.from], block_of[f.to]) {
                if a != b {
                    upper[a.max(b)].push(a.min(b));
                }
            }
        }
        for list in &mut upper {
            list.sort_unstable();
            list.dedup();
        }
        let fingerprint = Self::fingerprint_of(graph);
        let n = blocks * D;
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0);
        for (bc, rows) in upper.iter().enumerate() {
            for kc in 0..D {
                for &br in rows {
                    row_idx.extend(br * D..br * D + D);
                }
                row_idx.extend(bc * D..=bc * D + kc);
                col_ptr.push(row_idx.len());
            }
        }
        let symbolic_matrix = SymbolicSparseColMat::new_checked(n, n, col_ptr.clone(), None, row_idx);
        let symbolic =
            factorize_symbolic_cholesky(symbolic_matrix.as_ref(), Side::Upper, Default::default(), Default::default())
                .map_err(|e| SolveError::Factorisation(format!("{e:?}")))?;
        Ok(Self { fingerprint, block_of, blocks, upper, col_ptr, symbolic_matrix, symbolic })
    }

    fn fingerprint_of<G: Manifold<D>>(graph: &PoseGraph<G, D>) -> (usize, Vec<bool>, Vec<(usize, usize)>) {
        let mut pairs: Vec<(usize, usize)> =
            graph.betweens.iter().map(|f| (f.from.min(f.to), f.from.max(f.to))).collect();
        pairs.sort_unstable();
        pairs.dedup();
        (graph.values.len(), graph.fixed.clone(), pairs)
    }

    /// The symbolic Cholesky factorisation of H's pattern (ordering, elimination tree, supernodes).
    pub(crate) fn symbolic(&self) -> &SymbolicCholesky<usize> {
        &self.symbolic
    }

    /// Room for a numeric factor on this pattern and the scratch to compute it and to solve
    /// with it, `width` right-hand sides at a time.
    pub(crate) fn numeric_factor(&self, width: usize) -> Result<NumericFactor, SolveError> {
        let par = get_global_parallelism();
        let scratch = StackReq::any_of(&[
            self.symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
            self.symbolic.solve_in_place_scratch::<f64>(width, par),
        ]);
        let scratch = MemBuffer::try_new(scratch).map_err(|e| SolveError::Factorisation(format!("{e:?}")))?;
        Ok(NumericFactor { values: vec![0.0; self.symbolic.len_val()], scratch })
    }

    /// Factors the matrix whose upper triangle on this pattern holds `upper` into `factor`, as
    /// faer's `Llt::try_new_with_symbolic` does; `Singular` unless positive definite.
    pub(crate) fn factorize(&self, upper: &[f64], factor: &mut NumericFactor) -> Result<(), SolveError> {
        factor.values.fill(0.0);
        let matrix = SparseColMatRef::new(self.symbolic_matrix.as_ref(), upper);
        self.symbolic
            .factorize_numeric_llt(
                &mut factor.values,
                matrix,
                Side::Upper,
                Default::default(),
                get_global_parallelism(),
                MemStack::new(&mut factor.scratch),
                Default::default(),
            )
            .map(|_| ())
            .map_err(|_| SolveError::Singular)
    }

    /// Solves L Lᵀ X = B in place (B at most the `width` columns `factor` was made for).
    pub(crate) fn solve_in_place(&self, factor: &mut NumericFactor, x: MatMut<'_, f64>) {
        LltRef::new(&self.symbolic, &factor.values).solve_in_place_with_conj(
            Conj::No,
            x,
            get_global_parallelism(),
            MemStack::new(&mut factor.scratch),
        );
    }

    /// Whether this structure still describes `graph` (same variables, fixed flags and joined
    /// pairs): then its symbolic factorisation can be reused.
    pub fn fits<G: Manifold<D>>(&self, graph: &PoseGraph<G, D>) -> bool {
        self.fingerprint == Self::fingerprint_of(graph)
    }

    pub(crate) fn dim(&self) -> usize {
        self.blocks * D
    }

    /// Adds `m` into block (row block `br`, column block `bc`), br ≤ bc.
    fn add_block(&self, values: &mut [f64], br: usize, bc: usize, m: &SMatrix<f64, D, D>) {
        if br == bc {
            let below = self.upper[bc].len() * D;
            for kc in 0..D {
                let base = self.col_ptr[bc * D + kc] + below;
                for kr in 0..=kc {
                    values[base + kr] += m[(kr, kc)];
                }
            }
        } else {
            let pos = self.upper[bc].binary_search(&br).unwrap_or(0) * D;
            for kc in 0..D {
                let base = self.col_ptr[bc * D + kc] + pos;
                for kr in 0..D {
                    values[base + kr] += m[(kr, kc)];
                }
            }
        }
    }
}

/// A robust kernel on between factors: for factor `k` with squared whitened residual `s`,
/// returns (ρ(s), w) — its cost and its iteratively-reweighted-least-squares weight ρ'(s)·2.
/// Least squares: (s / 2, 1).
pub type Kernel<'a> = &'a dyn Fn(usize, f64) -> (f64, f64);

/// Least squares.
pub fn least_squares(_: usize, s: f64) -> (f64, f64) {
    (0.5 * s, 1.0)
}

/// Σ ρ over between factors plus ½ ‖r‖² over priors.
pub fn cost_at<G: Manifold<D>, const D: usize>(graph: &PoseGraph<G, D>, values: &[G], kernel: Kernel) -> f64 {
    let between: f64 = graph
        .betweens
        .iter()
        .enumerate()
        .map(|(k, f)| kernel(k, f.whitened_error(&values[f.from], &values[f.to]).norm_squared()).0)
        .sum();
    let prior: f64 = graph.priors.iter().map(|p| 0.5 * p.whitened_error(&values[p.variable]).norm_squared()).sum();
    between + prior
}

/// H (upper values) and g at `values`, each between factor weighted by its kernel weight.
pub(crate) fn assemble<G: Manifold<D>, const D: usize>(
    graph: &PoseGraph<G, D>,
    values: &[G],
    s: &Structure<D>,
    kernel: Kernel,
    h: &mut Vec<f64>,
    g: &mut Vec<f64>,
) {
    h.clear();
    h.resize(s.col_ptr[s.dim()], 0.0);
    g.clear();
    g.resize(s.dim(), 0.0);
    let mut add_gradient = |block: usize, v: &SVector<f64, D>| {
        for k in 0..D {
            g[block * D + k] += v[k];
        }
    };
    for (k, f) in graph.betweens.iter().enumerate() {
        let mut lin = f.linearize(&values[f.from], &values[f.to]);
        let (_, w) = kernel(k, lin.residual.norm_squared());
        if w <= 0.0 {
            continue;
        }
        if w != 1.0 {
            // √w scales r and J, so Jᵀ J and Jᵀ r carry w.
            let root = w.sqrt();
            lin.residual *= root;
            lin.d_from *= root;
            lin.d_to *= root;
        }
        let (bi, bj) = (s.block_of[f.from], s.block_of[f.to]);
        if let Some(a) = bi {
            s.add_block(h, a, a, &(lin.d_from.transpose() * lin.d_from));
            add_gradient(a, &(lin.d_from.transpose() * lin.residual));
        }
        if let Some(b) = bj {
            s.add_block(h, b, b, &(lin.d_to.transpose() * lin.d_to));
            add_gradient(b, &(lin.d_to.transpose() * lin.residual));
        }
        if let (Some(a), Some(b)) = (bi, bj) {
            if a < b {
                s.add_block(h, a, b, &(lin.d_from.transpose() * lin.d_to));
            } else if b < a {
                s.add_block(h, b, a, &(lin.d_to.transpose() * lin.d_from));
            }
        }
    }
    for p in &graph.priors {
        if let Some(a) = s.block_of[p.variable] {
            let (r, j) = p.linearize(&values[p.variable]);
            s.add_block(h, a, a, &(j.transpose() * j));
            add_gradient(a, &(j.transpose() * r));
        }
    }
}

/// Solves (H + λ I) δ = −g; `None` if not positive definite. `damped` and `factor` are
/// reused from one call to the next.
pub(crate) fn solve_damped<const D: usize>(
    s: &Structure<D>,
    h: &[f64],
    g: &[f64],
    lambda: f64,
    damped: &mut Vec<f64>,
    factor: &mut NumericFactor,
) -> Option<Vec<f64>> {
    damped.clear();
    damped.extend_from_slice(h);
    if lambda > 0.0 {
        for c in 0..s.dim() {
            damped[s.col_ptr[c + 1] - 1] += lambda;
        }
    }
    s.factorize(damped, factor).ok()?;
    let mut rhs: Vec<f64> = g.iter().map(|v| -v).collect();
    s.solve_in_place(factor, MatMut::from_column_major_slice_mut(&mut rhs, s.dim(), 1));
    rhs.iter().all(|v| v.is_finite()).then_some(rhs)
}

fn retract_all<G: Manifold<D>, const D: usize>(values: &[G], s: &Structure<D>, delta: &[f64]) -> Vec<G> {
    values
        .iter()
        .enumerate()
        .map(|(k, v)| match s.block_of[k] {
            Some(b) => v.retract(&SVector::<f64, D>::from_column_slice(&delta[b * D..b * D + D])),
            None => *v,
        })
        .collect()
}

/// Optimises `graph.values` in place by least squares.
pub fn optimize<G: Manifold<D>, const D: usize>(
    graph: &mut PoseGraph<G, D>,
    params: &LmParams,
) -> Result<Summary, SolveError> {
    let structure = Structure::new(graph)?;
    optimize_with(graph, params, &structure, &least_squares)
}

/// Optimises `graph.values` in place under a robust kernel, reusing a symbolic `structure`
/// (which must have been built for this graph's factors).
pub fn optimize_with<G: Manifold<D>, const D: usize>(
    graph: &mut PoseGraph<G, D>,
    params: &LmParams,
    structure: &Structure<D>,
    kernel: Kernel,
) -> Result<Summary, SolveError> {
    if graph.values.iter().any(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite);
    }
    let initial_error = cost_at(graph, &graph.values, kernel);
    let mut error = initial_error;
    let mut lambda = if params.gauss_newton { 0.0 } else { params.lambda_initial };
    let (mut h, mut g, mut damped) = (Vec::new(), Vec::new(), Vec::new());
    let mut factor = structure.numeric_factor(1)?;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < params.max_iterations {
        iterations += 1;
        assemble(graph, &graph.values, structure, kernel, &mut h, &mut g);
        // Inner loop: raise λ until a step lowers the error.
        let accepted = loop {
            let Some(delta) = solve_damped(structure, &h, &g, lambda, &mut damped, &mut factor) else {
                if params.gauss_newton || lambda >= params.lambda_max {
                    return Err(SolveError::Singular);
                }
                lambda = (lambda * params.lambda_factor).max(1e-12);
                continue;
            };
            let candidate = retract_all(&graph.values, structure, &delta);
            let new_error = cost_at(graph, &candidate, kernel);
            if params.gauss_newton || new_error < error {
                if !params.gauss_newton {
                    lambda /= params.lambda_factor;
                }
                break Some((candidate, new_error));
            }
            if lambda >= params.lambda_max {
                break None;
            }
            lambda = (lambda * params.lambda_factor).max(1e-12);
        };
        let Some((candidate, new_error)) = accepted else {
            converged = true; // no step lowers the error: at a minimum to machine precision
            break;
        };
        graph.values = candidate;
        let decrease = error - new_error;
        error = new_error;
        if decrease.abs() < params.absolute_error_tol || decrease.abs() < params.relative_error_tol * error.abs() {
            converged = true;
            break;
        }
    }
    Ok(Summary { initial_error, final_error: error, iterations, converged })
}

/// Repeated optimisation of a growing graph (robots optimise again and again as keyframes and
/// factors arrive): values are warm-started from the graph, and the symbolic factorisation is
/// kept while the structure is unchanged (new measurements between already-joined variables,
/// new priors), rebuilt otherwise.
#[derive(Default)]
pub struct Optimizer<const D: usize> {
    structure: Option<Structure<D>>,
    /// How many solves reused / rebuilt the symbolic factorisation.
    pub symbolic_reuses: usize,
    pub symbolic_builds: usize,
}

impl<const D: usize> Optimizer<D> {
    pub fn new() -> Self {
        Self { structure: None, symbolic_reuses: 0, symbolic_builds: 0 }
    }

    /// The structure for `graph`, reusing the cached one when it still fits.
    pub fn structure_for<G: Manifold<D>>(&mut self, graph: &PoseGraph<G, D>) -> Result<&Structure<D>, SolveError> {
        let fits = self.structure.as_ref().is_some_and(|s| s.fits(graph));
        if fits {
            self.symbolic_reuses += 1;
        } else {
            self.structure = Some(Structure::new(graph)?);
            self.symbolic_builds += 1;
        }
        self.structure.as_ref().ok_or(SolveError::NothingToSolve)
    }

    pub fn optimize<G: Manifold<D>>(
        &mut self,
        graph: &mut PoseGraph<G, D>,
        params: &LmParams,
    ) -> Result<Summary, SolveError> {
        let structure = self.structure_for(graph)?;
        optimize_with(graph, params, structure, &least_squares)
    }
}
