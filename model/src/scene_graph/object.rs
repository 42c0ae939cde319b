//! Object layer: vertices are objects with a label, a centroid and a size; edges are the Euclidean
//! distances between centroids (paper §IV-A, §IV-B: w_ij = ‖p_i − p_j‖₂).

use super::{KeyframeId, LabelId, ObjectId};
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;

/// An object of the object layer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Object {
    pub id: ObjectId,
    pub label: LabelId,
    /// The latest keyframe that observed the object: its position is stored in that body frame.
    pub anchor: KeyframeId,
    /// Centroid in the anchor keyframe's body frame.
    pub centroid_in_anchor: Point3<f64>,
    /// Extent along the world axes, metres.
    pub size: Vector3<f64>,
    /// Every keyframe that observed the object (cross-layer links).
    pub observed_in: BTreeSet<KeyframeId>,
}

/// An object-layer edge: two objects and the distance between their centroids (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectEdge {
    pub a: ObjectId,
    pub b: ObjectId,
    pub distance_m: f64,
}
