//! The variables of a pose graph: SE(2) (D = 3) and SE(3) (D = 6) behind one trait, so that
//! factors and the solver are written once.

use crate::geometry::lie::*;
use nalgebra::{Isometry2, Isometry3, SMatrix, SVector};

/// A pose group with a D-dimensional tangent space (GTSAM's chart: T ⊕ ξ = T · Exp(ξ)).
pub trait Manifold<const D: usize>: Copy + std::fmt::Debug + PartialEq {
    fn compose(&self, other: &Self) -> Self;
    fn inverse(&self) -> Self;
    fn exp(xi: &SVector<f64, D>) -> Self;
    fn log(&self) -> SVector<f64, D>;
    fn adjoint(&self) -> SMatrix<f64, D, D>;
    fn right_jacobian_inverse(xi: &SVector<f64, D>) -> SMatrix<f64, D, D>;
    /// self · Exp(ξ).
    fn retract(&self, xi: &SVector<f64, D>) -> Self {
        self.compose(&Self::exp(xi))
    }
    fn is_finite(&self) -> bool;
}

impl Manifold<3> for Isometry2<f64> {
    fn compose(&self, other: &Self) -> Self {
        self * other
    }
    fn inverse(&self) -> Self {
        Isometry2::inverse(self)
    }
    fn exp(xi: &SVector<f64, 3>) -> Self {
        se2_exp(xi)
    }
    fn log(&self) -> SVector<f64, 3> {
        se2_log(self)
    }
    fn adjoint(&self) -> SMatrix<f64, 3, 3> {
        se2_adjoint(self)
    }
    fn right_jacobian_inverse(xi: &SVector<f64, 3>) -> SMatrix<f64, 3, 3> {
        se2_right_jacobian(xi).try_inverse().unwrap_or_else(SMatrix::identity)
    }
    fn is_finite(&self) -> bool {
        self.translation.vector.iter().all(|v| v.is_finite()) && self.rotation.angle().is_finite()
    }
}

impl Manifold<6> for Isometry3<f64> {
    fn compose(&self, other: &Self) -> Self {
        self * other
    }
    fn inverse(&self) -> Self {
        Isometry3::inverse(self)
    }
    fn exp(xi: &SVector<f64, 6>) -> Self {
        se3_exp(xi)
    }
    fn log(&self) -> SVector<f64, 6> {
        se3_log(self)
    }
    fn adjoint(&self) -> SMatrix<f64, 6, 6> {
        se3_adjoint(self)
    }
    fn right_jacobian_inverse(xi: &SVector<f64, 6>) -> SMatrix<f64, 6, 6> {
        se3_right_jacobian_inverse(xi)
    }
    fn is_finite(&self) -> bool {
        self.translation.vector.iter().all(|v| v.is_finite()) && self.rotation.coords.iter().all(|v| v.is_finite())
    }
}
