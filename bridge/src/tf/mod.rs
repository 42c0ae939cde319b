//! tf in: the sensors' mounts on the body read from `/tf_static` and `/tf` when configuration
//! does not pin them (and checked against it when it does), and the odometry compared with
//! what tf says of the same frames. [`tree`] keeps the frames, [`mounts`] resolves each
//! sensor's mounting, [`listener`] is what the synchroniser owns.

pub mod listener;
pub mod mounts;
pub mod tree;

use serde::{Deserialize, Serialize};
use sgm_model::geometry::Pose3;

/// `[ros.tf]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TfConfig {
    /// Read tf at all (mounts, odometry check). Default true.
    pub listen: bool,
    /// tf2_msgs/TFMessage of moving frames in. Default `/tf`. A relative name resolves in the
    /// node's namespace (a robot whose odometry's tf is remapped to `/alpha/tf`: `tf`).
    pub topic: String,
    /// tf2_msgs/TFMessage of fixed frames in (latched). Default `/tf_static`.
    pub static_topic: String,
    /// A pinned mount that tf contradicts by more than this is a finding (`mount_disagrees`), m.
    /// Default 0.02.
    pub max_mount_disagreement_m: f64,
    /// The same, in rotation, degrees. Default 1.
    pub max_mount_disagreement_deg: f64,
    /// The odometry and tf's transform between the same world and body frames farther apart
    /// than this is a finding (`odometry_disagrees_with_tf`), m. Default 0.05.
    pub max_odometry_disagreement_m: f64,
    /// The same, in rotation, degrees. Default 2.
    pub max_odometry_disagreement_deg: f64,
}

impl Default for TfConfig {
    fn default() -> Self {
        Self {
            listen: true,
            topic: "/tf".into(),
            static_topic: "/tf_static".into(),
            max_mount_disagreement_m: 0.02,
            max_mount_disagreement_deg: 1.0,
            max_odometry_disagreement_m: 0.05,
            max_odometry_disagreement_deg: 2.0,
        }
    }
}

/// A `[ros.tf]` key out of range; the message names the key and its value.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TfConfigError {
    /// A disagreement threshold (`max_mount_disagreement_m`, `…_deg`,
    /// `max_odometry_disagreement_m`, `…_deg`) that is not finite and positive.
    #[error("ros.tf.{key} = {value}: finite and > 0 expected")]
    NotPositive { key: &'static str, value: f64 },
}

impl TfConfig {
    pub fn validate(&self) -> Result<(), TfConfigError> {
        for (key, v) in [
            ("max_mount_disagreement_m", self.max_mount_disagreement_m),
            ("max_mount_disagreement_deg", self.max_mount_disagreement_deg),
            ("max_odometry_disagreement_m", self.max_odometry_disagreement_m),
            ("max_odometry_disagreement_deg", self.max_odometry_disagreement_deg),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(TfConfigError::NotPositive { key, value: v });
            }
        }
        Ok(())
    }
}

/// One transform of a TFMessage, checked, its frames aliased.
#[derive(Clone, Debug, PartialEq)]
pub struct TfTransform {
    pub stamp: rosrust::Time,
    pub parent: String,
    pub child: String,
    pub parent_from_child: Pose3,
}

/// A TFMessage: the transforms that passed their checks, and why the others did not.
#[derive(Clone, Debug, PartialEq)]
pub struct TfBatch {
    pub is_static: bool,
    pub transforms: Vec<TfTransform>,
    /// One line per transform refused (its frames and the reason).
    pub refused: Vec<String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_thresholds_are_named() {
        assert_eq!(TfConfig::default().validate(), Ok(()));
        let e = TfConfig { max_odometry_disagreement_deg: 0.0, ..Default::default() }.validate().unwrap_err();
        assert_eq!(e, TfConfigError::NotPositive { key: "max_odometry_disagreement_deg", value: 0.0 });
        assert_eq!(e.to_string(), "ros.tf.max_odometry_disagreement_deg = 0: finite and > 0 expected");
    }
}
