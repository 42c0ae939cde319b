//! Keyframe layer: vertices are keyframes, edges are odometry, intra-robot loop and inter-robot
//! observations (paper §III: z^odom, z^intra, z^inter).

use super::{KeyframeId, RobotId};
use crate::geometry::Pose3;
use nalgebra::Matrix6;
use serde::{Deserialize, Serialize};

/// Time of a measurement, seconds since the mission's epoch (virtual or ROS time).
pub type Stamp = f64;

/// The stamp `nanos` nanoseconds after the epoch. Every clock in SGM (the scenario runner's
/// steps, ROS header stamps, bag records) goes through here, so a time that went out as
/// nanoseconds comes back as the very same `f64`.
pub fn stamp_from_nanos(nanos: i64) -> Stamp {
    nanos as f64 / 1e9
}

/// Nanoseconds after the epoch of `stamp`, rounded to the nearest (saturating).
pub fn nanos_from_stamp(stamp: Stamp) -> i64 {
    (stamp * 1e9).round() as i64
}

/// A keyframe: a robot pose selected by the front end, with its time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Keyframe {
    pub id: KeyframeId,
    pub stamp: Stamp,
    /// Pose of the body in this robot's world frame W_α (x_{αi} in the paper).
    pub world_from_body: Pose3,
}

/// The other end of a keyframe edge: one of ours, or a neighbour's keyframe.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum KeyframeRef {
    Local(KeyframeId),
    Remote { robot: RobotId, keyframe: KeyframeId },
}

/// Kind of a keyframe-layer edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum KeyframeEdgeKind {
    Odometry,
    Loop,
    InterRobot,
}

/// A relative-pose observation between a local keyframe and another keyframe.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KeyframeEdge {
    pub kind: KeyframeEdgeKind,
    pub from: KeyframeId,
    pub to: KeyframeRef,
    /// Measured pose of `to`'s body in `from`'s body frame.
    pub from_from_to: Pose3,
    /// Information matrix (inverse covariance) over the optimiser's SE(3) tangent (ω, v), right
    /// perturbation of `from_from_to`.
    pub information: Matrix6<f64>,
}
