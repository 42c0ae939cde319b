//! Semantic layer: one labelled scan per keyframe, in that keyframe's body frame.

use super::{LabelId, SceneGraph};
use crate::geometry::Pose3;
use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

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

/// Labelled points thinned to one per cubic voxel (the first to fall in it), for published and
/// exported semantic maps.
#[derive(Clone, Debug)]
pub struct LabelledVoxels {
    voxel_m: f64,
    cells: BTreeMap<(i64, i64, i64), (Point3<f64>, LabelId)>,
}

impl LabelledVoxels {
    pub fn new(voxel_m: f64) -> Self {
        Self { voxel_m, cells: BTreeMap::new() }
    }

    pub fn insert(&mut self, p: Point3<f64>, label: LabelId) {
        let key = |v: f64| (v / self.voxel_m).floor() as i64;
        self.cells.entry((key(p.x), key(p.y), key(p.z))).or_insert((p, label));
    }

    /// Every keyframe's semantic scan of `graph`, placed by `frame_from_world · world_from_body`.
    pub fn insert_graph(&mut self, graph: &SceneGraph, frame_from_world: &Pose3) {
        for keyframe in graph.keyframes() {
            let Some(scan) = graph.semantic_scan(keyframe.id) else { continue };
            let pose = frame_from_world * keyframe.world_from_body;
            for (p, label) in scan.points_in_body.iter().zip(&scan.labels) {
                self.insert(pose * p.cast::<f64>(), *label);
            }
        }
    }

    pub fn len(&self) -> usize {
        self.cells.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The kept points, in voxel order.
    pub fn points(&self) -> impl Iterator<Item = &(Point3<f64>, LabelId)> {
        self.cells.values()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_point_per_voxel_the_first() {
        let mut v = LabelledVoxels::new(0.5);
        v.insert(Point3::new(0.1, 0.1, 0.1), LabelId(1));
        v.insert(Point3::new(0.4, 0.2, 0.3), LabelId(2));
        v.insert(Point3::new(-0.1, 0.1, 0.1), LabelId(3));
        let kept: Vec<u16> = v.points().map(|(_, l)| l.0).collect();
        assert_eq!(kept, vec![3, 1]);
    }
}
