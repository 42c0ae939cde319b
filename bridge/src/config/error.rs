//! What can be wrong with a `[ros]` section: each error names the key, its value and what is
//! expected.

use super::HealthConfigError;
use crate::error::InputError;
use crate::tf::TfConfigError;

/// `RosConfigError::DeliverWithoutId`'s text, whole (`{id}` is the placeholder it asks for, not a
/// format argument; the troubleshooting table quotes it).
const DELIVER_WITHOUT_ID: &str = "ros.topics.deliver must contain {id}: one service per robot";

/// A `[ros]` key out of range, or two keys that contradict each other.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RosConfigError {
    /// A duration, interval or size that must be finite and positive.
    #[error("ros.{key} = {value}: finite and > 0 expected")]
    NotPositive { key: &'static str, value: f64 },
    #[error(
        "ros.sync.max_label_skew_s = {skew} is below ros.sync.image_tolerance_s = {tolerance}: at least that expected"
    )]
    SkewBelowTolerance { skew: f64, tolerance: f64 },
    #[error(transparent)]
    Health(#[from] HealthConfigError),
    #[error(transparent)]
    Tf(#[from] TfConfigError),
    /// A count that must be at least 1 (`timeline.confirm_messages`, `peers.queue`).
    #[error("ros.{key} = 0: ≥ 1 expected")]
    Zero { key: &'static str },
    #[error("ros.peers.backoff_max_s = {max}: ≥ backoff_initial_s ({initial}) expected")]
    BackoffBelowInitial { max: f64, initial: f64 },
    /// `queue_size`, `max_cloud_points` or `max_image_pixels` is 0.
    #[error("ros.queue_size, max_cloud_points and max_image_pixels must be ≥ 1")]
    NoRoom,
    #[error("ros.max_message_bytes = {0}: ≥ 1024 expected")]
    MessageBytes(usize),
    /// A topic name with characters ROS does not allow, empty, or with `//`.
    #[error("ros.{key} = {name:?}: not a valid ROS name")]
    Name { key: &'static str, name: String },
    #[error("{}", DELIVER_WITHOUT_ID)]
    DeliverWithoutId,
    #[error("ros.frames.aliases: {from:?} = {to:?}: both frame names must be non-empty")]
    EmptyAlias { from: String, to: String },
    #[error(
        "ros.camera_from_body and ros.body_from_camera are both set: they are one mounting (one the inverse of \
         the other), set one"
    )]
    BothCameraMounts,
    /// A pinned mounting (`camera_from_body`, `body_from_camera`, `body_from_lidar`) that is not
    /// a pose: non-finite, or not a unit quaternion.
    #[error("ros.{key}: {source}")]
    Mount { key: &'static str, source: InputError },
}
