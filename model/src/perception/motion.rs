//! The body's motion between sensor stamps under the constant-velocity model: the twist ξ
//! (body frame, per second) from two consecutive odometry poses,
//!
//!   ξ = Log(odom(t₀)⁻¹ · odom(t₁)) / (t₁ − t₀),    B(t₁ + δ) = B(t₁) · Exp(δ·ξ),
//!
//! used to deskew a sweep ([`super::deskew`]) and to label a scan from an image taken δ after
//! it: a point p of the body at the scan's stamp is, in the body at the image's,
//! Exp(δ·ξ)⁻¹ · p, so
//!
//!   camera_from_scan_body = camera_from_body · Exp(δ·ξ)⁻¹            ([`camera_at_offset`])

use crate::geometry::lie::{se3_exp, se3_log, Tangent3};
use crate::geometry::Pose3;

/// The constant body twist (per second) that takes `earlier` (at `t0`) to `later` (at `t1`);
/// none when the times do not increase.
pub fn twist_between(earlier: &Pose3, t0: f64, later: &Pose3, t1: f64) -> Option<Tangent3> {
    let dt = t1 - t0;
    (dt.is_finite() && dt > 0.0).then(|| se3_log(&(earlier.inverse() * later)) / dt)
}

/// The twist of a stream of odometry poses: from the previous pose to the latest.
#[derive(Clone, Debug, Default)]
pub struct ConstantVelocity {
    last: Option<(f64, Pose3)>,
}

impl ConstantVelocity {
    /// Takes the pose at `stamp`; returns the twist from the previous one to it (none for the
    /// first, or when time did not move on; a stamp that goes back is not kept).
    pub fn update(&mut self, stamp: f64, odom_from_body: &Pose3) -> Option<Tangent3> {
        let twist = self.last.and_then(|(t0, earlier)| twist_between(&earlier, t0, odom_from_body, stamp));
        if self.last.is_none_or(|(t0, _)| stamp > t0) {
            self.last = Some((stamp, *odom_from_body));
        }
        twist
    }
}

/// The camera of an image taken `offset_s` after a scan's stamp, from the body at the scan's
/// stamp, the body moving at `twist`.
pub fn camera_at_offset(camera_from_body: &Pose3, twist: &Tangent3, offset_s: f64) -> Pose3 {
    camera_from_body * se3_exp(&(twist * offset_s)).inverse()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_rpy_translation;
    use nalgebra::{Point3, Vector3};
    use proptest::prelude::*;

    #[test]
    fn the_twist_of_two_odometry_poses_is_per_second() {
        let a = pose_from_rpy_translation(0.0, 0.0, 0.2, Vector3::new(1.0, 0.0, 0.0));
        let b = a * pose_from_rpy_translation(0.0, 0.0, 0.1, Vector3::new(0.5, 0.0, 0.0));
        let twist = twist_between(&a, 10.0, &b, 10.5).expect("increasing times");
        assert!((twist[2] - 0.2).abs() < 1e-12, "0.1 rad in 0.5 s: {twist}");
        assert!(twist_between(&a, 10.0, &b, 10.0).is_none());
        let mut velocity = ConstantVelocity::default();
        assert!(velocity.update(10.0, &a).is_none(), "no earlier pose");
        assert!(velocity.update(9.0, &b).is_none(), "time went back");
        let again = velocity.update(10.5, &b).expect("the pose at 10 s was kept");
        assert!((again - twist).norm() < 1e-12);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// A point seen from the body at the scan's stamp projects where the camera at the
        /// image's stamp sees the same world point (closed form: the body moving at a constant
        /// twist, camera_at_offset against the true poses).
        #[test]
        fn the_camera_at_an_offset_sees_the_world_point_where_it_is(
            w in prop::array::uniform3(-1.0f64..1.0),
            v in prop::array::uniform3(-3.0f64..3.0),
            offset in -0.1f64..0.1,
            p in prop::array::uniform3(-10.0f64..10.0),
        ) {
            let twist = Tangent3::new(w[0], w[1], w[2], v[0], v[1], v[2]);
            let scan = pose_from_rpy_translation(0.1, -0.05, 1.0, Vector3::new(3.0, -2.0, 0.4));
            let image = scan * se3_exp(&(twist * offset));
            let mount = pose_from_rpy_translation(-1.5, 0.1, -1.4, Vector3::new(0.1, 0.02, -0.05));
            let world = Point3::from(p);
            let expected = mount * image.inverse() * world;
            let got = camera_at_offset(&mount, &twist, offset) * (scan.inverse() * world);
            prop_assert!((got - expected).norm() < 1e-9, "{got} vs {expected}");
        }
    }
}
