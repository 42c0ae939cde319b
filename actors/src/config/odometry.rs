//! `[odometry]`: where the robot's odometry comes from. `external` (the default) takes the pose
//! each frame brings (a `nav_msgs/Odometry` topic in ROS, the noise model in scenarios);
//! `internal` runs SGM's own LiDAR-inertial odometry (`model::odometry`) in the Odometry actor
//! on the frames' timed sweeps and IMU samples, configured by `[odometry.estimator]`.

use super::error::ConfigError;
use serde::{Deserialize, Serialize};
use sgm_model::odometry::config::OdometryConfig;

/// Where the odometry comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OdometrySource {
    /// The pose each frame brings is used as it is.
    #[default]
    External,
    /// SGM's LiDAR-inertial odometry estimates it from the frames' sweeps and IMU samples.
    Internal,
}

impl OdometrySource {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::External => "external",
            Self::Internal => "internal",
        }
    }
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OdometrySection {
    /// "external" or "internal". Default "external".
    pub source: OdometrySource,
    /// The internal odometry's parameters (`model::odometry::config`); unused when external.
    pub estimator: OdometryConfig,
}

impl OdometrySection {
    /// Checks `odometry.estimator.*` (only when it is used: an external source ignores it).
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.source == OdometrySource::Internal {
            self.estimator.validate().map_err(|e| ConfigError::Invalid {
                key: format!("odometry.estimator.{}", e.key),
                value: e.value.to_string(),
                allowed: e.allowed.into(),
            })?;
        }
        Ok(())
    }
}
