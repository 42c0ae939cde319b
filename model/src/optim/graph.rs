//! A pose graph: variables (keyed poses, some possibly fixed), between factors and priors.

use super::factors::{Between, Prior};
use super::manifold::Manifold;
use nalgebra::{Isometry2, Isometry3, SMatrix};

/// Poses with their external keys, and the factors over them.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseGraph<G, const D: usize> {
    /// External key of each variable (g2o vertex id; multi-robot keys carry the robot letter
    /// in the top byte).
    pub keys: Vec<u64>,
    pub values: Vec<G>,
    /// Fixed variables are constants (g2o `FIX`).
    pub fixed: Vec<bool>,
    pub betweens: Vec<Between<G, D>>,
    pub priors: Vec<Prior<G, D>>,
}

/// Planar pose graph.
pub type Graph2 = PoseGraph<Isometry2<f64>, 3>;
/// Spatial pose graph.
pub type Graph3 = PoseGraph<Isometry3<f64>, 6>;

impl<G: Manifold<D>, const D: usize> Default for PoseGraph<G, D> {
    fn default() -> Self {
        Self { keys: Vec::new(), values: Vec::new(), fixed: Vec::new(), betweens: Vec::new(), priors: Vec::new() }
    }
}

impl<G: Manifold<D>, const D: usize> PoseGraph<G, D> {
    /// GTSAM's error ½ Σ ‖r‖² (whitened) at `values`.
    pub fn error_at(&self, values: &[G]) -> f64 {
        let between: f64 =
            self.betweens.iter().map(|f| f.whitened_error(&values[f.from], &values[f.to]).norm_squared()).sum();
        let prior: f64 = self.priors.iter().map(|p| p.whitened_error(&values[p.variable]).norm_squared()).sum();
        0.5 * (between + prior)
    }

    pub fn error(&self) -> f64 {
        self.error_at(&self.values)
    }

    /// Index of the variable with `key`.
    pub fn index_of(&self, key: u64) -> Option<usize> {
        self.keys.iter().position(|&k| k == key)
    }

    /// Holds variable `index` at its current value with a prior of the given standard
    /// deviations (in tangent order), as GTSAM's examples anchor the first pose.
    pub fn add_prior_at_current(&mut self, index: usize, sigmas: [f64; D]) {
        let sqrt_information = SMatrix::<f64, D, D>::from_diagonal(&nalgebra::SVector::<f64, D>::from_iterator(
            sigmas.iter().map(|s| 1.0 / s),
        ));
        self.priors.push(Prior { variable: index, mean: self.values[index], sqrt_information });
    }
}

/// The prior GTSAM's g2o examples put on the first pose: variances (1e-6, 1e-6, 1e-8) for
/// (x, y, θ).
pub const GTSAM_PRIOR_SIGMAS_2D: [f64; 3] = [1e-3, 1e-3, 1e-4];
/// ... and (1e-6 × 3 rotation, 1e-4 × 3 translation) in 3-D.
pub const GTSAM_PRIOR_SIGMAS_3D: [f64; 6] = [1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2];
