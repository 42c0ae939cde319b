//! The scan's correction of the IMU's prediction: from a registered pose to the whole state.
//!
//! The error state splits into the pose a = (δθ, δp) and the rest b = (δv, δb_g, δb_a, δu), prior
//! N(0, P) around the prediction x̂ (`propagation`). A scan measures only the pose, so the
//! posterior is the pose's posterior times the rest given the pose (the Gaussian chain rule;
//! it is the iterated EKF's update when registration iterates the pose to convergence, as
//! FAST-LIO2 §IV-C does with the whole state):
//!
//! ```text
//! Σ_a⁺ = (P_aa⁻¹ + Λ)⁻¹                         Λ: the scan's information on a
//! a⁺   = the registered pose's error, (Log(R̂ᵀ R*), p* − p̂)
//! K    = P_ba P_aa⁻¹
//! b⁺   = K a⁺
//! P⁺   = [[Σ_a⁺, Σ_a⁺ Kᵀ], [K Σ_a⁺, P_bb − K P_ab + K Σ_a⁺ Kᵀ]]
//! ```
//!
//! Registration works in a left perturbation δ = (ω, v) of T = (R, p), T ← Exp(δ) T, so its
//! Hessian H (point-to-plane residuals in metres) becomes information on a through
//! δ = M a, M = [[R, 0], [p^ R, I]] (Exp(δ)·T moves R to R Exp(Rᵀω) and p to p + ω × p + v):
//!
//! ```text
//! Λ = Mᵀ H M / σ²                                σ: a residual's noise, m
//! ```
//!
//! and its prior, on e = Log(T̂⁻¹ T) ≈ (δθ, R̂ᵀ δp) = N a with N = diag(I, R̂ᵀ), has information
//! (N P_aa Nᵀ)⁻¹; the same N carries the posterior pose covariance out as Cov(e).

use super::propagation::{Matrix17, NavState, STATE_DIM, UP};
use super::registration::left_from_error;
use crate::geometry::lie::Matrix6;
use crate::geometry::Pose3;
use nalgebra::{Matrix3, SMatrix, Translation3, Vector3};

/// The rest b of the error state, after the pose.
const REST: usize = STATE_DIM - 6;
type MatrixRest = SMatrix<f64, REST, REST>;
type MatrixRestx6 = SMatrix<f64, REST, 6>;

/// The pose of a state.
pub fn pose_of(state: &NavState) -> Pose3 {
    Pose3::from_parts(Translation3::from(state.position), state.rotation)
}

/// N of the module notes at rotation `r`: e = N a.
pub(super) fn n_matrix(r: &Matrix3<f64>) -> Matrix6 {
    let mut n = Matrix6::identity();
    n.fixed_view_mut::<3, 3>(3, 3).copy_from(&r.transpose());
    n
}

/// Cov(e) of the pose block `p_aa` of a state at rotation `r`.
pub fn pose_covariance(p_aa: &Matrix6, state: &NavState) -> Matrix6 {
    let n = n_matrix(&state.rotation.to_rotation_matrix().into_inner());
    let c = n * p_aa * n.transpose();
    (c + c.transpose()) * 0.5
}

/// The information of e = Log(T̂⁻¹T) for registration's prior: (N P_aa Nᵀ)⁻¹ (none if singular).
pub fn prior_information(covariance: &Matrix17, state: &NavState) -> Option<Matrix6> {
    let p_aa = covariance.fixed_view::<6, 6>(0, 0).into_owned();
    let c = pose_covariance(&p_aa, state);
    c.cholesky().map(|ch| {
        let inv = ch.inverse();
        (inv + inv.transpose()) * 0.5
    })
}

/// Λ of the module notes: the scan Hessian `h_left` (left perturbation at `pose`) as
/// information on the error state's pose, for residual noise `sigma_m`.
pub fn scan_information(h_left: &Matrix6, pose: &Pose3, sigma_m: f64) -> Matrix6 {
    let m = left_from_error(pose);
    let l = m.transpose() * h_left * m / (sigma_m * sigma_m);
    (l + l.transpose()) * 0.5
}

/// Why an update was not applied.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum UpdateError {
    #[error("the prediction's pose covariance is not positive definite")]
    PriorSingular,
    #[error("the posterior is not positive definite")]
    PosteriorSingular,
}

/// The state and covariance after the scan: `registered` the registration's pose, `information`
/// Λ (module notes).
pub fn apply_pose_update(
    state: &NavState,
    covariance: &Matrix17,
    registered: &Pose3,
    information: &Matrix6,
) -> Result<(NavState, Matrix17), UpdateError> {
    let p_aa = covariance.fixed_view::<6, 6>(0, 0).into_owned();
    let p_ba: MatrixRestx6 = covariance.fixed_view::<REST, 6>(6, 0).into_owned();
    let p_bb: MatrixRest = covariance.fixed_view::<REST, REST>(6, 6).into_owned();
    let p_aa_inv = p_aa.cholesky().ok_or(UpdateError::PriorSingular)?.inverse();
    let posterior_info = p_aa_inv + information;
    let sigma_a = posterior_info.cholesky().ok_or(UpdateError::PosteriorSingular)?.inverse();
    let sigma_a = (sigma_a + sigma_a.transpose()) * 0.5;
    let dtheta = (state.rotation.inverse() * registered.rotation).scaled_axis();
    let dp = registered.translation.vector - state.position;
    let a = SMatrix::<f64, 6, 1>::from_iterator(dtheta.iter().chain(dp.iter()).copied());
    let k = p_ba * p_aa_inv;
    let b = k * a;
    let part = |i: usize| Vector3::new(b[i], b[i + 1], b[i + 2]);
    let next = NavState {
        rotation: registered.rotation,
        position: registered.translation.vector,
        velocity: state.velocity + part(0),
        gyro_bias: state.gyro_bias + part(3),
        accel_bias: state.accel_bias + part(6),
        up: state.up_moved(&nalgebra::Vector2::new(b[UP - 6], b[UP - 5])),
    };
    let mut p = Matrix17::zeros();
    let cross = k * sigma_a;
    p.fixed_view_mut::<6, 6>(0, 0).copy_from(&sigma_a);
    p.fixed_view_mut::<REST, 6>(6, 0).copy_from(&cross);
    p.fixed_view_mut::<6, REST>(0, 6).copy_from(&cross.transpose());
    let bb = p_bb - k * p_ba.transpose() + k * sigma_a * k.transpose();
    p.fixed_view_mut::<REST, REST>(6, 6).copy_from(&((bb + bb.transpose()) * 0.5));
    Ok((next, p))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::lie::{se3_log, Tangent3};
    use crate::geometry::pose_from_rpy_translation;
    use nalgebra::{SVector, UnitQuaternion};

    fn random_spd<const N: usize>(seed: u64) -> SMatrix<f64, N, N> {
        let mut x = seed;
        let mut next = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let a = SMatrix::<f64, N, N>::from_fn(|_, _| next());
        a * a.transpose() + SMatrix::<f64, N, N>::identity() * 0.1
    }

    fn state() -> NavState {
        NavState {
            rotation: UnitQuaternion::from_euler_angles(0.1, -0.2, 0.7),
            position: Vector3::new(3.0, -1.0, 0.5),
            velocity: Vector3::new(1.0, 0.2, 0.0),
            gyro_bias: Vector3::new(0.001, 0.0, -0.002),
            accel_bias: Vector3::new(0.01, 0.02, 0.0),
            up: Vector3::z(),
        }
    }

    /// The chain-rule update equals the textbook Kalman update in information form for a
    /// linear measurement of the pose block: P⁺ = (P⁻¹ + Hᵀ Λ H)⁻¹, x⁺ = P⁺ Hᵀ Λ z, where the
    /// measured pose error z is the one the MAP pose a⁺ implies, z = Λ⁻¹ (P_aa⁻¹ + Λ) a⁺.
    #[test]
    fn the_update_is_the_information_form_kalman_update() {
        let s = state();
        let p = random_spd::<STATE_DIM>(7) * 0.01;
        let lambda = random_spd::<6>(11) * 50.0;
        let a = SVector::<f64, 6>::new(0.01, -0.02, 0.005, 0.1, -0.05, 0.02);
        let registered = Pose3::from_parts(
            Translation3::from(s.position + Vector3::new(a[3], a[4], a[5])),
            s.rotation * UnitQuaternion::from_scaled_axis(Vector3::new(a[0], a[1], a[2])),
        );
        let (next, p_next) = apply_pose_update(&s, &p, &registered, &lambda).expect("well posed");
        let mut h = SMatrix::<f64, 6, STATE_DIM>::zeros();
        h.fixed_view_mut::<6, 6>(0, 0).copy_from(&Matrix6::identity());
        let p_aa = p.fixed_view::<6, 6>(0, 0).into_owned();
        let z = lambda.try_inverse().expect("spd") * (p_aa.try_inverse().expect("spd") + lambda) * a;
        let p_info = (p.try_inverse().expect("spd") + h.transpose() * lambda * h).try_inverse().expect("spd");
        let x = p_info * h.transpose() * lambda * z;
        assert!((p_info - p_next).amax() < 1e-9, "{}", (p_info - p_next).amax());
        assert!((x.fixed_rows::<6>(0) - a).amax() < 1e-9);
        assert!((next.velocity - s.velocity - Vector3::new(x[6], x[7], x[8])).amax() < 1e-9);
        assert!((next.accel_bias - s.accel_bias - Vector3::new(x[12], x[13], x[14])).amax() < 1e-9);
        let up = s.up_moved(&nalgebra::Vector2::new(x[UP], x[UP + 1]));
        assert!((next.up - up).amax() < 1e-9);
    }

    /// Λ = Mᵀ H M / σ²: the scan cost of a small error a, computed in registration's left
    /// perturbation, equals aᵀ Λ a (checked by moving the pose by a and reading δ back).
    #[test]
    fn scan_information_is_the_left_hessian_in_the_error_states_coordinates() {
        let pose = pose_from_rpy_translation(0.2, 0.1, -0.4, Vector3::new(5.0, -2.0, 1.0));
        let h = random_spd::<6>(3);
        let sigma = 0.05;
        let lambda = scan_information(&h, &pose, sigma);
        let a = SVector::<f64, 6>::new(1e-5, -2e-5, 3e-5, 2e-5, 1e-5, -1e-5);
        let moved = Pose3::from_parts(
            Translation3::from(pose.translation.vector + Vector3::new(a[3], a[4], a[5])),
            pose.rotation * UnitQuaternion::from_scaled_axis(Vector3::new(a[0], a[1], a[2])),
        );
        let delta: Tangent3 = se3_log(&(moved * pose.inverse()));
        let left = (delta.transpose() * h * delta)[0] / (sigma * sigma);
        let ours = (a.transpose() * lambda * a)[0];
        assert!((left - ours).abs() < 1e-3 * left.abs(), "{left} vs {ours}");
        // And e = Log(T̂⁻¹T) ≈ N a.
        let e = se3_log(&(pose.inverse() * moved));
        let r = pose.rotation.to_rotation_matrix().into_inner();
        assert!((e - n_matrix(&r) * a).amax() < 1e-9);
    }

    #[test]
    fn a_singular_prior_is_refused() {
        let s = state();
        let p = Matrix17::zeros();
        let r = pose_of(&s);
        assert_eq!(apply_pose_update(&s, &p, &r, &Matrix6::identity()), Err(UpdateError::PriorSingular));
    }
}
