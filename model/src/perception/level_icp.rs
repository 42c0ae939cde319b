//! ICP between two gravity-aligned bodies (beyond the paper): x, y, z and yaw only. Two robots
//! with IMUs each know their keyframes' tilt against gravity, and their worlds are level, so
//! the relative tilt of two keyframes is known before any registration. A 6-DoF registration
//! re-estimates it from the scans, and between sensors at 0.5 and 1.5 m that see walls more
//! than a shared floor it gets it wrong by a degree or two — and, through the lever of the
//! points' range, the height by decimetres (`handheld_indoor`'s inter-robot factors with the
//! handheld rig were 0.6–1.8° and −0.15…+0.32 m off in height; those between the two legged
//! robots 0.1–0.3° and 2 cm).
//!
//! So the Gauss–Newton step is taken in the subspace that keeps the tilt. With u the world's
//! up in the target body (the local keyframe's R_wᵀ ẑ) and ICP's left perturbation
//! T ← Exp(δ) T, δ = (ω, v):
//!
//! ```text
//! δ = B x,   B = [u 0; 0 I₃]  (6 × 4),   x = (θ, v):   x = −(Bᵀ H B)⁻¹ Bᵀ g
//! ```
//!
//! a turn θ about the vertical and any translation. The registration's information is the
//! 4-DoF estimate's, B (Bᵀ H B) Bᵀ, plus a weak σ = [`LEVEL_TILT_SIGMA_RAD`] on the two tilt
//! axes (I − u uᵀ on the rotation block), so that it is positive definite and a factor made from
//! it says next to nothing of the tilt, which the keyframes' gravity priors hold.

use crate::geometry::lie::{Matrix6, Tangent3};
use nalgebra::{Matrix3, SMatrix, Vector3};

/// The weak tilt σ given to a level registration's information, rad (5°).
pub const LEVEL_TILT_SIGMA_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// B: the perturbations that keep the tilt — a turn about `up` and the three translations.
pub fn basis(up: &Vector3<f64>) -> SMatrix<f64, 6, 4> {
    let mut b = SMatrix::<f64, 6, 4>::zeros();
    b.fixed_view_mut::<3, 1>(0, 0).copy_from(up);
    b.fixed_view_mut::<3, 3>(3, 1).copy_from(&Matrix3::identity());
    b
}

/// The Gauss–Newton step within the basis, δ = B x (`None` when BᵀHB is not positive definite
/// or the step is not finite).
pub fn step(hessian: &Matrix6, gradient: &Tangent3, up: &Vector3<f64>) -> Option<Tangent3> {
    let b = basis(up);
    let reduced = b.transpose() * hessian * b;
    let x = reduced.cholesky().map(|c| -c.solve(&(b.transpose() * gradient)))?;
    let step = b * x;
    step.iter().all(|v| v.is_finite()).then_some(step)
}

/// The information of a level registration in the left chart: the 4-DoF estimate's, B(BᵀHB)Bᵀ,
/// and 1/σ² on the two tilt axes (σ = [`LEVEL_TILT_SIGMA_RAD`]).
pub fn information(hessian: &Matrix6, up: &Vector3<f64>) -> Matrix6 {
    let b = basis(up);
    let mut information = b * (b.transpose() * hessian * b) * b.transpose();
    let tilt = (Matrix3::identity() - up * up.transpose()) / LEVEL_TILT_SIGMA_RAD.powi(2);
    let mut rotation = information.fixed_view_mut::<3, 3>(0, 0);
    rotation += tilt;
    information
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The step solves the normal equations restricted to B: its residual gradient is normal
    /// to every basis direction, and it has no component along the tilt axes.
    #[test]
    fn the_step_keeps_the_tilt_and_solves_the_reduced_equations() {
        let up = Vector3::new(0.05, -0.03, 1.0).normalize();
        let a =
            SMatrix::<f64, 6, 6>::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 - 2.0 + if i == j { 9.0 } else { 0.0 });
        let hessian = a.transpose() * a;
        let gradient = Tangent3::new(0.3, -0.2, 0.5, 1.0, -0.4, 0.2);
        let delta = step(&hessian, &gradient, &up).unwrap();
        let rotation = delta.fixed_rows::<3>(0).into_owned();
        assert!((rotation - up * up.dot(&rotation)).norm() < 1e-12, "a turn about the vertical only");
        let b = basis(&up);
        assert!((b.transpose() * (hessian * delta + gradient)).norm() < 1e-9);
    }

    #[test]
    fn the_information_holds_the_tilt_weakly() {
        let up = Vector3::new(-0.04, 0.02, 1.0).normalize();
        let hessian = Matrix6::identity() * 1e6;
        let info = information(&hessian, &up);
        let tilt_axis = up.cross(&Vector3::x()).normalize();
        let mut d = Tangent3::zeros();
        d.fixed_rows_mut::<3>(0).copy_from(&tilt_axis);
        assert!(((d.transpose() * info * d)[0] - LEVEL_TILT_SIGMA_RAD.powi(-2)).abs() < 1e-6);
        let mut yaw = Tangent3::zeros();
        yaw.fixed_rows_mut::<3>(0).copy_from(&up);
        assert!(((yaw.transpose() * info * yaw)[0] - 1e6).abs() < 1e-3);
        assert!(info.cholesky().is_some(), "positive definite");
    }
}
