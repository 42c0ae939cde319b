//! The odometry's local map: the points of recent scans in the odometry frame, in a hash of
//! voxels, bounded in space and in memory. The structure is KISS-ICP's (Vizzo et al. 2023,
//! "KISS-ICP: In Defense of Point-to-Point ICP", RA-L 8(2), §III-D): a voxel of side `voxel_m`
//! holds at most `max_points_per_voxel` points, and voxels far from the sensor are dropped. Two
//! additions make it safe to run for an hour on a robot:
//!
//! * **Spread inside a voxel.** A point joins a voxel only when it is at least
//!   s = voxel_m / √max_points_per_voxel from the points already there — the spacing at which
//!   that many points tile the voxel's face — so a robot standing still does not fill its voxels
//!   with copies of one surface patch and the map keeps the shape of what it saw.
//! * **A budget.** Beyond `max_voxels`, the voxels updated longest ago go first (ties: farthest
//!   from the sensor, then by key), so memory is bounded by
//!   `max_voxels · max_points_per_voxel` points whatever the route.
//!
//! Nearest neighbours are sought in the 3 × 3 × 3 voxels around the query's: every map point
//! within `voxel_m` of the query is among them, so a search within d ≤ `voxel_m` is exact;
//! beyond that it returns the nearest of those 27 voxels (KISS-ICP's approximation).
//!
//! **Planes, kept across scans.** Registration fits a plane through the `k` map points nearest
//! each map point it pairs with (`registration`). With [`LocalMap::cache_planes`], the fit is
//! kept beside the point until one of the 27 voxels around the point's changes (a point added,
//! a voxel dropped): exactly the voxels the fit's neighbour search reads, so a kept fit is
//! always the one a new fit would give. Most of a map is unchanged from one scan to the next.
//!
//! Determinism: lookups go by key; every pass over all voxels (pruning, the budget, `points`)
//! either does not depend on the order or sorts by key.

use crate::spatial::voxel::voxel_of;
use nalgebra::{Point3, Vector3};
use rustc_hash::{FxHashMap, FxHashSet};
use serde::{Deserialize, Serialize};
use std::cell::OnceCell;

/// The local map's parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalMapConfig {
    /// Side of a voxel, m. Default 1.0 (KISS-ICP: max range / 100).
    pub voxel_m: f64,
    /// Points kept per voxel. Default 20.
    pub max_points_per_voxel: usize,
    /// Voxels farther than this from the sensor are dropped, m. Default 100.
    pub max_distance_m: f64,
    /// At most this many voxels (memory budget). Default 200 000 (4 M points, 96 MB of f64).
    pub max_voxels: usize,
}

impl Default for LocalMapConfig {
    fn default() -> Self {
        Self { voxel_m: 1.0, max_points_per_voxel: 20, max_distance_m: 100.0, max_voxels: 200_000 }
    }
}

/// What a local map holds: points and voxels now, the most points it has held after an
/// insertion, and the most it may hold (`max_voxels · max_points_per_voxel`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LocalMapSize {
    pub points: u64,
    pub voxels: u64,
    pub peak_points: u64,
    pub budget_points: u64,
}

/// A parameter out of range: its name, its value, what is allowed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("odometry.local_map.{key} = {value}: must be {allowed}")]
pub struct LocalMapConfigError {
    pub key: &'static str,
    pub value: f64,
    pub allowed: &'static str,
}

impl LocalMapConfig {
    pub fn validate(&self) -> Result<(), LocalMapConfigError> {
        let check = |ok: bool, key, value: f64, allowed| {
            if ok {
                Ok(())
            } else {
                Err(LocalMapConfigError { key, value, allowed })
            }
        };
        check(self.voxel_m.is_finite() && self.voxel_m > 0.0, "voxel_m", self.voxel_m, "finite and > 0")?;
        check(self.max_points_per_voxel >= 1, "max_points_per_voxel", self.max_points_per_voxel as f64, "≥ 1")?;
        check(
            self.max_distance_m.is_finite() && self.max_distance_m > 0.0,
            "max_distance_m",
            self.max_distance_m,
            "finite and > 0",
        )?;
        check(self.max_voxels >= 1, "max_voxels", self.max_voxels as f64, "≥ 1")
    }
}

type Key = [i64; 3];

#[derive(Clone, Debug)]
struct Voxel {
    points: Vec<Point3<f64>>,
    /// Each point's plane fit, once made ([`LocalMap::cache_planes`]).
    planes: Vec<PlaneSlot>,
    /// The insertion (scan) that last added a point.
    updated: u64,
}

/// A map point's plane fit: its unit normal, or none (no plane there); empty until made.
pub type PlaneSlot = OnceCell<Option<Vector3<f64>>>;

/// What a plane fit depends on besides the map: the registration's `plane_neighbours`,
/// `plane_tolerance_m` and `planarity`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneParams {
    pub neighbours: usize,
    pub tolerance_m: f64,
    pub planarity: f64,
}

/// Points in the odometry frame, by voxel.
#[derive(Clone, Debug)]
pub struct LocalMap {
    config: LocalMapConfig,
    min_spacing2: f64,
    voxels: FxHashMap<Key, Voxel>,
    insertions: u64,
    points: usize,
    /// The most points held after any insertion.
    peak_points: usize,
    /// The parameters the kept plane fits were made with (none: fits are not kept).
    plane_params: Option<PlaneParams>,
}

impl LocalMap {
    pub fn new(config: LocalMapConfig) -> Result<Self, LocalMapConfigError> {
        config.validate()?;
        let spacing = config.voxel_m / (config.max_points_per_voxel as f64).sqrt();
        Ok(Self {
            min_spacing2: spacing * spacing,
            config,
            voxels: FxHashMap::default(),
            insertions: 0,
            points: 0,
            peak_points: 0,
            plane_params: None,
        })
    }

    /// Keep plane fits made with `params` beside their points (module notes); fits made before
    /// are forgotten.
    pub fn cache_planes(&mut self, params: PlaneParams) {
        self.plane_params = Some(params);
        for voxel in self.voxels.values_mut() {
            voxel.planes.iter_mut().for_each(|slot| *slot = PlaneSlot::new());
        }
    }

    /// The parameters plane fits are kept for, if any.
    pub fn plane_params(&self) -> Option<PlaneParams> {
        self.plane_params
    }

    /// Forgets the plane fits of the points in the 27 voxels around each of `keys`.
    fn forget_planes_around(&mut self, keys: &FxHashSet<Key>) {
        let mut around: FxHashSet<Key> = FxHashSet::default();
        for [x, y, z] in keys {
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        around.insert([x + dx, y + dy, z + dz]);
                    }
                }
            }
        }
        for key in &around {
            if let Some(voxel) = self.voxels.get_mut(key) {
                voxel.planes.iter_mut().for_each(|slot| *slot = PlaneSlot::new());
            }
        }
    }

    pub fn config(&self) -> &LocalMapConfig {
        &self.config
    }

    /// Points held.
    pub fn len(&self) -> usize {
        self.points
    }

    /// What the map holds, its peak and its budget (for a status).
    pub fn size(&self) -> LocalMapSize {
        LocalMapSize {
            points: self.points as u64,
            voxels: self.voxels.len() as u64,
            peak_points: self.peak_points as u64,
            budget_points: (self.config.max_voxels as u64).saturating_mul(self.config.max_points_per_voxel as u64),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.points == 0
    }

    /// Voxels held.
    pub fn voxels(&self) -> usize {
        self.voxels.len()
    }

    fn key(&self, p: &Point3<f64>) -> Key {
        voxel_of(p, self.config.voxel_m)
    }

    /// Adds a scan's points (odometry frame; non-finite ones are skipped), then drops the voxels
    /// beyond `max_distance_m` of `sensor` and, over the budget, the oldest.
    pub fn insert(&mut self, points: &[Point3<f64>], sensor: &Point3<f64>) {
        self.insertions += 1;
        let mut changed: FxHashSet<Key> = FxHashSet::default();
        for p in points.iter().filter(|p| p.coords.iter().all(|c| c.is_finite())) {
            let key = self.key(p);
            let (cap, spacing2, stamp) = (self.config.max_points_per_voxel, self.min_spacing2, self.insertions);
            let voxel = self.voxels.entry(key).or_insert_with(|| Voxel {
                points: Vec::with_capacity(cap),
                planes: Vec::with_capacity(cap),
                updated: stamp,
            });
            if voxel.points.len() < cap && voxel.points.iter().all(|q| (q - p).norm_squared() >= spacing2) {
                voxel.points.push(*p);
                voxel.planes.push(PlaneSlot::new());
                voxel.updated = stamp;
                self.points += 1;
                changed.insert(key);
            }
        }
        changed.extend(self.prune(sensor));
        self.peak_points = self.peak_points.max(self.points);
        if self.plane_params.is_some() && !changed.is_empty() {
            self.forget_planes_around(&changed);
        }
    }

    /// A voxel's distance from the sensor: its first point's, as KISS-ICP measures it.
    fn distance2(voxel: &Voxel, sensor: &Point3<f64>) -> f64 {
        voxel.points.first().map_or(f64::INFINITY, |p| (p - sensor).norm_squared())
    }

    /// Drops the voxels out of range and over the budget; returns their keys.
    fn prune(&mut self, sensor: &Point3<f64>) -> Vec<Key> {
        let max2 = self.config.max_distance_m * self.config.max_distance_m;
        let mut dropped: Vec<Key> =
            self.voxels.iter().filter(|(_, v)| Self::distance2(v, sensor) > max2).map(|(k, _)| *k).collect();
        for key in &dropped {
            self.voxels.remove(key);
        }
        if self.voxels.len() > self.config.max_voxels {
            let mut order: Vec<(u64, f64, Key)> =
                self.voxels.iter().map(|(k, v)| (v.updated, -Self::distance2(v, sensor), *k)).collect();
            order.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
            let excess = self.voxels.len() - self.config.max_voxels;
            for (_, _, key) in order.into_iter().take(excess) {
                self.voxels.remove(&key);
                dropped.push(key);
            }
        }
        self.points = self.voxels.values().map(|v| v.points.len()).sum();
        dropped
    }

    /// The nearest map point to `p` within `max_distance` (see the module notes), with its
    /// distance; ties go to the voxel visited first (fixed order), then the point added first.
    pub fn nearest(&self, p: &Point3<f64>, max_distance: f64) -> Option<(Point3<f64>, f64)> {
        self.nearest_with_plane(p, max_distance).map(|(q, d, _)| (q, d))
    }

    /// [`LocalMap::nearest`], with the point's plane slot (kept across scans only under
    /// [`LocalMap::cache_planes`]).
    pub fn nearest_with_plane(&self, p: &Point3<f64>, max_distance: f64) -> Option<(Point3<f64>, f64, &PlaneSlot)> {
        let [x, y, z] = self.key(p);
        let mut best: Option<(Point3<f64>, f64, &PlaneSlot)> = None;
        let mut best2 = max_distance * max_distance;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let key = [x + dx, y + dy, z + dz];
                    // No point of a voxel farther than the best so far can win (nor tie).
                    if self.box_distance2(&key, p) > best2 {
                        continue;
                    }
                    let Some(voxel) = self.voxels.get(&key) else { continue };
                    for (q, slot) in voxel.points.iter().zip(&voxel.planes) {
                        let d2 = (q - p).norm_squared();
                        if d2 <= best2 && best.is_none_or(|(_, b, _)| d2 < b * b) {
                            best2 = d2;
                            best = Some((*q, d2.sqrt(), slot));
                        }
                    }
                }
            }
        }
        best
    }

    /// Up to `k` map points nearest to `p` within `radius` ≤ `voxel_m` (exact, as `nearest`),
    /// nearest first; ties by the order of the search.
    pub fn nearest_k(&self, p: &Point3<f64>, k: usize, radius: f64) -> Vec<Point3<f64>> {
        let [x, y, z] = self.key(p);
        let r2 = radius * radius;
        // The k nearest so far, nearest first; a point goes after those at its distance or
        // nearer, so ties keep the search's order (as a stable sort of all would).
        let mut best: Vec<(f64, Point3<f64>)> = Vec::with_capacity(k + 1);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let key = [x + dx, y + dy, z + dz];
                    let bound = if best.len() == k { best.last().map_or(r2, |b| b.0) } else { r2 };
                    if k == 0 || self.box_distance2(&key, p) > bound {
                        continue;
                    }
                    let Some(voxel) = self.voxels.get(&key) else { continue };
                    for q in &voxel.points {
                        let d2 = (q - p).norm_squared();
                        if d2 > r2 || (best.len() == k && best.last().is_some_and(|b| d2 >= b.0)) {
                            continue;
                        }
                        let at = best.partition_point(|b| b.0 <= d2);
                        best.insert(at, (d2, *q));
                        best.truncate(k);
                    }
                }
            }
        }
        best.into_iter().map(|(_, q)| q).collect()
    }

    /// Squared distance from `p` to the box of the voxel `key` (0 inside it), the box grown by
    /// a micrometre: a point that `key` rounded into the voxel may lie a rounding error outside
    /// key · v, and must not be skipped.
    fn box_distance2(&self, key: &Key, p: &Point3<f64>) -> f64 {
        const SLACK_M: f64 = 1e-6;
        let v = self.config.voxel_m;
        (0..3)
            .map(|i| {
                let lo = key[i] as f64 * v - SLACK_M;
                let gap = (lo - p[i]).max(p[i] - (lo + v + 2.0 * SLACK_M)).max(0.0);
                gap * gap
            })
            .sum()
    }

    /// The points of the voxel that holds `p` (empty when none).
    pub fn voxel_points(&self, p: &Point3<f64>) -> &[Point3<f64>] {
        self.voxels.get(&self.key(p)).map_or(&[], |v| &v.points[..])
    }

    /// Every point, voxels in key order.
    pub fn points(&self) -> Vec<Point3<f64>> {
        let mut keys: Vec<&Key> = self.voxels.keys().collect();
        keys.sort();
        keys.into_iter().flat_map(|k| self.voxels[k].points.iter().copied()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn map(config: LocalMapConfig) -> LocalMap {
        LocalMap::new(config).unwrap()
    }

    /// A wall x = 0 sampled every `step` m over y, z ∈ [0, 4).
    fn wall(step: f64) -> Vec<Point3<f64>> {
        let n = (4.0 / step) as usize;
        (0..n).flat_map(|i| (0..n).map(move |j| Point3::new(0.0, i as f64 * step, j as f64 * step))).collect()
    }

    #[test]
    fn a_voxel_keeps_at_most_its_share_of_points_spread_over_it() {
        let mut m = map(LocalMapConfig { max_points_per_voxel: 4, ..Default::default() });
        // 100 points per voxel of 1 m, in 16 voxels; spacing ≥ 1/√4 = 0.5 m.
        m.insert(&wall(0.1), &Point3::origin());
        assert_eq!(m.voxels(), 16);
        assert_eq!(m.len(), 16 * 4);
        let points = m.points();
        for (i, p) in points.iter().enumerate() {
            for q in &points[i + 1..] {
                if m.key(p) == m.key(q) {
                    assert!((p - q).norm() >= 0.5 - 1e-12, "{p} {q}");
                }
            }
        }
        // The same scan again adds nothing.
        m.insert(&wall(0.1), &Point3::origin());
        assert_eq!(m.len(), 16 * 4);
    }

    #[test]
    fn voxels_beyond_the_range_of_the_sensor_are_dropped() {
        let mut m = map(LocalMapConfig { max_distance_m: 10.0, ..Default::default() });
        m.insert(&wall(0.5), &Point3::origin());
        assert_eq!(m.voxels(), 16);
        // The sensor moves 12 m away along x: every voxel's first point is ≥ 12 m from it.
        m.insert(&[], &Point3::new(12.0, 0.0, 0.0));
        assert!(m.is_empty() && m.voxels() == 0);
    }

    #[test]
    fn over_the_budget_the_oldest_voxels_go_first() {
        let mut m = map(LocalMapConfig { max_voxels: 3, ..Default::default() });
        for x in 0..5 {
            m.insert(&[Point3::new(x as f64 + 0.5, 0.5, 0.5)], &Point3::origin());
        }
        assert_eq!(m.voxels(), 3);
        let xs: Vec<f64> = m.points().iter().map(|p| p.x).collect();
        assert_eq!(xs, vec![2.5, 3.5, 4.5]);
    }

    #[test]
    fn non_finite_points_are_skipped() {
        let mut m = map(LocalMapConfig::default());
        m.insert(&[Point3::new(f64::NAN, 0.0, 0.0), Point3::new(0.0, f64::INFINITY, 0.0)], &Point3::origin());
        assert!(m.is_empty());
        assert!(m.nearest(&Point3::origin(), 1.0).is_none());
    }

    #[test]
    fn bad_parameters_are_named() {
        let e = LocalMap::new(LocalMapConfig { voxel_m: -1.0, ..Default::default() }).unwrap_err();
        assert_eq!(e.to_string(), "odometry.local_map.voxel_m = -1: must be finite and > 0");
        assert!(LocalMap::new(LocalMapConfig { max_points_per_voxel: 0, ..Default::default() }).is_err());
        assert!(LocalMap::new(LocalMapConfig { max_voxels: 0, ..Default::default() }).is_err());
        assert!(LocalMap::new(LocalMapConfig { max_distance_m: f64::NAN, ..Default::default() }).is_err());
    }

    proptest! {
        /// Within one voxel side the search is exact: it agrees with brute force over every point.
        #[test]
        fn nearest_within_a_voxel_side_is_exact(
            cloud in prop::collection::vec((-5.0f64..5.0, -5.0f64..5.0, -2.0f64..2.0), 1..200),
            query in (-6.0f64..6.0, -6.0f64..6.0, -3.0f64..3.0),
            radius in 0.05f64..1.0,
        ) {
            let mut m = map(LocalMapConfig { voxel_m: 1.0, max_points_per_voxel: 1000, ..Default::default() });
            let points: Vec<Point3<f64>> = cloud.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            m.insert(&points, &Point3::origin());
            let kept = m.points();
            let q = Point3::new(query.0, query.1, query.2);
            let brute = kept.iter().map(|p| (p - q).norm()).filter(|d| *d <= radius).fold(None, |b: Option<f64>, d| Some(b.map_or(d, |b| b.min(d))));
            let found = m.nearest(&q, radius).map(|(_, d)| d);
            prop_assert_eq!(found.is_some(), brute.is_some());
            if let (Some(f), Some(b)) = (found, brute) {
                prop_assert!((f - b).abs() < 1e-12);
            }
        }

        /// So is the k-nearest search: the brute force's k nearest distances.
        #[test]
        fn nearest_k_within_a_voxel_side_is_exact(
            cloud in prop::collection::vec((-3.0f64..3.0, -3.0f64..3.0, -1.0f64..1.0), 1..200),
            query in (-3.0f64..3.0, -3.0f64..3.0, -1.0f64..1.0),
            k in 1usize..8,
        ) {
            let mut m = map(LocalMapConfig { voxel_m: 1.0, max_points_per_voxel: 1000, ..Default::default() });
            let points: Vec<Point3<f64>> = cloud.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            m.insert(&points, &Point3::origin());
            let q = Point3::new(query.0, query.1, query.2);
            let mut brute: Vec<f64> = m.points().iter().map(|p| (p - q).norm()).filter(|d| *d <= 1.0).collect();
            brute.sort_by(f64::total_cmp);
            brute.truncate(k);
            let found: Vec<f64> = m.nearest_k(&q, k, 1.0).iter().map(|p| (p - q).norm()).collect();
            prop_assert_eq!(found.len(), brute.len());
            for (f, b) in found.iter().zip(&brute) {
                prop_assert!((f - b).abs() < 1e-12);
            }
        }

        /// A kept plane fit is always what a fresh fit would give, whatever scans came since:
        /// every slot is filled after each scan, and checked against a fresh fit after the next
        /// (a fit here is any function of the k nearest map points, as the real one is). The
        /// budget and the range make scans drop voxels too.
        #[test]
        fn kept_plane_fits_are_what_a_fresh_fit_gives(
            scans in prop::collection::vec(prop::collection::vec((-4.0f64..4.0, -4.0f64..4.0, -1.5f64..1.5), 0..80), 1..6),
            sensor in prop::collection::vec((-4.0f64..4.0, -4.0f64..4.0), 6),
        ) {
            let config = LocalMapConfig { max_voxels: 60, max_points_per_voxel: 6, max_distance_m: 5.0, ..Default::default() };
            let mut m = map(config);
            m.cache_planes(PlaneParams { neighbours: 5, tolerance_m: 0.1, planarity: 0.1 });
            let fit = |m: &LocalMap, q: &Point3<f64>| {
                Some(m.nearest_k(q, 5, 1.0).iter().fold(Vector3::zeros(), |a, p| a + p.coords))
            };
            for (scan, (sx, sy)) in scans.iter().zip(&sensor) {
                let points: Vec<Point3<f64>> = scan.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
                m.insert(&points, &Point3::new(*sx, *sy, 0.0));
                for q in m.points() {
                    let (_, d, slot) = m.nearest_with_plane(&q, 1e-9).expect("a map point is its own nearest");
                    prop_assert_eq!(d, 0.0);
                    let kept = *slot.get_or_init(|| fit(&m, &q));
                    prop_assert_eq!(kept, fit(&m, &q));
                }
            }
        }

        /// Memory stays within the budget whatever is inserted.
        #[test]
        fn the_budget_holds(scans in prop::collection::vec(prop::collection::vec((-50.0f64..50.0, -50.0f64..50.0, -5.0f64..5.0), 0..100), 1..10)) {
            let config = LocalMapConfig { max_voxels: 40, max_points_per_voxel: 3, ..Default::default() };
            let mut m = map(config);
            let mut peak = 0;
            for scan in &scans {
                let points: Vec<Point3<f64>> = scan.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
                m.insert(&points, &Point3::origin());
                prop_assert!(m.voxels() <= 40 && m.len() <= 120);
                prop_assert_eq!(m.len(), m.points().len());
                peak = peak.max(m.len() as u64);
                let size = m.size();
                prop_assert_eq!((size.points, size.voxels, size.peak_points, size.budget_points), (m.len() as u64, m.voxels() as u64, peak, 120));
            }
        }
    }
}
