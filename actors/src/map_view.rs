//! `MapView`: the robot's map as the Matcher and Comms read it. The Tracker owns the map
//! (`model::perception::mapper::Mapper`); after every change (a keyframe added, the cloud
//! budget fitted, optimised poses applied, a restored map republished) it takes one snapshot
//! and shares it, read-only, behind an `Arc`. The scans inside are the map's own (shared, not
//! copied), so a snapshot costs one pose and one pointer per keyframe plus the object list.
//!
//! The readers hold the latest snapshot whole: keyframe poses, the scans still held and the
//! confirmed objects always belong to the same moment of the map, and no reader keeps a mirror
//! in sync by hand.

use sgm_model::geometry::Pose3;
use sgm_model::matching::GraphObject;
use sgm_model::perception::classes::ClassTable;
use sgm_model::perception::mapper::{Mapper, MapperConfig};
use sgm_model::scene_graph::{KeyframeId, ObjectId, SemanticScan};
use std::collections::BTreeMap;
use std::sync::Arc;

/// A keyframe whose scan the map still holds: its latest (optimised) pose and the scan.
#[derive(Clone, Debug)]
pub struct ViewKeyframe {
    pub world_from_body: Pose3,
    pub scan: Arc<SemanticScan>,
}

/// The confirmed, matchable objects (world frame) and which keyframes observed each: what the
/// object-graph matching uses and what Comms broadcasts.
#[derive(Clone, Debug, Default)]
pub struct LocalObjects {
    pub objects: Vec<GraphObject>,
    pub observed_in: BTreeMap<ObjectId, Vec<KeyframeId>>,
}

/// One moment of the map.
#[derive(Clone, Debug, Default)]
pub struct MapView {
    /// Keyframes whose scan the map holds (evicted ones are absent), by id.
    pub keyframes: BTreeMap<KeyframeId, ViewKeyframe>,
    pub objects: LocalObjects,
    /// What neighbours are told of each of those keyframes' poses, with
    /// `comms.pose_updates.own_estimates`: our own measurements' estimate (the Tracker's
    /// `told_pose`), not the joint solve's. Empty without it: the map poses are told.
    pub told: BTreeMap<KeyframeId, Pose3>,
}

/// What changed between two snapshots in the keyframes a reader can register against.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct KeyframeChanges {
    /// Keyframes the newer snapshot holds and the older did not, ascending.
    pub added: Vec<KeyframeId>,
    /// Keyframes the older snapshot held and the newer does not (their scans evicted), ascending.
    pub removed: Vec<KeyframeId>,
}

impl MapView {
    /// The snapshot of `map`: every keyframe with a held scan, and the objects that are
    /// matchable (`classes`) and confirmed (`config.min_observations`), each with its centroid.
    pub fn of(map: &Mapper, classes: &ClassTable, config: &MapperConfig) -> Self {
        let keyframes = map
            .graph
            .keyframes()
            .filter_map(|k| {
                let scan = map.graph.semantic_scan_shared(k.id)?;
                Some((k.id, ViewKeyframe { world_from_body: k.world_from_body, scan }))
            })
            .collect();
        let mut objects = LocalObjects::default();
        for o in map.graph.objects() {
            if !classes.is_matchable(o.label) || !map.is_confirmed(o.id, config) {
                continue;
            }
            let Some(centroid) = map.graph.centroid_in_world(o.id) else { continue };
            objects.objects.push(GraphObject { id: o.id, label: o.label, centroid, size: Some(o.size) });
            objects.observed_in.insert(o.id, o.observed_in.iter().copied().collect());
        }
        Self { keyframes, objects, told: BTreeMap::new() }
    }

    /// The keyframes `self` holds that `older` did not, and those it no longer holds.
    pub fn changes_since(&self, older: &MapView) -> KeyframeChanges {
        KeyframeChanges {
            added: self.keyframes.keys().filter(|k| !older.keyframes.contains_key(k)).copied().collect(),
            removed: older.keyframes.keys().filter(|k| !self.keyframes.contains_key(k)).copied().collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix6, Point3, Vector3};
    use sgm_model::perception::classes::ClassSpec;
    use sgm_model::perception::clustering::ObjectCandidate;
    use sgm_model::perception::keyframes::KeyframeConfig;
    use sgm_model::perception::loop_closure::LoopClosureConfig;
    use sgm_model::perception::mapper::ScanInput;
    use sgm_model::perception::tracker::TrackerConfig;
    use sgm_model::scene_graph::cloud_store::CloudStoreConfig;
    use sgm_model::scene_graph::LabelId;

    fn config() -> MapperConfig {
        MapperConfig {
            keyframes: KeyframeConfig::default(),
            tracking: TrackerConfig::default(),
            loop_closure: LoopClosureConfig::default(),
            cloud_store: CloudStoreConfig::default(),
            odometry_information: Matrix6::identity() * 100.0,
        }
    }

    /// Chairs (label 3) are matchable; tables (label 4) are objects but not matched.
    fn classes() -> ClassTable {
        let spec = |name: &str, id: u16, matchable: bool| ClassSpec {
            name: name.into(),
            id,
            colour: [1, 2, 3],
            matchable,
            object: true,
            dynamic: false,
            min_points: 1,
            max_points: 100,
            max_extent_m: 2.0,
        };
        ClassTable::new(vec![spec("chair", 3, true), spec("table", 4, false)]).expect("a valid table")
    }

    /// A map of `n` keyframes 2 m apart along x, each seeing the same chair at (1, 2, 0) and the
    /// same table at (1, -2, 0) in the world.
    fn map(n: u32) -> Mapper {
        let (config, classes) = (config(), classes());
        let mut map = Mapper::default();
        for k in 0..n {
            let x = 2.0 * f64::from(k);
            let odom = Pose3::from_parts(Vector3::new(x, 0.0, 0.0).into(), nalgebra::UnitQuaternion::identity());
            let points = vec![Point3::new(1.0 - x, 2.0, 0.0), Point3::new(1.0 - x, -2.0, 0.0)];
            let labels = vec![Some(LabelId(3)), Some(LabelId(4))];
            let candidate =
                |label, centroid| ObjectCandidate { label, centroid, size: Vector3::repeat(0.5), points: 1 };
            let candidates = vec![candidate(LabelId(3), points[0]), candidate(LabelId(4), points[1])];
            let input = ScanInput {
                stamp: f64::from(k),
                odom_from_body: &odom,
                points_in_body: &points,
                labels: &labels,
                candidates: &candidates,
                motion_covariance: None,
            };
            map.add_keyframe(input, &classes, &config, &sgm_model::workers::Workers::sequential())
                .expect("a keyframe on a fresh map");
        }
        map
    }

    #[test]
    fn the_view_holds_every_scanned_keyframe_and_the_confirmed_matchable_objects() {
        let (config, classes) = (config(), classes());
        let confirm_after = config.tracking.confirm_after;
        // Seen once fewer than needed: no object is shared yet.
        let early = MapView::of(&map(confirm_after - 1), &classes, &config);
        assert_eq!(early.keyframes.len(), (confirm_after - 1) as usize);
        assert!(early.objects.objects.is_empty());

        let map = map(confirm_after + 1);
        let view = MapView::of(&map, &classes, &config);
        assert_eq!(view.keyframes.len(), map.graph.keyframe_count());
        for (id, k) in &view.keyframes {
            let kf = map.graph.keyframe(*id).expect("the view's keyframe is the map's");
            assert_eq!(k.world_from_body, kf.world_from_body);
            let held = map.graph.semantic_scan_shared(*id).expect("held");
            assert!(Arc::ptr_eq(&k.scan, &held), "the scan is shared, not copied");
        }
        // The chair, not the table.
        assert_eq!(view.objects.objects.len(), 1, "{:?}", view.objects.objects);
        let chair = &view.objects.objects[0];
        assert_eq!(chair.label, LabelId(3));
        assert!((chair.centroid - Point3::new(1.0, 2.0, 0.0)).norm() < 1e-9, "{}", chair.centroid);
        assert_eq!(view.objects.observed_in[&chair.id].len(), (confirm_after + 1) as usize);
    }

    #[test]
    fn changes_name_the_added_and_the_evicted_keyframes() {
        let scan = Arc::new(SemanticScan::default());
        let view = |ids: &[u32]| MapView {
            keyframes: ids
                .iter()
                .map(|k| (KeyframeId(*k), ViewKeyframe { world_from_body: Pose3::identity(), scan: scan.clone() }))
                .collect(),
            objects: LocalObjects::default(),
            told: BTreeMap::new(),
        };
        let changes = view(&[2, 3, 5, 6]).changes_since(&view(&[1, 2, 3, 4]));
        assert_eq!(changes.added, vec![KeyframeId(5), KeyframeId(6)]);
        assert_eq!(changes.removed, vec![KeyframeId(1), KeyframeId(4)]);
        assert_eq!(view(&[1]).changes_since(&view(&[1])), KeyframeChanges::default());
    }
}
