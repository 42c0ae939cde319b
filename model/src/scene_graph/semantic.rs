//! Semantic layer: one labelled scan per keyframe, in that keyframe's body frame.

use super::{LabelId, SceneGraph};
use crate::geometry::Pose3;
use nalgebra::Point3;
use rustc_hash::FxHashMap;
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

/// A voxel's index along x, y and z.
type VoxelKey = (i64, i64, i64);

/// Labelled points thinned to one per cubic voxel (the first to fall in it), for published and
/// exported semantic maps. Voxels are found by hash while points go in (a team's map is millions
/// of points) and put in order when they come out.
#[derive(Clone, Debug)]
pub struct LabelledVoxels {
    voxel_m: f64,
    cells: FxHashMap<VoxelKey, (Point3<f64>, LabelId)>,
}

impl LabelledVoxels {
    pub fn new(voxel_m: f64) -> Self {
        Self { voxel_m, cells: FxHashMap::default() }
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

    /// The kept points, in voxel order (x, then y, then z index). Sorted as copies side by side
    /// (a sort through references to the hashed cells waits on memory at every comparison).
    pub fn points(&self) -> impl Iterator<Item = (Point3<f64>, LabelId)> {
        let mut cells: Vec<(VoxelKey, (Point3<f64>, LabelId))> =
            self.cells.iter().map(|(key, kept)| (*key, *kept)).collect();
        cells.sort_unstable_by_key(|(key, _)| *key);
        cells.into_iter().map(|(_, kept)| kept)
    }

    /// Adds the kept points of `later` (same voxel size) as if its points had been inserted after
    /// this map's: a voxel both hold keeps this map's point. Each of `later`'s voxels holds one
    /// point, so the order they come in does not matter.
    pub fn merge(&mut self, later: &LabelledVoxels) {
        debug_assert_eq!(self.voxel_m.to_bits(), later.voxel_m.to_bits());
        self.cells.reserve(later.cells.len());
        for (key, kept) in &later.cells {
            self.cells.entry(*key).or_insert(*kept);
        }
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

    /// Merging per-part maps in order gives the map of all points inserted in that order.
    #[test]
    fn merging_in_order_is_inserting_in_order() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let parts: Vec<Vec<(Point3<f64>, LabelId)>> = (0..4)
            .map(|_| {
                (0..500)
                    .map(|_| {
                        let p = Point3::new(
                            rng.random_range(-2.0..2.0),
                            rng.random_range(-2.0..2.0),
                            rng.random_range(0.0..1.0),
                        );
                        (p, LabelId(rng.random_range(0..20)))
                    })
                    .collect()
            })
            .collect();
        let mut whole = LabelledVoxels::new(0.5);
        let mut merged = LabelledVoxels::new(0.5);
        for part in &parts {
            let mut one = LabelledVoxels::new(0.5);
            for &(p, label) in part {
                whole.insert(p, label);
                one.insert(p, label);
            }
            merged.merge(&one);
        }
        assert_eq!(whole.len(), merged.len());
        assert!(whole.points().zip(merged.points()).all(|(a, b)| a == b));
    }
}
