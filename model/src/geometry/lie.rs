//! SE(2) and SE(3) as Lie groups, in GTSAM's conventions so that errors compare exactly:
//! retraction T ⊕ ξ = T · Exp(ξ); SE(2) tangent ξ = (v_x, v_y, ω); SE(3) tangent ξ = (ω, v)
//! (rotation first). Exp/Log are the true group maps (with the V(ω) coupling), not a split
//! rotation/translation chart.
//!
//! Right Jacobian J_r(ξ): Exp(ξ + δ) ≈ Exp(ξ) · Exp(J_r(ξ) δ), and so
//! Log(Exp(ξ) · Exp(δ)) ≈ ξ + J_r⁻¹(ξ) δ. SE(3) follows Barfoot, *State Estimation for Robotics*
//! (2017), eqs. 7.83–7.86 with J_r(ξ) = J_l(−ξ); SE(2) follows Solà et al., *A micro Lie theory*
//! (2018), eq. 163. Both are checked against numeric differentiation in the tests.

use nalgebra::{
    Isometry2, Isometry3, Matrix3, SMatrix, SVector, Translation2, Translation3, UnitComplex, UnitQuaternion, Vector2,
    Vector3,
};

/// Below this θ² the trigonometric coefficients are evaluated by their Taylor series to fourth
/// order (truncation ~θ⁶ < 1e-12); above it, directly (cancellation error < 1e-11).
const SERIES_BELOW: f64 = 1e-4;

/// The cross-product matrix: hat(w) · x = w × x.
pub fn hat(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

// ----- SE(3) ------------------------------------------------------------------------------

/// SE(3) tangent, (ω, v).
pub type Tangent3 = SVector<f64, 6>;
/// 6 × 6 matrix over SE(3) tangents.
pub type Matrix6 = SMatrix<f64, 6, 6>;

/// Exp: R = exp(ω^), t = V(ω) v, V = I + (1 − cos θ)/θ² ω^ + (θ − sin θ)/θ³ ω^².
pub fn se3_exp(xi: &Tangent3) -> Isometry3<f64> {
    let w = Vector3::new(xi[0], xi[1], xi[2]);
    let v = Vector3::new(xi[3], xi[4], xi[5]);
    let rotation = UnitQuaternion::from_scaled_axis(w);
    let t = so3_left_jacobian(&w) * v;
    Isometry3::from_parts(Translation3::from(t), rotation)
}

/// Log: ω = log(R), v = V(ω)⁻¹ t.
pub fn se3_log(pose: &Isometry3<f64>) -> Tangent3 {
    let w = pose.rotation.scaled_axis();
    let v = so3_left_jacobian_inverse(&w) * pose.translation.vector;
    Tangent3::new(w.x, w.y, w.z, v.x, v.y, v.z)
}

/// Adjoint in (ω, v) ordering: Ad(T) = [[R, 0], [t^ R, R]].
pub fn se3_adjoint(pose: &Isometry3<f64>) -> Matrix6 {
    let r = pose.rotation.to_rotation_matrix().into_inner();
    let mut ad = Matrix6::zeros();
    ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(3, 0).copy_from(&(hat(&pose.translation.vector) * r));
    ad
}

/// SO(3) left Jacobian J_l(φ) = I + (1 − cos θ)/θ² φ^ + (θ − sin θ)/θ³ φ^² (= V above).
pub fn so3_left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.norm_squared();
    let (a, b) = if theta2 < SERIES_BELOW {
        let t4 = theta2 * theta2;
        (0.5 - theta2 / 24.0 + t4 / 720.0, 1.0 / 6.0 - theta2 / 120.0 + t4 / 5040.0)
    } else {
        let theta = theta2.sqrt();
        ((1.0 - theta.cos()) / theta2, (theta - theta.sin()) / (theta2 * theta))
    };
    let k = hat(phi);
    Matrix3::identity() + a * k + b * k * k
}

/// J_l(φ)⁻¹ = I − ½ φ^ + (1/θ² − (1 + cos θ)/(2 θ sin θ)) φ^².
pub fn so3_left_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.norm_squared();
    let c = if theta2 < SERIES_BELOW {
        1.0 / 12.0 + theta2 / 720.0 + theta2 * theta2 / 30240.0
    } else {
        let theta = theta2.sqrt();
        1.0 / theta2 - (1.0 + theta.cos()) / (2.0 * theta * theta.sin())
    };
    let k = hat(phi);
    Matrix3::identity() - 0.5 * k + c * k * k
}

/// Barfoot's Q_l(ρ, φ) (eq. 7.86), the coupling block of the SE(3) left Jacobian.
fn se3_q(rho: &Vector3<f64>, phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.norm_squared();
    let (c1, c2, c3) = if theta2 < SERIES_BELOW {
        let t4 = theta2 * theta2;
        (
            1.0 / 6.0 - theta2 / 120.0 + t4 / 5040.0,
            1.0 / 24.0 - theta2 / 720.0 + t4 / 40320.0,
            1.0 / 120.0 - theta2 / 2520.0 + t4 / 120960.0,
        )
    } else {
        let theta = theta2.sqrt();
        let (s, c) = theta.sin_cos();
        (
            (theta - s) / (theta2 * theta),
            (theta2 + 2.0 * c - 2.0) / (2.0 * theta2 * theta2),
            (2.0 * theta - 3.0 * s + theta * c) / (2.0 * theta2 * theta2 * theta),
        )
    };
    let (p, r) = (hat(phi), hat(rho));
    0.5 * r
        + c1 * (p * r + r * p + p * r * p)
        + c2 * (p * p * r + r * p * p - 3.0 * p * r * p)
        + c3 * (p * r * p * p + p * p * r * p)
}

/// SE(3) right Jacobian J_r(ξ) = J_l(−ξ), (ω, v) ordering: [[J, 0], [Q, J]].
pub fn se3_right_jacobian(xi: &Tangent3) -> Matrix6 {
    let phi = -Vector3::new(xi[0], xi[1], xi[2]);
    let rho = -Vector3::new(xi[3], xi[4], xi[5]);
    lower_block(&so3_left_jacobian(&phi), &se3_q(&rho, &phi))
}

/// J_r(ξ)⁻¹ = [[J⁻¹, 0], [−J⁻¹ Q J⁻¹, J⁻¹]].
pub fn se3_right_jacobian_inverse(xi: &Tangent3) -> Matrix6 {
    let phi = -Vector3::new(xi[0], xi[1], xi[2]);
    let rho = -Vector3::new(xi[3], xi[4], xi[5]);
    let j_inv = so3_left_jacobian_inverse(&phi);
    lower_block(&j_inv, &(-j_inv * se3_q(&rho, &phi) * j_inv))
}

/// [[diagonal, 0], [coupling, diagonal]].
fn lower_block(diagonal: &Matrix3<f64>, coupling: &Matrix3<f64>) -> Matrix6 {
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(diagonal);
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(diagonal);
    out.fixed_view_mut::<3, 3>(3, 0).copy_from(coupling);
    out
}

// ----- SE(2) ------------------------------------------------------------------------------

/// SE(2) tangent, (v_x, v_y, ω).
pub type Tangent2 = SVector<f64, 3>;

/// (sin ω / ω, (1 − cos ω) / ω), with their limits at 0.
fn se2_v_coefficients(w: f64) -> (f64, f64) {
    if w.abs() < 1e-4 {
        let w2 = w * w;
        (1.0 - w2 / 6.0 + w2 * w2 / 120.0, w / 2.0 - w * w2 / 24.0)
    } else {
        (w.sin() / w, (1.0 - w.cos()) / w)
    }
}

/// Exp: t = V(ω) v with V = [[a, −b], [b, a]], a = sin ω/ω, b = (1 − cos ω)/ω.
pub fn se2_exp(xi: &Tangent2) -> Isometry2<f64> {
    let (a, b) = se2_v_coefficients(xi[2]);
    let t = Vector2::new(a * xi[0] - b * xi[1], b * xi[0] + a * xi[1]);
    Isometry2::from_parts(Translation2::from(t), UnitComplex::new(xi[2]))
}

/// Log: v = V(ω)⁻¹ t.
pub fn se2_log(pose: &Isometry2<f64>) -> Tangent2 {
    let w = pose.rotation.angle();
    let (a, b) = se2_v_coefficients(w);
    let det = a * a + b * b;
    let t = pose.translation.vector;
    Tangent2::new((a * t.x + b * t.y) / det, (-b * t.x + a * t.y) / det, w)
}

/// Adjoint: [[R, (t_y, −t_x)ᵀ], [0, 1]].
pub fn se2_adjoint(pose: &Isometry2<f64>) -> Matrix3<f64> {
    let (s, c) = pose.rotation.angle().sin_cos();
    let t = pose.translation.vector;
    Matrix3::new(c, -s, t.y, s, c, -t.x, 0.0, 0.0, 1.0)
}

/// SE(2) right Jacobian (Solà et al. eq. 163).
pub fn se2_right_jacobian(xi: &Tangent2) -> Matrix3<f64> {
    let (vx, vy, w) = (xi[0], xi[1], xi[2]);
    let (a, b) = se2_v_coefficients(w);
    let (j02, j12) = if w.abs() < 1e-4 {
        let w2 = w * w;
        (-vy / 2.0 + w * vx / 6.0 + w2 * vy / 24.0, vx / 2.0 + w * vy / 6.0 - w2 * vx / 24.0)
    } else {
        let (s, c) = w.sin_cos();
        ((w * vx - vy + vy * c - vx * s) / (w * w), (vx + w * vy - vx * c - vy * s) / (w * w))
    };
    Matrix3::new(a, b, j02, -b, a, j12, 0.0, 0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn numeric_right_jacobian6(xi: &Tangent3) -> Matrix6 {
        // Column k: central difference of Log(Exp(ξ)⁻¹ · Exp(ξ ± h e_k)).
        let h = 1e-5;
        let base = se3_exp(xi).inverse();
        let mut out = Matrix6::zeros();
        for k in 0..6 {
            let (mut plus, mut minus) = (*xi, *xi);
            plus[k] += h;
            minus[k] -= h;
            let col = (se3_log(&(base * se3_exp(&plus))) - se3_log(&(base * se3_exp(&minus)))) / (2.0 * h);
            out.set_column(k, &col);
        }
        out
    }

    fn numeric_right_jacobian3(xi: &Tangent2) -> Matrix3<f64> {
        let h = 1e-5;
        let base = se2_exp(xi).inverse();
        let mut out = Matrix3::zeros();
        for k in 0..3 {
            let (mut plus, mut minus) = (*xi, *xi);
            plus[k] += h;
            minus[k] -= h;
            out.set_column(k, &((se2_log(&(base * se2_exp(&plus))) - se2_log(&(base * se2_exp(&minus)))) / (2.0 * h)));
        }
        out
    }

    proptest! {
        #[test]
        fn se3_exp_log_round_trip_and_jacobians(w in prop::array::uniform3(-1.8f64..1.8), v in prop::array::uniform3(-10.0f64..10.0), tiny in proptest::bool::ANY) {
            let scale = if tiny { 1e-7 } else { 1.0 };
            let xi = Tangent3::new(w[0] * scale, w[1] * scale, w[2] * scale, v[0], v[1], v[2]);
            let back = se3_log(&se3_exp(&xi));
            prop_assert!((back - xi).norm() < 1e-9, "{back} vs {xi}");
            let jr = se3_right_jacobian(&xi);
            prop_assert!((jr - numeric_right_jacobian6(&xi)).norm() < 1e-6, "{jr} vs {}", numeric_right_jacobian6(&xi));
            prop_assert!((se3_right_jacobian_inverse(&xi) * jr - Matrix6::identity()).norm() < 1e-9);
        }

        #[test]
        fn se2_exp_log_round_trip_and_jacobian(vx in -10.0f64..10.0, vy in -10.0f64..10.0, w in -3.0f64..3.0, tiny in proptest::bool::ANY) {
            let xi = Tangent2::new(vx, vy, if tiny { w * 1e-8 } else { w });
            prop_assert!((se2_log(&se2_exp(&xi)) - xi).norm() < 1e-9);
            prop_assert!((se2_right_jacobian(&xi) - numeric_right_jacobian3(&xi)).norm() < 1e-6);
        }

        #[test]
        fn adjoints_move_tangents_across(w in prop::array::uniform3(-1.5f64..1.5), v in prop::array::uniform3(-5.0f64..5.0), d in prop::array::uniform3(-0.5f64..0.5)) {
            // T · Exp(δ) = Exp(Ad(T) δ) · T
            let t = se3_exp(&Tangent3::new(w[0], w[1], w[2], v[0], v[1], v[2]));
            let delta = Tangent3::new(d[0], d[1], d[2], d[2], d[0], d[1]);
            let lhs = t * se3_exp(&delta);
            let rhs = se3_exp(&(se3_adjoint(&t) * delta)) * t;
            prop_assert!((se3_log(&(lhs.inverse() * rhs))).norm() < 1e-9);
            let t2 = se2_exp(&Tangent2::new(v[0], v[1], w[0]));
            let d2 = Tangent2::new(d[0], d[1], d[2]);
            let lhs2 = t2 * se2_exp(&d2);
            let rhs2 = se2_exp(&(se2_adjoint(&t2) * d2)) * t2;
            prop_assert!(se2_log(&(lhs2.inverse() * rhs2)).norm() < 1e-9);
        }
    }
}
