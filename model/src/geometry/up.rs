//! Up, the direction against gravity, as a body or an odometry measures it: shared by the
//! odometry, which learns it, and the pose graph's gravity priors (`optim::gravity`), which hold
//! keyframes to it.

use nalgebra::{UnitQuaternion, Vector3};

/// The world's up seen in a body at `attitude` (world_from_body rotation), or `None` unless the
/// attitude is a finite unit quaternion.
pub fn up_in_body(attitude: &UnitQuaternion<f64>) -> Option<Vector3<f64>> {
    let q = attitude.quaternion();
    let rotation = q.coords.iter().all(|v| v.is_finite()) && (q.norm() - 1.0).abs() < 1e-6;
    rotation.then(|| attitude.inverse() * Vector3::z())
}

/// What an odometry that estimates up measured at a scan: the body's attitude in the
/// odometry's own frame (fixed for its run), and up in that frame as it knew it then, with its
/// σ (rad, on each horizontal axis).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeasuredUp {
    pub attitude_in_frame: UnitQuaternion<f64>,
    pub up_in_frame: Vector3<f64>,
    pub sigma_rad: f64,
}

impl MeasuredUp {
    /// Whether the attitude is a finite unit quaternion, up a finite unit vector (both within
    /// 1e-6) and σ finite and ≥ 0: what came from outside is checked once, here.
    pub fn is_valid(&self) -> bool {
        unit_up(&self.up_in_frame)
            && up_in_body(&self.attitude_in_frame).is_some()
            && self.sigma_rad.is_finite()
            && self.sigma_rad >= 0.0
    }

    /// Up in the body: R_Fᵀ û.
    pub fn up_in_body(&self) -> Vector3<f64> {
        self.attitude_in_frame.inverse() * self.up_in_frame
    }
}

/// Whether `up` is a finite unit vector (within 1e-6).
pub fn unit_up(up: &Vector3<f64>) -> bool {
    up.iter().all(|v| v.is_finite()) && (up.norm() - 1.0).abs() < 1e-6
}
