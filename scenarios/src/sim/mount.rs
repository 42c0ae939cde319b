//! Where a sensor sits on the body, and what the robot is told: the configured mount is off the
//! true one by a seeded calibration error, each robot its own. The error is a motion of the
//! sensor in the body,
//!
//!   body_from_told = body_from_true · E,    E = (R(axis, error_deg), t: |t| = error_m),
//!
//! with the axis and the translation's direction drawn uniformly on the sphere.

use crate::scenario::LidarSpec;
use nalgebra::{Point3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use sgm_model::geometry::{pose_from_rpy_translation, Pose3};

/// `body_from_sensor` for a mount at `xyz_m` turned by `rpy_deg` (roll, pitch, yaw).
pub fn body_from_mount(xyz_m: [f64; 3], rpy_deg: [f64; 3]) -> Pose3 {
    let [roll, pitch, yaw] = rpy_deg.map(f64::to_radians);
    pose_from_rpy_translation(roll, pitch, yaw, Vector3::from(xyz_m))
}

/// The calibration error E of robot `robot`'s sensor (`salt` tells the sensors apart), drawn
/// from `seed`; `None` when none is asked.
pub fn calibration_error(error_deg: f64, error_m: f64, seed: u64, salt: u64, robot: usize) -> Option<Pose3> {
    if error_deg == 0.0 && error_m == 0.0 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ salt ^ ((robot as u64 + 1) << 32));
    let mut unit = || {
        let v = Vector3::from_fn(|_, _| StandardNormal.sample(&mut rng));
        v.try_normalize(1e-9).unwrap_or_else(Vector3::x)
    };
    let axis = Unit::new_normalize(unit());
    Some(Pose3::from_parts(
        Translation3::from(unit() * error_m),
        UnitQuaternion::from_axis_angle(&axis, error_deg.to_radians()),
    ))
}

/// A robot's LiDAR mount (`[lidar] mount_*`): the true one, from which the simulator casts, and
/// the one the robot is told, with which its driver brings the returns into the body frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LidarMount {
    pub body_from_lidar: Pose3,
    /// `None`: the LiDAR is the body (the default), nothing to convert.
    told_from_true: Option<Pose3>,
}

const LIDAR_SALT: u64 = 0x11DA_8A00;

impl LidarMount {
    pub fn new(spec: &LidarSpec, seed: u64, robot: usize) -> Self {
        let at_body = spec.mount_xyz_m == [0.0; 3] && spec.mount_rpy_deg == [0.0; 3];
        let body_from_lidar =
            if at_body { Pose3::identity() } else { body_from_mount(spec.mount_xyz_m, spec.mount_rpy_deg) };
        let error = calibration_error(spec.mount_error_deg, spec.mount_error_m, seed, LIDAR_SALT, robot);
        // A return p in the body (through the true mount) is p_lidar = body_from_lidar⁻¹ · p;
        // the robot puts it at body_from_told · p_lidar = body_from_lidar · E · body_from_lidar⁻¹ · p.
        let told_from_true = error.map(|e| body_from_lidar * e * body_from_lidar.inverse());
        Self { body_from_lidar, told_from_true }
    }

    /// Whether the simulator casts from the body itself.
    pub fn at_body(&self) -> bool {
        self.body_from_lidar == Pose3::identity()
    }

    /// The returns (in the body frame, through the true mount) where the robot's configured
    /// mount puts them, in float32 as a driver publishes them; unchanged without an error.
    pub fn as_told(&self, points: &[Point3<f64>]) -> Option<Vec<Point3<f64>>> {
        let told_from_true = self.told_from_true?;
        Some(points.iter().map(|p| (told_from_true * p).map(|v| f64::from(v as f32))).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_told_lidar_mount_is_off_by_the_error_and_each_robot_has_its_own() {
        let spec = LidarSpec {
            mount_xyz_m: [0.2, 0.0, 0.1],
            mount_rpy_deg: [0.0, 10.0, 0.0],
            mount_error_deg: 1.0,
            mount_error_m: 0.03,
            ..LidarSpec::default()
        };
        let (a, b) = (LidarMount::new(&spec, 5, 0), LidarMount::new(&spec, 5, 1));
        assert_ne!(a.told_from_true, b.told_from_true);
        // A return 10 m ahead of the LiDAR, through each robot's told mount.
        let p_lidar = Point3::new(10.0, 0.0, 0.0);
        for m in [a, b] {
            let p_true = m.body_from_lidar * p_lidar;
            let told = m.as_told(&[p_true]).expect("an error was asked")[0];
            // Told = body_from_lidar · E · p_lidar: E's rotation moves it by 10 m · 2 sin(½°)
            // at most, its translation by 3 cm.
            let moved = (told - p_true).norm();
            assert!(moved > 0.0 && moved <= 10.0 * 2.0 * 0.5f64.to_radians().sin() + 0.03 + 1e-5, "{moved}");
            let e = m.body_from_lidar.inverse() * m.told_from_true.expect("error") * m.body_from_lidar;
            assert!((e.rotation.angle().to_degrees() - 1.0).abs() < 1e-9);
            assert!((e.translation.vector.norm() - 0.03).abs() < 1e-9);
        }
        let exact = LidarMount::new(&LidarSpec { mount_error_deg: 0.0, mount_error_m: 0.0, ..spec }, 5, 0);
        assert!(exact.as_told(&[p_lidar]).is_none() && !exact.at_body());
        assert!(LidarMount::new(&LidarSpec::default(), 5, 0).at_body());
    }
}
