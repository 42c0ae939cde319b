//! Factors of the pose graph, with whitened residuals and analytic Jacobians on the manifold.
//!
//! Between (odometry, loop, inter-robot; GTSAM's `BetweenFactor`):
//!   e = Log(z⁻¹ · x_i⁻¹ · x_j),
//!   ∂e/∂δ_j = J_r⁻¹(e),  ∂e/∂δ_i = −J_r⁻¹(e) · Ad(x_j⁻¹ · x_i),
//! from x_j ⊕ δ_j = x_j Exp(δ_j) and x_i⁻¹ ⊕ = Exp(−δ_i) x_i⁻¹ moved through Ad.
//! Prior (`PriorFactor`): e = Log(z⁻¹ · x), ∂e/∂δ = J_r⁻¹(e).
//! Whitening: r = S e, J ← S J with Sᵀ S = Ω (the information matrix); error ½ ‖r‖².

use super::manifold::Manifold;
use nalgebra::{SMatrix, SVector};

/// Relative-pose measurement `measured` = x_from⁻¹ · x_to.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Between<G, const D: usize> {
    pub from: usize,
    pub to: usize,
    pub measured: G,
    /// S with Sᵀ S = Ω.
    pub sqrt_information: SMatrix<f64, D, D>,
}

/// Absolute-pose measurement.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Prior<G, const D: usize> {
    pub variable: usize,
    pub mean: G,
    pub sqrt_information: SMatrix<f64, D, D>,
}

/// Whitened residual and Jacobians of a between factor.
pub struct Linearized<const D: usize> {
    pub residual: SVector<f64, D>,
    pub d_from: SMatrix<f64, D, D>,
    pub d_to: SMatrix<f64, D, D>,
}

impl<G: Manifold<D>, const D: usize> Between<G, D> {
    pub fn whitened_error(&self, from: &G, to: &G) -> SVector<f64, D> {
        self.sqrt_information * self.measured.inverse().compose(&from.inverse().compose(to)).log()
    }

    pub fn linearize(&self, from: &G, to: &G) -> Linearized<D> {
        let from_to = from.inverse().compose(to);
        let e = self.measured.inverse().compose(&from_to).log();
        let jr_inv = G::right_jacobian_inverse(&e);
        let d_to = self.sqrt_information * jr_inv;
        let d_from = -(d_to * from_to.inverse().adjoint());
        Linearized { residual: self.sqrt_information * e, d_from, d_to }
    }
}

impl<G: Manifold<D>, const D: usize> Prior<G, D> {
    /// A prior from a covariance in the tangent space of `mean` (e.g. a neighbour keyframe's
    /// marginal covariance from its keyframe response). `None` unless symmetric positive
    /// definite and finite.
    pub fn from_covariance(variable: usize, mean: G, covariance: &SMatrix<f64, D, D>) -> Option<Self> {
        if covariance.iter().any(|v| !v.is_finite())
            || (covariance - covariance.transpose()).norm() > 1e-9 * covariance.norm()
        {
            return None;
        }
        // Ω = Σ⁻¹ = Sᵀ S with S = L⁻¹ where Σ = L Lᵀ.
        let l = covariance.cholesky()?.l();
        let sqrt_information = l.try_inverse()?;
        Some(Self { variable, mean, sqrt_information })
    }

    pub fn whitened_error(&self, x: &G) -> SVector<f64, D> {
        self.sqrt_information * self.mean.inverse().compose(x).log()
    }

    /// (r, ∂r/∂δ).
    pub fn linearize(&self, x: &G) -> (SVector<f64, D>, SMatrix<f64, D, D>) {
        let e = self.mean.inverse().compose(x).log();
        (self.sqrt_information * e, self.sqrt_information * G::right_jacobian_inverse(&e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::lie::{se2_exp, se3_exp, Tangent2, Tangent3};
    use nalgebra::{Isometry2, Isometry3};
    use proptest::prelude::*;

    /// Central differences of the whitened error through the retraction.
    fn numeric<G: Manifold<D>, const D: usize>(
        f: &Between<G, D>,
        a: &G,
        b: &G,
    ) -> (SMatrix<f64, D, D>, SMatrix<f64, D, D>) {
        let h = 1e-6;
        let (mut da, mut db) = (SMatrix::<f64, D, D>::zeros(), SMatrix::<f64, D, D>::zeros());
        for k in 0..D {
            let mut d = SVector::<f64, D>::zeros();
            d[k] = h;
            let col_a = (f.whitened_error(&a.retract(&d), b) - f.whitened_error(&a.retract(&-d), b)) / (2.0 * h);
            let col_b = (f.whitened_error(a, &b.retract(&d)) - f.whitened_error(a, &b.retract(&-d))) / (2.0 * h);
            da.set_column(k, &col_a);
            db.set_column(k, &col_b);
        }
        (da, db)
    }

    #[test]
    fn prior_from_covariance_whitens_by_its_inverse() {
        let mut cov = SMatrix::<f64, 3, 3>::new(0.04, 0.01, 0.0, 0.01, 0.09, 0.0, 0.0, 0.0, 0.01);
        let p = Prior::from_covariance(0, Isometry2::identity(), &cov).unwrap();
        let omega = p.sqrt_information.transpose() * p.sqrt_information;
        assert!((omega * cov - SMatrix::<f64, 3, 3>::identity()).norm() < 1e-12);
        cov[(2, 2)] = -1.0;
        assert!(Prior::from_covariance(0, Isometry2::identity(), &cov).is_none());
        cov[(2, 2)] = f64::NAN;
        assert!(Prior::from_covariance(0, Isometry2::identity(), &cov).is_none());
    }

    proptest! {
        #[test]
        fn se3_between_jacobians_match_numeric(a in prop::array::uniform6(-1.0f64..1.0), b in prop::array::uniform6(-1.0f64..1.0), z in prop::array::uniform6(-0.8f64..0.8)) {
            let t = |v: [f64; 6], s: f64| se3_exp(&Tangent3::new(v[0], v[1], v[2], s * v[3], s * v[4], s * v[5]));
            let (xa, xb): (Isometry3<f64>, Isometry3<f64>) = (t(a, 10.0), t(b, 10.0));
            let mut s = SMatrix::<f64, 6, 6>::identity() * 3.0;
            s[(0, 4)] = 0.5;
            let f = Between { from: 0, to: 1, measured: t(z, 3.0), sqrt_information: s };
            let lin = f.linearize(&xa, &xb);
            let (na, nb) = numeric(&f, &xa, &xb);
            prop_assert!((lin.d_from - na).norm() < 1e-5 * (1.0 + na.norm()), "{} vs {}", lin.d_from, na);
            prop_assert!((lin.d_to - nb).norm() < 1e-5 * (1.0 + nb.norm()));
            prop_assert!((lin.residual - f.whitened_error(&xa, &xb)).norm() < 1e-12);
        }

        #[test]
        fn se2_between_jacobians_match_numeric(a in prop::array::uniform3(-3.0f64..3.0), b in prop::array::uniform3(-3.0f64..3.0), z in prop::array::uniform3(-2.0f64..2.0)) {
            let t = |v: [f64; 3]| se2_exp(&Tangent2::new(5.0 * v[0], 5.0 * v[1], v[2]));
            let (xa, xb): (Isometry2<f64>, Isometry2<f64>) = (t(a), t(b));
            let f = Between { from: 0, to: 1, measured: t(z), sqrt_information: SMatrix::<f64, 3, 3>::new(2.0, 0.1, 0.0, 0.0, 2.0, 0.3, 0.0, 0.0, 5.0) };
            let lin = f.linearize(&xa, &xb);
            let (na, nb) = numeric(&f, &xa, &xb);
            prop_assert!((lin.d_from - na).norm() < 1e-5 * (1.0 + na.norm()));
            prop_assert!((lin.d_to - nb).norm() < 1e-5 * (1.0 + nb.norm()));
        }

        #[test]
        fn prior_jacobian_matches_numeric(a in prop::array::uniform6(-1.0f64..1.0), z in prop::array::uniform6(-1.0f64..1.0)) {
            let t = |v: [f64; 6]| se3_exp(&Tangent3::new(v[0], v[1], v[2], 4.0 * v[3], 4.0 * v[4], 4.0 * v[5]));
            let p = Prior { variable: 0, mean: t(z), sqrt_information: SMatrix::<f64, 6, 6>::identity() * 2.0 };
            let x: Isometry3<f64> = t(a);
            let (_, j) = p.linearize(&x);
            let h = 1e-6;
            for k in 0..6 {
                let mut d = SVector::<f64, 6>::zeros();
                d[k] = h;
                let col = (p.whitened_error(&x.retract(&d)) - p.whitened_error(&x.retract(&-d))) / (2.0 * h);
                prop_assert!((j.column(k) - col).norm() < 1e-5);
            }
        }
    }
}
