//! Object candidates from labelled points (paper §IV-A: "the labeled point cloud is clustered into
//! distinct objects"): within each class, points are binned into voxels of side `tolerance_m`
//! and occupied voxels that touch (26-neighbourhood) form one cluster — connected components by
//! union–find over the sorted voxel keys, near-linear in the number of points. Two points in
//! one cluster are linked by a chain of steps shorter than 2√3 · tolerance; points farther than
//! 2 · tolerance from every other voxel's points are never joined. Clusters are kept when their
//! point count and extent are plausible for the class.
//!
//! A cluster that lies flat — labels that bled onto the ground behind an object — is refused
//! when its thickness is below `min_height_m`. On a slope (or under a tilted body) such a patch
//! rises along z with the ground, 2 m of it 0.35 m on a 10° hill, so its thickness is measured
//! along its own normal too: the eigenvector n of the smallest eigenvalue of the cluster's
//! covariance, when n is within [`MAX_GROUND_TILT_DEG`] of z (the patch lies like ground, not
//! stands like a wall):
//!
//! ```text
//! C = 1/N Σ (p − p̄)(p − p̄)ᵀ,   C n = λ_min n
//! thickness = min( extent_z,  max_p n·p − min_p n·p )   if |n_z| ≥ cos(MAX_GROUND_TILT_DEG)
//!           = extent_z                                   otherwise
//! ```
//!
//! On level ground a flat patch's normal is z and an upright object's thinnest side is either
//! its height (the same extent) or horizontal, so level scenes cluster as with extent_z alone.

use crate::scene_graph::LabelId;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A flat cluster whose normal is within this angle of z lies like the ground (a hill, a ramp
/// or the body's tilt), degrees: its thickness is measured along the normal.
pub const MAX_GROUND_TILT_DEG: f64 = 45.0;

/// Plausibility limits of one class's clusters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClassLimits {
    pub min_points: usize,
    pub max_points: usize,
    /// Largest axis-aligned extent, m.
    pub max_extent_m: f64,
}

impl Default for ClassLimits {
    fn default() -> Self {
        Self { min_points: 10, max_points: 50_000, max_extent_m: 10.0 }
    }
}

/// Clustering parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClusterConfig {
    /// Voxel side: points in touching voxels of this size join one cluster, m. Default 0.3.
    pub tolerance_m: f64,
    /// Limits for classes without their own entry.
    pub default_limits: ClassLimits,
    /// Per-class limits, by class id.
    pub classes: BTreeMap<u16, ClassLimits>,
    /// Clusters thinner than this are refused (labels bleeding onto the ground behind an
    /// object): thickness along z, or along the cluster's normal when it lies like sloped
    /// ground (module documentation), m. Default 0: off.
    pub min_height_m: f64,
}

impl Default for ClusterConfig {
    fn default() -> Self {
        Self { tolerance_m: 0.3, default_limits: ClassLimits::default(), classes: BTreeMap::new(), min_height_m: 0.0 }
    }
}

/// One cluster: an object candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectCandidate {
    pub label: LabelId,
    pub centroid: Point3<f64>,
    /// Axis-aligned extent, m.
    pub size: Vector3<f64>,
    pub points: usize,
}

/// Clusters `points` by class (`labels[k]` is point k's class; `None` points are ignored).
/// Output is ordered by class, then by each cluster's first point: deterministic.
pub fn cluster(points: &[Point3<f64>], labels: &[Option<LabelId>], config: &ClusterConfig) -> Vec<ObjectCandidate> {
    let mut by_class: BTreeMap<LabelId, Vec<usize>> = BTreeMap::new();
    for (k, (p, l)) in points.iter().zip(labels).enumerate() {
        if let Some(l) = l {
            if p.coords.iter().all(|v| v.is_finite()) {
                by_class.entry(*l).or_default().push(k);
            }
        }
    }
    let size = config.tolerance_m;
    let mut out = Vec::new();
    if !size.is_finite() || size <= 0.0 {
        return out;
    }
    for (label, members) in by_class {
        let limits = config.classes.get(&label.0).unwrap_or(&config.default_limits);
        // Voxel key of every member, members sorted by key: equal keys are contiguous.
        let key = |k: usize| {
            let p = points[k];
            [(p.x / size).floor() as i64, (p.y / size).floor() as i64, (p.z / size).floor() as i64]
        };
        let mut keyed: Vec<([i64; 3], usize)> = members.iter().map(|&k| (key(k), k)).collect();
        keyed.sort_unstable();
        let mut voxels: Vec<[i64; 3]> = Vec::new();
        let mut voxel_of = Vec::with_capacity(keyed.len());
        for (kk, _) in &keyed {
            if voxels.last() != Some(kk) {
                voxels.push(*kk);
            }
            voxel_of.push(voxels.len() - 1);
        }
        // Union–find over voxels, joining each voxel to its 13 "forward" neighbours.
        let mut parent: Vec<usize> = (0..voxels.len()).collect();
        fn root(parent: &mut [usize], mut v: usize) -> usize {
            while parent[v] != v {
                parent[v] = parent[parent[v]];
                v = parent[v];
            }
            v
        }
        for (v, k) in voxels.iter().enumerate() {
            for dx in -1..=1i64 {
                for dy in -1..=1i64 {
                    for dz in -1..=1i64 {
                        if (dx, dy, dz) <= (0, 0, 0) {
                            continue;
                        }
                        let neighbour = [k[0] + dx, k[1] + dy, k[2] + dz];
                        if let Ok(w) = voxels.binary_search(&neighbour) {
                            let (a, b) = (root(&mut parent, v), root(&mut parent, w));
                            if a != b {
                                parent[a.max(b)] = a.min(b);
                            }
                        }
                    }
                }
            }
        }
        // Gather clusters in order of their first point (smallest index).
        let mut clusters: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        let mut first_of_root: BTreeMap<usize, usize> = BTreeMap::new();
        for (i, &(_, k)) in keyed.iter().enumerate() {
            let r = root(&mut parent, voxel_of[i]);
            first_of_root.entry(r).and_modify(|f| *f = (*f).min(k)).or_insert(k);
            clusters.entry(r).or_default().push(k);
        }
        let mut ordered: Vec<(usize, Vec<usize>)> =
            clusters.into_iter().map(|(r, pts)| (first_of_root.get(&r).copied().unwrap_or(usize::MAX), pts)).collect();
        ordered.sort_by_key(|(first, _)| *first);
        for (_, cluster_points) in ordered {
            if cluster_points.len() < limits.min_points || cluster_points.len() > limits.max_points {
                continue;
            }
            let (mut lo, mut hi, mut sum) = (Vector3::repeat(f64::MAX), Vector3::repeat(f64::MIN), Vector3::zeros());
            for &k in &cluster_points {
                let p = points[k].coords;
                lo = lo.inf(&p);
                hi = hi.sup(&p);
                sum += p;
            }
            let extent = hi - lo;
            if extent.max() > limits.max_extent_m || extent.z < config.min_height_m {
                continue;
            }
            if config.min_height_m > 0.0 && thickness_along_normal(points, &cluster_points) < config.min_height_m {
                continue;
            }
            out.push(ObjectCandidate {
                label,
                centroid: Point3::from(sum / cluster_points.len() as f64),
                size: extent,
                points: cluster_points.len(),
            });
        }
    }
    out
}

/// The cluster's extent along its normal (the eigenvector of its covariance's smallest
/// eigenvalue) when that normal is within [`MAX_GROUND_TILT_DEG`] of z; infinite otherwise (the
/// cluster stands rather than lies) or when the normal is undefined.
fn thickness_along_normal(points: &[Point3<f64>], members: &[usize]) -> f64 {
    let n = members.len() as f64;
    let mean = members.iter().map(|&k| points[k].coords).sum::<Vector3<f64>>() / n;
    let covariance = members.iter().fold(nalgebra::Matrix3::zeros(), |c, &k| {
        let d = points[k].coords - mean;
        c + d * d.transpose() / n
    });
    let eigen = covariance.symmetric_eigen();
    let smallest = eigen.eigenvalues.imin();
    let normal = eigen.eigenvectors.column(smallest).into_owned();
    if !normal.iter().all(|v| v.is_finite()) || normal.z.abs() < MAX_GROUND_TILT_DEG.to_radians().cos() {
        return f64::INFINITY;
    }
    let (lo, hi) = members.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &k| {
        let d = normal.dot(&points[k].coords);
        (lo.min(d), hi.max(d))
    });
    hi - lo
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn boxed(rng: &mut ChaCha8Rng, centre: [f64; 3], half: f64, n: usize) -> Vec<Point3<f64>> {
        (0..n)
            .map(|_| {
                Point3::new(
                    centre[0] + rng.random_range(-half..half),
                    centre[1] + rng.random_range(-half..half),
                    centre[2] + rng.random_range(-half..half),
                )
            })
            .collect()
    }

    #[test]
    fn flat_clusters_are_refused_when_asked() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        // A 2 m × 2 m patch of "object" labels on the ground, and a real 1 m box.
        let mut points: Vec<Point3<f64>> =
            (0..200).map(|_| Point3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), -0.8)).collect();
        points.extend(boxed(&mut rng, [10.0, 0.0, 0.0], 0.5, 200));
        let labels = vec![Some(LabelId(3)); points.len()];
        let all = cluster(&points, &labels, &ClusterConfig::default());
        assert_eq!(all.len(), 2);
        let upright = cluster(&points, &labels, &ClusterConfig { min_height_m: 0.2, ..ClusterConfig::default() });
        assert_eq!(upright.len(), 1);
        assert!((upright[0].centroid.x - 10.0).abs() < 0.1);
    }

    /// A patch of `side` × `side` m of ground labels on ground rising at `slope` along
    /// `azimuth` (2 cm of noise), and a 0.6 m box standing on that ground 8 m away.
    fn sloped_scene(rng: &mut ChaCha8Rng, slope: f64, azimuth: f64, side: f64) -> Vec<Point3<f64>> {
        let (c, s, tan) = (azimuth.cos(), azimuth.sin(), slope.tan());
        let ground = |x: f64, y: f64| -0.8 + tan * (c * x + s * y);
        let half = side / 2.0;
        let mut points: Vec<Point3<f64>> = (0..300)
            .map(|_| {
                let (x, y) = (rng.random_range(-half..half), rng.random_range(-half..half));
                Point3::new(x, y, ground(x, y) + rng.random_range(-0.02..0.02))
            })
            .collect();
        let (bx, by) = (8.0 * c, 8.0 * s);
        points.extend(boxed(rng, [bx, by, ground(bx, by) + 0.3], 0.3, 200));
        points
    }

    #[test]
    fn a_label_patch_on_a_10_degree_slope_is_refused_and_the_box_on_it_kept() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        // 2.5 m of a 10° slope rises 0.44 m along z: the old z-extent test took it for an object.
        let points = sloped_scene(&mut rng, 10f64.to_radians(), 0.4, 2.5);
        let labels = vec![Some(LabelId(3)); points.len()];
        let config = ClusterConfig { min_height_m: 0.2, ..ClusterConfig::default() };
        let kept = cluster(&points, &labels, &config);
        assert_eq!(kept.len(), 1, "{kept:?}");
        assert!((kept[0].centroid.x - 8.0 * 0.4f64.cos()).abs() < 0.1);
    }

    #[test]
    fn a_thin_standing_object_is_not_taken_for_ground() {
        // A sign: 1 m wide, 1.2 m tall, 3 cm thick; its thinnest side is horizontal.
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let points: Vec<Point3<f64>> = (0..300)
            .map(|_| Point3::new(rng.random_range(0.0..0.03), rng.random_range(-0.5..0.5), rng.random_range(0.0..1.2)))
            .collect();
        let labels = vec![Some(LabelId(3)); points.len()];
        let config = ClusterConfig { min_height_m: 0.2, ..ClusterConfig::default() };
        assert_eq!(cluster(&points, &labels, &config).len(), 1);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// Ground up to 25° steep relative to the sensor (a 15° hill under a body tilted the
        /// other way), in any direction, patches of 1 to 3 m: the patch is refused, the box kept.
        #[test]
        fn label_patches_on_slopes_are_refused(
            slope_deg in 0.0..25.0f64,
            azimuth in 0.0..std::f64::consts::TAU,
            side in 1.0..3.0f64,
            seed: u64,
        ) {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let points = sloped_scene(&mut rng, slope_deg.to_radians(), azimuth, side);
            let labels = vec![Some(LabelId(3)); points.len()];
            let config = ClusterConfig { min_height_m: 0.2, ..ClusterConfig::default() };
            let kept = cluster(&points, &labels, &config);
            proptest::prop_assert_eq!(kept.len(), 1);
            let box_at = Point3::new(8.0 * azimuth.cos(), 8.0 * azimuth.sin(), 0.0);
            proptest::prop_assert!((kept[0].centroid.xy() - box_at.xy()).norm() < 0.1);
        }
    }

    #[test]
    fn separates_boxes_by_class_and_distance_and_drops_implausible_ones() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut points = Vec::new();
        let mut labels = Vec::new();
        let mut add = |pts: Vec<Point3<f64>>, label: Option<u16>| {
            labels.extend(std::iter::repeat_n(label.map(LabelId), pts.len()));
            points.extend(pts);
        };
        add(boxed(&mut rng, [0.0, 0.0, 0.5], 0.3, 200), Some(1)); // chair A
        add(boxed(&mut rng, [3.0, 0.0, 0.5], 0.3, 200), Some(1)); // chair B, 3 m away
        add(boxed(&mut rng, [0.0, 0.0, 0.5], 0.3, 150), Some(2)); // a table in the same place, other class
        add(boxed(&mut rng, [10.0, 10.0, 0.5], 0.05, 5), Some(1)); // too few points
        add(boxed(&mut rng, [5.0, 5.0, 0.5], 0.3, 300), None); // unlabelled
        let wall: Vec<Point3<f64>> = (0..600).map(|k| Point3::new(20.0 + 0.05 * k as f64, 0.0, 1.0)).collect(); // 30 m long
        add(wall, Some(1));
        let candidates = cluster(&points, &labels, &ClusterConfig::default());
        assert_eq!(candidates.len(), 3, "{candidates:?}");
        let chairs: Vec<_> = candidates.iter().filter(|c| c.label == LabelId(1)).collect();
        assert_eq!(chairs.len(), 2);
        assert!((chairs[0].centroid - Point3::new(0.0, 0.0, 0.5)).norm() < 0.05);
        assert!((chairs[1].centroid - Point3::new(3.0, 0.0, 0.5)).norm() < 0.05);
        assert!(chairs.iter().all(|c| c.points == 200 && c.size.max() < 0.6 && c.size.min() > 0.5));
        let table = candidates.iter().find(|c| c.label == LabelId(2)).unwrap();
        assert_eq!(table.points, 150);
        // Per-class limits: walls of class 1 become acceptable with a larger extent.
        let mut config = ClusterConfig::default();
        config.classes.insert(1, ClassLimits { max_extent_m: 50.0, ..ClassLimits::default() });
        assert_eq!(cluster(&points, &labels, &config).len(), 4);
    }
}
