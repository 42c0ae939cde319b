//! One scan's semantic fusion as plain state (paper §IV-A): each point's pixel value (from a
//! label image, `projection::label_points`, or given per point) becomes an SGM class through the
//! segmenter's table (`label_map`; values it does not know are counted and carry no class); a
//! vote among 3-D neighbours undoes labels that bled across depth edges (`label_vote`); classes
//! that are not objects are cleared; returns of a dynamic class (people: `ClassSpec::dynamic`)
//! are dropped, so that nothing that moves reaches the object layer or a keyframe's cloud;
//! returns beyond `max_range_m` (or not finite) are dropped;
//! objects are clustered per class from the returns within `object_range_m` only
//! (`clustering`). The Fusion actor owns one.

use super::classes::ClassTable;
use super::clustering::{cluster, ClusterConfig, ObjectCandidate};
use super::label_map::{LabelMap, Mapped, UnknownLabels, NO_CLASS};
use super::label_vote::{vote, LabelVote};
use crate::scene_graph::LabelId;
use nalgebra::{Point3, UnitQuaternion};

/// How scans are fused.
#[derive(Clone, Debug, PartialEq)]
pub struct ScanFusionConfig {
    pub clustering: ClusterConfig,
    /// Returns farther than this are dropped, m.
    pub max_range_m: f64,
    /// Objects are clustered from returns within this range only, m.
    pub object_range_m: f64,
    pub label_vote: LabelVote,
}

/// A fused scan: the kept returns (body frame), their object classes, and the object candidates.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FusedScan {
    pub points_in_body: Vec<Point3<f64>>,
    pub labels: Vec<Option<LabelId>>,
    pub candidates: Vec<ObjectCandidate>,
    /// Pixel values heard for the first time that `[classes]` does not know (to be reported
    /// once each).
    pub new_unknown_ids: Vec<u16>,
}

pub struct ScanFusion {
    classes: ClassTable,
    label_map: LabelMap,
    config: ScanFusionConfig,
    unknown: UnknownLabels,
}

impl ScanFusion {
    pub fn new(classes: ClassTable, label_map: LabelMap, config: ScanFusionConfig) -> Self {
        Self { classes, label_map, config, unknown: UnknownLabels::default() }
    }

    /// The segmenter whose pixel values the label map reads.
    pub fn segmenter(&self) -> &str {
        self.label_map.segmenter()
    }

    /// Returns whose pixel values no class knows, counted per value.
    pub fn unknown(&self) -> &UnknownLabels {
        &self.unknown
    }

    /// Fuses one scan: `pixels[k]` is point k's pixel value (`None`: unlabelled). Candidates'
    /// extents are measured along the odometry frame's axes (`clustering`), `odom_from_body`
    /// being the body's attitude at the scan.
    pub fn fuse(
        &mut self,
        points_in_body: &[Point3<f64>],
        pixels: Vec<Option<LabelId>>,
        odom_from_body: &UnitQuaternion<f64>,
    ) -> FusedScan {
        let mut new_unknown_ids = Vec::new();
        let labels: Vec<Option<LabelId>> = pixels
            .into_iter()
            .map(|l| {
                l.map(|LabelId(pixel)| match self.label_map.get(pixel) {
                    Mapped::Class(class) => class,
                    Mapped::Ignored => NO_CLASS,
                    Mapped::Unknown => {
                        if self.unknown.add(pixel) {
                            new_unknown_ids.push(pixel);
                        }
                        NO_CLASS
                    }
                })
            })
            .collect();
        let classes = &self.classes;
        let labels = vote(points_in_body, &labels, &self.config.label_vote, |l| classes.object_label(l.0).is_some());
        let (r2, near) = (
            self.config.max_range_m * self.config.max_range_m,
            self.config.object_range_m * self.config.object_range_m,
        );
        let n = labels.len();
        let (mut points, mut kept, mut clustered) =
            (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
        for (p, l) in points_in_body.iter().zip(labels) {
            if l.is_some_and(|l| self.classes.is_dynamic(l)) {
                continue;
            }
            let d2 = p.coords.norm_squared();
            if p.coords.iter().all(|v| v.is_finite()) && d2 <= r2 {
                let label = l.and_then(|LabelId(id)| self.classes.object_label(id));
                points.push(*p);
                kept.push(label);
                // Objects are clustered from returns within the object range only.
                clustered.push(if d2 <= near { label } else { None });
            }
        }
        let candidates = cluster(&points, &clustered, &self.config.clustering, odom_from_body);
        FusedScan { points_in_body: points, labels: kept, candidates, new_unknown_ids }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::perception::classes::ClassSpec;

    fn class(name: &str, id: u16, object: bool) -> ClassSpec {
        ClassSpec {
            name: name.into(),
            id,
            colour: [0, 0, 0],
            matchable: object,
            object,
            dynamic: false,
            min_points: 5,
            max_points: 10_000,
            max_extent_m: 5.0,
        }
    }

    fn fusion() -> ScanFusion {
        let person = ClassSpec { dynamic: true, matchable: false, ..class("person", 2, true) };
        let classes = ClassTable::new(vec![class("ground", 0, false), class("tree", 1, true), person]).expect("table");
        let config = ScanFusionConfig {
            // Blocks of returns that fill their volume: the mean is the centre, no far-side shift.
            clustering: ClusterConfig { far_side_shift: 0.0, ..classes.cluster_config(0.5) },
            max_range_m: 50.0,
            object_range_m: 20.0,
            label_vote: LabelVote { voxel_m: 0.0 },
        };
        let map = LabelMap::identity(&classes);
        ScanFusion::new(classes, map, config)
    }

    /// A 3 × 3 × 3 block of returns 0.1 m apart, its corner at (x, 0, 0).
    fn block(x: f64) -> Vec<Point3<f64>> {
        (0..27)
            .map(|k| Point3::new(x + 0.1 * f64::from(k % 3), 0.1 * f64::from(k / 3 % 3), 0.1 * f64::from(k / 9)))
            .collect()
    }

    #[test]
    fn near_objects_cluster_far_ones_are_kept_unclustered_and_beyond_range_dropped() {
        let mut fusion = fusion();
        let mut points = block(5.0); // a tree within the object range
        points.extend(block(30.0)); // a tree beyond it, within the maximum range
        points.extend(block(60.0)); // beyond the maximum range
        points.push(Point3::new(f64::NAN, 0.0, 0.0));
        let n = points.len();
        let fused = fusion.fuse(&points, vec![Some(LabelId(1)); n], &UnitQuaternion::identity());
        assert_eq!(fused.points_in_body.len(), 54, "the 27 returns at 60 m and the NaN are dropped");
        assert!(fused.labels.iter().all(|l| *l == Some(LabelId(1))), "far returns keep their class");
        assert_eq!(fused.candidates.len(), 1, "only the tree within 20 m is an object");
        let tree = &fused.candidates[0];
        assert_eq!((tree.label, tree.points), (LabelId(1), 27));
        assert!((tree.centroid - Point3::new(5.1, 0.1, 0.1)).norm() < 1e-9);
    }

    #[test]
    fn classes_that_are_not_objects_are_cleared_and_unknown_values_reported_once() {
        let mut fusion = fusion();
        let points = block(5.0);
        let mut pixels = vec![Some(LabelId(0)); 27];
        pixels[0] = Some(LabelId(7));
        pixels[1] = Some(LabelId(7));
        pixels[2] = None;
        let fused = fusion.fuse(&points, pixels.clone(), &UnitQuaternion::identity());
        assert!(fused.labels.iter().all(Option::is_none), "ground is not an object; 7 is no class");
        assert!(fused.candidates.is_empty());
        assert_eq!(fused.new_unknown_ids, vec![7], "reported once per value");
        assert_eq!(fusion.unknown().points, 2);
        let again = fusion.fuse(&points, pixels, &UnitQuaternion::identity());
        assert!(again.new_unknown_ids.is_empty(), "already reported");
        assert_eq!(fusion.unknown().points, 4);
        assert_eq!(fusion.unknown().ids.get(&7), Some(&4));
    }

    #[test]
    fn returns_of_a_dynamic_class_are_dropped_and_never_become_objects() {
        let mut fusion = fusion();
        let mut points = block(5.0); // a tree
        points.extend(block(8.0)); // a person
        let mut pixels = vec![Some(LabelId(1)); 27];
        pixels.extend(vec![Some(LabelId(2)); 27]);
        let fused = fusion.fuse(&points, pixels, &UnitQuaternion::identity());
        assert_eq!(fused.points_in_body.len(), 27, "the person's returns are gone from the scan");
        assert!(fused.points_in_body.iter().all(|p| p.x < 6.0));
        assert_eq!(fused.candidates.len(), 1);
        assert_eq!(fused.candidates[0].label, LabelId(1));
    }
}
