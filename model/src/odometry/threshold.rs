//! The adaptive correspondence threshold of scan-to-map registration (KISS-ICP, Vizzo et al.
//! 2023, RA-L 8(2), §III-C): how far a scan point may lie from its map partner is learnt from how
//! wrong the motion prediction has been, not tuned per sensor and place.
//!
//! After each registration the correction of the prediction, ΔT = T_pred⁻¹ · T_est = (R, t),
//! moves a point at the sensor's range r_max by at most
//!
//! ```text
//! δ(ΔT) = 2 r_max sin(θ / 2) + ‖t‖,        θ = the angle of R
//! ```
//!
//! (the chord a rotation by θ sweeps at r_max, plus the translation). Over the frames in which
//! the sensor moved more than `min_motion_m` — standing still says nothing about the
//! prediction —
//!
//! ```text
//! σ² = (1/|M|) Σ_{j ∈ M} δ_j²,    correspondence threshold τ = 3σ,  robust kernel κ = σ / 3
//! ```
//!
//! and τ = 3σ₀ (`initial_sigma_m`) until the first such frame. With an IMU the prediction is
//! better than KISS-ICP's constant velocity, the corrections are smaller, and so is τ.

use crate::geometry::Pose3;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ThresholdConfig {
    /// σ before any sample, m. Default 2.0 (KISS-ICP's).
    pub initial_sigma_m: f64,
    /// Frames that moved less than this do not update σ, m. Default 0.1.
    pub min_motion_m: f64,
    /// The range at which rotation errors are measured, m. Default 100.
    pub max_range_m: f64,
}

impl Default for ThresholdConfig {
    fn default() -> Self {
        Self { initial_sigma_m: 2.0, min_motion_m: 0.1, max_range_m: 100.0 }
    }
}

/// δ(ΔT) of the module notes, m.
pub fn model_error(correction: &Pose3, max_range_m: f64) -> f64 {
    let theta = correction.rotation.angle();
    2.0 * max_range_m * (theta / 2.0).sin() + correction.translation.vector.norm()
}

/// The running σ.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdaptiveThreshold {
    config: ThresholdConfig,
    sum_squares: f64,
    samples: u64,
}

impl AdaptiveThreshold {
    pub fn new(config: ThresholdConfig) -> Self {
        Self { config, sum_squares: 0.0, samples: 0 }
    }

    /// σ, m.
    pub fn sigma(&self) -> f64 {
        if self.samples == 0 {
            self.config.initial_sigma_m
        } else {
            (self.sum_squares / self.samples as f64).sqrt()
        }
    }

    /// Largest distance of a correspondence, τ = 3σ, m.
    pub fn correspondence_m(&self) -> f64 {
        3.0 * self.sigma()
    }

    /// Scale of the robust kernel, κ = σ/3, m.
    pub fn kernel_m(&self) -> f64 {
        self.sigma() / 3.0
    }

    /// Records one registration: `correction` = T_pred⁻¹ · T_est, `motion` the frame's motion
    /// (previous pose⁻¹ · this one). Non-finite corrections are ignored.
    pub fn update(&mut self, correction: &Pose3, motion: &Pose3) {
        let moved = model_error(motion, 0.0);
        let delta = model_error(correction, self.config.max_range_m);
        if moved > self.config.min_motion_m && delta.is_finite() {
            self.sum_squares += delta * delta;
            self.samples += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_rpy_translation;
    use nalgebra::Vector3;

    #[test]
    fn the_model_error_is_the_chord_at_range_plus_the_translation() {
        // A turn of 0.01 rad at 100 m sweeps a chord of 2·100·sin(0.005); plus 0.3 m.
        let correction = pose_from_rpy_translation(0.0, 0.0, 0.01, Vector3::new(0.3, 0.0, 0.0));
        let expected = 200.0 * 0.005f64.sin() + 0.3;
        assert!((model_error(&correction, 100.0) - expected).abs() < 1e-12);
        // The chord, measured directly: a point at 100 m turned by 0.01 rad.
        let p = nalgebra::Point3::new(100.0, 0.0, 0.0);
        let chord = (correction.rotation * p - p).norm();
        assert!((200.0 * 0.005f64.sin() - chord).abs() < 1e-9);
    }

    #[test]
    fn sigma_is_the_rms_of_the_errors_of_frames_that_moved() {
        let mut t = AdaptiveThreshold::new(ThresholdConfig::default());
        assert_eq!(t.sigma(), 2.0);
        assert_eq!(t.correspondence_m(), 6.0);
        let moved = pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::new(1.0, 0.0, 0.0));
        let still = Pose3::identity();
        let shift = |d: f64| pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::new(0.0, d, 0.0));
        t.update(&shift(0.3), &still); // standing: ignored
        assert_eq!(t.sigma(), 2.0);
        t.update(&shift(0.3), &moved);
        t.update(&shift(0.4), &moved);
        let rms = ((0.09 + 0.16) / 2.0f64).sqrt();
        assert!((t.sigma() - rms).abs() < 1e-12);
        assert!((t.kernel_m() - rms / 3.0).abs() < 1e-12);
        let nan = pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::new(f64::NAN, 0.0, 0.0));
        t.update(&nan, &moved);
        assert!((t.sigma() - rms).abs() < 1e-12);
    }
}
