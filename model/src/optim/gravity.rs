//! Gravity priors on a robot's own keyframes (beyond the paper): with an IMU the odometry's
//! roll and pitch are measured against gravity at every scan, so a keyframe's tilt is known
//! absolutely, not only relative to the keyframe before it. A pose graph of between factors
//! alone forgets that: a loop closure or an inter-robot factor whose registration leaves the
//! vertical weakly determined (walls without a shared floor, sensors at 0.5 and 1.5 m) bends the
//! chain, and the map tilts by degrees — the world is then no longer the gravity-aligned frame
//! the matcher's 4-DoF transform and the level anchors assume. VINS-Mono's loop closure
//! optimises only x, y, z and yaw for the same reason.
//!
//! Each local keyframe X = (R, t) whose attitude was measured, R_m (odometry's
//! odom_from_body rotation: gravity-aligned, its yaw free), gets a prior on its tilt alone:
//!
//! ```text
//! M = (R_z(ψ(X₀)) · T(R_m), t(X₀))        T(R) = R_z(ψ(R))⁻¹ · R = R_y(pitch) R_x(roll)
//! e = P · Log(M⁻¹ · X)[ω],   P = I − u uᵀ,   u = R_M⁻¹ · ẑ,   Ω = P / σ²
//! ```
//!
//! (X₀ the keyframe before the solve: the mean takes its yaw and translation again before each
//! solve, as the level anchors' do, so the residual is the tilt however far the yaw has moved;
//! u is the world's up in the mean's body frame, so a right perturbation δ = θu — a turn about
//! the vertical — costs nothing, exactly, to first order. The translation and the yaw are left to
//! the other factors.)

use super::factors::Prior;
use crate::geometry::{yaw_of, Pose3};
use nalgebra::{Isometry3, Matrix3, Matrix6, Translation3, UnitQuaternion, Vector3};

/// The tilt part of an attitude: R_z(ψ)⁻¹ · R = R_y(pitch) R_x(roll), ψ its yaw about the vertical.
pub fn tilt_of(attitude: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    let yaw = attitude.euler_angles().2;
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -yaw) * attitude
}

/// The gravity prior of a keyframe now at `current` whose measured tilt is `tilt` (from
/// [`tilt_of`]), σ = `sigma_rad` on each horizontal axis.
pub fn gravity_prior(variable: usize, current: &Pose3, tilt: &UnitQuaternion<f64>, sigma_rad: f64) -> Prior<Pose3, 6> {
    let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_of(current)) * tilt;
    let mean = Isometry3::from_parts(Translation3::from(current.translation.vector), rotation);
    let up = rotation.inverse() * Vector3::z();
    let projection = Matrix3::identity() - up * up.transpose();
    let mut sqrt_information = Matrix6::zeros();
    sqrt_information.fixed_view_mut::<3, 3>(0, 0).copy_from(&(projection / sigma_rad));
    Prior { variable, mean, sqrt_information }
}

/// How far `pose`'s tilt is from `tilt`: the angle between the vertical each puts in the body, rad.
pub fn tilt_error(pose: &Pose3, tilt: &UnitQuaternion<f64>) -> f64 {
    let measured = tilt.inverse() * Vector3::z();
    let now = pose.rotation.inverse() * Vector3::z();
    measured.angle(&now)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::factors::Between;
    use crate::optim::graph::{Graph3, GTSAM_PRIOR_SIGMAS_3D};
    use crate::optim::solver::{least_squares, optimize_with, LmParams, Structure};
    use proptest::prelude::*;

    fn attitude(roll: f64, pitch: f64, yaw: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(roll, pitch, yaw)
    }

    fn pose(roll: f64, pitch: f64, yaw: f64, t: [f64; 3]) -> Pose3 {
        Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), attitude(roll, pitch, yaw))
    }

    proptest! {
        /// The residual is zero at the measured tilt whatever the yaw and translation, and a turn
        /// about the vertical (a right perturbation along the world's up) changes it by nothing.
        #[test]
        fn yaw_and_translation_are_free(
            roll in -0.3f64..0.3, pitch in -0.3f64..0.3, yaw in -3.1f64..3.1, other_yaw in -3.1f64..3.1,
            x in -50.0f64..50.0, turn in -0.5f64..0.5,
        ) {
            let tilt = tilt_of(&attitude(roll, pitch, other_yaw));
            let current = pose(roll, pitch, yaw, [x, -x, 0.3 * x]);
            let prior = gravity_prior(0, &current, &tilt, 0.01);
            prop_assert!(prior.whitened_error(&current).norm() < 1e-9);
            let turned = Isometry3::from_parts(
                current.translation,
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * current.rotation,
            );
            prop_assert!(prior.whitened_error(&turned).norm() < 1e-9, "{}", prior.whitened_error(&turned).norm());
        }

        /// Tilted by a small angle about a horizontal axis, the whitened residual is that angle
        /// over σ, and the angle is what [`tilt_error`] reports.
        #[test]
        fn a_tilt_costs_its_angle_over_sigma(
            roll in -0.2f64..0.2, pitch in -0.2f64..0.2, yaw in -3.1f64..3.1,
            axis in 0.0f64..std::f64::consts::TAU, angle in 1e-4f64..0.02,
        ) {
            let current = pose(roll, pitch, yaw, [1.0, 2.0, 3.0]);
            let tilt = tilt_of(&current.rotation);
            let sigma = 0.003;
            let prior = gravity_prior(0, &current, &tilt, sigma);
            let horizontal = nalgebra::Unit::new_normalize(Vector3::new(axis.cos(), axis.sin(), 0.0));
            let tilted = Isometry3::from_parts(
                current.translation,
                UnitQuaternion::from_axis_angle(&horizontal, angle) * current.rotation,
            );
            let whitened = prior.whitened_error(&tilted).norm();
            prop_assert!((whitened - angle / sigma).abs() < 1e-3 * angle / sigma, "{whitened} vs {}", angle / sigma);
            prop_assert!((tilt_error(&tilted, &tilt) - angle).abs() < 1e-9);
        }
    }

    /// Closed form: one keyframe held by a relative measurement that tilts it by θ about x
    /// (σ_b on rotation) and by its gravity prior (σ_g) settles at the information-weighted
    /// mean, θ · σ_g² / (σ_g² + σ_b²), its yaw where the measurement puts it.
    #[test]
    fn a_keyframe_settles_at_the_weighted_mean_of_its_tilts() {
        let (sigma_b, sigma_g, theta, yaw) = (0.01, 0.004, 0.05, 0.7);
        let mut graph = Graph3::default();
        for value in [Pose3::identity(), Pose3::identity()] {
            graph.keys.push(graph.keys.len() as u64);
            graph.values.push(value);
            graph.fixed.push(false);
        }
        graph.add_prior_at_current(0, GTSAM_PRIOR_SIGMAS_3D);
        let measured = pose(theta, 0.0, yaw, [2.0, 0.0, 0.0]);
        let sqrt_information = Matrix6::from_diagonal(&nalgebra::Vector6::new(
            1.0 / sigma_b,
            1.0 / sigma_b,
            1.0 / sigma_b,
            100.0,
            100.0,
            100.0,
        ));
        graph.betweens.push(Between { from: 0, to: 1, measured, sqrt_information });
        graph.priors.push(gravity_prior(1, &Pose3::identity(), &UnitQuaternion::identity(), sigma_g));
        // The prior's mean took yaw 0 from the start value; refit it at the yaw the solve finds.
        for _ in 0..3 {
            let structure = Structure::new(&graph).unwrap();
            optimize_with(&mut graph, &LmParams::default(), &structure, &least_squares).unwrap();
            let current = graph.values[1];
            *graph.priors.last_mut().unwrap() = gravity_prior(1, &current, &UnitQuaternion::identity(), sigma_g);
        }
        let x = graph.values[1];
        let expected = theta * sigma_g.powi(2) / (sigma_g.powi(2) + sigma_b.powi(2));
        let roll = tilt_error(&x, &UnitQuaternion::identity());
        assert!((roll - expected).abs() < 1e-4, "tilt {roll} vs {expected}");
        assert!((yaw_of(&x) - yaw).abs() < 1e-4, "yaw {}", yaw_of(&x));
    }
}
