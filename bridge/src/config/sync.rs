//! `[ros.sync]`: how the synchroniser (`sync`) pairs clouds with their odometry and
//! label image.

use serde::{Deserialize, Serialize};

/// How clouds meet their odometry and label image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SyncConfig {
    /// A label image within this of the cloud's stamp labels it as it is, s. Default 0.05.
    pub image_tolerance_s: f64,
    /// A label image farther than `image_tolerance_s` but within this of the cloud labels it
    /// with the body's motion in between compensated (the odometry at both stamps), s: a
    /// segmenter slower than the LiDAR is normal. Default 0.5.
    pub max_label_skew_s: f64,
    /// What becomes of a cloud with no label image within `max_label_skew_s`: `keep` (default:
    /// assembled without labels, so it still feeds keyframes and the map's geometry) or `drop`.
    pub unlabelled: Unlabelled,
    /// The odometry poses bracketing a cloud may be at most this far apart to interpolate, s.
    /// Default 0.5.
    pub max_odometry_gap_s: f64,
    /// A cloud still missing its odometry or image when the streams are this far past it is
    /// dropped, s. Default 1.
    pub max_wait_s: f64,
}

impl Default for SyncConfig {
    fn default() -> Self {
        Self {
            image_tolerance_s: 0.05,
            max_label_skew_s: 0.5,
            unlabelled: Unlabelled::Keep,
            max_odometry_gap_s: 0.5,
            max_wait_s: 1.0,
        }
    }
}

/// `ros.sync.unlabelled`: a cloud no label image reaches.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Unlabelled {
    /// Assembled without labels (counted as `unlabelled`).
    Keep,
    /// Dropped (counted as `no_image`).
    Drop,
}
