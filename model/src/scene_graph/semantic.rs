//! Semantic layer: one labelled scan per keyframe, in that keyframe's body frame.

use super::LabelId;
use nalgebra::Point3;
use serde::{Deserialize, Serialize};

/// Labelled points of one keyframe; `labels[k]` is the class of `points_in_body[k]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SemanticScan {
    pub points_in_body: Vec<Point3<f32>>,
    pub labels: Vec<LabelId>,
}

impl SemanticScan {
    pub fn len(&self) -> usize {
        self.points_in_body.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points_in_body.is_empty()
    }
}
