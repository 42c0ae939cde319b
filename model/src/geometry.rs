//! Rigid transforms over nalgebra and weighted rigid fits between corresponding point sets.
//!
//! Paper §IV-C: with matched centroids p_local ↔ p_remote, find T = `local_from_remote` such that
//! p_local ≈ T · p_remote. Two models:
//!
//! * **planar** (the paper's choice, robots' world frames are gravity aligned): yaw θ and
//!   translation (tx, ty) from the horizontal coordinates by weighted 2-D Procrustes, then the z
//!   offset as the weighted mean of z_local − z_remote. With weights w_k, centred points
//!   a_k = p_k − p̄, b_k = q_k − q̄ (weighted means):
//!   θ = atan2(Σ w_k (b_k × a_k), Σ w_k (b_k · a_k)),  t = p̄ − R(θ) q̄.
//! * **full 3-D** (Umeyama 1991 without scale, i.e. weighted Kabsch): H = Σ w_k b_k a_kᵀ,
//!   H = U Σ Vᵀ, R = V diag(1, 1, det(V Uᵀ)) Uᵀ, t = p̄ − R q̄.

pub mod lie;
pub mod point_to_plane;
pub mod up;

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// A rigid transform in 3-D. Name values `a_from_b`.
pub type Pose3 = Isometry3<f64>;

/// Builds `a_from_b` from a yaw angle (radians, about +z) and a translation.
pub fn pose_from_yaw_translation(yaw: f64, translation: Vector3<f64>) -> Pose3 {
    Isometry3::from_parts(Translation3::from(translation), UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw))
}

/// Builds a pose from roll, pitch, yaw (radians, extrinsic x-y-z as nalgebra) and a translation.
pub fn pose_from_rpy_translation(roll: f64, pitch: f64, yaw: f64, translation: Vector3<f64>) -> Pose3 {
    Isometry3::from_parts(Translation3::from(translation), UnitQuaternion::from_euler_angles(roll, pitch, yaw))
}

/// The pose a fraction `s` ∈ [0, 1] of the way from `a` to `b`: translation linear, rotation
/// by slerp (the constant-velocity model between two stamped poses).
pub fn interpolate(a: &Pose3, b: &Pose3, s: f64) -> Pose3 {
    let translation = a.translation.vector.lerp(&b.translation.vector, s);
    Isometry3::from_parts(Translation3::from(translation), a.rotation.slerp(&b.rotation, s))
}

/// Yaw of a pose's rotation (radians in (−π, π]).
pub fn yaw_of(pose: &Pose3) -> f64 {
    pose.rotation.euler_angles().2
}

/// `pose` levelled: its yaw ([`yaw_of`]) and translation, no roll or pitch.
pub fn levelled(pose: &Pose3) -> Pose3 {
    pose_from_yaw_translation(yaw_of(pose), pose.translation.vector)
}

/// A pose for log lines and messages: "(x, y, z) m, yaw θ°" (centimetres, tenths of a degree).
pub struct Brief<'a>(pub &'a Pose3);

impl std::fmt::Display for Brief<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let t = self.0.translation.vector;
        write!(f, "({:.2}, {:.2}, {:.2}) m, yaw {:.1}°", t.x, t.y, t.z, yaw_of(self.0).to_degrees())
    }
}

/// Smallest signed difference a − b of two angles, in (−π, π].
pub fn angle_difference(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    if d > std::f64::consts::PI {
        d - std::f64::consts::TAU
    } else {
        d
    }
}

/// Which rigid model a fit estimates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum RigidModel {
    /// x, y, yaw from the horizontal coordinates plus a z offset (paper §IV-C).
    #[default]
    Planar,
    /// Full SE(3) by weighted Kabsch/Umeyama.
    Full3d,
}

/// One weighted correspondence: `in_local ≈ local_from_remote · in_remote`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Correspondence {
    pub in_local: Point3<f64>,
    pub in_remote: Point3<f64>,
    pub weight: f64,
}

/// Weighted means of both sides; `None` when the total weight is not positive.
fn weighted_centroids(pairs: &[Correspondence]) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    let total: f64 = pairs.iter().map(|c| c.weight).sum();
    if !total.is_finite() || total <= 0.0 {
        return None;
    }
    let (mut local, mut remote) = (Vector3::zeros(), Vector3::zeros());
    for c in pairs {
        local += c.weight * c.in_local.coords;
        remote += c.weight * c.in_remote.coords;
    }
    Some((local / total, remote / total, total))
}

/// Weighted least-squares `local_from_remote` under `model`. `None` if the weights are degenerate
/// (no positive weight, or non-finite input). Needs ≥ 2 pairs for planar, ≥ 3 non-collinear for 3-D
/// to be well determined; with fewer it still returns the minimum-norm answer.
pub fn fit_rigid(pairs: &[Correspondence], model: RigidModel) -> Option<Pose3> {
    let (local_mean, remote_mean, _) = weighted_centroids(pairs)?;
    let pose = match model {
        RigidModel::Planar => {
            let (mut dot, mut cross) = (0.0, 0.0);
            for c in pairs {
                let a = c.in_local.coords - local_mean;
                let b = c.in_remote.coords - remote_mean;
                dot += c.weight * (b.x * a.x + b.y * a.y);
                cross += c.weight * (b.x * a.y - b.y * a.x);
            }
            let yaw = if dot == 0.0 && cross == 0.0 { 0.0 } else { cross.atan2(dot) };
            let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
            let t = local_mean - rotation * remote_mean;
            Isometry3::from_parts(Translation3::from(t), rotation)
        }
        RigidModel::Full3d => {
            let mut h = Matrix3::zeros();
            for c in pairs {
                let a = c.in_local.coords - local_mean;
                let b = c.in_remote.coords - remote_mean;
                h += c.weight * b * a.transpose();
            }
            let svd = h.svd(true, true);
            let (u, v_t) = (svd.u?, svd.v_t?);
            let v = v_t.transpose();
            let d = (v * u.transpose()).determinant().signum();
            let correction = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, if d == 0.0 { 1.0 } else { d }));
            let r = v * correction * u.transpose();
            let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
            let t = local_mean - rotation * remote_mean;
            Isometry3::from_parts(Translation3::from(t), rotation)
        }
    };
    pose.translation.vector.iter().all(|x| x.is_finite()).then_some(pose)
}

/// Standard deviation of the points along their weakest horizontal (planar) or spatial (3-D)
/// principal axis: near zero when the points are (nearly) collinear.
pub fn minor_axis_spread(points: &[Point3<f64>], model: RigidModel) -> f64 {
    if points.len() < 2 {
        return 0.0;
    }
    let n = points.len() as f64;
    let mean = points.iter().fold(Vector3::zeros(), |acc, p| acc + p.coords) / n;
    let mut cov = Matrix3::zeros();
    for p in points {
        let d = p.coords - mean;
        cov += d * d.transpose();
    }
    cov /= n;
    let smallest = match model {
        RigidModel::Planar => {
            let (a, b, c) = (cov[(0, 0)], cov[(0, 1)], cov[(1, 1)]);
            let mid = 0.5 * (a + c);
            let radius = (0.25 * (a - c) * (a - c) + b * b).sqrt();
            mid - radius
        }
        RigidModel::Full3d => {
            // Spread along the second axis: three collinear points have two zero eigenvalues.
            let mut eig: Vec<f64> = cov.symmetric_eigenvalues().iter().copied().collect();
            eig.sort_by(|x, y| x.total_cmp(y));
            eig[1]
        }
    };
    smallest.max(0.0).sqrt()
}

/// Per-axis rotation error (roll, pitch, yaw) in degrees of `estimate` against `truth`, and the
/// translation error in metres: the success criterion of paper §V-A.
pub fn pose_error(estimate: &Pose3, truth: &Pose3) -> PoseError {
    let delta = truth.rotation.inverse() * estimate.rotation;
    let (r, p, y) = delta.euler_angles();
    PoseError {
        translation_m: (estimate.translation.vector - truth.translation.vector).norm(),
        roll_deg: r.abs().to_degrees(),
        pitch_deg: p.abs().to_degrees(),
        yaw_deg: y.abs().to_degrees(),
    }
}

/// Error of an estimated transform against the truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseError {
    pub translation_m: f64,
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
}

impl PoseError {
    /// Largest of the three per-axis rotation errors, degrees.
    pub fn max_axis_rotation_deg(&self) -> f64 {
        self.roll_deg.max(self.pitch_deg).max(self.yaw_deg)
    }
}

/// The pose with the smallest summed distance to the others (translation in m plus rotation in
/// rad × 10 m): a robust average of a handful of estimates.
pub fn medoid(poses: &[Pose3]) -> Option<Pose3> {
    let distance = |a: &Pose3, b: &Pose3| {
        let e = a.inverse() * b;
        e.translation.vector.norm() + 10.0 * e.rotation.angle()
    };
    poses
        .iter()
        .map(|p| (p, poses.iter().map(|q| distance(p, q)).sum::<f64>()))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(p, _)| *p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn pairs_from(truth: &Pose3, remote: &[Point3<f64>]) -> Vec<Correspondence> {
        remote.iter().map(|q| Correspondence { in_local: truth * q, in_remote: *q, weight: 1.0 }).collect()
    }

    proptest! {
        #[test]
        fn planar_fit_recovers_any_yaw_translation(
            yaw in -std::f64::consts::PI..std::f64::consts::PI, tx in -200.0f64..200.0, ty in -200.0f64..200.0, tz in -5.0f64..5.0,
            pts in prop::collection::vec((-50.0f64..50.0, -50.0f64..50.0, 0.0f64..3.0), 3..20),
        ) {
            let remote: Vec<Point3<f64>> = pts.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            prop_assume!(minor_axis_spread(&remote, RigidModel::Planar) > 0.5);
            let truth = pose_from_yaw_translation(yaw, Vector3::new(tx, ty, tz));
            let fit = fit_rigid(&pairs_from(&truth, &remote), RigidModel::Planar).unwrap();
            let e = pose_error(&fit, &truth);
            prop_assert!(e.translation_m < 1e-8, "{e:?}");
            prop_assert!(e.max_axis_rotation_deg() < 1e-8, "{e:?}");
        }

        #[test]
        fn full_fit_recovers_any_rigid_transform(
            r in -3.1f64..3.1, p in -1.5f64..1.5, y in -3.1f64..3.1,
            t in (-100.0f64..100.0, -100.0f64..100.0, -100.0f64..100.0),
            pts in prop::collection::vec((-50.0f64..50.0, -50.0f64..50.0, -10.0f64..10.0), 4..20),
        ) {
            let remote: Vec<Point3<f64>> = pts.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            prop_assume!(minor_axis_spread(&remote, RigidModel::Full3d) > 0.5);
            let truth = pose_from_rpy_translation(r, p, y, Vector3::new(t.0, t.1, t.2));
            let fit = fit_rigid(&pairs_from(&truth, &remote), RigidModel::Full3d).unwrap();
            let delta = truth.inverse() * fit;
            prop_assert!(delta.translation.vector.norm() < 1e-7);
            prop_assert!(delta.rotation.angle() < 1e-8);
        }
    }

    #[test]
    fn planar_weights_follow_closed_form_two_point_case() {
        // Two remote points on the x axis, local ones rotated by 90° and shifted: exact answer.
        let truth = pose_from_yaw_translation(std::f64::consts::FRAC_PI_2, Vector3::new(1.0, 2.0, 0.5));
        let remote = [Point3::new(0.0, 0.0, 0.0), Point3::new(4.0, 0.0, 1.0)];
        let fit = fit_rigid(&pairs_from(&truth, &remote), RigidModel::Planar).unwrap();
        assert!((yaw_of(&fit) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((fit.translation.vector - Vector3::new(1.0, 2.0, 0.5)).norm() < 1e-12);
    }

    #[test]
    fn zero_weights_give_none() {
        let c = Correspondence { in_local: Point3::origin(), in_remote: Point3::origin(), weight: 0.0 };
        assert!(fit_rigid(&[c, c], RigidModel::Planar).is_none());
    }

    #[test]
    fn collinear_points_have_no_spread() {
        let pts: Vec<_> = (0..5).map(|i| Point3::new(i as f64, 2.0 * i as f64, 0.3)).collect();
        assert!(minor_axis_spread(&pts, RigidModel::Planar) < 1e-9);
        assert!(minor_axis_spread(&pts, RigidModel::Full3d) < 1e-9);
        let square = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(2.0, 0.0, 0.0),
            Point3::new(0.0, 2.0, 0.0),
            Point3::new(2.0, 2.0, 0.0),
        ];
        assert!((minor_axis_spread(&square, RigidModel::Planar) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn angle_difference_wraps() {
        assert!((angle_difference(3.1, -3.1) - (6.2 - std::f64::consts::TAU)).abs() < 1e-12);
        assert!((angle_difference(0.5, 0.2) - 0.3).abs() < 1e-12);
    }
}
