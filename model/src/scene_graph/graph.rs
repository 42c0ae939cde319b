//! The scene graph: the three layers and their cross-layer links, changed only through methods
//! that keep every link consistent. Maps are ordered (`BTreeMap`) so that iteration, and so every
//! output derived from it, is deterministic.

use super::cloud_store::{CloudChange, CloudStoreConfig, CloudStoreStats, KeyframeCloudStore};
use super::{
    KeyframeEdge, KeyframeId, KeyframeRef, LabelId, Object, ObjectEdge, ObjectId, SceneGraphError, SemanticScan, Stamp,
};
use crate::geometry::Pose3;
use crate::scene_graph::Keyframe;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// One robot's scene graph.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SceneGraph {
    keyframes: BTreeMap<KeyframeId, Keyframe>,
    edges: Vec<KeyframeEdge>,
    objects: BTreeMap<ObjectId, Object>,
    /// Cross-layer index: the objects each keyframe observed.
    objects_by_keyframe: BTreeMap<KeyframeId, BTreeSet<ObjectId>>,
    /// The semantic layer, within a byte budget when the owner calls [`SceneGraph::fit_clouds`].
    semantic: KeyframeCloudStore,
    next_object_id: u32,
}

fn finite_pose(pose: &Pose3) -> bool {
    pose.translation.vector.iter().all(|v| v.is_finite()) && pose.rotation.coords.iter().all(|v| v.is_finite())
}

fn finite_point(p: &Point3<f64>) -> bool {
    p.coords.iter().all(|v| v.is_finite())
}

impl SceneGraph {
    pub fn new() -> Self {
        Self::default()
    }

    // ----- keyframe layer -------------------------------------------------------------------

    /// Adds a keyframe. Stamps must not go backwards; ids must be new.
    pub fn add_keyframe(&mut self, keyframe: Keyframe) -> Result<(), SceneGraphError> {
        if self.keyframes.contains_key(&keyframe.id) {
            return Err(SceneGraphError::DuplicateKeyframe(keyframe.id));
        }
        if !keyframe.stamp.is_finite() {
            return Err(SceneGraphError::NonFinite { what: "keyframe stamp" });
        }
        if !finite_pose(&keyframe.world_from_body) {
            return Err(SceneGraphError::NonFinite { what: "keyframe pose" });
        }
        if let Some(latest) = self.latest_keyframe() {
            if keyframe.stamp < latest.stamp {
                return Err(SceneGraphError::StampNotIncreasing {
                    id: keyframe.id,
                    stamp: keyframe.stamp,
                    latest: latest.stamp,
                });
            }
        }
        self.keyframes.insert(keyframe.id, keyframe);
        Ok(())
    }

    pub fn keyframe(&self, id: KeyframeId) -> Option<&Keyframe> {
        self.keyframes.get(&id)
    }

    pub fn keyframes(&self) -> impl Iterator<Item = &Keyframe> {
        self.keyframes.values()
    }

    pub fn keyframe_count(&self) -> usize {
        self.keyframes.len()
    }

    /// The keyframe with the latest stamp (ties: the largest id).
    pub fn latest_keyframe(&self) -> Option<&Keyframe> {
        self.keyframes.values().max_by(|a, b| a.stamp.total_cmp(&b.stamp).then(a.id.cmp(&b.id)))
    }

    /// Adds an odometry, loop or inter-robot edge. Its local endpoints must exist.
    pub fn add_edge(&mut self, edge: KeyframeEdge) -> Result<(), SceneGraphError> {
        if !self.keyframes.contains_key(&edge.from) {
            return Err(SceneGraphError::UnknownKeyframe(edge.from));
        }
        if let KeyframeRef::Local(to) = edge.to {
            if !self.keyframes.contains_key(&to) {
                return Err(SceneGraphError::UnknownKeyframe(to));
            }
        }
        if !finite_pose(&edge.from_from_to) || edge.information.iter().any(|v| !v.is_finite()) {
            return Err(SceneGraphError::NonFinite { what: "edge measurement" });
        }
        self.edges.push(edge);
        Ok(())
    }

    pub fn edges(&self) -> &[KeyframeEdge] {
        &self.edges
    }

    /// Replaces keyframe poses (e.g. after pose-graph optimisation). All-or-nothing: if any id is
    /// unknown or any pose is not finite, nothing changes. Objects follow their anchor keyframes.
    pub fn update_keyframe_poses<'a>(
        &mut self,
        poses: impl IntoIterator<Item = (KeyframeId, &'a Pose3)>,
    ) -> Result<(), SceneGraphError> {
        let poses: Vec<(KeyframeId, Pose3)> = poses.into_iter().map(|(id, p)| (id, *p)).collect();
        for (id, pose) in &poses {
            if !self.keyframes.contains_key(id) {
                return Err(SceneGraphError::UnknownKeyframe(*id));
            }
            if !finite_pose(pose) {
                return Err(SceneGraphError::NonFinite { what: "keyframe pose" });
            }
        }
        for (id, pose) in poses {
            if let Some(kf) = self.keyframes.get_mut(&id) {
                kf.world_from_body = pose;
            }
        }
        Ok(())
    }

    // ----- object layer ---------------------------------------------------------------------

    /// Adds a new object seen from `keyframe` at `centroid_in_world`; returns its id.
    pub fn add_object(
        &mut self,
        label: LabelId,
        centroid_in_world: Point3<f64>,
        size: Vector3<f64>,
        keyframe: KeyframeId,
    ) -> Result<ObjectId, SceneGraphError> {
        let world_from_body = self.checked_observation(keyframe, &centroid_in_world, &size)?;
        let id = ObjectId(self.next_object_id);
        self.next_object_id += 1;
        let object = Object {
            id,
            label,
            anchor: keyframe,
            centroid_in_anchor: world_from_body.inverse_transform_point(&centroid_in_world),
            size,
            observed_in: BTreeSet::from([keyframe]),
        };
        self.objects.insert(id, object);
        self.objects_by_keyframe.entry(keyframe).or_default().insert(id);
        Ok(id)
    }

    /// Records a new sighting of an existing object from `keyframe`. If `keyframe` is at least as
    /// recent as the object's anchor, it becomes the anchor and the estimate moves toward the
    /// new one by `share` ∈ [0, 1] (1: replaced, the paper's re-anchoring), both read in the
    /// world through the current keyframe poses:
    ///
    /// ```text
    /// c ← c_old + share · (c_new − c_old),   size ← size_old + share · (size_new − size_old)
    /// ```
    ///
    /// An older sighting only adds the cross-layer link.
    pub fn observe_object(
        &mut self,
        id: ObjectId,
        centroid_in_world: Point3<f64>,
        size: Vector3<f64>,
        keyframe: KeyframeId,
        share: f64,
    ) -> Result<(), SceneGraphError> {
        let world_from_body = self.checked_observation(keyframe, &centroid_in_world, &size)?;
        if !(0.0..=1.0).contains(&share) {
            return Err(SceneGraphError::ShareOutOfRange { id, share });
        }
        let new_stamp = self.stamp_of(keyframe)?;
        let anchor = self.objects.get(&id).ok_or(SceneGraphError::UnknownObject(id))?.anchor;
        let anchor_stamp = self.stamp_of(anchor)?;
        let old_in_world = self.centroid_in_world(id).ok_or(SceneGraphError::UnknownKeyframe(anchor))?;
        let object = self.objects.get_mut(&id).ok_or(SceneGraphError::UnknownObject(id))?;
        if (new_stamp, keyframe) >= (anchor_stamp, anchor) {
            let fused = old_in_world + share * (centroid_in_world - old_in_world);
            object.anchor = keyframe;
            object.centroid_in_anchor = world_from_body.inverse_transform_point(&fused);
            object.size += share * (size - object.size);
        }
        object.observed_in.insert(keyframe);
        self.objects_by_keyframe.entry(keyframe).or_default().insert(id);
        Ok(())
    }

    /// Folds object `gone` into `keep`, one object the tracker saw as two: `keep` takes every
    /// sighting of `gone` and the more recent of the two anchors. Its centroid is the mean of
    /// both pieces' points, `gone_share` ∈ [0, 1] being the share of them in `gone`'s estimate,
    /// and its size the extent of both (world axes; the box of each read as its centroid ± ½
    /// size): one object seen in two pieces, a lamp post cut by a gap between beams, is their
    /// union. The size is stored beside the centroid, not the extent's centre, so a box read
    /// back as centroid ± ½ size is off by the difference where the pieces' returns are uneven
    /// (as every object's box is where its returns crowd to one end).
    ///
    /// ```text
    /// centroid = (1 − w) c_keep + w c_gone,     w = gone_share
    /// lo = min(c_k − ½ s_k, c_g − ½ s_g),  hi = max(c_k + ½ s_k, c_g + ½ s_g),  size = hi − lo
    /// ```
    ///
    /// `gone` and its links are removed. Both must exist, be distinct and share a label, and
    /// `gone_share` must lie in [0, 1]; otherwise nothing changes.
    pub fn merge_objects(&mut self, keep: ObjectId, gone: ObjectId, gone_share: f64) -> Result<(), SceneGraphError> {
        let (Some(k), Some(g)) = (self.objects.get(&keep), self.objects.get(&gone)) else {
            let missing = if self.objects.contains_key(&keep) { gone } else { keep };
            return Err(SceneGraphError::UnknownObject(missing));
        };
        if keep == gone || k.label != g.label || !(0.0..=1.0).contains(&gone_share) {
            return Err(SceneGraphError::NotOneObject { keep, gone });
        }
        let fresher = (self.stamp_of(g.anchor)?, g.anchor) > (self.stamp_of(k.anchor)?, k.anchor);
        let anchor = if fresher { g.anchor } else { k.anchor };
        let world_from_anchor =
            self.keyframes.get(&anchor).ok_or(SceneGraphError::UnknownKeyframe(anchor))?.world_from_body;
        let c_k = self.centroid_in_world(keep).ok_or(SceneGraphError::UnknownKeyframe(k.anchor))?;
        let c_g = self.centroid_in_world(gone).ok_or(SceneGraphError::UnknownKeyframe(g.anchor))?;
        let lo = (c_k.coords - 0.5 * k.size).inf(&(c_g.coords - 0.5 * g.size));
        let hi = (c_k.coords + 0.5 * k.size).sup(&(c_g.coords + 0.5 * g.size));
        let centroid_in_world = Point3::from(c_k.coords.lerp(&c_g.coords, gone_share));
        let removed = self.remove_object(gone)?;
        for keyframe in &removed.observed_in {
            self.objects_by_keyframe.entry(*keyframe).or_default().insert(keep);
        }
        let object = self.objects.get_mut(&keep).ok_or(SceneGraphError::UnknownObject(keep))?;
        object.observed_in.extend(removed.observed_in);
        object.anchor = anchor;
        object.centroid_in_anchor = world_from_anchor.inverse_transform_point(&centroid_in_world);
        object.size = hi - lo;
        Ok(())
    }

    /// Removes an object and its cross-layer links; returns it.
    pub fn remove_object(&mut self, id: ObjectId) -> Result<Object, SceneGraphError> {
        let object = self.objects.remove(&id).ok_or(SceneGraphError::UnknownObject(id))?;
        for keyframe in &object.observed_in {
            if let Some(seen) = self.objects_by_keyframe.get_mut(keyframe) {
                seen.remove(&id);
                if seen.is_empty() {
                    self.objects_by_keyframe.remove(keyframe);
                }
            }
        }
        Ok(object)
    }

    fn stamp_of(&self, keyframe: KeyframeId) -> Result<Stamp, SceneGraphError> {
        self.keyframes.get(&keyframe).map(|k| k.stamp).ok_or(SceneGraphError::UnknownKeyframe(keyframe))
    }

    fn checked_observation(
        &self,
        keyframe: KeyframeId,
        centroid: &Point3<f64>,
        size: &Vector3<f64>,
    ) -> Result<Pose3, SceneGraphError> {
        if !finite_point(centroid) {
            return Err(SceneGraphError::NonFinite { what: "object centroid" });
        }
        if size.iter().any(|v| !v.is_finite()) {
            return Err(SceneGraphError::NonFinite { what: "object size" });
        }
        self.keyframes.get(&keyframe).map(|k| k.world_from_body).ok_or(SceneGraphError::UnknownKeyframe(keyframe))
    }

    pub fn object(&self, id: ObjectId) -> Option<&Object> {
        self.objects.get(&id)
    }

    pub fn objects(&self) -> impl Iterator<Item = &Object> {
        self.objects.values()
    }

    pub fn object_count(&self) -> usize {
        self.objects.len()
    }

    /// Current centroid of an object in this robot's world frame: the anchor keyframe's pose
    /// applied to the stored body-frame centroid.
    pub fn centroid_in_world(&self, id: ObjectId) -> Option<Point3<f64>> {
        let object = self.objects.get(&id)?;
        let anchor = self.keyframes.get(&object.anchor)?;
        Some(anchor.world_from_body * object.centroid_in_anchor)
    }

    /// Object-layer edges: every pair of objects (a < b) with the distance between their current
    /// centroids. Fully connected as in the paper; `max_distance_m` keeps only shorter edges.
    pub fn object_edges(&self, max_distance_m: f64) -> Vec<ObjectEdge> {
        let placed: Vec<(ObjectId, Point3<f64>)> =
            self.objects.keys().filter_map(|&id| self.centroid_in_world(id).map(|p| (id, p))).collect();
        let mut edges = Vec::new();
        for (k, (a, pa)) in placed.iter().enumerate() {
            for (b, pb) in &placed[k + 1..] {
                let distance_m = (pa - pb).norm();
                if distance_m <= max_distance_m {
                    edges.push(ObjectEdge { a: *a, b: *b, distance_m });
                }
            }
        }
        edges
    }

    // ----- cross-layer links and semantic layer ---------------------------------------------

    /// Objects observed in a keyframe.
    pub fn objects_observed_in(&self, keyframe: KeyframeId) -> impl Iterator<Item = ObjectId> + '_ {
        self.objects_by_keyframe.get(&keyframe).into_iter().flat_map(|s| s.iter().copied())
    }

    /// Keyframes that observed an object.
    pub fn keyframes_observing(&self, id: ObjectId) -> impl Iterator<Item = KeyframeId> + '_ {
        self.objects.get(&id).into_iter().flat_map(|o| o.observed_in.iter().copied())
    }

    /// Attaches the labelled scan captured at `keyframe` (replacing any previous one).
    pub fn set_semantic_scan(&mut self, keyframe: KeyframeId, scan: SemanticScan) -> Result<(), SceneGraphError> {
        if !self.keyframes.contains_key(&keyframe) {
            return Err(SceneGraphError::UnknownKeyframe(keyframe));
        }
        if scan.points_in_body.len() != scan.labels.len() {
            return Err(SceneGraphError::LabelCountMismatch {
                points: scan.points_in_body.len(),
                labels: scan.labels.len(),
            });
        }
        if scan.points_in_body.iter().any(|p| p.coords.iter().any(|v| !v.is_finite())) {
            return Err(SceneGraphError::NonFinite { what: "semantic point" });
        }
        self.semantic.insert(keyframe, scan);
        Ok(())
    }

    /// The scan of `keyframe`; `None` when it has none or it was evicted.
    pub fn semantic_scan(&self, keyframe: KeyframeId) -> Option<&SemanticScan> {
        self.semantic.get(keyframe)
    }

    /// The scan of `keyframe`, shared with its reader rather than copied.
    pub fn semantic_scan_shared(&self, keyframe: KeyframeId) -> Option<std::sync::Arc<SemanticScan>> {
        self.semantic.shared(keyframe)
    }

    /// Brings the semantic layer within `config`'s budget ([`KeyframeCloudStore::fit`]), judging
    /// redundancy at the keyframes' current positions.
    pub fn fit_clouds(
        &mut self,
        config: &CloudStoreConfig,
        object_class: impl Fn(LabelId) -> bool,
    ) -> Vec<CloudChange> {
        let keyframes = &self.keyframes;
        self.semantic.fit(config, object_class, |k| keyframes.get(&k).map(|kf| kf.world_from_body.translation.vector))
    }

    pub fn cloud_stats(&self) -> CloudStoreStats {
        self.semantic.stats()
    }

    /// The semantic points of every keyframe with `label`, in the world frame (at the keyframes'
    /// current poses).
    pub fn semantic_points_in_world(&self, label: LabelId) -> Vec<Point3<f64>> {
        let mut out = Vec::new();
        for (id, scan) in self.semantic.iter() {
            let Some(kf) = self.keyframes.get(&id) else { continue };
            for (p, l) in scan.points_in_body.iter().zip(&scan.labels) {
                if *l == label {
                    out.push(kf.world_from_body * p.cast::<f64>());
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_yaw_translation;
    use crate::scene_graph::{KeyframeEdgeKind, RobotId};
    use nalgebra::Matrix6;

    fn kf(id: u32, stamp: f64, x: f64, yaw: f64) -> Keyframe {
        Keyframe {
            id: KeyframeId(id),
            stamp,
            world_from_body: pose_from_yaw_translation(yaw, Vector3::new(x, 0.0, 0.0)),
        }
    }

    fn graph_with_three_keyframes() -> SceneGraph {
        let mut g = SceneGraph::new();
        for (i, x) in [0.0, 5.0, 10.0].into_iter().enumerate() {
            g.add_keyframe(kf(i as u32, i as f64, x, 0.0)).unwrap();
        }
        g
    }

    /// A sighting with share ½ moves the estimate (read in the world, through both anchors'
    /// poses) halfway to the new one and re-anchors it; a share outside [0, 1] is refused and
    /// changes nothing.
    #[test]
    fn a_sighting_moves_the_estimate_by_its_share() {
        let mut g = SceneGraph::new();
        for (k, x) in [(0, 0.0), (1, 4.0)] {
            let world_from_body = Pose3::translation(x, 0.0, 0.0);
            g.add_keyframe(Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body }).unwrap();
        }
        let id =
            g.add_object(LabelId(6), Point3::new(6.0, 2.0, 0.5), Vector3::new(0.4, 0.4, 0.8), KeyframeId(0)).unwrap();
        let before = g.clone();
        let e = g.observe_object(id, Point3::new(6.0, 2.4, 0.5), Vector3::repeat(1.0), KeyframeId(1), 1.5);
        assert_eq!(e, Err(SceneGraphError::ShareOutOfRange { id, share: 1.5 }));
        assert_eq!(g, before);
        g.observe_object(id, Point3::new(6.0, 2.4, 0.5), Vector3::new(0.6, 0.4, 0.8), KeyframeId(1), 0.5).unwrap();
        let o = g.object(id).unwrap();
        assert_eq!(o.anchor, KeyframeId(1));
        assert!((g.centroid_in_world(id).unwrap() - Point3::new(6.0, 2.2, 0.5)).norm() < 1e-12);
        assert!((o.centroid_in_anchor - Point3::new(2.0, 2.2, 0.5)).norm() < 1e-12);
        assert!((o.size - Vector3::new(0.5, 0.4, 0.8)).norm() < 1e-12);
    }

    #[test]
    fn objects_follow_their_latest_observing_keyframe_when_poses_change() {
        let mut g = graph_with_three_keyframes();
        let chair = LabelId(1);
        let id = g.add_object(chair, Point3::new(6.0, 2.0, 0.5), Vector3::new(0.5, 0.5, 1.0), KeyframeId(0)).unwrap();
        g.observe_object(id, Point3::new(6.2, 2.0, 0.5), Vector3::new(0.5, 0.5, 1.0), KeyframeId(2), 1.0).unwrap();
        assert_eq!(g.object(id).unwrap().anchor, KeyframeId(2));
        // An older sighting adds the link but does not move the anchor.
        g.observe_object(id, Point3::new(9.0, 9.0, 9.0), Vector3::new(1.0, 1.0, 1.0), KeyframeId(1), 1.0).unwrap();
        assert_eq!(g.object(id).unwrap().anchor, KeyframeId(2));
        assert_eq!(g.keyframes_observing(id).collect::<Vec<_>>(), vec![KeyframeId(0), KeyframeId(1), KeyframeId(2)]);
        assert!((g.centroid_in_world(id).unwrap() - Point3::new(6.2, 2.0, 0.5)).norm() < 1e-12);

        // A loop closure rotates keyframe 2 by 90° about its own origin and shifts it by (0, 1).
        let corrected = pose_from_yaw_translation(std::f64::consts::FRAC_PI_2, Vector3::new(10.0, 1.0, 0.0));
        g.update_keyframe_poses([(KeyframeId(2), &corrected)]).unwrap();
        // In keyframe 2's body the object was at (-3.8, 2.0, 0.5); now world = R·p + t.
        let expected = Point3::new(10.0 - 2.0, 1.0 - 3.8, 0.5);
        assert!((g.centroid_in_world(id).unwrap() - expected).norm() < 1e-12);
    }

    /// Two objects that are one: the kept id takes every link, the fresher anchor, the mean of
    /// both pieces' returns and the extent of both; what cannot be merged (an unknown id,
    /// itself, another label, a share outside [0, 1]) leaves the graph as it was.
    #[test]
    fn merging_two_objects_keeps_every_link_and_the_extent_of_both() {
        let mut g = graph_with_three_keyframes();
        let post = LabelId(3);
        // The lower piece of a lamp post, 0–1.2 m, and its upper piece, 3.0–5.0 m, a little off.
        let a = g.add_object(post, Point3::new(7.0, 2.0, 0.6), Vector3::new(0.2, 0.2, 1.2), KeyframeId(0)).unwrap();
        let b = g.add_object(post, Point3::new(7.0, 2.0, 3.7), Vector3::new(0.5, 0.5, 0.5), KeyframeId(1)).unwrap();
        g.observe_object(b, Point3::new(7.1, 2.0, 4.0), Vector3::new(0.4, 0.2, 2.0), KeyframeId(2), 1.0).unwrap();
        let chair = g.add_object(LabelId(1), Point3::new(9.0, 2.0, 0.5), Vector3::repeat(0.5), KeyframeId(2)).unwrap();
        let before = g.clone();
        for (keep, gone, share) in [
            (a, ObjectId(99), 0.5),
            (ObjectId(99), a, 0.5),
            (a, a, 0.5),
            (a, chair, 0.5),
            (a, b, 1.5),
            (a, b, f64::NAN),
        ] {
            assert!(g.merge_objects(keep, gone, share).is_err(), "{keep} ← {gone} ({share})");
            assert_eq!(g, before);
        }
        // The pole's estimate holds three times the head's returns.
        g.merge_objects(a, b, 0.25).unwrap();
        assert_eq!(g.object_count(), 2);
        assert!(g.object(b).is_none());
        let kept = g.object(a).unwrap();
        assert_eq!(kept.anchor, KeyframeId(2), "b's sighting at keyframe 2 is the freshest");
        // ¾ (7.0, 2.0, 0.6) + ¼ (7.1, 2.0, 4.0); the box x: [6.9, 7.3], y: [1.9, 2.1], z: [0.0, 5.0].
        let centroid = g.centroid_in_world(a).unwrap();
        assert!((centroid - Point3::new(7.025, 2.0, 1.45)).norm() < 1e-12, "{centroid}");
        assert!((kept.size - Vector3::new(0.4, 0.2, 5.0)).norm() < 1e-12, "{}", kept.size);
        assert_eq!(g.keyframes_observing(a).collect::<Vec<_>>(), [0, 1, 2].map(KeyframeId));
        for k in 0..3 {
            assert!(!g.objects_observed_in(KeyframeId(k)).any(|o| o == b));
            assert!(g.objects_observed_in(KeyframeId(k)).any(|o| o == a), "keyframe {k}");
        }
        // Removing an object drops its links too.
        assert_eq!(g.remove_object(chair).unwrap().id, chair);
        assert_eq!(g.objects_observed_in(KeyframeId(2)).collect::<Vec<_>>(), vec![a]);
        assert!(g.remove_object(chair).is_err());
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(128))]
        /// Whatever two objects of one label a merge folds, from keyframes turned any way: the
        /// kept centroid lies on the segment between the two, at `gone_share` of the way (in
        /// the world, through the anchors' poses); the kept size is the extent of both boxes;
        /// the kept object is seen by every keyframe that saw either.
        #[test]
        fn a_merge_keeps_both_boxes_and_weighs_the_centroid(
            yaws in proptest::array::uniform2(-3.1f64..3.1),
            a in proptest::array::uniform3(-20.0f64..20.0),
            b in proptest::array::uniform3(-20.0f64..20.0),
            size_a in proptest::array::uniform3(0.0f64..5.0),
            size_b in proptest::array::uniform3(0.0f64..5.0),
            share in 0.0f64..=1.0,
        ) {
            let mut g = SceneGraph::new();
            g.add_keyframe(kf(0, 0.0, 1.0, yaws[0])).unwrap();
            g.add_keyframe(kf(1, 1.0, -2.0, yaws[1])).unwrap();
            let (a, b) = (Point3::from(a), Point3::from(b));
            let (size_a, size_b) = (Vector3::from(size_a), Vector3::from(size_b));
            let keep = g.add_object(LabelId(2), a, size_a, KeyframeId(0)).unwrap();
            let gone = g.add_object(LabelId(2), b, size_b, KeyframeId(1)).unwrap();
            g.merge_objects(keep, gone, share).unwrap();
            proptest::prop_assert!(g.object(gone).is_none());
            let merged = g.object(keep).unwrap();
            proptest::prop_assert_eq!(merged.anchor, KeyframeId(1));
            let centroid = g.centroid_in_world(keep).unwrap();
            proptest::prop_assert!((centroid - (a + share * (b - a))).norm() < 1e-9, "{}", centroid);
            let lo = (a.coords - 0.5 * size_a).inf(&(b.coords - 0.5 * size_b));
            let hi = (a.coords + 0.5 * size_a).sup(&(b.coords + 0.5 * size_b));
            proptest::prop_assert!((merged.size - (hi - lo)).norm() < 1e-9, "{}", merged.size);
            proptest::prop_assert_eq!(g.keyframes_observing(keep).collect::<Vec<_>>(), vec![KeyframeId(0), KeyframeId(1)]);
        }
    }

    #[test]
    fn failed_pose_update_changes_nothing() {
        let mut g = graph_with_three_keyframes();
        let before = g.clone();
        let good = pose_from_yaw_translation(0.3, Vector3::new(1.0, 1.0, 0.0));
        let err = g.update_keyframe_poses([(KeyframeId(0), &good), (KeyframeId(9), &good)]).unwrap_err();
        assert_eq!(err, SceneGraphError::UnknownKeyframe(KeyframeId(9)));
        assert_eq!(g, before);
        let mut nan = good;
        nan.translation.vector.x = f64::NAN;
        assert!(g.update_keyframe_poses([(KeyframeId(0), &nan)]).is_err());
        assert_eq!(g, before);
    }

    #[test]
    fn keyframe_layer_rejects_bad_input() {
        let mut g = graph_with_three_keyframes();
        assert_eq!(g.add_keyframe(kf(1, 5.0, 0.0, 0.0)), Err(SceneGraphError::DuplicateKeyframe(KeyframeId(1))));
        assert!(matches!(g.add_keyframe(kf(7, 0.5, 0.0, 0.0)), Err(SceneGraphError::StampNotIncreasing { .. })));
        assert!(g.add_keyframe(kf(8, f64::NAN, 0.0, 0.0)).is_err());
        let edge = |from, to| KeyframeEdge {
            kind: KeyframeEdgeKind::Odometry,
            from: KeyframeId(from),
            to,
            from_from_to: Pose3::identity(),
            information: Matrix6::identity(),
        };
        assert!(g.add_edge(edge(0, KeyframeRef::Local(KeyframeId(1)))).is_ok());
        assert_eq!(
            g.add_edge(edge(0, KeyframeRef::Local(KeyframeId(5)))),
            Err(SceneGraphError::UnknownKeyframe(KeyframeId(5)))
        );
        let inter = edge(2, KeyframeRef::Remote { robot: RobotId(1), keyframe: KeyframeId(40) });
        assert!(g.add_edge(KeyframeEdge { kind: KeyframeEdgeKind::InterRobot, ..inter }).is_ok());
        assert_eq!(g.edges().len(), 2);
        assert_eq!(g.keyframe_count(), 3);
    }

    #[test]
    fn object_edges_are_centroid_distances_and_cross_links_are_kept() {
        let mut g = graph_with_three_keyframes();
        let a = g.add_object(LabelId(0), Point3::new(0.0, 0.0, 0.0), Vector3::repeat(1.0), KeyframeId(0)).unwrap();
        let b = g.add_object(LabelId(0), Point3::new(3.0, 4.0, 0.0), Vector3::repeat(1.0), KeyframeId(1)).unwrap();
        let c = g.add_object(LabelId(2), Point3::new(30.0, 40.0, 0.0), Vector3::repeat(1.0), KeyframeId(1)).unwrap();
        let edges = g.object_edges(f64::INFINITY);
        assert_eq!(edges.len(), 3);
        assert_eq!((edges[0].a, edges[0].b), (a, b));
        assert!((edges[0].distance_m - 5.0).abs() < 1e-12);
        assert_eq!(g.object_edges(10.0).len(), 1);
        assert_eq!(g.objects_observed_in(KeyframeId(1)).collect::<Vec<_>>(), vec![b, c]);
        assert!(g
            .add_object(LabelId(0), Point3::new(f64::NAN, 0.0, 0.0), Vector3::repeat(1.0), KeyframeId(0))
            .is_err());
        assert!(g.add_object(LabelId(0), Point3::origin(), Vector3::repeat(1.0), KeyframeId(42)).is_err());
        assert_eq!(g.object_count(), 3);
    }

    #[test]
    fn semantic_layer_is_linked_to_keyframes_and_moves_with_them() {
        let mut g = graph_with_three_keyframes();
        let scan = SemanticScan {
            points_in_body: vec![Point3::new(1.0, 0.0, 0.0), Point3::new(2.0, 0.0, 0.0)],
            labels: vec![LabelId(3), LabelId(4)],
        };
        g.set_semantic_scan(KeyframeId(1), scan.clone()).unwrap();
        assert_eq!(g.semantic_points_in_world(LabelId(3)), vec![Point3::new(6.0, 0.0, 0.0)]);
        let moved = pose_from_yaw_translation(0.0, Vector3::new(5.0, 2.0, 0.0));
        g.update_keyframe_poses([(KeyframeId(1), &moved)]).unwrap();
        assert_eq!(g.semantic_points_in_world(LabelId(3)), vec![Point3::new(6.0, 2.0, 0.0)]);
        let bad = SemanticScan { labels: vec![LabelId(1)], ..scan };
        assert!(matches!(g.set_semantic_scan(KeyframeId(1), bad), Err(SceneGraphError::LabelCountMismatch { .. })));
        assert!(g.set_semantic_scan(KeyframeId(9), SemanticScan::default()).is_err());
        assert_eq!(g.semantic_scan(KeyframeId(1)).map(|s| s.len()), Some(2));
    }
}
