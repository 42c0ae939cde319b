//! Gravity priors on a robot's own keyframes (beyond the paper): with an IMU the odometry's
//! roll and pitch are measured against gravity at every scan, so a keyframe's tilt is known
//! absolutely, not only relative to the keyframe before it. A pose graph of between factors
//! alone forgets that: a loop closure or an inter-robot factor whose registration leaves the
//! vertical weakly determined (walls without a shared floor, sensors at 0.5 and 1.5 m) bends the
//! chain, and the map tilts by degrees — the world is then no longer the gravity-aligned frame
//! the matcher's 4-DoF transform and the level anchors assume. VINS-Mono's loop closure
//! optimises only x, y, z and yaw for the same reason.
//!
//! A keyframe's measured tilt is the world's up seen in its body, u_m = R_mᵀ ẑ (R_m the
//! odometry's odom_from_body rotation: gravity-aligned, its yaw free). A keyframe X = (R, t)
//! gets a prior on that alone:
//!
//! ```text
//! M = (R₀ · S, t₀),   S = the least rotation taking u_m to u₀ = R₀ᵀ ẑ   (so R_Mᵀ ẑ = u_m)
//! e = P · Log(M⁻¹ · X)[ω],   P = I − u_m u_mᵀ,   Ω = P / σ²
//! ```
//!
//! (X₀ = (R₀, t₀) the keyframe before the solve). M is the pose nearest X₀ that holds the
//! measured tilt, so at X₀ the residual is a pure swing of angle ∠(u_m, u₀) about an axis
//! normal to u_m — the tilt error, with no twist. A right perturbation δ = θ u_m, a turn about
//! the vertical, costs nothing; the translation rows are zero. The mean is made again before each
//! solve: a yaw that moves by β within one solve changes the tilt's cost by a factor
//! ((β/2)/sin(β/2))², 0.2 % at 0.2 rad. No Euler angles, so no heading is ever extracted.
//!
//! An odometry that estimates up itself (SGM's own LiDAR-inertial one) keeps a frame of its
//! own and learns where up is in it, û with σ_u ([`MeasuredUp`]). The graph keeps each
//! keyframe's attitude in that frame, R_F, and the latest û: u_m = R_Fᵀ û_latest, σ =
//! √(σ² + σ_u²). What the odometry learns later levels the keyframes it measured before, whose
//! ups were wrong together (a turn-on bias of the accelerometer tilts every one alike until the
//! body turns). Its pose's R_mᵀ ẑ would not do: the published frame follows the filter's up
//! only once the two part by 3σ_u (a swaying start's first 12 s on `handheld_indoor` seed 1:
//! 2.1° off, while the filter's own up was within 0.3° after 2 s).
//!
//! With gravity priors the map's tilt is measured, not a gauge: the first keyframe's anchor
//! (GTSAM's default prior) then holds only its yaw and position ([`yaw_only`]), or it would pin
//! the whole map to the tilt of its first pose.

pub use crate::geometry::up::{unit_up, up_in_body, MeasuredUp};

use super::factors::Prior;
use crate::geometry::Pose3;
use crate::scene_graph::KeyframeId;
use nalgebra::{Isometry3, Matrix3, Matrix6, UnitQuaternion, Vector3};
use std::collections::BTreeMap;

/// `prior` (on a pose, residual (ω, v) in its body) holding only the turn about `up` (the
/// body's up) of its rotation, and its translation: S' = S · diag(u uᵀ, I). A keyframe's tilt is
/// then its gravity prior's to hold.
pub fn yaw_only(prior: &Prior<Pose3, 6>, up: &Vector3<f64>) -> Prior<Pose3, 6> {
    let mut keep = Matrix6::identity();
    keep.fixed_view_mut::<3, 3>(0, 0).copy_from(&(up * up.transpose()));
    Prior { sqrt_information: prior.sqrt_information * keep, ..prior.clone() }
}

/// The gravity prior of a keyframe now at `current` whose measured up is `up` (from
/// [`up_in_body`]), σ = `sigma_rad` on each horizontal axis; `None` when the two ups are opposite
/// (a body measured upside down against one the right way up: no least rotation).
pub fn gravity_prior(variable: usize, current: &Pose3, up: &Vector3<f64>, sigma_rad: f64) -> Option<Prior<Pose3, 6>> {
    let now = current.rotation.inverse() * Vector3::z();
    let swing = UnitQuaternion::rotation_between(up, &now)?;
    let mean = Isometry3::from_parts(current.translation, current.rotation * swing);
    let projection = Matrix3::identity() - up * up.transpose();
    let mut sqrt_information = Matrix6::zeros();
    sqrt_information.fixed_view_mut::<3, 3>(0, 0).copy_from(&(projection / sigma_rad));
    Some(Prior { variable, mean, sqrt_information })
}

/// The gravity priors of the keyframes in `ups` that have a variable (`variable_of`), at their
/// values in `values`; σ = √(`sigma_rad`² + σ_u²) with σ_u a keyframe's in `up_sigmas` (0 if
/// absent).
pub fn gravity_priors(
    ups: &BTreeMap<KeyframeId, Vector3<f64>>,
    up_sigmas: &BTreeMap<KeyframeId, f64>,
    variable_of: impl Fn(KeyframeId) -> Option<usize>,
    values: &[Pose3],
    sigma_rad: f64,
) -> Vec<Prior<Pose3, 6>> {
    ups.iter()
        .filter_map(|(k, up)| {
            let i = variable_of(*k)?;
            let sigma = up_sigmas.get(k).map_or(sigma_rad, |s| sigma_rad.hypot(*s));
            gravity_prior(i, values.get(i)?, up, sigma)
        })
        .collect()
}

/// How far `pose`'s tilt is from the measured `up`: the angle between the two ups, rad.
pub fn tilt_error(pose: &Pose3, up: &Vector3<f64>) -> f64 {
    (pose.rotation.inverse() * Vector3::z()).angle(up)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::factors::Between;
    use crate::optim::graph::{Graph3, GTSAM_PRIOR_SIGMAS_3D};
    use crate::optim::solver::{least_squares, optimize_with, LmParams, Structure};
    use nalgebra::Translation3;
    use proptest::prelude::*;

    fn pose(roll: f64, pitch: f64, yaw: f64, t: [f64; 3]) -> Pose3 {
        Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), UnitQuaternion::from_euler_angles(roll, pitch, yaw))
    }

    fn up(roll: f64, pitch: f64, yaw: f64) -> Vector3<f64> {
        up_in_body(&UnitQuaternion::from_euler_angles(roll, pitch, yaw)).unwrap()
    }

    proptest! {
        /// At the measured tilt the residual is zero whatever the yaw; a turn about the vertical
        /// and any move of the translation change it by nothing, and its linearisation has no
        /// translation columns.
        #[test]
        fn yaw_and_translation_are_free(
            roll in -0.3f64..0.3, pitch in -0.3f64..0.3, yaw in -3.1f64..3.1, other_yaw in -3.1f64..3.1,
            x in -50.0f64..50.0, turn in -3.0f64..3.0, shift in -5.0f64..5.0,
        ) {
            let current = pose(roll, pitch, yaw, [x, -x, 0.3 * x]);
            let prior = gravity_prior(0, &current, &up(roll, pitch, other_yaw), 0.01).unwrap();
            prop_assert!(prior.whitened_error(&current).norm() < 1e-9);
            let moved = Isometry3::from_parts(
                Translation3::from(current.translation.vector + Vector3::new(shift, 2.0 * shift, -shift)),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * current.rotation,
            );
            prop_assert!(prior.whitened_error(&moved).norm() < 1e-9, "{}", prior.whitened_error(&moved).norm());
            let (_, jacobian) = prior.linearize(&moved);
            prop_assert!(jacobian.fixed_view::<6, 3>(0, 3).norm() < 1e-12);
        }

        /// Tilted by a small angle about a horizontal axis, the whitened residual is that angle
        /// over σ, and the angle is what [`tilt_error`] reports; the prior made at the tilted
        /// pose says the same (the residual there is the swing back to the measured up).
        #[test]
        fn a_tilt_costs_its_angle_over_sigma(
            roll in -0.2f64..0.2, pitch in -0.2f64..0.2, yaw in -3.1f64..3.1,
            axis in 0.0f64..std::f64::consts::TAU, angle in 1e-4f64..0.02,
        ) {
            let current = pose(roll, pitch, yaw, [1.0, 2.0, 3.0]);
            let measured = up(roll, pitch, yaw);
            let sigma = 0.003;
            let horizontal = nalgebra::Unit::new_normalize(Vector3::new(axis.cos(), axis.sin(), 0.0));
            let tilted = Isometry3::from_parts(
                current.translation,
                UnitQuaternion::from_axis_angle(&horizontal, angle) * current.rotation,
            );
            for at in [current, tilted] {
                let prior = gravity_prior(0, &at, &measured, sigma).unwrap();
                let whitened = prior.whitened_error(&tilted).norm();
                prop_assert!((whitened - angle / sigma).abs() < 1e-3 * angle / sigma, "{whitened} vs {}", angle / sigma);
            }
            prop_assert!((tilt_error(&tilted, &measured) - angle).abs() < 1e-9);
        }
    }

    #[test]
    fn attitudes_that_are_not_rotations_give_no_up_and_opposite_ups_no_prior() {
        let nan = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
        assert_eq!(up_in_body(&nan), None);
        let unnormalised = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(2.0, 0.0, 0.0, 0.0));
        assert_eq!(up_in_body(&unnormalised), None);
        let upside_down = pose(std::f64::consts::PI, 0.0, 0.0, [0.0; 3]);
        assert!(gravity_prior(0, &upside_down, &Vector3::z(), 0.01).is_none());
        let ups = BTreeMap::from([(KeyframeId(0), Vector3::z()), (KeyframeId(1), Vector3::z())]);
        let priors = gravity_priors(&ups, &BTreeMap::new(), |k| (k.0 == 1).then_some(0), &[Pose3::identity()], 0.01);
        assert_eq!(priors.len(), 1, "a keyframe without a variable has no prior");
    }

    #[test]
    fn measured_ups_are_checked_and_their_uncertainty_widens_the_prior() {
        let m = MeasuredUp {
            attitude_in_frame: UnitQuaternion::from_euler_angles(0.0, 0.5, 0.0),
            up_in_frame: Vector3::z(),
            sigma_rad: 0.01,
        };
        assert!(m.is_valid());
        assert!((m.up_in_body() - up(0.0, 0.5, 0.0)).norm() < 1e-12);
        assert!(!MeasuredUp { up_in_frame: Vector3::new(f64::NAN, 0.0, 1.0), ..m }.is_valid());
        assert!(!MeasuredUp { up_in_frame: Vector3::new(0.0, 0.0, 1.01), ..m }.is_valid(), "not unit");
        let unnormalised = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(2.0, 0.0, 0.0, 0.0));
        assert!(!MeasuredUp { attitude_in_frame: unnormalised, ..m }.is_valid());
        assert!(!MeasuredUp { sigma_rad: -0.01, ..m }.is_valid());
        assert!(!MeasuredUp { sigma_rad: f64::INFINITY, ..m }.is_valid());
        // σ = √(σ_config² + σ_u²): 3 and 4 make 5; a keyframe without σ_u keeps σ_config.
        let ups = BTreeMap::from([(KeyframeId(0), Vector3::z()), (KeyframeId(1), Vector3::z())]);
        let sigmas = BTreeMap::from([(KeyframeId(1), 0.004)]);
        let values = [Pose3::identity(), Pose3::identity()];
        let priors = gravity_priors(&ups, &sigmas, |k| Some(k.0 as usize), &values, 0.003);
        let weight = |p: &Prior<Pose3, 6>| p.sqrt_information[(0, 0)];
        assert!((weight(&priors[0]) - 1.0 / 0.003).abs() < 1e-9);
        assert!((weight(&priors[1]) - 1.0 / 0.005).abs() < 1e-9);
    }

    /// Closed form: a keyframe anchored at a pose tilted by θ (GTSAM's default prior, σ_a =
    /// 1e-3 rad) and held to level by its gravity prior (σ_g) settles at θ σ_g²/(σ_g² + σ_a²),
    /// nearly θ: the anchor pins the map's tilt. Anchored in yaw and position only, it settles
    /// level, at the anchor's yaw and position.
    #[test]
    fn an_anchor_in_yaw_and_position_only_leaves_the_tilt_to_gravity() {
        let (theta, yaw, sigma_g) = (0.03, 0.8, 0.0035);
        let start = pose(theta, 0.0, yaw, [1.0, 2.0, 0.5]);
        let level = Vector3::z();
        let settle = |yaw_only_anchor: bool| {
            let mut graph = Graph3::default();
            graph.keys.push(0);
            graph.values.push(start);
            graph.fixed.push(false);
            graph.add_prior_at_current(0, GTSAM_PRIOR_SIGMAS_3D);
            if yaw_only_anchor {
                graph.priors[0] = yaw_only(&graph.priors[0], &up_in_body(&start.rotation).unwrap());
            }
            graph.priors.push(gravity_prior(0, &start, &level, sigma_g).unwrap());
            for _ in 0..3 {
                let structure = Structure::new(&graph).unwrap();
                optimize_with(&mut graph, &LmParams::default(), &structure, &least_squares).unwrap();
                *graph.priors.last_mut().unwrap() = gravity_prior(0, &graph.values[0], &level, sigma_g).unwrap();
            }
            graph.values[0]
        };
        let pinned = settle(false);
        let expected = theta * sigma_g.powi(2) / (sigma_g.powi(2) + 1e-6);
        assert!((tilt_error(&pinned, &level) - expected).abs() < 1e-4, "{}", tilt_error(&pinned, &level));
        let free = settle(true);
        assert!(tilt_error(&free, &level) < 1e-6, "{}", tilt_error(&free, &level));
        assert!((crate::geometry::yaw_of(&free) - crate::geometry::yaw_of(&start)).abs() < 1e-3);
        assert!((free.translation.vector - start.translation.vector).norm() < 1e-9);
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
        let level = Vector3::z();
        graph.priors.push(gravity_prior(1, &Pose3::identity(), &level, sigma_g).unwrap());
        // The prior's mean was made at the start value; made again where each solve ends.
        for _ in 0..3 {
            let structure = Structure::new(&graph).unwrap();
            optimize_with(&mut graph, &LmParams::default(), &structure, &least_squares).unwrap();
            let current = graph.values[1];
            *graph.priors.last_mut().unwrap() = gravity_prior(1, &current, &level, sigma_g).unwrap();
        }
        let x = graph.values[1];
        let expected = theta * sigma_g.powi(2) / (sigma_g.powi(2) + sigma_b.powi(2));
        let tilt = tilt_error(&x, &level);
        assert!((tilt - expected).abs() < 1e-4, "tilt {tilt} vs {expected}");
        assert!((crate::geometry::yaw_of(&x) - yaw).abs() < 1e-4, "yaw {}", crate::geometry::yaw_of(&x));
    }
}
