//! `[ros.health]`: the thresholds of the health checks (`health`).

use serde::{Deserialize, Serialize};

/// `[ros.health]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HealthConfig {
    /// Clouds per window over which the shares are judged. Default 50.
    pub window_frames: u64,
    /// A window in which more than this share of the assembled frames had no label image is a
    /// finding (`no_labels`). Default 0.5.
    pub max_unlabelled_share: f64,
    /// A window in which more than this share of the clouds found no odometry pose is a
    /// finding (`no_odometry`), and so is one with that share short of the IMU with the robot's
    /// own odometry (`imu_short`). Default 0.5.
    pub max_no_odometry_share: f64,
    /// Frames flowing and still no confirmed object in the map (none seen often enough to be
    /// shared) after this much mission time is a finding (`no_objects`), s. Default 60.
    pub no_objects_after_s: f64,
    /// A window whose labelled frames project less than this share of their points into the
    /// label image is a finding (`points_outside_image`). Default 0.01.
    pub min_points_in_image_share: f64,
    /// A window in which more than this share of an input topic's messages was refused is a
    /// finding (`input_refused`, naming the topic and the last reason). Default 0.5.
    pub max_refused_share: f64,
}

impl Default for HealthConfig {
    fn default() -> Self {
        Self {
            window_frames: 50,
            max_unlabelled_share: 0.5,
            max_no_odometry_share: 0.5,
            no_objects_after_s: 60.0,
            min_points_in_image_share: 0.01,
            max_refused_share: 0.5,
        }
    }
}

/// A `[ros.health]` key out of range; the message names the key and its value.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HealthConfigError {
    /// A share (`max_unlabelled_share`, `max_no_odometry_share`, `min_points_in_image_share`,
    /// `max_refused_share`) outside [0, 1].
    #[error("ros.health.{key} = {value}: a share in [0, 1] expected")]
    NotAShare { key: &'static str, value: f64 },
    #[error("ros.health.window_frames = 0: at least 1 expected")]
    NoWindow,
    #[error("ros.health.no_objects_after_s = {0}: finite and > 0 expected")]
    NoObjectsAfter(f64),
}

impl HealthConfig {
    pub fn validate(&self) -> Result<(), HealthConfigError> {
        let share = |value: f64, key: &'static str| {
            if (0.0..=1.0).contains(&value) {
                Ok(())
            } else {
                Err(HealthConfigError::NotAShare { key, value })
            }
        };
        share(self.max_unlabelled_share, "max_unlabelled_share")?;
        share(self.max_no_odometry_share, "max_no_odometry_share")?;
        share(self.min_points_in_image_share, "min_points_in_image_share")?;
        share(self.max_refused_share, "max_refused_share")?;
        if self.window_frames == 0 {
            return Err(HealthConfigError::NoWindow);
        }
        if !(self.no_objects_after_s.is_finite() && self.no_objects_after_s > 0.0) {
            return Err(HealthConfigError::NoObjectsAfter(self.no_objects_after_s));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_thresholds_are_named() {
        let e = HealthConfig { max_unlabelled_share: 1.5, ..Default::default() }.validate().unwrap_err();
        assert_eq!(e, HealthConfigError::NotAShare { key: "max_unlabelled_share", value: 1.5 });
        assert_eq!(e.to_string(), "ros.health.max_unlabelled_share = 1.5: a share in [0, 1] expected");
        let e = HealthConfig { window_frames: 0, ..Default::default() }.validate().unwrap_err();
        assert_eq!(e.to_string(), "ros.health.window_frames = 0: at least 1 expected");
        let e = HealthConfig { no_objects_after_s: f64::NAN, ..Default::default() }.validate().unwrap_err();
        assert_eq!(e.to_string(), "ros.health.no_objects_after_s = NaN: finite and > 0 expected");
    }
}
