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
    /// Share the pose graph's own factors with aligned neighbours and hold theirs
    /// (`optim::shared_factors`): each robot then solves the pair's whole graph — its own
    /// keyframes and the neighbour's chain, both robots' odometry, loop closures and inter-robot
    /// factors — instead of holding the neighbour's keyframes by their marginals. Default false.
    pub share_factors: bool,
    /// With `share_factors`: how often each aligned neighbour is asked for its log's new
    /// entries, s (a request or reply lost on the radio is made good at the next). Default 2.
    pub share_period_s: f64,
    /// With `share_factors`: most keyframes and factors held of one neighbour's chain; a reply
    /// beyond it is refused and the neighbour no longer asked (status `chains[].full`).
    /// Default 50 000.
    pub max_chain_items: usize,
}

impl Default for OptimiserConfig {
    fn default() -> Self {
        Self {
            odometry_sigmas: [0.01, 0.01, 0.01, 0.05, 0.05, 0.05],
            every_keyframes: 10,
            reject_outliers: true,
            gravity_sigma_deg: 0.2,
            share_factors: false,
            share_period_s: 2.0,
            max_chain_items: sgm_model::optim::keyframe_graph::DEFAULT_CHAIN_ITEMS,
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
        check(positive(o.share_period_s), "optimiser.share_period_s", o.share_period_s, "> 0")?;
        check(o.max_chain_items >= 1, "optimiser.max_chain_items", o.max_chain_items, "≥ 1")?;
        Ok(())
    }
}
