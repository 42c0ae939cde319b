//! `[optimiser]`: odometry noise, solve cadence and outlier rejection of the pose graph.

use super::error::{check, positive, ConfigError};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OptimiserConfig {
    /// Odometry noise per keyframe step, standard deviations (rotation rad ×3, translation m ×3).
    /// Default 0.01 rad, 0.05 m.
    pub odometry_sigmas: [f64; 6],
    /// Optimise after this many new keyframes (1: every keyframe), and at once on a loop closure
    /// or new inter-robot constraints. Default 10.
    pub every_keyframes: usize,
    /// Reject wrong loop closures and inter-robot factors: graduated non-convexity with
    /// truncated least squares over them (odometry and priors are trusted), decided again at
    /// every solve. false: plain least squares. Default true.
    pub reject_outliers: bool,
    /// In gravity-aligned worlds (`matcher.max_tilt_deg = 0`: an IMU's), each own keyframe is held
    /// to the tilt its odometry measured, σ per horizontal axis, degrees; 0: not held (the pose
    /// graph's between factors alone decide the tilt). Default 0.2 (an IMU's gravity estimate).
    pub gravity_sigma_deg: f64,
}

impl Default for OptimiserConfig {
    fn default() -> Self {
        Self {
            odometry_sigmas: [0.01, 0.01, 0.01, 0.05, 0.05, 0.05],
            every_keyframes: 10,
            reject_outliers: true,
            gravity_sigma_deg: 0.2,
        }
    }
}

impl OptimiserConfig {
    /// Checks every `optimiser.*` key against its allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let o = self;
        check(
            o.odometry_sigmas.iter().all(|s| positive(*s)),
            "optimiser.odometry_sigmas",
            format!("{:?}", o.odometry_sigmas),
            "six values > 0",
        )?;
        check(o.every_keyframes >= 1, "optimiser.every_keyframes", o.every_keyframes, "≥ 1")?;
        check(
            o.gravity_sigma_deg.is_finite() && (0.0..=10.0).contains(&o.gravity_sigma_deg),
            "optimiser.gravity_sigma_deg",
            o.gravity_sigma_deg,
            "0 (off) ≤ x ≤ 10°",
        )?;
        Ok(())
    }
}
