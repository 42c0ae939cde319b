//! The semantic layer's storage: each keyframe's labelled scan, held within a byte budget.
//!
//! A scan is stored once and shared (`Arc`) with the actors that read it. When the scans held
//! exceed `budget_mb`, [`KeyframeCloudStore::fit`] makes room in two stages, oldest keyframe
//! first, never touching the newest `keep_recent`:
//!
//! 1. **compaction**: a scan is thinned to one point (the centroid) per label and voxel:
//!    `object_voxel_m` for the classes objects are made of, `structure_voxel_m` for the rest.
//!    Each reader already thins at least that much (object clouds at 0.1 m, keyframe ICP at
//!    0.3 m, loop-closure ICP at 0.4 m), so compaction keeps what they use.
//! 2. **eviction**: a compacted scan is dropped, first those with a newer scan held within
//!    `redundant_within_m` of their keyframe (the place stays covered), then the oldest.
//!
//! Only the cloud goes: the keyframe, its edges and its object links stay. Readers that find no
//! scan (a neighbour asking for the keyframe, loop closure, object clouds) skip it; the wire
//! answers such a request with `KeyframeRefusalReason::Unknown` ("unknown, or its cloud was evicted").

use super::{KeyframeId, LabelId, SemanticScan};
use crate::spatial::point_tree::PointTree;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

/// Bytes one stored point costs: three `f32` coordinates and a `u16` label.
pub const BYTES_PER_POINT: usize = 14;

/// Bytes of bookkeeping per stored scan (map entry, `Arc` header, two vectors).
pub const BYTES_PER_SCAN: usize = 96;

/// How much of the semantic layer a robot holds (`[tracker.cloud_store]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CloudStoreConfig {
    /// Scans held at most, MiB (points at 14 bytes, plus 96 bytes per scan). Default 256:
    /// about 1 200 full scans of the simulated 32-beam LiDAR (216 KB), or 4 000 compacted ones.
    pub budget_mb: f64,
    /// The newest keyframes whose scans are never compacted or evicted (they may exceed the
    /// budget on their own). Default 30.
    pub keep_recent: usize,
    /// Voxel of compacted points of object classes, m. Default 0.1 (the object clouds' voxel).
    pub object_voxel_m: f64,
    /// Voxel of compacted points of every other class and of unlabelled points, m. Default 0.3
    /// (keyframe ICP's voxel).
    pub structure_voxel_m: f64,
    /// A compacted scan with a newer scan held this close to its keyframe is evicted before
    /// older ones, m. Default 2.
    pub redundant_within_m: f64,
}

impl Default for CloudStoreConfig {
    fn default() -> Self {
        Self { budget_mb: 256.0, keep_recent: 30, object_voxel_m: 0.1, structure_voxel_m: 0.3, redundant_within_m: 2.0 }
    }
}

impl CloudStoreConfig {
    pub fn budget_bytes(&self) -> usize {
        (self.budget_mb.max(0.0) * 1024.0 * 1024.0) as usize
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct StoredScan {
    scan: Arc<SemanticScan>,
    compacted: bool,
}

/// What a [`KeyframeCloudStore::fit`] changed: a keyframe's scan replaced by its compacted
/// version (`Some`) or evicted (`None`).
pub type CloudChange = (KeyframeId, Option<Arc<SemanticScan>>);

/// Counts of the store, for status and reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CloudStoreStats {
    /// Scans held (full and compacted).
    pub scans: usize,
    /// Of those, compacted.
    pub compacted: usize,
    /// Scans evicted since the mission started.
    pub evicted: u64,
    /// Bytes held, as the budget counts them.
    pub bytes: usize,
}

/// The scans of one robot's keyframes, by keyframe id (ids grow with time, so id order is age
/// order).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyframeCloudStore {
    scans: BTreeMap<KeyframeId, StoredScan>,
    evicted: u64,
}

fn scan_bytes(scan: &SemanticScan) -> usize {
    BYTES_PER_SCAN + scan.len() * BYTES_PER_POINT
}

impl KeyframeCloudStore {
    /// Stores (or replaces) the scan of `keyframe`, uncompacted.
    pub fn insert(&mut self, keyframe: KeyframeId, scan: SemanticScan) {
        self.scans.insert(keyframe, StoredScan { scan: Arc::new(scan), compacted: false });
    }

    pub fn get(&self, keyframe: KeyframeId) -> Option<&SemanticScan> {
        self.scans.get(&keyframe).map(|s| s.scan.as_ref())
    }

    /// The scan of `keyframe`, shared.
    pub fn shared(&self, keyframe: KeyframeId) -> Option<Arc<SemanticScan>> {
        self.scans.get(&keyframe).map(|s| s.scan.clone())
    }

    pub fn iter(&self) -> impl Iterator<Item = (KeyframeId, &SemanticScan)> {
        self.scans.iter().map(|(k, s)| (*k, s.scan.as_ref()))
    }

    pub fn bytes(&self) -> usize {
        self.scans.values().map(|s| scan_bytes(&s.scan)).sum()
    }

    pub fn stats(&self) -> CloudStoreStats {
        CloudStoreStats {
            scans: self.scans.len(),
            compacted: self.scans.values().filter(|s| s.compacted).count(),
            evicted: self.evicted,
            bytes: self.bytes(),
        }
    }

    /// Brings the store within `config`'s budget (see the module's documentation).
    /// `object_class` says which labels objects are made of; `position` gives a keyframe's
    /// current position (keyframes without one are never judged redundant). Returns what changed,
    /// in the order it was done.
    pub fn fit(
        &mut self,
        config: &CloudStoreConfig,
        object_class: impl Fn(LabelId) -> bool,
        position: impl Fn(KeyframeId) -> Option<Vector3<f64>>,
    ) -> Vec<CloudChange> {
        let budget = config.budget_bytes();
        let mut bytes = self.bytes();
        let mut changes = Vec::new();
        if bytes <= budget {
            return changes;
        }
        let older: Vec<KeyframeId> = self.scans.keys().rev().skip(config.keep_recent).rev().copied().collect();
        // 1. Compaction, oldest first.
        for id in &older {
            if bytes <= budget {
                return changes;
            }
            let Some(stored) = self.scans.get_mut(id) else { continue };
            if stored.compacted {
                continue;
            }
            let compact = Arc::new(compacted(&stored.scan, config, &object_class));
            bytes = bytes - scan_bytes(&stored.scan) + scan_bytes(&compact);
            *stored = StoredScan { scan: compact.clone(), compacted: true };
            changes.push((*id, Some(compact)));
        }
        // 2. Eviction: redundant scans first, then the oldest.
        let radius = config.redundant_within_m;
        if radius.is_finite() && radius > 0.0 {
            let held: Vec<(KeyframeId, Point3<f64>)> =
                self.scans.keys().filter_map(|&k| Some((k, Point3::from(position(k)?)))).collect();
            let tree = PointTree::new(&held.iter().map(|(_, p)| *p).collect::<Vec<_>>());
            for id in &older {
                if bytes <= budget {
                    return changes;
                }
                let Some(here) = position(*id) else { continue };
                // A keyframe newer than this one, with its scan held, within the radius.
                let near = tree.nearest_k_within(&Point3::from(here), held.len(), radius);
                if near.into_iter().any(|i| held[i].0 > *id) {
                    bytes -= self.evict(*id);
                    changes.push((*id, None));
                }
            }
        }
        for id in &older {
            if bytes <= budget {
                break;
            }
            if self.scans.contains_key(id) {
                bytes -= self.evict(*id);
                changes.push((*id, None));
            }
        }
        changes
    }

    /// Drops the scan of `keyframe`; the bytes it held.
    fn evict(&mut self, keyframe: KeyframeId) -> usize {
        match self.scans.remove(&keyframe) {
            Some(stored) => {
                self.evicted += 1;
                scan_bytes(&stored.scan)
            }
            None => 0,
        }
    }
}

/// `scan` with one point per label and voxel (their centroid), in first-seen order.
fn compacted(scan: &SemanticScan, config: &CloudStoreConfig, object_class: impl Fn(LabelId) -> bool) -> SemanticScan {
    let mut slots: HashMap<(LabelId, [i64; 3]), usize> = HashMap::with_capacity(scan.len() / 4 + 1);
    let mut sums: Vec<(Vector3<f64>, usize, LabelId)> = Vec::new();
    for (p, &label) in scan.points_in_body.iter().zip(&scan.labels) {
        let voxel = if object_class(label) { config.object_voxel_m } else { config.structure_voxel_m };
        let key = if voxel.is_finite() && voxel > 0.0 {
            let at = |v: f32| (f64::from(v) / voxel).floor() as i64;
            [at(p.x), at(p.y), at(p.z)]
        } else {
            // No voxel: every point is its own cell.
            [sums.len() as i64, 0, 0]
        };
        let slot = *slots.entry((label, key)).or_insert_with(|| {
            sums.push((Vector3::zeros(), 0, label));
            sums.len() - 1
        });
        sums[slot].0 += p.coords.cast::<f64>();
        sums[slot].1 += 1;
    }
    let (points_in_body, labels) =
        sums.into_iter().map(|(sum, n, label)| (Point3::from((sum / n as f64).cast::<f32>()), label)).unzip();
    SemanticScan { points_in_body, labels }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(n: usize, label: u16) -> SemanticScan {
        SemanticScan {
            points_in_body: (0..n).map(|k| Point3::new(k as f32 * 0.01, 0.0, 0.0)).collect(),
            labels: vec![LabelId(label); n],
        }
    }

    fn config(budget_bytes: usize, keep_recent: usize) -> CloudStoreConfig {
        CloudStoreConfig { budget_mb: budget_bytes as f64 / 1024.0 / 1024.0, keep_recent, ..Default::default() }
    }

    #[test]
    fn within_budget_nothing_changes() {
        let mut store = KeyframeCloudStore::default();
        store.insert(KeyframeId(0), scan(100, 1));
        let before = store.clone();
        let changes = store.fit(&CloudStoreConfig::default(), |_| false, |_| None);
        assert!(changes.is_empty());
        assert_eq!(store, before);
        assert_eq!(store.bytes(), BYTES_PER_SCAN + 100 * BYTES_PER_POINT);
    }

    #[test]
    fn compaction_keeps_one_centroid_per_label_and_voxel() {
        // 100 points 1 cm apart on 1 m of x: 10 cells of 0.1 m or 4 of 0.3 m (0–0.3, …, 0.9–1).
        let mut s = scan(100, 7);
        s.labels[0] = LabelId(8);
        let config = CloudStoreConfig::default();
        let objects = compacted(&s, &config, |l| l == LabelId(7));
        assert_eq!(objects.len(), 11, "10 object cells and the lone label-8 point");
        // First-seen order: the label-8 point, then the first label-7 cell: points 1 to 9 (0.01
        // to 0.09 m; 0.1 m itself is 0.099999994 in f32, so possibly point 10 too).
        assert_eq!(objects.labels[..2], [LabelId(8), LabelId(7)]);
        assert_eq!(objects.labels.iter().filter(|l| **l == LabelId(8)).count(), 1);
        let x = objects.points_in_body[1].x;
        assert!((x - 0.05).abs() < 1e-6 || (x - 0.055).abs() < 1e-6, "centroid {x}");
        let structure = compacted(&s, &config, |_| false);
        assert_eq!(structure.len(), 5, "4 structure cells of label 7 and one of label 8");
    }

    #[test]
    fn compacts_oldest_first_then_evicts_redundant_then_oldest_and_spares_the_recent() {
        let mut store = KeyframeCloudStore::default();
        for k in 0..6 {
            store.insert(KeyframeId(k), scan(1000, 1));
        }
        let full = BYTES_PER_SCAN + 1000 * BYTES_PER_POINT;
        let compact = BYTES_PER_SCAN + 34 * BYTES_PER_POINT; // 10 m of x at 0.3 m: 34 cells
                                                             // Budget: two full scans and four compacted ones, keep the newest two.
        let config = config(2 * full + 4 * compact, 2);
        // Keyframes 0 and 3 stand where keyframe 5 stands (redundant), the others apart.
        let position = |k: KeyframeId| {
            Some(Vector3::new(if matches!(k.0, 0 | 3 | 5) { 0.0 } else { 10.0 * k.0 as f64 }, 0.0, 0.0))
        };
        let changes = store.fit(&config, |_| false, position);
        let kinds: Vec<(u32, bool)> = changes.iter().map(|(k, s)| (k.0, s.is_some())).collect();
        // All four older scans compacted (oldest first) and the budget met without eviction.
        assert_eq!(kinds, vec![(0, true), (1, true), (2, true), (3, true)]);
        assert!(store.bytes() <= config.budget_bytes());
        assert_eq!(
            store.stats(),
            CloudStoreStats { scans: 6, compacted: 4, evicted: 0, bytes: 2 * full + 4 * compact }
        );

        // A smaller budget: the redundant keyframes 0 and 3 go first, then the oldest (1).
        let tight = CloudStoreConfig { budget_mb: (2 * full + compact) as f64 / 1024.0 / 1024.0, ..config };
        let changes = store.fit(&tight, |_| false, position);
        let kinds: Vec<(u32, bool)> = changes.iter().map(|(k, s)| (k.0, s.is_some())).collect();
        assert_eq!(kinds, vec![(0, false), (3, false), (1, false)]);
        assert_eq!(store.iter().map(|(k, _)| k.0).collect::<Vec<_>>(), vec![2, 4, 5]);
        assert_eq!(store.stats().evicted, 3);

        // Nothing left to give: the recent scans stay even over budget.
        let zero = CloudStoreConfig { budget_mb: 0.0, ..tight };
        store.fit(&zero, |_| false, position);
        assert_eq!(store.iter().map(|(k, _)| k.0).collect::<Vec<_>>(), vec![4, 5]);
    }

    mod properties {
        use super::*;
        use proptest::prelude::*;

        /// A scan's points (x, y, z, label) and its keyframe's (x, y).
        type Input = (Vec<(f32, f32, f32, u16)>, (f64, f64));

        fn scans() -> impl Strategy<Value = Vec<Input>> {
            let point = (-20.0f32..20.0, -20.0f32..20.0, -2.0f32..4.0, 0u16..4);
            prop::collection::vec((prop::collection::vec(point, 0..300), (-10.0f64..10.0, -10.0f64..10.0)), 1..25)
        }

        proptest! {
            /// After `fit`: within budget unless only the recent scans are left; the recent scans
            /// untouched; a compacted scan keeps each label's points inside that label's original
            /// bounds; and the changes replayed on a copy of the old map give the new store (what a
            /// reader that mirrors the store by the changes holds).
            #[test]
            fn fit_meets_the_budget_and_its_changes_describe_it(
                input in scans(),
                budget_kb in 0.0f64..100.0,
                keep_recent in 0usize..6,
                redundant in 0.0f64..6.0,
            ) {
                let mut store = KeyframeCloudStore::default();
                let mut positions = BTreeMap::new();
                for (k, (points, (x, y))) in input.iter().enumerate() {
                    let scan = SemanticScan {
                        points_in_body: points.iter().map(|p| Point3::new(p.0, p.1, p.2)).collect(),
                        labels: points.iter().map(|p| LabelId(p.3)).collect(),
                    };
                    store.insert(KeyframeId(k as u32), scan);
                    positions.insert(KeyframeId(k as u32), Vector3::new(*x, *y, 0.0));
                }
                let before = store.clone();
                let config = CloudStoreConfig {
                    budget_mb: budget_kb / 1024.0,
                    keep_recent,
                    redundant_within_m: redundant,
                    ..Default::default()
                };
                let changes = store.fit(&config, |l| l.0 < 2, |k| positions.get(&k).copied());

                let recent: Vec<KeyframeId> = before.scans.keys().rev().take(keep_recent).copied().collect();
                for id in &recent {
                    prop_assert!(Arc::ptr_eq(&before.scans[id].scan, &store.scans[id].scan));
                }
                if store.bytes() > config.budget_bytes() {
                    prop_assert_eq!(store.scans.len(), recent.len());
                }
                let mut mirror: BTreeMap<KeyframeId, Arc<SemanticScan>> =
                    before.scans.iter().map(|(k, s)| (*k, s.scan.clone())).collect();
                for (id, change) in &changes {
                    match change {
                        Some(scan) => { mirror.insert(*id, scan.clone()); }
                        None => { mirror.remove(id); }
                    }
                }
                let now: BTreeMap<KeyframeId, Arc<SemanticScan>> =
                    store.scans.iter().map(|(k, s)| (*k, s.scan.clone())).collect();
                prop_assert_eq!(mirror, now);
                prop_assert_eq!(store.stats().evicted as usize, before.scans.len() - store.scans.len());

                for (id, stored) in store.scans.iter().filter(|(_, s)| s.compacted) {
                    let original = &before.scans[id].scan;
                    for (p, l) in stored.scan.points_in_body.iter().zip(&stored.scan.labels) {
                        let same: Vec<&Point3<f32>> = original.points_in_body.iter().zip(&original.labels)
                            .filter(|(_, m)| *m == l).map(|(q, _)| q).collect();
                        prop_assert!(!same.is_empty());
                        for axis in 0..3 {
                            let lo = same.iter().map(|q| q[axis]).fold(f32::INFINITY, f32::min);
                            let hi = same.iter().map(|q| q[axis]).fold(f32::NEG_INFINITY, f32::max);
                            prop_assert!(p[axis] >= lo - 1e-4 && p[axis] <= hi + 1e-4);
                        }
                    }
                    prop_assert!(stored.scan.len() <= original.len());
                }
            }
        }
    }
}
