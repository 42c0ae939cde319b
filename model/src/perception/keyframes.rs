//! Keyframe selection as in LIO-SAM: a new keyframe when the body has moved at least
//! `min_translation_m` or turned at least `min_rotation_rad` since the last keyframe.

use crate::geometry::Pose3;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KeyframeConfig {
    /// Default 1.0 m (LIO-SAM's `surroundingkeyframeAddingDistThreshold`).
    pub min_translation_m: f64,
    /// Default 0.2 rad (LIO-SAM's `surroundingkeyframeAddingAngleThreshold`).
    pub min_rotation_rad: f64,
}

impl Default for KeyframeConfig {
    fn default() -> Self {
        Self { min_translation_m: 1.0, min_rotation_rad: 0.2 }
    }
}

/// Whether `current` should become a keyframe after `last` (always, if there is none).
pub fn is_keyframe(last: Option<&Pose3>, current: &Pose3, config: &KeyframeConfig) -> bool {
    let Some(last) = last else { return true };
    let delta = last.inverse() * current;
    delta.translation.vector.norm() >= config.min_translation_m || delta.rotation.angle() >= config.min_rotation_rad
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_yaw_translation;
    use nalgebra::Vector3;

    #[test]
    fn distance_or_angle_makes_a_keyframe() {
        let c = KeyframeConfig::default();
        let last = pose_from_yaw_translation(0.5, Vector3::new(3.0, 1.0, 0.0));
        assert!(is_keyframe(None, &last, &c));
        assert!(!is_keyframe(Some(&last), &(last * pose_from_yaw_translation(0.1, Vector3::new(0.5, 0.2, 0.0))), &c));
        assert!(is_keyframe(Some(&last), &(last * pose_from_yaw_translation(0.0, Vector3::new(0.8, 0.7, 0.0))), &c));
        assert!(is_keyframe(Some(&last), &(last * pose_from_yaw_translation(-0.25, Vector3::zeros())), &c));
    }
}
