//! Relative drift of an odometry, KITTI's metric (Geiger, Lenz & Urtasun 2012, the odometry
//! benchmark's devkit): for each segment length L and each start frame i (every `step`-th), the
//! first frame j whose path from i (along the truth) is at least L long; the error of the
//! segment's motion
//!
//! ```text
//! E = (T̂_i⁻¹ T̂_j)⁻¹ (T_i⁻¹ T_j)
//! ```
//!
//! gives a translation error ‖t_E‖ / L and a rotation error angle(E) / L. The drift is their
//! mean over every segment of every length (the devkit's average; evo's `evo_rpe --delta L
//! --delta_unit m` computes the same per-segment errors).

use crate::geometry::Pose3;

/// Mean drift over the segments.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Drift {
    /// Translation error per distance, %.
    pub translation_pct: f64,
    /// Rotation error per distance, degrees per 100 m.
    pub rotation_deg_per_100m: f64,
    pub segments: usize,
}

/// The drift of `estimate` against `truth` (same frames, same order) over segments of
/// `lengths` m starting every `step` frames; none when no segment fits.
pub fn kitti_drift(estimate: &[Pose3], truth: &[Pose3], lengths: &[f64], step: usize) -> Option<Drift> {
    let n = estimate.len().min(truth.len());
    let mut along = vec![0.0; n];
    for k in 1..n {
        along[k] = along[k - 1] + (truth[k].translation.vector - truth[k - 1].translation.vector).norm();
    }
    let (mut t_sum, mut r_sum, mut segments) = (0.0, 0.0, 0usize);
    for &length in lengths.iter().filter(|l| l.is_finite() && **l > 0.0) {
        for i in (0..n).step_by(step.max(1)) {
            let Some(j) = (i..n).find(|&j| along[j] - along[i] >= length) else { break };
            let error = (estimate[i].inverse() * estimate[j]).inverse() * (truth[i].inverse() * truth[j]);
            t_sum += error.translation.vector.norm() / length;
            r_sum += error.rotation.angle() / length;
            segments += 1;
        }
    }
    (segments > 0).then(|| Drift {
        translation_pct: 100.0 * t_sum / segments as f64,
        rotation_deg_per_100m: 100.0 * (r_sum / segments as f64).to_degrees(),
        segments,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_rpy_translation;
    use nalgebra::Vector3;

    /// A straight line at 1 m per frame.
    fn line(n: usize, scale: f64) -> Vec<Pose3> {
        (0..n).map(|k| pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::new(k as f64 * scale, 0.0, 0.0))).collect()
    }

    #[test]
    fn a_one_percent_scale_error_is_one_percent_drift() {
        let d = kitti_drift(&line(500, 1.01), &line(500, 1.0), &[100.0, 200.0], 10).expect("segments fit");
        assert!((d.translation_pct - 1.0).abs() < 1e-9, "{d:?}");
        assert!(d.rotation_deg_per_100m.abs() < 1e-12);
        // 100 m segments start at 0, 10, …, 390; 200 m ones at 0, …, 290.
        assert_eq!(d.segments, 40 + 30);
    }

    #[test]
    fn a_constant_heading_error_rate_is_its_rotation_drift() {
        // The estimate turns 0.1° per 100 m more than the truth on a straight line.
        let truth = line(301, 1.0);
        let rate = 0.1f64.to_radians() / 100.0;
        let estimate: Vec<Pose3> = truth
            .iter()
            .enumerate()
            .map(|(k, p)| p * pose_from_rpy_translation(0.0, 0.0, rate * k as f64, Vector3::zeros()))
            .collect();
        let d = kitti_drift(&estimate, &truth, &[100.0], 50).expect("segments fit");
        assert!((d.rotation_deg_per_100m - 0.1).abs() < 1e-9, "{d:?}");
        assert!(kitti_drift(&estimate, &truth, &[1000.0], 50).is_none());
    }
}
