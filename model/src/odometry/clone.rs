//! The covariance of the odometry's motion between two scans: a stochastic clone of the pose
//! at the first (Roumeliotis and Burdick, "Stochastic cloning", ICRA 2002).
//!
//! A filter's covariance is that of the pose in its own frame. It grows without bound in
//! position and yaw, which nothing measures. A pose-graph edge between two keyframes needs the
//! covariance of their relative motion instead. That motion is much better known than either
//! pose, because the two poses' errors are strongly correlated. The clone keeps the pose error
//! a_i = (δθ, δp) at the marked scan beside the running state x, with their cross-covariance
//! C = Cov(δx, a_i) and its own Σ_c = Cov(a_i):
//!
//! ```text
//! marked:      C = P[:, a],  Σ_c = P_aa
//! propagated:  C ← F C                          (the clone does not move)
//! updated:     W = P_aa⁻¹ − P_aa⁻¹ Σ_a⁺ P_aa⁻¹     (= (P_aa + Λ⁻¹)⁻¹, Λ never inverted)
//!              C ← C − P[:, a] W C_a,  Σ_c ← Σ_c − C_aᵀ W C_a
//! ```
//!
//! The update is the Kalman update of the augmented state [x; a_i] by the scan's measurement
//! of a. P is the prior and Σ_a⁺ the posterior pose block (`update`), and C_a is the pose rows of C.
//! With e = N a the body-frame error of a pose (`update`) and Δ̂ = T̂_i⁻¹ T̂_j, the motion's error
//! is
//!
//! ```text
//! Δ = Δ̂ Exp(e_Δ),   e_Δ = e_j − Ad(Δ̂⁻¹) e_i = J [a_j; a_i],   J = [N_j, −Ad(Δ̂⁻¹) N_i]
//! Cov(e_Δ) = J [[P_aa, C_a], [C_aᵀ, Σ_c]] Jᵀ
//! ```

use super::propagation::{Matrix17, NavState, STATE_DIM};
use super::update::{n_matrix, pose_of};
use crate::geometry::lie::{se3_adjoint, Matrix6};
use nalgebra::SMatrix;

/// 17 × 6: the running error state against the clone's pose error.
pub type Matrix17x6 = SMatrix<f64, STATE_DIM, 6>;

/// The pose at a marked scan, and its error's covariance with the running state.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseClone {
    pub state: NavState,
    /// Cov(δx, a_i).
    pub cross: Matrix17x6,
    /// Cov(a_i).
    pub covariance: Matrix6,
}

impl PoseClone {
    /// The clone of `state` with covariance `covariance` (the module notes: marked).
    pub fn of(state: &NavState, covariance: &Matrix17) -> Self {
        Self {
            state: *state,
            cross: covariance.fixed_view::<STATE_DIM, 6>(0, 0).into_owned(),
            covariance: covariance.fixed_view::<6, 6>(0, 0).into_owned(),
        }
    }

    /// The running state moved by the transition `f`.
    pub fn propagate(&mut self, f: &Matrix17) {
        self.cross = f * self.cross;
    }

    /// The scan's update took the covariance from `prior` to `posterior`; `None` (clone
    /// unchanged) if the prior's pose block is singular.
    pub fn update(&mut self, prior: &Matrix17, posterior: &Matrix17) -> Option<()> {
        let p_aa_inv = prior.fixed_view::<6, 6>(0, 0).into_owned().cholesky()?.inverse();
        let sigma_a = posterior.fixed_view::<6, 6>(0, 0).into_owned();
        let w = p_aa_inv - p_aa_inv * sigma_a * p_aa_inv;
        let c_a = self.cross.fixed_view::<6, 6>(0, 0).into_owned();
        let p_xa = prior.fixed_view::<STATE_DIM, 6>(0, 0).into_owned();
        self.cross -= p_xa * w * c_a;
        let c = self.covariance - c_a.transpose() * w * c_a;
        self.covariance = (c + c.transpose()) * 0.5;
        Some(())
    }

    /// Cov(e_Δ) of the motion from the clone to `state` (covariance `covariance`), in the body
    /// frame at `state`, ordered (ω, v) (the module notes).
    pub fn motion_covariance(&self, state: &NavState, covariance: &Matrix17) -> Matrix6 {
        let n = |s: &NavState| n_matrix(&s.rotation.to_rotation_matrix().into_inner());
        let motion = pose_of(&self.state).inverse() * pose_of(state);
        let mut j = SMatrix::<f64, 6, 12>::zeros();
        j.fixed_view_mut::<6, 6>(0, 0).copy_from(&n(state));
        j.fixed_view_mut::<6, 6>(0, 6).copy_from(&(-se3_adjoint(&motion.inverse()) * n(&self.state)));
        let c_a = self.cross.fixed_view::<6, 6>(0, 0).into_owned();
        let mut joint = SMatrix::<f64, 12, 12>::zeros();
        joint.fixed_view_mut::<6, 6>(0, 0).copy_from(&covariance.fixed_view::<6, 6>(0, 0));
        joint.fixed_view_mut::<6, 6>(0, 6).copy_from(&c_a);
        joint.fixed_view_mut::<6, 6>(6, 0).copy_from(&c_a.transpose());
        joint.fixed_view_mut::<6, 6>(6, 6).copy_from(&self.covariance);
        let m = j * joint * j.transpose();
        (m + m.transpose()) * 0.5
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::odometry::propagation::{ImuNoise, Propagator};
    use crate::odometry::update::apply_pose_update;
    use crate::perception::imu::ImuSample;
    use nalgebra::{UnitQuaternion, Vector3};

    fn state() -> NavState {
        NavState {
            velocity: Vector3::new(1.0, 0.2, 0.0),
            ..NavState::at_rest(UnitQuaternion::from_euler_angles(0.02, -0.01, 0.7), Vector3::new(3.0, -2.0, 0.5))
        }
    }

    /// A turning, accelerating body: 200 Hz for `seconds`.
    fn samples(seconds: f64) -> Vec<ImuSample> {
        (0..(seconds * 200.0) as usize)
            .map(|k| ImuSample {
                stamp: k as f64 / 200.0,
                angular_velocity: Vector3::new(0.05, -0.02, 0.3),
                specific_force: Vector3::new(0.4, 0.1, 9.81),
            })
            .collect()
    }

    /// The filter's covariance, with `yaw_m` of yaw (rad) and `position_m` of position (m)
    /// standard deviation besides a small tilt, velocity and bias uncertainty.
    fn covariance(yaw: f64, position_m: f64) -> Matrix17 {
        let mut d = [1e-6; STATE_DIM];
        d[2] = yaw * yaw;
        for v in d.iter_mut().skip(3).take(3) {
            *v = position_m * position_m;
        }
        for v in d.iter_mut().skip(6).take(3) {
            *v = 1e-3;
        }
        Matrix17::from_diagonal(&SMatrix::<f64, STATE_DIM, 1>::from_iterator(d))
    }

    fn propagated(p0: Matrix17, seconds: f64) -> (Propagator, PoseClone) {
        propagated_from(state(), p0, seconds)
    }

    fn propagated_from(start: NavState, p0: Matrix17, seconds: f64) -> (Propagator, PoseClone) {
        let mut p = Propagator::new(start, p0, ImuNoise::default());
        p.clone = Some(PoseClone::of(&p.state, &p.covariance));
        for s in samples(seconds) {
            assert!(p.propagate(&s, 0.005));
        }
        let clone = p.clone.take().expect("carried along");
        (p, clone)
    }

    /// Closed form: marked and not moved, the motion is the identity, known exactly.
    #[test]
    fn the_motion_to_the_marked_scan_itself_is_certain() {
        let p = covariance(0.3, 5.0);
        let clone = PoseClone::of(&state(), &p);
        assert!(clone.motion_covariance(&state(), &p).norm() < 1e-12);
    }

    /// Where the filter stands and which way it faces about gravity is not what the motion
    /// since the mark depends on (nothing in the dynamics knows them): a level body at rest,
    /// with 1 mrad and 0.5 rad of yaw, 1 cm and 100 m of position, then driven by the same
    /// second of samples, gives the same motion covariance, while the two pose covariances
    /// differ by ten orders of magnitude. (A body already moving would not: its velocity is
    /// held in the world's axes, so its yaw error turns the motion.)
    #[test]
    fn the_motion_covariance_does_not_see_the_frames_own_uncertainty() {
        let level = NavState::at_rest(UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7), Vector3::new(3.0, -2.0, 0.5));
        let (a, clone_a) = propagated_from(level, covariance(1e-3, 0.01), 1.0);
        let (b, clone_b) = propagated_from(level, covariance(0.5, 100.0), 1.0);
        let ma = clone_a.motion_covariance(&a.state, &a.covariance);
        let mb = clone_b.motion_covariance(&b.state, &b.covariance);
        // To rounding: 10⁴ m² of position cancels down to 10⁻³ (1e-7 relative here; 1e-9 at 10 m).
        assert!((ma - mb).norm() < 1e-6 * ma.norm(), "{} of {}", (ma - mb).norm(), ma.norm());
        assert!(ma.diagonal().iter().all(|v| *v > 0.0), "the motion is not known exactly: {ma}");
        let pose_b = b.covariance.fixed_view::<6, 6>(0, 0).norm();
        assert!(pose_b > 1e6 * ma.norm(), "the pose is far less certain than the motion");
    }

    /// The update is the augmented state's Kalman update: checked against the 23-state filter
    /// built explicitly and updated by the textbook form P⁺ = P − P Hᵀ (H P Hᵀ + Λ⁻¹)⁻¹ H P.
    #[test]
    fn the_update_is_the_augmented_kalman_update() {
        let (p, mut clone) = propagated(covariance(0.1, 1.0), 0.5);
        let lambda = Matrix6::from_diagonal(&nalgebra::Vector6::new(400.0, 300.0, 900.0, 2e4, 1e4, 5e3));
        let registered = pose_of(&p.state);
        let (next, posterior) = apply_pose_update(&p.state, &p.covariance, &registered, &lambda).expect("updates");
        const N: usize = STATE_DIM + 6;
        let mut augmented = SMatrix::<f64, N, N>::zeros();
        augmented.fixed_view_mut::<STATE_DIM, STATE_DIM>(0, 0).copy_from(&p.covariance);
        augmented.fixed_view_mut::<STATE_DIM, 6>(0, STATE_DIM).copy_from(&clone.cross);
        augmented.fixed_view_mut::<6, STATE_DIM>(STATE_DIM, 0).copy_from(&clone.cross.transpose());
        augmented.fixed_view_mut::<6, 6>(STATE_DIM, STATE_DIM).copy_from(&clone.covariance);
        let mut h = SMatrix::<f64, 6, N>::zeros();
        h.fixed_view_mut::<6, 6>(0, 0).copy_from(&Matrix6::identity());
        let s = h * augmented * h.transpose() + lambda.try_inverse().expect("invertible");
        let expected = augmented - augmented * h.transpose() * s.try_inverse().expect("invertible") * h * augmented;
        clone.update(&p.covariance, &posterior).expect("a regular prior");
        let scale = expected.norm();
        assert!((clone.cross - expected.fixed_view::<STATE_DIM, 6>(0, STATE_DIM)).norm() < 1e-9 * scale);
        assert!((clone.covariance - expected.fixed_view::<6, 6>(STATE_DIM, STATE_DIM)).norm() < 1e-9 * scale);
        let p_next = expected.fixed_view::<STATE_DIM, STATE_DIM>(0, 0);
        assert!((posterior - p_next).norm() < 1e-9 * scale, "update agrees too");
        let motion = clone.motion_covariance(&next, &posterior);
        assert!(motion.cholesky().is_some(), "positive definite: {motion}");
    }
}
