//! IMU propagation of the odometry's state and of its uncertainty: the prediction that scan
//! registration starts from and is held by (`registration::Prior`).
//!
//! State: world_from_body rotation R, position p and velocity v in the odometry frame, the
//! direction u of "up" (against gravity) in that frame, gyroscope and accelerometer biases
//! b_g, b_a. A sample (ω̃, f̃) holds over Δt:
//!
//! ```text
//! v ← v + (R (f̃ − b_a) − g u) Δt
//! p ← p + v Δt                      (the new v: semi-implicit Euler)
//! R ← R Exp((ω̃ − b_g) Δt)
//! ```
//!
//! the discretisation the simulator's samples are built for, so noise-free samples integrate
//! back to the truth exactly. The error state δx = (δθ, δp, δv, δb_g, δb_a, δu), R = R̂ Exp(δθ),
//! u = Exp(B δu) û with B = [x̂ ŷ] (a tilt of up about the frame's horizontal axes: u stays
//! within degrees of ẑ, where B spans its tangent; FAST-LIO2 keeps gravity on S² the same way)
//! (Solà 2017, "Quaternion kinematics for the error-state Kalman filter", §5.3 and §7.2, with
//! this discretisation), propagates as P ← F P Fᵀ + Q with, for ω = ω̃ − b̂_g, f = f̃ − b̂_a:
//!
//! ```text
//! δθ' = Exp(−ω Δt) δθ − J_r(ω Δt) Δt δb_g
//! δv' = δv − R̂ f^ Δt δθ − R̂ Δt δb_a + g û^ B Δt δu
//! δp' = δp + Δt δv'
//! δb' = δb,  δu' = δu
//! Q: σ_g² Δt on δθ, σ_a² Δt on δv (and Δt² of it on δp, Δt on their cross term),
//!    σ_bg² Δt, σ_ba² Δt on the biases        (σ: continuous densities, per √Hz)
//! ```
//!
//! Why up is estimated: the odometry frame is levelled from the first samples' mean force,
//! which is gravity only if the body did not accelerate and the accelerometer had no bias. A
//! rig swaying in a hand, or a turn-on bias of 9 mg, tilts it by half a degree or more, and a
//! filter sure that up is ẑ reads g·sin(tilt) as motion: an accelerometer bias absorbs it
//! only while the heading holds. Without this state a 0.5° tilt sent a legged robot 64 m off
//! in a minute, and the handheld rig of `handheld_indoor` 570 m.
//!
//! F is checked against numeric differentiation of the propagation in the tests.

use crate::geometry::lie::{hat, se3_right_jacobian, Tangent3};
use crate::perception::imu::ImuSample;
use nalgebra::{Matrix3, SMatrix, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Dimension of the error state (δθ, δp, δv, δb_g, δb_a, δu).
pub const STATE_DIM: usize = 17;
/// Where δu starts in the error state.
pub const UP: usize = 15;
/// 17 × 17 over the error state.
pub type Matrix17 = SMatrix<f64, STATE_DIM, STATE_DIM>;
/// An error state.
pub type Vector17 = SMatrix<f64, STATE_DIM, 1>;

/// Continuous noise densities of the IMU (a datasheet's or a Kalibr calibration's). Defaults:
/// EuRoC's ADIS16448, as the simulator's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImuNoise {
    /// rad/s/√Hz. Default 1.6968e-4.
    pub gyro_noise: f64,
    /// m/s²/√Hz. Default 2.0e-3.
    pub accel_noise: f64,
    /// rad/s²/√Hz. Default 1.9393e-5.
    pub gyro_bias_walk: f64,
    /// m/s³/√Hz. Default 3.0e-3.
    pub accel_bias_walk: f64,
    /// m/s². Default 9.81.
    pub gravity_mps2: f64,
}

impl Default for ImuNoise {
    fn default() -> Self {
        Self {
            gyro_noise: 1.6968e-4,
            accel_noise: 2.0e-3,
            gyro_bias_walk: 1.9393e-5,
            accel_bias_walk: 3.0e-3,
            gravity_mps2: 9.81,
        }
    }
}

/// The navigation state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NavState {
    pub rotation: UnitQuaternion<f64>,
    pub position: Vector3<f64>,
    pub velocity: Vector3<f64>,
    pub gyro_bias: Vector3<f64>,
    pub accel_bias: Vector3<f64>,
    /// Up (against gravity) in the odometry frame, a unit vector.
    pub up: Vector3<f64>,
}

impl NavState {
    /// At rest at `position`, turned by `rotation`, biases zero, up ẑ.
    pub fn at_rest(rotation: UnitQuaternion<f64>, position: Vector3<f64>) -> Self {
        Self {
            rotation,
            position,
            velocity: Vector3::zeros(),
            gyro_bias: Vector3::zeros(),
            accel_bias: Vector3::zeros(),
            up: Vector3::z(),
        }
    }

    /// Up moved by the error δu: Exp(B δu) û (module notes).
    pub fn up_moved(&self, du: &nalgebra::Vector2<f64>) -> Vector3<f64> {
        (UnitQuaternion::from_scaled_axis(Vector3::new(du.x, du.y, 0.0)) * self.up).normalize()
    }

    /// The state after one sample held for `dt` (the module's equations).
    pub fn propagated(&self, sample: &ImuSample, dt: f64, gravity_mps2: f64) -> Self {
        let f = sample.specific_force - self.accel_bias;
        let w = sample.angular_velocity - self.gyro_bias;
        let velocity = self.velocity + (self.rotation * f - self.up * gravity_mps2) * dt;
        Self {
            rotation: self.rotation * UnitQuaternion::from_scaled_axis(w * dt),
            position: self.position + velocity * dt,
            velocity,
            ..*self
        }
    }
}

/// SO(3) right Jacobian, the rotation block of SE(3)'s.
fn so3_right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let xi = Tangent3::new(phi.x, phi.y, phi.z, 0.0, 0.0, 0.0);
    se3_right_jacobian(&xi).fixed_view::<3, 3>(0, 0).into_owned()
}

/// B of the module notes: δu's axes, the frame's x̂ and ŷ.
fn up_basis() -> SMatrix<f64, 3, 2> {
    SMatrix::<f64, 3, 2>::new(1.0, 0.0, 0.0, 1.0, 0.0, 0.0)
}

/// F of the module notes for one sample at `state`, gravity `gravity_mps2`.
pub fn transition(state: &NavState, sample: &ImuSample, dt: f64, gravity_mps2: f64) -> Matrix17 {
    let f = sample.specific_force - state.accel_bias;
    let w = (sample.angular_velocity - state.gyro_bias) * dt;
    let r = state.rotation.to_rotation_matrix().into_inner();
    let i = Matrix3::identity();
    let mut m = Matrix17::identity();
    let f_vtheta = -r * hat(&f) * dt;
    let f_vba = -r * dt;
    let f_vu = hat(&state.up) * up_basis() * (gravity_mps2 * dt);
    m.fixed_view_mut::<3, 2>(6, UP).copy_from(&f_vu);
    m.fixed_view_mut::<3, 2>(3, UP).copy_from(&(f_vu * dt));
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&UnitQuaternion::from_scaled_axis(-w).to_rotation_matrix().into_inner());
    m.fixed_view_mut::<3, 3>(0, 9).copy_from(&(-so3_right_jacobian(&w) * dt));
    m.fixed_view_mut::<3, 3>(6, 0).copy_from(&f_vtheta);
    m.fixed_view_mut::<3, 3>(6, 12).copy_from(&f_vba);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(f_vtheta * dt));
    m.fixed_view_mut::<3, 3>(3, 6).copy_from(&(i * dt));
    m.fixed_view_mut::<3, 3>(3, 12).copy_from(&(f_vba * dt));
    m
}

/// Q of the module notes.
pub fn process_noise(noise: &ImuNoise, dt: f64) -> Matrix17 {
    let i = Matrix3::identity();
    let (g2, a2) = (noise.gyro_noise.powi(2) * dt, noise.accel_noise.powi(2) * dt);
    let mut q = Matrix17::zeros();
    q.fixed_view_mut::<3, 3>(0, 0).copy_from(&(i * g2));
    q.fixed_view_mut::<3, 3>(6, 6).copy_from(&(i * a2));
    q.fixed_view_mut::<3, 3>(3, 3).copy_from(&(i * a2 * dt * dt));
    q.fixed_view_mut::<3, 3>(3, 6).copy_from(&(i * a2 * dt));
    q.fixed_view_mut::<3, 3>(6, 3).copy_from(&(i * a2 * dt));
    q.fixed_view_mut::<3, 3>(9, 9).copy_from(&(i * noise.gyro_bias_walk.powi(2) * dt));
    q.fixed_view_mut::<3, 3>(12, 12).copy_from(&(i * noise.accel_bias_walk.powi(2) * dt));
    q
}

/// The state and its covariance, propagated sample by sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Propagator {
    pub state: NavState,
    pub covariance: Matrix17,
    pub noise: ImuNoise,
    /// The pose at a marked scan, carried along for the motion's covariance since (`clone`).
    pub clone: Option<super::clone::PoseClone>,
}

impl Propagator {
    pub fn new(state: NavState, covariance: Matrix17, noise: ImuNoise) -> Self {
        Self { state, covariance, noise, clone: None }
    }

    /// One sample held for `dt` s. Non-finite samples and non-positive or non-finite `dt` are
    /// refused (false) and change nothing.
    pub fn propagate(&mut self, sample: &ImuSample, dt: f64) -> bool {
        let noise = self.noise;
        self.propagate_with(sample, dt, &noise)
    }

    /// As [`Self::propagate`], with the process noise of `noise` instead of the IMU's (a sample
    /// held over a gap is less certain than one that was measured); gravity stays the IMU's.
    pub fn propagate_with(&mut self, sample: &ImuSample, dt: f64, noise: &ImuNoise) -> bool {
        let finite = sample.angular_velocity.iter().chain(sample.specific_force.iter()).all(|v| v.is_finite());
        if !(finite && dt.is_finite() && dt > 0.0) {
            return false;
        }
        let f = transition(&self.state, sample, dt, self.noise.gravity_mps2);
        self.covariance = f * self.covariance * f.transpose() + process_noise(noise, dt);
        if let Some(clone) = &mut self.clone {
            clone.propagate(&f);
        }
        self.state = self.state.propagated(sample, dt, self.noise.gravity_mps2);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An analytic motion: turning and climbing, rolling and pitching.
    fn truth(t: f64) -> (UnitQuaternion<f64>, Vector3<f64>) {
        let rotation = UnitQuaternion::from_euler_angles(0.1 * (2.0 * t).sin(), 0.05 * (3.0 * t).cos(), 0.4 * t);
        let position = Vector3::new(5.0 * (0.4 * t).cos(), 5.0 * (0.4 * t).sin(), 0.2 * t + 0.05 * (4.0 * t).sin());
        (rotation, position)
    }

    /// The samples the simulator would build from `truth` at ticks k·dt (its module's notes).
    fn sample(k: i64, dt: f64, g: f64) -> ImuSample {
        let t = k as f64 * dt;
        let ((r0, p0), (r1, p1), (_, pm)) = (truth(t), truth(t + dt), truth(t - dt));
        let w = (r0.inverse() * r1).scaled_axis() / dt;
        let a = (p1 - 2.0 * p0 + pm) / (dt * dt);
        ImuSample { stamp: t, angular_velocity: w, specific_force: r0.inverse() * (a + Vector3::z() * g) }
    }

    #[test]
    fn noise_free_samples_propagate_back_to_the_truth() {
        let (dt, g) = (0.005, 9.81);
        let (r0, p0) = truth(0.0);
        let before = truth(-dt).1;
        let mut state = NavState { velocity: (p0 - before) / dt, ..NavState::at_rest(r0, p0) };
        for k in 0..2000 {
            state = state.propagated(&sample(k, dt, g), dt, g);
        }
        let (r, p) = truth(2000.0 * dt);
        assert!((state.position - p).norm() < 1e-6, "{} vs {p}", state.position);
        assert!(state.rotation.angle_to(&r) < 1e-9);
    }

    /// The state moved by an error δx: R Exp(δθ), p + δp, v + δv, biases + δb, Exp(B δu) u.
    fn perturbed(s: &NavState, d: &Vector17) -> NavState {
        let v = |k: usize| Vector3::new(d[k], d[k + 1], d[k + 2]);
        NavState {
            rotation: s.rotation * UnitQuaternion::from_scaled_axis(v(0)),
            position: s.position + v(3),
            velocity: s.velocity + v(6),
            gyro_bias: s.gyro_bias + v(9),
            accel_bias: s.accel_bias + v(12),
            up: s.up_moved(&nalgebra::Vector2::new(d[UP], d[UP + 1])),
        }
    }

    /// The error between two states, the inverse of `perturbed` (to first order in δu: the
    /// least-squares δu of a.up − b.up ≈ −b.up^ B δu).
    fn difference(a: &NavState, b: &NavState) -> Vector17 {
        let mut d = Vector17::zeros();
        d.fixed_rows_mut::<3>(0).copy_from(&(b.rotation.inverse() * a.rotation).scaled_axis());
        d.fixed_rows_mut::<3>(3).copy_from(&(a.position - b.position));
        d.fixed_rows_mut::<3>(6).copy_from(&(a.velocity - b.velocity));
        d.fixed_rows_mut::<3>(9).copy_from(&(a.gyro_bias - b.gyro_bias));
        d.fixed_rows_mut::<3>(12).copy_from(&(a.accel_bias - b.accel_bias));
        let j = -hat(&b.up) * up_basis();
        let du = (j.transpose() * j).try_inverse().expect("B spans up's tangent") * j.transpose() * (a.up - b.up);
        d.fixed_rows_mut::<2>(UP).copy_from(&du);
        d
    }

    #[test]
    fn the_transition_matches_numeric_differentiation() {
        let (dt, g) = (0.01, 9.81);
        let state = NavState {
            rotation: UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1),
            position: Vector3::new(1.0, 2.0, 3.0),
            velocity: Vector3::new(0.5, -0.3, 0.1),
            gyro_bias: Vector3::new(0.01, -0.02, 0.005),
            accel_bias: Vector3::new(0.1, 0.05, -0.08),
            up: (UnitQuaternion::from_euler_angles(0.03, -0.02, 0.0) * Vector3::z()),
        };
        let s = ImuSample {
            stamp: 0.0,
            angular_velocity: Vector3::new(0.8, -1.5, 2.0),
            specific_force: Vector3::new(1.0, -0.5, 9.9),
        };
        let f = transition(&state, &s, dt, g);
        let nominal = state.propagated(&s, dt, g);
        let h = 1e-6;
        for k in 0..STATE_DIM {
            let mut d = Vector17::zeros();
            d[k] = h;
            let plus = difference(&perturbed(&state, &d).propagated(&s, dt, g), &nominal);
            let minus = difference(&perturbed(&state, &(-d)).propagated(&s, dt, g), &nominal);
            let numeric = (plus - minus) / (2.0 * h);
            assert!((numeric - f.column(k)).norm() < 1e-6, "column {k}: {numeric} vs {}", f.column(k));
        }
    }

    #[test]
    fn uncertainty_grows_and_bad_samples_change_nothing() {
        let state = NavState::at_rest(UnitQuaternion::identity(), Vector3::zeros());
        let mut p = Propagator::new(state, Matrix17::identity() * 1e-6, ImuNoise::default());
        let still = ImuSample { stamp: 0.0, angular_velocity: Vector3::zeros(), specific_force: Vector3::z() * 9.81 };
        for _ in 0..200 {
            assert!(p.propagate(&still, 0.005));
        }
        // At rest it stays put, and position uncertainty grew beyond its start.
        assert!(p.state.position.norm() < 1e-12 && p.state.velocity.norm() < 1e-12);
        assert!(p.covariance[(3, 3)] > 1e-6);
        let before = p.clone();
        let nan = ImuSample { specific_force: Vector3::new(f64::NAN, 0.0, 0.0), ..still };
        assert!(!p.propagate(&nan, 0.005));
        assert!(!p.propagate(&still, 0.0));
        assert!(!p.propagate(&still, f64::INFINITY));
        assert_eq!(p, before);
    }
}
