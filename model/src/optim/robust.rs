//! Robust estimation against wrong loop closures and wrong inter-robot factors.
//!
//! * Huber: ρ(s) = s/2 for e = √s ≤ k, else k e − k²/2; weight 1 or k/e.
//! * Cauchy: ρ(s) = k²/2 · ln(1 + s/k²); weight 1/(1 + s/k²).
//! * GNC-TLS (Yang, Antonante, Tzoumas, Carlone, *Graduated Non-Convexity for Robust Spatial
//!   Perception*, RA-L 2020): truncated least squares ρ(s) = min(s, c̄²)/2, reached through the
//!   surrogate family ρ_μ, convex for small μ and TLS as μ → ∞. With weights fixed, solve the
//!   weighted least squares; then update each candidate's weight in closed form —
//!   w = 1 if s ≤ μ/(μ+1) c̄², 0 if s ≥ (μ+1)/μ c̄², else c̄ √(μ(μ+1)) / √s − μ — and raise
//!   μ ← 1.4 μ, until the weights are binary. μ₀ = c̄² / (2 max s − c̄²) with s at the initial
//!   values, and every weighted solve restarts from the initial values (as GTSAM's
//!   `GncOptimizer`): an early estimate distorted by outliers cannot trap the later ones.
//!   Candidates are the loop-closure edges (keys not consecutive); odometry and priors are
//!   trusted. Rejected: final weight < ½. The reported final error is the least-squares error
//!   of the factors kept; the initial one, of all factors.
//!
//! Default scales are the 99% χ² quantile of the factor's dimension: a correct factor's
//! squared whitened residual is χ²_D distributed.

use super::graph::PoseGraph;
use super::manifold::Manifold;
use super::solver::{cost_at, optimize_with, LmParams, SolveError, Structure, Summary};

/// The kernel of `sgm optimize --robust`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum RobustKernel {
    #[default]
    None,
    Huber,
    Cauchy,
    Gnc,
}

/// 99% quantile of χ² with D degrees of freedom (D = 3, 6).
pub fn chi2_99(d: usize) -> f64 {
    match d {
        1 => 6.635,
        2 => 9.210,
        3 => 11.345,
        6 => 16.812,
        _ => d as f64 + 2.33 * (2.0 * d as f64).sqrt(),
    }
}

/// Largest number of graduated steps of GNC.
const GNC_MAX_STEPS: usize = 200;
/// μ growth per GNC step (the paper's 1.4).
const GNC_MU_GROWTH: f64 = 1.4;

/// Whether a between factor is a loop closure (its keys are not consecutive), i.e. a GNC
/// candidate.
fn is_loop_closure<G: Manifold<D>, const D: usize>(graph: &PoseGraph<G, D>, k: usize) -> bool {
    let f = &graph.betweens[k];
    graph.keys[f.from].abs_diff(graph.keys[f.to]) != 1
}

/// Optimises under `kernel`; returns the summary and, for GNC, the rejected between factors
/// (indices into `graph.betweens`, i.e. edge order in the file).
pub fn optimize_robust<G: Manifold<D>, const D: usize>(
    graph: &mut PoseGraph<G, D>,
    params: &LmParams,
    kernel: RobustKernel,
) -> Result<(Summary, Vec<usize>), SolveError> {
    let structure = Structure::new(graph)?;
    let k2 = chi2_99(D);
    let k = k2.sqrt();
    match kernel {
        RobustKernel::None => {
            Ok((optimize_with(graph, params, &structure, &super::solver::least_squares)?, Vec::new()))
        }
        RobustKernel::Huber => {
            let huber = move |_: usize, s: f64| {
                let e = s.sqrt();
                if e <= k {
                    (0.5 * s, 1.0)
                } else {
                    (k * e - 0.5 * k2, k / e)
                }
            };
            Ok((optimize_with(graph, params, &structure, &huber)?, Vec::new()))
        }
        RobustKernel::Cauchy => {
            let cauchy = move |_: usize, s: f64| (0.5 * k2 * (s / k2).ln_1p(), 1.0 / (1.0 + s / k2));
            Ok((optimize_with(graph, params, &structure, &cauchy)?, Vec::new()))
        }
        RobustKernel::Gnc => {
            let candidates: Vec<bool> = (0..graph.betweens.len()).map(|k| is_loop_closure(graph, k)).collect();
            gnc_tls(graph, params, &structure, k2, &candidates)
        }
    }
}

/// Binary TLS weights of `factors` between factors: 0 for the `rejected` (indices beyond the
/// graph are ignored), 1 for the rest.
pub fn rejection_weights(factors: usize, rejected: &[usize]) -> Vec<f64> {
    let mut weights = vec![1.0; factors];
    for &k in rejected.iter().filter(|k| **k < factors) {
        weights[k] = 0.0;
    }
    weights
}

/// The kernel that scales each between factor's least-squares cost by its weight:
/// ρ_k(s) = w_k s / 2, IRLS weight w_k.
pub fn weighted(weights: &[f64]) -> impl Fn(usize, f64) -> (f64, f64) + '_ {
    move |k, s| (weights[k] * 0.5 * s, weights[k])
}

/// Squared whitened residual of every between factor at the graph's values.
fn squared_residuals<G: Manifold<D>, const D: usize>(graph: &PoseGraph<G, D>) -> Vec<f64> {
    graph.betweens.iter().map(|f| f.whitened_error(&graph.values[f.from], &graph.values[f.to]).norm_squared()).collect()
}

/// GNC-TLS for a graph that grows and is solved again and again (a robot's Optimiser).
/// `candidates[k]`: between factor k may be rejected (loop closures, inter-robot factors);
/// `previous`: the candidates the last solve rejected.
///
/// First, least squares with `previous` left out, warm-started from the current values. If then
/// every kept candidate is an inlier (s ≤ c̄²) and every left-out one still an outlier
/// (s > c̄²), the binary weights are a fixed point of GNC's update at any μ, i.e. the TLS
/// decision stands, and that solve is the answer: one solve, the usual case. Otherwise the
/// values go back to where they were and full GNC runs from them. (Also requiring every new
/// factor's innovation to be an inlier before the solve was tried: on `faults/clean` it sent a
/// correct drift-correcting loop closure to GNC, which rejected it, and caught no more false
/// factors on `faults/false_factors`.)
pub fn optimize_gnc_incremental<G: Manifold<D>, const D: usize>(
    graph: &mut PoseGraph<G, D>,
    params: &LmParams,
    candidates: &[bool],
    previous: &[usize],
) -> Result<(Summary, Vec<usize>), SolveError> {
    let structure = Structure::new(graph)?;
    optimize_gnc_incremental_with(graph, params, &structure, candidates, previous)
}

/// As [`optimize_gnc_incremental`], on a symbolic `structure` built for this graph's factors
/// (the caller keeps it for the marginal covariances after the solve).
pub fn optimize_gnc_incremental_with<G: Manifold<D>, const D: usize>(
    graph: &mut PoseGraph<G, D>,
    params: &LmParams,
    structure: &Structure<D>,
    candidates: &[bool],
    previous: &[usize],
) -> Result<(Summary, Vec<usize>), SolveError> {
    let c2 = chi2_99(D);
    let n = graph.betweens.len();
    let candidate = |k: usize| k < n && candidates.get(k).copied().unwrap_or(false);
    let left_out: Vec<usize> = previous.iter().copied().filter(|k| candidate(*k)).collect();
    let weights = rejection_weights(n, &left_out);
    let start = graph.values.clone();
    let summary = optimize_with(graph, params, structure, &weighted(&weights))?;
    let stands = squared_residuals(graph)
        .iter()
        .enumerate()
        .filter(|(k, _)| candidate(*k))
        .all(|(k, s)| (weights[k] == 1.0) == (*s <= c2));
    if stands {
        let rejected = (0..weights.len()).filter(|k| weights[*k] == 0.0).collect();
        return Ok((summary, rejected));
    }
    graph.values = start;
    let mask: Vec<bool> = (0..graph.betweens.len()).map(candidate).collect();
    gnc_tls(graph, params, structure, c2, &mask)
}

fn gnc_tls<G: Manifold<D>, const D: usize>(
    graph: &mut PoseGraph<G, D>,
    params: &LmParams,
    structure: &Structure<D>,
    c2: f64,
    candidates: &[bool],
) -> Result<(Summary, Vec<usize>), SolveError> {
    let initial_error = cost_at(graph, &graph.values, &super::solver::least_squares);
    let initial_values = graph.values.clone();
    let mut weights = vec![1.0; graph.betweens.len()];
    // μ₀ from the largest candidate residual at the initial values (as GTSAM's GncOptimizer).
    let max_s =
        squared_residuals(graph).iter().zip(candidates).filter(|(_, c)| **c).map(|(s, _)| *s).fold(0.0, f64::max);
    let mut iterations = optimize_with(graph, params, structure, &weighted(&weights))?.iterations;
    let mut converged = true;
    if max_s > c2 {
        let mut mu = c2 / (2.0 * max_s - c2).max(1e-12);
        converged = false;
        let c = c2.sqrt();
        for _ in 0..GNC_MAX_STEPS {
            // Weights from the current estimate ...
            for (k, s) in squared_residuals(graph).iter().enumerate() {
                if !candidates[k] {
                    continue;
                }
                weights[k] = if *s <= mu / (mu + 1.0) * c2 {
                    1.0
                } else if *s >= (mu + 1.0) / mu * c2 {
                    0.0
                } else {
                    (c * (mu * (mu + 1.0)).sqrt() / s.sqrt() - mu).clamp(0.0, 1.0)
                };
            }
            // ... and the weighted problem solved again from the initial values, so that an
            // early, distorted estimate cannot trap the later ones.
            graph.values.clone_from(&initial_values);
            iterations += optimize_with(graph, params, structure, &weighted(&weights))?.iterations;
            if weights.iter().all(|w| *w == 0.0 || *w == 1.0) {
                converged = true;
                break;
            }
            mu *= GNC_MU_GROWTH;
        }
    }
    let rejected: Vec<usize> = weights.iter().enumerate().filter(|(_, w)| **w < 0.5).map(|(k, _)| k).collect();
    // Least-squares error of the factors kept (weights are binary at convergence).
    let final_error = cost_at(graph, &graph.values, &weighted(&weights));
    Ok((Summary { initial_error, final_error, iterations, converged }, rejected))
}
