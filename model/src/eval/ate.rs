//! Absolute trajectory error (Sturm et al., IROS 2012), as `evo_ape tum -a` computes it: the
//! estimate is aligned to the truth by the SE(3) transform minimising the squared position
//! error (Umeyama without scale, `geometry::fit_rigid`), then
//!
//! ```text
//! ATE_rmse = sqrt( 1/N Σ_i ‖p_i^truth − T·p_i^estimate‖² )
//! ```
//!
//! over corresponding positions (same stamps).

use crate::geometry::{fit_rigid, Correspondence, Pose3, RigidModel};
use nalgebra::Point3;

/// The error of an aligned estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ate {
    pub rmse_m: f64,
    pub mean_m: f64,
    pub max_m: f64,
    /// The alignment: p_truth ≈ truth_from_estimate · p_estimate.
    pub truth_from_estimate: Pose3,
    pub count: usize,
}

/// ATE of `estimate` against `truth` (pairs by index). `None` with fewer than 3 pairs, different
/// lengths, or non-finite input.
pub fn ate(estimate: &[Point3<f64>], truth: &[Point3<f64>]) -> Option<Ate> {
    if estimate.len() != truth.len() || estimate.len() < 3 {
        return None;
    }
    let pairs: Vec<Correspondence> =
        estimate.iter().zip(truth).map(|(e, t)| Correspondence { in_local: *t, in_remote: *e, weight: 1.0 }).collect();
    let truth_from_estimate = fit_rigid(&pairs, RigidModel::Full3d)?;
    Some(error_under(estimate, truth, truth_from_estimate))
}

/// The error of `estimate` moved by a given `truth_from_estimate` (no fitting).
pub fn error_under(estimate: &[Point3<f64>], truth: &[Point3<f64>], truth_from_estimate: Pose3) -> Ate {
    let errors: Vec<f64> = estimate.iter().zip(truth).map(|(e, t)| (t - truth_from_estimate * e).norm()).collect();
    let n = errors.len().max(1) as f64;
    Ate {
        rmse_m: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        mean_m: errors.iter().sum::<f64>() / n,
        max_m: errors.iter().copied().fold(0.0, f64::max),
        truth_from_estimate,
        count: errors.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_rpy_translation;
    use nalgebra::Vector3;
    use proptest::prelude::*;

    fn path(n: usize) -> Vec<Point3<f64>> {
        (0..n).map(|i| Point3::new(i as f64, (i as f64 * 0.3).sin() * 5.0, (i as f64 * 0.1).cos())).collect()
    }

    #[test]
    fn a_rigidly_moved_estimate_has_no_error_and_its_transform_is_recovered() {
        let truth = path(50);
        let truth_from_estimate = pose_from_rpy_translation(0.1, -0.2, 2.0, Vector3::new(3.0, -1.0, 0.5));
        let estimate: Vec<_> = truth.iter().map(|p| truth_from_estimate.inverse() * p).collect();
        let a = ate(&estimate, &truth).unwrap();
        assert!(a.rmse_m < 1e-9, "{a:?}");
        let d = a.truth_from_estimate.inverse() * truth_from_estimate;
        assert!(d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-9);
    }

    #[test]
    fn scatter_that_no_rigid_motion_removes_stays() {
        // Ends displaced +d along y, the middle −2d: zero mean, no net turn, so no rigid motion
        // reduces it and the RMSE is the closed form below.
        let truth = vec![Point3::new(-1.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0)];
        let d = 0.1;
        let estimate = vec![Point3::new(-1.0, d, 0.0), Point3::new(0.0, -2.0 * d, 0.0), Point3::new(1.0, d, 0.0)];
        let a = ate(&estimate, &truth).unwrap();
        let expected = ((d * d + 4.0 * d * d + d * d) / 3.0_f64).sqrt();
        assert!((a.rmse_m - expected).abs() < 1e-12, "{} vs {expected}", a.rmse_m);
    }

    #[test]
    fn bad_input_gives_none() {
        assert!(ate(&path(2), &path(2)).is_none());
        assert!(ate(&path(5), &path(6)).is_none());
    }

    proptest! {
        /// The alignment is a minimum: no small rigid perturbation of it lowers the RMSE.
        #[test]
        fn the_alignment_is_optimal(seed in 0u64..500, axis in 0usize..6, sign in prop::bool::ANY) {
            let truth = path(30);
            let estimate: Vec<_> = truth
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let k = (seed as f64 + i as f64 * 1.7).sin();
                    pose_from_rpy_translation(0.05, 0.02, 0.4, Vector3::new(1.0, 2.0, 0.0)) * p
                        + Vector3::new(k * 0.3, (k * 3.1).cos() * 0.2, k * 0.1)
                })
                .collect();
            let best = ate(&estimate, &truth).unwrap();
            let mut delta = [0.0; 6];
            delta[axis] = if sign { 1e-3 } else { -1e-3 };
            let nudge = pose_from_rpy_translation(delta[0], delta[1], delta[2], Vector3::new(delta[3], delta[4], delta[5]));
            let worse = error_under(&estimate, &truth, nudge * best.truth_from_estimate);
            prop_assert!(worse.rmse_m >= best.rmse_m - 1e-12);
        }
    }
}
